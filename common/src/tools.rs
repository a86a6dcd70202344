//! Tools and the enhancers they drive (G10 §4 "Flexible ray traversal and
//! compositing", §5 "Custom compositing behavior"): each tool is a `[[tool]]`
//! table of the scene, with its pose in display space and its parameters.
//! The front end broadcasts them (re-sent only when they change); each back
//! end turns every tool into one enhancer of the ray caster's chain (at most
//! [`MAX_ENHANCERS`], each receiving the previous one's output).
//!
//! ```toml
//! [[tool]]
//! kind = "clip-plane"
//! point = [0.0, 0.0, 0.0]    # m, display space: a point on the plane
//! normal = [0.0, 0.0, 1.0]   # the half-space it points into is cut away
//! thickness = 0.0            # m, emphasis band behind the plane; 0 = none
//! context = [0.3, 0.7]       # f_l, f_h of the view-dependent factor
//! ```

use crate::camera::Placement;
use anyhow::{bail, Result};
use glam::DVec3;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Enhancers chained in one kernel at most (G10 §5: "a series of up to three
/// chained enhancing behaviors").
pub const MAX_ENHANCERS: usize = 3;

/// One tool, as written in a scene file (a table with its `kind`) and as
/// broadcast to the back ends (bincode, which cannot read self-describing
/// tags: the wire form names the variant by its index).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Tool {
    /// The default enhancer: changes nothing (and compiles to nothing). A
    /// scene may name it to measure what the chain itself costs.
    PassThrough,
    /// Clip plane with view-dependent context (G10 §4).
    ClipPlane(ClipPlane),
    /// Diagnostic: each pixel shows its ray's final direction (volume space,
    /// x/y/z as red/green/blue from [−1, 1]), opaque — how refraction is
    /// checked against Snell's law.
    ExitDirection,
}

/// G10 §4 "Clip plane with view-dependent context": on the side the normal
/// points into (δ = n·x + p > 0) a sample's opacity is multiplied by
/// μ = smoothstep(f_l, f_h, 1 − max(0, −n·v)); in the band −thickness < δ < 0
/// opacity and shading go smoothly from the sample's own at δ = −thickness to
/// full opacity and ambient-plus-emission shading at δ = 0.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClipPlane {
    /// A point on the plane (m, display space).
    pub point: [f64; 3],
    /// Points into the half-space that is cut away (display space).
    pub normal: [f64; 3],
    /// Thickness of the emphasis band behind the plane (m); 0: none.
    #[serde(default)]
    pub thickness: f64,
    /// f_l, f_h of the view-dependent factor.
    #[serde(default = "default_context")]
    pub context: [f64; 2],
}

fn default_context() -> [f64; 2] {
    [0.3, 0.7]
}

/// The scene-file form of [`Tool`]: `kind = "…"` beside the parameters.
#[derive(Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
enum ToolTable {
    PassThrough,
    ClipPlane(ClipPlane),
    ExitDirection,
}

impl From<ToolTable> for Tool {
    fn from(t: ToolTable) -> Tool {
        match t {
            ToolTable::PassThrough => Tool::PassThrough,
            ToolTable::ClipPlane(c) => Tool::ClipPlane(c),
            ToolTable::ExitDirection => Tool::ExitDirection,
        }
    }
}

impl From<Tool> for ToolTable {
    fn from(t: Tool) -> ToolTable {
        match t {
            Tool::PassThrough => ToolTable::PassThrough,
            Tool::ClipPlane(c) => ToolTable::ClipPlane(c),
            Tool::ExitDirection => ToolTable::ExitDirection,
        }
    }
}

/// `#[serde(with = "tools::list")]`: a tool list as `[[tool]]` tables in
/// readable formats, in [`Tool`]'s own (indexed) form on the wire.
pub mod list {
    use super::*;
    use serde::{Deserializer, Serializer};

    pub fn serialize<S: Serializer>(tools: &[Tool], s: S) -> Result<S::Ok, S::Error> {
        if s.is_human_readable() {
            let t: Vec<ToolTable> = tools.iter().cloned().map(ToolTable::from).collect();
            t.serialize(s)
        } else {
            tools.serialize(s)
        }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<Tool>, D::Error> {
        if d.is_human_readable() {
            let t: Vec<ToolTable> = Vec::deserialize(d)?;
            Ok(t.into_iter().map(Tool::from).collect())
        } else {
            Vec::<Tool>::deserialize(d)
        }
    }
}

/// The kinds of enhancer a kernel can be built with.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub enum EnhancerKind {
    PassThrough,
    ClipPlane,
    ExitDirection,
}

impl EnhancerKind {
    pub const ALL: [EnhancerKind; 3] = [
        EnhancerKind::PassThrough,
        EnhancerKind::ClipPlane,
        EnhancerKind::ExitDirection,
    ];

    /// The WGSL file of the enhancer, in `shaders/enhancers/`.
    pub fn file(self) -> &'static str {
        match self {
            EnhancerKind::PassThrough => "pass-through",
            EnhancerKind::ClipPlane => "clip-plane",
            EnhancerKind::ExitDirection => "exit-direction",
        }
    }
}

impl Tool {
    pub fn enhancer(&self) -> EnhancerKind {
        match self {
            Tool::PassThrough => EnhancerKind::PassThrough,
            Tool::ClipPlane(_) => EnhancerKind::ClipPlane,
            Tool::ExitDirection => EnhancerKind::ExitDirection,
        }
    }

    /// Checks a tool's parameters; `what` names the file and the table.
    pub fn check(&self, what: &str) -> Result<()> {
        match self {
            Tool::PassThrough | Tool::ExitDirection => Ok(()),
            Tool::ClipPlane(c) => {
                let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
                if !finite(&c.point) {
                    bail!("{what}: point must be finite (got {:?})", c.point);
                }
                let n = DVec3::from(c.normal);
                if !finite(&c.normal) || n.length() < 1e-12 {
                    bail!(
                        "{what}: normal must be a finite non-zero vector (got {:?})",
                        c.normal
                    );
                }
                if !(c.thickness.is_finite() && c.thickness >= 0.0) {
                    bail!("{what}: thickness must be ≥ 0 (got {})", c.thickness);
                }
                let [lo, hi] = c.context;
                if !(finite(&c.context) && (0.0..=1.0).contains(&lo) && lo < hi && hi <= 1.0) {
                    bail!(
                        "{what}: context must be [f_l, f_h] with 0 ≤ f_l < f_h ≤ 1 (got {:?})",
                        c.context
                    );
                }
                Ok(())
            }
        }
    }
}

/// Checks a scene's tool list.
pub fn check_tools(tools: &[Tool], file: &Path) -> Result<()> {
    if tools.len() > MAX_ENHANCERS {
        bail!(
            "{}: tool: {} tools, at most {MAX_ENHANCERS} can be chained",
            file.display(),
            tools.len()
        );
    }
    for (i, t) in tools.iter().enumerate() {
        t.check(&format!("{}: tool[{i}]", file.display()))?;
    }
    Ok(())
}

/// A plane in volume space (data length units): δ(q) = normal·q + offset is
/// the signed distance in display metres of the display point q maps to;
/// `unit` is the plane's unit normal in volume space (for n·v with a
/// volume-space ray direction v).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VolumePlane {
    pub normal: DVec3,
    pub offset: f64,
    pub unit: DVec3,
}

impl ClipPlane {
    /// The plane in the volume space of `placement` (a volume point q maps to
    /// x = c + R·k·(q − e/2), so n·x − n·point = (k·Rᵀn)·q + n·(c − point) −
    /// k·(Rᵀn)·e/2).
    pub fn in_volume(&self, placement: &Placement, extent: [f64; 3]) -> VolumePlane {
        let n = DVec3::from(self.normal).normalize();
        let k = placement.scale(extent);
        let unit = placement.rotation().transpose() * n;
        let normal = unit * k;
        let offset = n.dot(DVec3::from(placement.center) - DVec3::from(self.point))
            - normal.dot(DVec3::from(extent) * 0.5);
        VolumePlane {
            normal,
            offset,
            unit,
        }
    }

    /// G10 §4: μ = smoothstep(f_l, f_h, 1 − max(0, −n·v)) for a unit view
    /// direction v (display space), the factor on the cut-away side.
    pub fn context_factor(&self, v: DVec3) -> f64 {
        let n = DVec3::from(self.normal).normalize();
        smoothstep(self.context[0], self.context[1], 1.0 - (-n.dot(v)).max(0.0))
    }
}

/// The cubic smoothstep of GLSL and WGSL.
pub fn smoothstep(lo: f64, hi: f64, x: f64) -> f64 {
    let t = ((x - lo) / (hi - lo)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plane_in_volume_space_measures_display_distance() {
        let placement = Placement {
            center: [0.1, -0.05, 0.2],
            rotation_deg: [20.0, -35.0, 10.0],
            size: 0.3,
        };
        let ext = [181.0, 217.0, 181.0];
        let plane = ClipPlane {
            point: [0.02, 0.01, 0.15],
            normal: [0.3, -0.2, 1.0],
            thickness: 0.0,
            context: [0.3, 0.7],
        };
        let vp = plane.in_volume(&placement, ext);
        let n = DVec3::from(plane.normal).normalize();
        for q in [
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(90.0, 100.0, 10.0),
            DVec3::new(181.0, 3.0, 150.0),
        ] {
            let x = placement.to_display(ext, q);
            let want = n.dot(x - DVec3::from(plane.point));
            let got = vp.normal.dot(q) + vp.offset;
            assert!((want - got).abs() < 1e-12, "{want} {got}");
        }
        // n·v is the same in both spaces.
        let v = DVec3::new(0.2, 0.1, -1.0).normalize();
        let (_, vv) = placement.ray_to_volume(ext, DVec3::ZERO, v);
        assert!((vp.unit.dot(vv) - n.dot(v)).abs() < 1e-12);
    }

    #[test]
    fn context_factor_is_zero_head_on_and_one_parallel() {
        let plane = ClipPlane {
            point: [0.0; 3],
            normal: [0.0, 0.0, 1.0],
            thickness: 0.0,
            context: [0.3, 0.7],
        };
        assert_eq!(plane.context_factor(DVec3::new(0.0, 0.0, -1.0)), 0.0);
        assert_eq!(plane.context_factor(DVec3::new(1.0, 0.0, 0.0)), 1.0);
        let mut last = -1.0;
        for deg in 0..=90 {
            let a = (deg as f64).to_radians();
            let mu = plane.context_factor(DVec3::new(a.sin(), 0.0, -a.cos()));
            assert!(mu >= last);
            last = mu;
        }
    }

    #[test]
    fn tools_parse_and_bad_ones_name_the_field() {
        #[derive(Deserialize)]
        struct S {
            #[serde(with = "list")]
            tool: Vec<Tool>,
        }
        let s: S = toml::from_str(
            "[[tool]]\nkind = \"clip-plane\"\npoint = [0, 0, 0]\nnormal = [0, 0, 1]\n[[tool]]\nkind = \"pass-through\"\n",
        )
        .unwrap();
        assert_eq!(s.tool.len(), 2);
        assert_eq!(s.tool[0].enhancer(), EnhancerKind::ClipPlane);
        check_tools(&s.tool, Path::new("s.toml")).unwrap();
        for (text, field) in [
            ("normal = [0, 0, 0]\ncontext = [0.3, 0.7]", "normal"),
            ("normal = [0, 0, 1]\ncontext = [0.7, 0.3]", "context"),
            ("normal = [0, 0, 1]\nthickness = -1", "thickness"),
        ] {
            let s: S = toml::from_str(&format!(
                "[[tool]]\nkind = \"clip-plane\"\npoint = [0, 0, 0]\n{text}\n"
            ))
            .unwrap();
            let e = check_tools(&s.tool, Path::new("s.toml"))
                .unwrap_err()
                .to_string();
            assert!(e.contains("s.toml: tool[0]") && e.contains(field), "{e}");
        }
        let four = vec![Tool::PassThrough; 4];
        assert!(check_tools(&four, Path::new("s.toml")).is_err());
    }
}

#[cfg(test)]
mod wire_tests {
    use super::*;

    #[test]
    fn tools_cross_the_wire() {
        let tools = vec![
            Tool::ClipPlane(ClipPlane {
                point: [0.1, 0.0, 0.0],
                normal: [0.0, 1.0, 0.0],
                thickness: 0.01,
                context: [0.2, 0.8],
            }),
            Tool::PassThrough,
            Tool::ExitDirection,
        ];
        #[derive(Debug, PartialEq, Serialize, Deserialize)]
        struct M {
            #[serde(with = "list")]
            tools: Vec<Tool>,
        }
        let m = M { tools };
        let b = bincode::serde::encode_to_vec(&m, bincode::config::standard()).unwrap();
        let (back, _): (M, usize) =
            bincode::serde::decode_from_slice(&b, bincode::config::standard()).unwrap();
        assert_eq!(back, m);
    }
}
