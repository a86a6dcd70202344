//! Where a node is and how large its voxels look: node boxes in volume space,
//! projected voxel size per view (G08 §4, L12 §4.2 "the projected size of a
//! voxel"), and the view-frustum test (G08 §4, L12 §4.2).

use crate::geometry::SceneGeometry;
use crate::store::NodeKey;
use glam::DVec3;
use parallax_common::camera::View;

/// Observer closer than this (metres) to a node's box counts as inside it:
/// the node's voxels project to an unbounded number of pixels.
const TOUCHING_M: f64 = 1e-9;

/// A light field display's spatial resolution (G10 §4): s(z) = s0 +
/// 2|z|·tan(Φ/2) at distance |z| from the screen plane.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LightField {
    /// s0: the pixel size on the screen (m).
    pub pixel_size: f64,
    /// Φ: the screen's angular accuracy (degrees).
    pub angular_accuracy_deg: f64,
}

impl LightField {
    pub fn resolution_at(&self, z: f64) -> f64 {
        self.pixel_size + 2.0 * z.abs() * (self.angular_accuracy_deg.to_radians() / 2.0).tan()
    }
}

/// One view, prepared for a frame.
#[derive(Clone, Debug)]
struct ViewGeom {
    /// The observer V in display space and in volume space.
    observer: DVec3,
    observer_vol: DVec3,
    /// Distance from the observer to the screen plane, |V_z|.
    screen_dist: f64,
    /// Width of one of the view's pixels on the screen (m).
    pixel_m: f64,
    /// The pyramids (apex, inward normals of the four side planes) whose
    /// union holds every ray of the view: one from the observer (η = 0), or
    /// two from the ends of the segment that a multi-centre projector's ray
    /// origins lie on (η > 0, G10 Eq. 1); `None` = no culling (a degenerate
    /// view).
    planes: Option<Vec<(DVec3, [DVec3; 4])>>,
    /// A light field view (η > 0): its detail follows s(z), not its pixels.
    parallax: bool,
}

/// What refinement needs to know about a node this frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Assessment {
    /// Projected voxel size in display pixels: the largest over the views
    /// that may see the node (G10 §5: the finest requirement among this
    /// process's views); over all views when none does.
    pub pixels: f64,
    /// The same from the distance to the closest point alone (what L12
    /// §4.2.1 improves on off the view axis; kept for tests and figures).
    pub distance_pixels: f64,
    /// Whether at least one view frustum contains (part of) the node.
    pub seen: bool,
}

/// The views of one frame in the placement of one frame.
pub(crate) struct FrameGeometry {
    scene: SceneGeometry,
    scale: f64,
    views: Vec<ViewGeom>,
    lightfield: Option<LightField>,
}

impl FrameGeometry {
    pub fn new(scene: &SceneGeometry, views: &[View]) -> Self {
        let scale = scene.scale();
        let (placement, extent) = (&scene.placement, scene.extent());
        let views: Vec<ViewGeom> = views
            .iter()
            .map(|v| {
                let observer = DVec3::from(v.observer);
                let (observer_vol, _) = placement.ray_to_volume(extent, observer, DVec3::X);
                ViewGeom {
                    observer,
                    observer_vol,
                    screen_dist: v.observer[2].abs(),
                    pixel_m: v.region[2] / v.resolution[0].max(1) as f64,
                    planes: view_pyramids(v),
                    parallax: v.eta != 0.0,
                }
            })
            .collect();
        FrameGeometry {
            scene: *scene,
            scale,
            views,
            lightfield: None,
        }
    }

    /// Views with η > 0 take their level of detail from the display's
    /// depth-dependent resolution (G10 §4).
    pub fn with_lightfield(mut self, lightfield: Option<LightField>) -> Self {
        self.lightfield = lightfield;
        self
    }

    /// Projected voxel size and frustum status of a node.
    ///
    /// For a view, the larger of two estimates:
    ///
    /// * by distance: voxel_m · D / (dist · pixel_m), voxel_m the node's
    ///   voxel edge in display metres, D = |V_z| the observer's distance to
    ///   the screen, dist the distance from the observer to the closest point
    ///   of the node's box, pixel_m = region width / W (G08 §4). The
    ///   placement is a similarity, so the closest point is found exactly by
    ///   clamping the observer, mapped to volume space, to the box there;
    ///   dist ≈ 0 (the observer inside or on the box) gives +∞;
    /// * L12 §4.2.1 Eq. 1: the projection on the screen plane of the box's
    ///   bounding sphere (radius R, centre O), |A'B'| = D·|tan(α+β) +
    ///   tan(α−β)| with sin α = R/|VO| and β the angle between VO and the
    ///   screen normal, divided by the voxels across the sphere (2R/voxel_m).
    ///   Off the view axis this grows as 1/cos²β, where the distance alone
    ///   under-refines (L12 Fig. 4); a sphere that reaches the observer's
    ///   plane (α + β ≥ 90°) gives +∞.
    pub fn assess(&self, key: NodeKey) -> Assessment {
        let (lo, hi) = self.scene.geom.node_box(key);
        let voxel_m = self.scene.geom.voxel_len(key.level as u32) * self.scale;
        let lf = self
            .lightfield
            .filter(|_| self.views.iter().any(|v| v.parallax));
        let corners = self.corners(lo, hi);
        // Light field: the display resolves s(z) at the node's depth closest
        // to the screen plane (0 where the node straddles it).
        let lf_pixels = lf.map(|lf| {
            let (zmin, zmax) = corners
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
                    (a.min(p.z), b.max(p.z))
                });
            let z = if zmin <= 0.0 && zmax >= 0.0 {
                0.0
            } else {
                zmin.abs().min(zmax.abs())
            };
            voxel_m / lf.resolution_at(z)
        });
        let centre = self.scene.to_display((lo + hi) * 0.5);
        let radius = (hi - lo).length() * 0.5 * self.scale;
        let mut best_seen = f64::NEG_INFINITY;
        let mut best_any = f64::NEG_INFINITY;
        let mut best_distance = f64::NEG_INFINITY;
        let mut seen = false;
        for v in &self.views {
            let closest = v.observer_vol.clamp(lo, hi);
            let dist = (closest - v.observer_vol).length() * self.scale;
            let by_distance = if dist <= TOUCHING_M || v.pixel_m <= 0.0 {
                f64::INFINITY
            } else {
                voxel_m * v.screen_dist / (dist * v.pixel_m)
            };
            let px = if let (true, Some(p)) = (v.parallax, lf_pixels) {
                p
            } else {
                // The point-wise size (what multilevel sampling blends by)
                // at the corners and the closest point.
                let closest_d = self.scene.to_display(closest);
                let pointwise = corners
                    .iter()
                    .chain(std::iter::once(&closest_d))
                    .map(|&p| point_pixels(p - v.observer, voxel_m, v.screen_dist, v.pixel_m))
                    .fold(0.0, f64::max);
                by_distance.max(pointwise).max(l12_pixels(
                    centre - v.observer,
                    radius,
                    voxel_m,
                    v.screen_dist,
                    v.pixel_m,
                ))
            };
            best_distance = best_distance.max(by_distance);
            best_any = best_any.max(px);
            let inside = match &v.planes {
                Some(p) => box_in_union(p, &corners),
                None => true,
            };
            if inside {
                seen = true;
                best_seen = best_seen.max(px);
            }
        }
        let pixels = if seen { best_seen } else { best_any };
        Assessment {
            distance_pixels: best_distance.max(0.0),
            // no views (−∞) or a degenerate one (NaN): nothing to refine for
            pixels: if pixels.is_nan() {
                0.0
            } else {
                pixels.max(0.0)
            },
            seen,
        }
    }

    fn corners(&self, lo: DVec3, hi: DVec3) -> [DVec3; 8] {
        std::array::from_fn(|c| {
            let p = DVec3::new(
                if c & 1 == 0 { lo.x } else { hi.x },
                if c & 2 == 0 { lo.y } else { hi.y },
                if c & 4 == 0 { lo.z } else { hi.z },
            );
            self.scene.to_display(p)
        })
    }
}

/// L12 §4.2.1 Eq. 1: the size in pixels of one voxel (edge `voxel_m`) of a
/// node whose bounding sphere (radius `r`) is at `po` from the observer, on
/// the screen plane `d` away along its normal (pixels of `pixel_m`).
/// L12 §4.2.1 Eq. 1 in the limit of a small sphere at `rel` from the
/// observer: a voxel's projection on the screen plane, D·|VP|/Δz² times its
/// edge (the magnification 1/cos²β off the axis), in pixels. Multilevel
/// sampling (shaders/shared/sampling.wgsl `lod_offset`) blends levels by
/// the same size, so refinement takes the largest over a node's corners
/// and closest point; +∞ where the point reaches the observer's plane.
fn point_pixels(rel: DVec3, voxel_m: f64, d: f64, pixel_m: f64) -> f64 {
    let dz = rel.z.abs();
    if dz <= TOUCHING_M || pixel_m <= 0.0 {
        return f64::INFINITY;
    }
    voxel_m * d * rel.length() / (dz * dz * pixel_m)
}

fn l12_pixels(po: DVec3, r: f64, voxel_m: f64, d: f64, pixel_m: f64) -> f64 {
    let len = po.length();
    if pixel_m <= 0.0 || r <= 0.0 {
        return 0.0;
    }
    if len <= r {
        return f64::INFINITY;
    }
    let alpha = (r / len).asin();
    let beta = (po.z.abs() / len).clamp(0.0, 1.0).acos();
    if alpha + beta >= std::f64::consts::FRAC_PI_2 - 1e-9 {
        return f64::INFINITY;
    }
    let across = d * ((alpha + beta).tan() + (alpha - beta).tan()).abs();
    across / pixel_m * voxel_m / (2.0 * r)
}

/// The four side planes (inward normals, through the apex) of the pyramid
/// from `apex` through the screen rectangle `region` = [x0, y0, w, h] on
/// z = 0. `None` when the pyramid is degenerate (apex on the screen plane or
/// an empty region): such a view culls nothing.
fn frustum_planes(apex: DVec3, region: [f64; 4]) -> Option<[DVec3; 4]> {
    let [x0, y0, w, h] = region;
    if !(w > 0.0 && h > 0.0) || apex.z.abs() < 1e-12 || !apex.is_finite() {
        return None;
    }
    let q = [
        DVec3::new(x0, y0, 0.0),
        DVec3::new(x0 + w, y0, 0.0),
        DVec3::new(x0 + w, y0 + h, 0.0),
        DVec3::new(x0, y0 + h, 0.0),
    ];
    let mid = DVec3::new(x0 + w / 2.0, y0 + h / 2.0, 0.0) - apex;
    Some(std::array::from_fn(|e| {
        let n = (q[e] - apex).cross(q[(e + 1) % 4] - apex);
        if n.dot(mid) < 0.0 {
            -n
        } else {
            n
        }
    }))
}

/// The pyramids whose union holds every ray of `v`. With η > 0 the ray of
/// screen point Q starts at ((1−η)·V_x + η·M_x(Q), V_y, V_z), M_x(Q) the
/// multi-centre x of G10 Eq. 1, linear in Q_x: the origins lie on the
/// segment between those of the region's left and right edges, and every
/// ray lies in the pyramid from some point of that segment through the
/// region (see [`box_in_union`] for why the two end pyramids suffice).
fn view_pyramids(v: &View) -> Option<Vec<(DVec3, [DVec3; 4])>> {
    let observer = DVec3::from(v.observer);
    if v.eta == 0.0 {
        return frustum_planes(observer, v.region).map(|p| vec![(observer, p)]);
    }
    let e = DVec3::from(v.eye);
    let origin_x = |qx: f64| {
        let m = if e.z.abs() > 1e-12 {
            e.x + (qx - e.x) / (-e.z) * (observer.z - e.z)
        } else {
            observer.x
        };
        (1.0 - v.eta) * observer.x + v.eta * m
    };
    let [x0, _, w, _] = v.region;
    let ends = [origin_x(x0), origin_x(x0 + w)];
    let mut out = Vec::new();
    for x in ends {
        let apex = DVec3::new(x, observer.y, observer.z);
        out.push((apex, frustum_planes(apex, v.region)?));
    }
    Some(out)
}

/// Conservative test against the union of pyramids through one screen
/// region whose apexes lie on a segment parallel to x: the box is outside
/// when, for one side of the region, all eight corners lie strictly outside
/// that side's plane of every end pyramid. The top and bottom planes do not
/// depend on the apex's x (they hold the x direction); a left or right plane
/// holds the y direction, and at any depth the union's leftmost (rightmost)
/// point is a ray from an end of the segment, x being linear along it. So
/// a point inside the union is inside one end pyramid's plane on every
/// side.
fn box_in_union(pyramids: &[(DVec3, [DVec3; 4])], corners: &[DVec3; 8]) -> bool {
    (0..4).all(|side| {
        pyramids
            .iter()
            .any(|(apex, planes)| corners.iter().any(|c| planes[side].dot(*c - *apex) >= 0.0))
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Geometry;
    use crate::store::OctreeLayout;
    use parallax_common::camera::Placement;

    /// The frame geometry of `views` with the volume `g` placed at `pl`.
    fn frame(g: &Geometry, views: &[View], pl: &Placement) -> FrameGeometry {
        FrameGeometry::new(
            &SceneGeometry {
                geom: *g,
                placement: *pl,
            },
            views,
        )
    }

    fn geom() -> Geometry {
        // 64³ voxels of 0.5 × 0.5 × 1.0, bricks of 8: L = 3.
        Geometry::new(OctreeLayout::new([64, 64, 64], 8), [0.5, 0.5, 1.0])
    }

    #[test]
    fn node_boxes_cover_and_clamp() {
        let g = Geometry::new(OctreeLayout::new([40, 64, 64], 8), [1.0, 1.0, 1.0]);
        assert_eq!(g.layout.levels, 4);
        // root covers 64 voxels, clamped to the 40-voxel x extent
        let (lo, hi) = g.node_box(NodeKey::root());
        assert_eq!(lo, DVec3::ZERO);
        assert_eq!(hi, DVec3::new(40.0, 64.0, 64.0));
        let (lo, hi) = g.node_box(NodeKey::new(2, 1, 2, 3));
        assert_eq!(lo, DVec3::new(16.0, 32.0, 48.0));
        assert_eq!(hi, DVec3::new(32.0, 48.0, 64.0));
        assert_eq!(g.voxel_len(3), 1.0);
        assert_eq!(g.voxel_len(0), 8.0);
    }

    #[test]
    fn light_field_views_follow_the_display_resolution() {
        // G10 §4: s(z) = s0 + 2|z|·tan(Φ/2). A level-3 node (voxel 0.5 data
        // units) of a box placed 20 cm in front of the screen.
        let g = geom();
        let pl = Placement {
            center: [0.0, 0.0, 0.35],
            rotation_deg: [0.0, 0.0, 0.0],
            size: 0.3,
        };
        let mut v = View::window([64, 64], [1.6, 0.9], [0.0, 0.0, 2.0]);
        v.eta = 1.0;
        let lf = LightField {
            pixel_size: 0.0015,
            angular_accuracy_deg: 0.8,
        };
        let f = frame(&g, &[v], &pl).with_lightfield(Some(lf));
        // the box spans z = 0.35 ± 0.15: closest to the screen at z = 0.2
        let key = NodeKey::new(3, 0, 0, 0);
        let voxel_m = 0.5 * 0.3 / 64.0;
        // node (0,0,0) lies at the box's back: z = 0.2 … 0.2375
        let want = voxel_m / (0.0015 + 2.0 * 0.2 * 0.4f64.to_radians().tan());
        let got = f.assess(key).pixels;
        assert!((got - want).abs() < 1e-9 * want, "{got} vs {want}");
        // without the light field, the same view uses its pixel grid
        let plain = frame(&g, &[v], &pl).assess(key).pixels;
        assert!((plain - want).abs() > 0.1 * want);
        // a node straddling the screen plane gets s0
        let pl0 = Placement {
            center: [0.0, 0.0, 0.0],
            ..pl
        };
        let f0 = frame(&g, &[v], &pl0).with_lightfield(Some(lf));
        // the root's voxels: 8 source voxels, its longest edge 8 · 1.0
        let root_voxel = 8.0 * 0.3 / 64.0;
        assert!((f0.assess(NodeKey::root()).pixels - root_voxel / 0.0015).abs() < 1e-9);
    }

    #[test]
    fn projected_size_matches_the_formula() {
        let g = geom();
        // extent 32 × 32 × 64: scale = 0.3 / 64 m per data unit
        let pl = Placement {
            center: [0.0, 0.0, 0.0],
            rotation_deg: [0.0, 0.0, 0.0],
            size: 0.3,
        };
        let v = View::window([64, 64], [0.4, 0.4], [0.0, 0.0, 2.0]);
        let f = frame(&g, &[v], &pl);
        let a = f.assess(NodeKey::root());
        // voxel size at level 0: its longest edge, 8 · 1.0 = 8 data units
        // = 8 · 0.3/64 m (a leaf's: its finest, 0.5); closest point: the
        // box front at z = +0.15, dist = 1.85.
        assert_eq!(
            (g.voxel_len(3), g.voxel_len(2), g.voxel_len(0)),
            (0.5, 2.0, 8.0)
        );
        let voxel_m = 8.0 * 0.3 / 64.0;
        let by_distance = voxel_m * 2.0 / (1.85 * (0.4 / 64.0));
        assert!((a.distance_pixels - by_distance).abs() < 1e-9 * by_distance);
        // The point-wise size (L12 for a small sphere, D·|VP|/Δz² per unit)
        // is largest at the front corners (±0.075, ±0.075, 0.15) m, a
        // little above the distance's; L12's bounding sphere gives less.
        let dist = (2.0 * 0.075f64.powi(2) + 1.85f64.powi(2)).sqrt();
        let want = voxel_m * 2.0 * dist / (1.85 * 1.85 * (0.4 / 64.0));
        assert!(want > by_distance && want < 1.01 * by_distance);
        assert!(
            (a.pixels - want).abs() < 1e-9 * want,
            "{} vs {want}",
            a.pixels
        );
        assert!(a.seen);
        // an observer inside the box: infinite
        let inside = View::window([64, 64], [0.4, 0.4], [0.0, 0.0, 0.1]);
        let f = frame(&g, &[inside], &pl);
        assert_eq!(f.assess(NodeKey::root()).pixels, f64::INFINITY);
        // the finest of two views wins
        let far = View::window([64, 64], [0.4, 0.4], [0.0, 0.0, 20.0]);
        let f = frame(&g, &[far, v], &pl);
        assert!((f.assess(NodeKey::root()).pixels - want).abs() < 1e-9 * want);
    }

    /// L12 Fig. 4: two bricks at the same distance, one on the view axis and
    /// one far off it. The distance alone gives both the same size; the
    /// projection on the screen is larger off the axis, where L12's formula
    /// refines a brick that the distance leaves coarse.
    #[test]
    fn an_off_axis_brick_is_refined_by_l12_and_not_by_distance() {
        let g = geom();
        let v = View::window([256, 256], [4.0, 4.0], [0.0, 0.0, 0.5]);
        let at = |x: f64, z: f64| Placement {
            center: [x, 0.0, z],
            rotation_deg: [0.0, 0.0, 0.0],
            size: 0.3,
        };
        // Same distance from the observer (0.9 m to the centre): on the
        // axis, and 60° off it.
        let key = NodeKey::new(2, 1, 1, 1);
        let on = frame(&g, &[v], &at(0.0, -0.4)).assess(key);
        let off60 = 60f64.to_radians();
        let off = frame(&g, &[v], &at(0.9 * off60.sin(), 0.5 - 0.9 * off60.cos())).assess(key);
        assert!(on.seen && off.seen);
        // By distance the two are alike (within the box's extent).
        assert!(
            (off.distance_pixels / on.distance_pixels - 1.0).abs() < 0.15,
            "{} {}",
            off.distance_pixels,
            on.distance_pixels
        );
        // On the axis L12 agrees with the distance; off it, about 1/cos²60° = 4×.
        assert!(on.pixels <= on.distance_pixels * 1.05, "{on:?}");
        assert!(off.pixels > 3.0 * off.distance_pixels, "{off:?}");
        // So with accuracy between the two, the distance leaves it coarse
        // and L12 refines it.
        let accuracy = 2.0 * off.distance_pixels;
        assert!(off.distance_pixels <= accuracy && off.pixels > accuracy);
    }

    #[test]
    fn rotation_keeps_the_distance() {
        let g = geom();
        let v = View::window([64, 64], [0.4, 0.4], [0.05, 0.02, 1.0]);
        let key = NodeKey::new(3, 7, 0, 0); // at the back
        let mut sizes = Vec::new();
        for rot in [[0.0, 0.0, 0.0], [0.0, 180.0, 0.0]] {
            let pl = Placement {
                center: [0.0, 0.0, 0.0],
                rotation_deg: rot,
                size: 0.3,
            };
            let f = frame(&g, &[v], &pl);
            // brute force: nearest of a dense sample of the display-space box
            let (lo, hi) = g.node_box(key);
            let mut best = f64::INFINITY;
            for i in 0..=20 {
                for j in 0..=20 {
                    for k in 0..=20 {
                        let t = DVec3::new(i as f64, j as f64, k as f64) / 20.0;
                        let p = pl.to_display(g.extent, lo + (hi - lo) * t);
                        best = best.min((p - DVec3::from(v.observer)).length());
                    }
                }
            }
            let voxel_m = g.voxel_len(3) * pl.scale(g.extent);
            let want = voxel_m * 1.0 / (best * 0.4 / 64.0);
            let a = f.assess(key);
            let got = a.distance_pixels;
            assert!((got - want).abs() <= 1e-9 * want, "{got} vs {want}");
            // L12's estimate only ever adds to it.
            assert!(a.pixels >= got);
            sizes.push(got);
        }
        // turned around, the back node comes to the front: larger
        assert!(sizes[1] > 1.25 * sizes[0], "{sizes:?}");
    }

    #[test]
    fn frustum_culls_what_is_beside_the_view() {
        let g = geom();
        let pl = Placement {
            center: [0.0, 0.0, 0.0],
            rotation_deg: [0.0, 0.0, 0.0],
            size: 0.3,
        };
        let ahead = View::window([64, 64], [0.4, 0.4], [0.0, 0.0, 1.0]);
        let mut aside = ahead;
        aside.region = [5.0, 5.0, 0.4, 0.4];
        let f = frame(&g, &[aside], &pl);
        assert!(!f.assess(NodeKey::root()).seen);
        let f = frame(&g, &[ahead], &pl);
        assert!(f.assess(NodeKey::root()).seen);
        // a narrow region right of centre: the left half of the volume is out
        let mut right = ahead;
        right.region = [0.03, -0.2, 0.1, 0.4];
        let f = frame(&g, &[right], &pl);
        assert!(!f.assess(NodeKey::new(1, 0, 0, 0)).seen);
        assert!(f.assess(NodeKey::new(1, 1, 0, 0)).seen);
        // behind the observer (the pyramid opens towards −z): out
        let mut behind = ahead;
        behind.region = [-0.2, -0.2, 0.4, 0.4];
        let pl_front = Placement {
            center: [0.0, 0.0, 2.0],
            ..pl
        };
        let f = frame(&g, &[behind], &pl_front);
        assert!(!f.assess(NodeKey::root()).seen);
        // η > 0: culled by the rays of the multi-centre projector, which
        // reach the volume for the view ahead and not for the one aside.
        for eye in [[0.3, 0.0, 1.2], [-0.5, 0.0, 1.5]] {
            let mut lf_aside = aside;
            lf_aside.eta = 1.0;
            lf_aside.eye = eye;
            let f = frame(&g, &[lf_aside], &pl);
            assert!(!f.assess(NodeKey::root()).seen, "{eye:?}");
            let mut lf_ahead = ahead;
            lf_ahead.eta = 1.0;
            lf_ahead.eye = eye;
            let f = frame(&g, &[lf_ahead], &pl);
            assert!(f.assess(NodeKey::root()).seen, "{eye:?}");
        }
    }
}
