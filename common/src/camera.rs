//! Where a pixel's ray comes from: the scene placement (display space ↔
//! volume space) and the multiple-centre-of-projection ray of G10 §4 Eq. 1
//! (docs/design.md "Which ray a pixel gets").

use glam::{DMat3, DVec3};
use serde::{Deserialize, Serialize};

/// Where the volume's box sits in display space (metres): a volume point p
/// maps to center + R·(size / max(N·s))·(p − N·s/2), R rotating about x, then
/// y, then z (fixed axes) (docs/design.md "Volume space").
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Placement {
    pub center: [f64; 3],
    #[serde(default)]
    pub rotation_deg: [f64; 3],
    /// Length of the box's longest side in display space (m).
    pub size: f64,
}

impl Placement {
    pub fn rotation(&self) -> DMat3 {
        let [rx, ry, rz] = self.rotation_deg.map(f64::to_radians);
        DMat3::from_rotation_z(rz) * DMat3::from_rotation_y(ry) * DMat3::from_rotation_x(rx)
    }

    /// Display metres per data length unit.
    pub fn scale(&self, extent: [f64; 3]) -> f64 {
        self.size / extent.iter().cloned().fold(0.0, f64::max)
    }

    /// Maps a display-space ray to volume space. The direction stays a unit
    /// vector, so distances along the returned ray are in data units.
    pub fn ray_to_volume(&self, extent: [f64; 3], origin: DVec3, dir: DVec3) -> (DVec3, DVec3) {
        let rt = self.rotation().transpose();
        let half = DVec3::from(extent) * 0.5;
        let o = rt * (origin - DVec3::from(self.center)) / self.scale(extent) + half;
        (o, (rt * dir).normalize())
    }

    /// Maps a volume point to display space.
    pub fn to_display(&self, extent: [f64; 3], p: DVec3) -> DVec3 {
        let half = DVec3::from(extent) * 0.5;
        DVec3::from(self.center) + self.rotation() * ((p - half) * self.scale(extent))
    }
}

/// Largest side of a view, pixels (a 16K projector or window).
pub const MAX_VIEW_SIDE: u32 = 16384;
/// Most pixels rendered by one back end in one frame, all its views
/// together (2^28: pixel offsets stay 32-bit on the GPU; 4 GiB of float
/// RGBA). Counted in u64 so no sum of resolutions can wrap.
pub const MAX_FRAME_PIXELS: u64 = 1 << 28;

/// One rendered view: a projector (or a window) whose W×H image covers the
/// screen region (x0, y0, w, h) of the z = 0 plane.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct View {
    pub resolution: [u32; 2],
    /// [x0, y0, w, h] in metres.
    pub region: [f64; 4],
    /// The projector position E (for a window: the eye).
    pub eye: [f64; 3],
    /// The observer V.
    pub observer: [f64; 3],
    /// η: 0 = one perspective view from V, 1 = full horizontal parallax.
    pub eta: f64,
}

impl View {
    /// A desktop window: one perspective view from `eye` through the screen
    /// rectangle centred on the origin (η = 0, the eye is the observer).
    pub fn window(resolution: [u32; 2], screen: [f64; 2], eye: [f64; 3]) -> Self {
        View {
            resolution,
            region: [-screen[0] / 2.0, -screen[1] / 2.0, screen[0], screen[1]],
            eye,
            observer: eye,
            eta: 0.0,
        }
    }

    /// The screen point Q of pixel (col i, row j), row 0 at the top.
    pub fn screen_point(&self, i: u32, j: u32) -> DVec3 {
        let [w, h] = self.resolution;
        let [x0, y0, rw, rh] = self.region;
        DVec3::new(
            x0 + (i as f64 + 0.5) / w as f64 * rw,
            y0 + rh - (j as f64 + 0.5) / h as f64 * rh,
            0.0,
        )
    }

    /// The ray of pixel (i, j): origin O from G10 Eq. 1, direction towards Q.
    ///
    /// O = ((1−η)·V_x + η·(E_x + (Q_x−E_x)/(Q_z−E_z)·(V_z−E_z)), V_y, V_z).
    /// E on the screen plane (E_z = Q_z = 0) has no such ray: the caller
    /// rejects that geometry when the display is loaded; here it falls back to
    /// the η = 0 origin rather than dividing by zero.
    pub fn ray(&self, i: u32, j: u32) -> (DVec3, DVec3) {
        let q = self.screen_point(i, j);
        let e = DVec3::from(self.eye);
        let v = DVec3::from(self.observer);
        let dz = q.z - e.z;
        let mcop_x = if dz.abs() > 1e-12 {
            e.x + (q.x - e.x) / dz * (v.z - e.z)
        } else {
            v.x
        };
        let o = DVec3::new((1.0 - self.eta) * v.x + self.eta * mcop_x, v.y, v.z);
        let d = q - o;
        let len = d.length();
        let dir = if len > 0.0 { d / len } else { DVec3::NEG_Z };
        (o, dir)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn window_rays_pass_through_pixel_centres() {
        let v = View::window([4, 2], [0.4, 0.2], [0.0, 0.0, 1.0]);
        let (o, d) = v.ray(0, 0);
        assert_eq!(o, DVec3::new(0.0, 0.0, 1.0));
        // pixel (0,0): Q = (-0.15, 0.05, 0)
        let q = o + d * (1.0 / -d.z);
        assert!((q - DVec3::new(-0.15, 0.05, 0.0)).length() < 1e-12);
    }

    #[test]
    fn full_parallax_ray_passes_through_the_projector() {
        // η = 1: the ray from O through Q, extended back, meets the
        // projector's depth at the projector's x (the projector emits it).
        let v = View {
            resolution: [8, 8],
            region: [-0.5, -0.5, 1.0, 1.0],
            eye: [0.3, 0.0, -2.0],
            observer: [0.0, 0.1, 2.5],
            eta: 1.0,
        };
        for i in 0..8 {
            let (o, d) = v.ray(i, 3);
            let t = (v.eye[2] - o.z) / d.z;
            let p = o + d * t;
            assert!((p.x - v.eye[0]).abs() < 1e-12, "{p:?}");
        }
    }

    #[test]
    fn degenerate_geometry_gives_finite_rays() {
        // η outside [0, 1] extrapolates Eq. 1 (depth exaggeration or
        // inversion), a projector on the screen plane falls back to η = 0,
        // an observer on the screen point gets a fixed direction: never NaN.
        for eta in [-3.0, -1.0, 0.0, 0.5, 1.0, 2.0, 1e6] {
            for eye_z in [-2.0, 0.0, 1e-15, 3.0] {
                let v = View {
                    resolution: [5, 3],
                    region: [-0.5, -0.5, 1.0, 1.0],
                    eye: [0.3, 0.1, eye_z],
                    observer: [0.0, 0.0, 2.0],
                    eta,
                };
                for i in 0..5 {
                    for j in 0..3 {
                        let (o, d) = v.ray(i, j);
                        assert!(
                            o.is_finite() && d.is_finite(),
                            "η {eta}, E_z {eye_z}: {o:?} {d:?}"
                        );
                        assert!((d.length() - 1.0).abs() < 1e-12);
                    }
                }
            }
        }
        let on_screen = View {
            resolution: [1, 1],
            region: [-0.5, -0.5, 1.0, 1.0],
            eye: [0.0, 0.0, 0.0],
            observer: [0.0, 0.0, 0.0],
            eta: 0.0,
        };
        let (o, d) = on_screen.ray(0, 0);
        assert!(o.is_finite() && d.is_finite());
    }

    #[test]
    fn placement_round_trip() {
        let pl = Placement {
            center: [0.1, -0.2, 0.3],
            rotation_deg: [30.0, -45.0, 10.0],
            size: 0.5,
        };
        let ext = [181.0, 217.0, 181.0];
        let p = DVec3::new(10.0, 20.0, 30.0);
        let q = pl.to_display(ext, p);
        let (back, _) = pl.ray_to_volume(ext, q, DVec3::X);
        assert!((back - p).length() < 1e-9);
        // the longest side maps to `size`
        let a = pl.to_display(ext, DVec3::ZERO);
        let b = pl.to_display(ext, DVec3::new(0.0, 217.0, 0.0));
        assert!(((a - b).length() - 0.5).abs() < 1e-12);
    }
}
