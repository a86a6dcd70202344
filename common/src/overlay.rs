//! Tool geometry (G10 §5 "overlaying rasterised images"): the 3D cursor,
//! the clip plane's outline, the probe's sphere and the band picker's axis,
//! with text labels, drawn over every view's volume image. Each shape is a
//! set of display-space polylines and anchored labels; the back end
//! rasterises them with a wgpu render pass (`shaders/overlay.wgsl`) whose
//! vertex stage projects each point by [`project`]: in a light field view
//! a point lands where the projector's Eq. 1 ray through it leaves the
//! projector, so every eye sees the cursor at the same place in space.
//!
//! ```toml
//! [render.overlay]
//! show = true
//! cursor = [0.0, 0.0, 0.05]  # m, display space; leave out for no cursor
//! cursor_size = 0.015        # m, half the crosshair's arm; 0: the dot alone
//! labels = true
//! label_height = 0.012       # m: text in space, parallel to the screen
//! line_width = 2.0           # pixels
//! color = [1.0, 0.85, 0.2, 1.0]
//! depth = false              # true: hidden behind the volume's opaque parts
//! ```
//!
//! By default the geometry shines through the volume (it is drawn over the
//! image). With `depth`, each fragment is compared with its pixel's depth
//! (where the ray's opacity first reaches ½) and hidden behind it. That
//! needs straight rays: with refraction it is refused (G10 §5).

use crate::camera::View;
use crate::tools::{PackContext, Tool};
use anyhow::{bail, Result};
use glam::DVec3;
use serde::{Deserialize, Serialize};

/// `[render.overlay]`: what is drawn over the volume. Off by default: a
/// scene without it pays nothing.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Overlay {
    /// Draw the tools' geometry and the cursor.
    #[serde(default)]
    pub show: bool,
    /// The 3D cursor (m, display space).
    #[serde(default)]
    pub cursor: Option<[f64; 3]>,
    /// Half the length of the cursor's crosshair arms (m); 0 draws only its
    /// dot.
    #[serde(default = "default_cursor_size")]
    pub cursor_size: f64,
    /// Name each shape beside it.
    #[serde(default = "yes")]
    pub labels: bool,
    /// The labels' text height (m): text in space, in the plane parallel
    /// to the screen through the shape's anchor.
    #[serde(default = "default_label_height")]
    pub label_height: f64,
    /// Lines' width (pixels of each view).
    #[serde(default = "default_width")]
    pub line_width: f64,
    /// RGBA, 0–1, straight (not premultiplied) alpha.
    #[serde(default = "default_color")]
    pub color: [f64; 4],
    /// Depth combination: geometry behind the point where its pixel's ray
    /// reaches opacity ½ is hidden. Refused with refraction.
    #[serde(default)]
    pub depth: bool,
}

fn default_cursor_size() -> f64 {
    0.015
}

fn yes() -> bool {
    true
}

fn default_label_height() -> f64 {
    0.012
}

fn default_width() -> f64 {
    2.0
}

fn default_color() -> [f64; 4] {
    [1.0, 0.85, 0.2, 1.0]
}

impl Default for Overlay {
    fn default() -> Self {
        Overlay {
            show: false,
            cursor: None,
            cursor_size: default_cursor_size(),
            labels: yes(),
            label_height: default_label_height(),
            line_width: default_width(),
            color: default_color(),
            depth: false,
        }
    }
}

impl Overlay {
    /// Checks the table; `what` names the file, `refraction` says whether
    /// rays bend.
    pub fn check(&self, what: &str, refraction: bool) -> Result<()> {
        if self.show && self.depth && refraction {
            bail!(
                "{what}: render.overlay.depth: depth combination needs straight rays, and render.refraction bends them (G10 §5); draw the geometry over the volume (depth = false) or turn refraction off"
            );
        }
        if let Some(c) = self.cursor {
            if !c.iter().all(|x| x.is_finite() && x.abs() <= 10.0) {
                bail!("{what}: render.overlay.cursor must be finite and within 10 m (got {c:?})");
            }
        }
        if !(self.cursor_size.is_finite() && (0.0..=10.0).contains(&self.cursor_size)) {
            bail!(
                "{what}: render.overlay.cursor_size must be in [0, 10] m (got {})",
                self.cursor_size
            );
        }
        if !(self.label_height.is_finite() && self.label_height > 0.0 && self.label_height <= 1.0) {
            bail!(
                "{what}: render.overlay.label_height must be in (0, 1] m (got {})",
                self.label_height
            );
        }
        if !(self.line_width.is_finite() && (0.5..=64.0).contains(&self.line_width)) {
            bail!(
                "{what}: render.overlay.line_width must be in [0.5, 64] pixels (got {})",
                self.line_width
            );
        }
        if !self
            .color
            .iter()
            .all(|c| c.is_finite() && (0.0..=1.0).contains(c))
        {
            bail!(
                "{what}: render.overlay.color must be four values in [0, 1] (got {:?})",
                self.color
            );
        }
        Ok(())
    }
}

/// Where display point `x` lands in `view`: the pixel coordinates (x right,
/// y down, pixel centres at .5) of the screen point Q whose ray (G10 Eq. 1,
/// [`View::ray`]) passes through `x`; `None` for a point at or behind the
/// observer's depth, which no ray reaches.
///
/// With t = 1 − x_z/V_z the ray's parameter at x's depth (the ray runs
/// from O at V_z to Q at z = 0), Q_y = V_y + (x_y − V_y)/t, and since O_x =
/// a + b·Q_x is affine in Q_x (a = (1−η)·V_x + η·E_x·(1 − c), b = η·c, c =
/// (E_z − V_z)/E_z), x_x = O_x + t·(Q_x − O_x) gives Q_x = (x_x − a·(1 − t))
/// / (b·(1 − t) + t).
pub fn project(view: &View, x: DVec3) -> Option<[f64; 2]> {
    let [vx, vy, vz] = view.observer;
    let [ex, _, ez] = view.eye;
    let t = 1.0 - x.z / vz;
    if t.is_nan() || t <= 1e-9 || vz.abs() < 1e-12 {
        return None;
    }
    let c = if ez.abs() > 1e-12 {
        (ez - vz) / ez
    } else {
        0.0
    };
    let eta = view.eta;
    let a = (1.0 - eta) * vx + eta * ex * (1.0 - c);
    let b = eta * c;
    let den = b * (1.0 - t) + t;
    if den.abs() < 1e-12 {
        return None;
    }
    let qx = (x.x - a * (1.0 - t)) / den;
    let qy = vy + (x.y - vy) / t;
    let [x0, y0, rw, rh] = view.region;
    let [w, h] = view.resolution;
    Some([(qx - x0) / rw * w as f64, (y0 + rh - qy) / rh * h as f64])
}

/// One thing to draw: a polyline through display points, a text label
/// (text in space, parallel to the screen, up and right of its anchor), or
/// a dot of a few pixels centred on its point.
#[derive(Clone, Debug, PartialEq)]
pub enum Shape {
    Polyline(Vec<DVec3>),
    Label(DVec3, String),
    Dot(DVec3),
}

/// Segments a curve is cut into: Eq. 1's projection bends straight lines
/// of a light field view (its x and y have different denominators), so a
/// straight edge is drawn as a polyline too.
pub const SEGMENTS: usize = 32;

pub(crate) fn subdivided(a: DVec3, b: DVec3) -> Vec<DVec3> {
    (0..=SEGMENTS)
        .map(|i| a.lerp(b, i as f64 / SEGMENTS as f64))
        .collect()
}

pub(crate) fn circle(c: DVec3, r: f64, u: DVec3, v: DVec3) -> Vec<DVec3> {
    let n = 2 * SEGMENTS;
    (0..=n)
        .map(|i| {
            let a = std::f64::consts::TAU * i as f64 / n as f64;
            c + (u * a.cos() + v * a.sin()) * r
        })
        .collect()
}

/// The shapes of the overlay: the cursor and each tool's geometry, in
/// display space (`ctx` places the volume).
pub fn shapes(overlay: &Overlay, tools: &[Tool], ctx: &PackContext) -> Vec<Shape> {
    let mut out = Vec::new();
    if !overlay.show {
        return out;
    }
    let label = |out: &mut Vec<Shape>, at: DVec3, text: String| {
        if overlay.labels {
            out.push(Shape::Label(at, text));
        }
    };
    if let Some(c) = overlay.cursor {
        let c = DVec3::from(c);
        out.push(Shape::Dot(c));
        let s = overlay.cursor_size;
        if s > 0.0 {
            for axis in [DVec3::X, DVec3::Y, DVec3::Z] {
                out.push(Shape::Polyline(subdivided(c - axis * s, c + axis * s)));
            }
        }
        label(&mut out, c, "cursor".into());
    }
    for tool in tools {
        out.extend(
            tool.shapes(ctx)
                .into_iter()
                .filter(|s| overlay.labels || !matches!(s, Shape::Label(..))),
        );
    }
    out
}

/// The clip plane's outline: where it cuts the volume's box, in display
/// space, in order around the polygon (empty where it misses the box).
pub fn plane_in_box(plane: &crate::tools::ClipPlane, ctx: &PackContext) -> Vec<DVec3> {
    let v = plane.in_volume(&ctx.placement, ctx.extent);
    let e = DVec3::from(ctx.extent);
    let corner = |i: usize| {
        DVec3::new(
            if i & 1 == 0 { 0.0 } else { e.x },
            if i & 2 == 0 { 0.0 } else { e.y },
            if i & 4 == 0 { 0.0 } else { e.z },
        )
    };
    let mut pts = Vec::new();
    for i in 0..8 {
        for bit in [1, 2, 4] {
            let j = i | bit;
            if j == i {
                continue;
            }
            let (a, b) = (corner(i), corner(j));
            let (da, db) = (v.normal.dot(a) + v.offset, v.normal.dot(b) + v.offset);
            if (da <= 0.0) != (db <= 0.0) {
                pts.push(a + (b - a) * (da / (da - db)));
            }
        }
    }
    if pts.len() < 3 {
        return Vec::new();
    }
    let centre = pts.iter().copied().sum::<DVec3>() / pts.len() as f64;
    let n = v.unit;
    let u = (pts[0] - centre).normalize_or_zero();
    let w = n.cross(u);
    pts.sort_by(|a, b| {
        let (ra, rb) = (*a - centre, *b - centre);
        ra.dot(w)
            .atan2(ra.dot(u))
            .total_cmp(&rb.dot(w).atan2(rb.dot(u)))
    });
    pts.into_iter()
        .map(|q| ctx.placement.to_display(ctx.extent, q))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Placement;
    use crate::tools::ClipPlane;

    /// The pixel `project` gives is the one whose Eq. 1 ray passes through
    /// the point: in a window, a light field view (η = 1) and halfway.
    #[test]
    fn projected_pixels_rays_pass_through_the_point() {
        for eta in [0.0, 0.5, 1.0] {
            let view = View {
                resolution: [200, 100],
                region: [-0.5, -0.25, 1.0, 0.5],
                eye: [0.7, 0.1, -2.0],
                observer: [-0.1, 0.05, 2.5],
                eta,
            };
            for x in [
                DVec3::new(0.0, 0.0, 0.0),
                DVec3::new(0.1, -0.05, 0.2),
                DVec3::new(-0.2, 0.1, -0.3),
            ] {
                let [px, py] = project(&view, x).unwrap();
                // The ray through the fractional pixel: screen point from
                // the same map View::screen_point uses.
                let [x0, y0, rw, rh] = view.region;
                let q = DVec3::new(x0 + px / 200.0 * rw, y0 + rh - py / 100.0 * rh, 0.0);
                // View::ray at pixel centres; here its formula at Q.
                let (v, e) = (DVec3::from(view.observer), DVec3::from(view.eye));
                let mcop = e.x + (q.x - e.x) / (q.z - e.z) * (v.z - e.z);
                let o = DVec3::new((1.0 - eta) * v.x + eta * mcop, v.y, v.z);
                let d = (q - o).normalize();
                let miss = (x - o).cross(d).length();
                assert!(miss < 1e-12, "η {eta}, {x}: the ray misses by {miss}");
            }
        }
        let view = View::window([10, 10], [1.0, 1.0], [0.0, 0.0, 1.0]);
        assert!(project(&view, DVec3::new(0.0, 0.0, 1.0)).is_none());
        assert!(project(&view, DVec3::new(0.0, 0.0, 2.0)).is_none());
    }

    #[test]
    fn a_plane_through_the_centre_cuts_the_box_in_a_square() {
        let ctx = PackContext {
            placement: Placement {
                center: [0.0; 3],
                rotation_deg: [0.0; 3],
                size: 0.2,
            },
            extent: [10.0, 10.0, 10.0],
            gradient_max: 1.0,
        };
        let plane = ClipPlane {
            point: [0.0; 3],
            normal: [0.0, 0.0, 1.0],
            thickness: 0.0,
            context: [0.3, 0.7],
        };
        let poly = plane_in_box(&plane, &ctx);
        assert_eq!(poly.len(), 4);
        for q in &poly {
            assert!(q.z.abs() < 1e-12 && (q.x.abs() - 0.1).abs() < 1e-12);
        }
        let far = ClipPlane {
            point: [0.0, 0.0, 5.0],
            ..plane
        };
        assert!(plane_in_box(&far, &ctx).is_empty());
    }

    #[test]
    fn bad_overlays_name_the_field() {
        let bad = [
            Overlay {
                cursor: Some([f64::NAN, 0.0, 0.0]),
                ..Default::default()
            },
            Overlay {
                line_width: 0.0,
                ..Default::default()
            },
            Overlay {
                color: [1.0, 2.0, 0.0, 1.0],
                ..Default::default()
            },
        ];
        for (o, field) in bad.iter().zip(["cursor", "line_width", "color"]) {
            let e = o.check("s.toml", false).unwrap_err().to_string();
            assert!(e.contains("s.toml") && e.contains(field), "{e}");
        }
        Overlay::default().check("s.toml", false).unwrap();
        let depth = Overlay {
            show: true,
            depth: true,
            ..Default::default()
        };
        depth.check("s.toml", false).unwrap();
        let e = depth.check("s.toml", true).unwrap_err().to_string();
        assert!(
            e.contains("render.overlay.depth") && e.contains("refraction"),
            "{e}"
        );
    }
}
