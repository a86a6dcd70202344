//! Tools and the enhancers they drive (G10 §4 "Flexible ray traversal and
//! compositing", §5 "Custom compositing behavior"): each tool is a `[[tool]]`
//! table of the scene, with its pose in display space and its parameters.
//! The front end broadcasts them (re-sent only when they change); each back
//! end turns every tool into one enhancer of the ray caster's chain (at most
//! [`MAX_ENHANCERS`], each receiving the previous one's output).
//!
//! **Tools are data.** Each kind is two files of one name: its WGSL
//! enhancer `shaders/enhancers/<name>.wgsl` and its declaration
//! `common/src/tools/<name>.rs` — the struct of its parameters (the scene's
//! table) and its [`Enhancer`] impl: what it needs from the kernel and does
//! to a ray ([`Needs`]), how its parameters are packed and checked, where it
//! acts, the geometry drawn for it and the hints the live page shows for
//! its fields. Adding a kind is those two files and its line in the
//! registration below; the `Tool` variant, the scene's `kind`, the wire
//! form, the kernel's constants, the culling of empty space, the naga test,
//! script keys (any numeric field, by name) and the live page (its list of
//! kinds, its fields' inputs, a new tool's table) follow from them.
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
use crate::overlay::Shape;
use anyhow::{bail, Context, Result};
use glam::DVec3;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// How far from the screen's centre a tool's pose and size may reach (m),
/// whichever way it is set (scene, script, live page).
pub const REACH_M: f64 = 10.0;

/// Enhancers chained in one kernel at most (G10 §5: "a series of up to three
/// chained enhancing behaviors").
pub const MAX_ENHANCERS: usize = 3;

/// The registration: one line a kind, `module::Type` (the module is
/// `common/src/tools/<module>.rs`, the type its parameters' struct, which
/// is also the `Tool` variant's name). `tool_kinds!` declares the modules
/// and makes [`Tool`], its scene-file form `ToolTable`, [`EnhancerKind`]
/// (with `ALL`), [`ENHANCERS`] and `Tool`'s methods, each handing over to
/// the kind's [`Enhancer`] impl.
macro_rules! tool_kinds {
    ($( $(#[doc = $doc:literal])* $module:ident :: $kind:ident ),* $(,)?) => {
        $( pub mod $module; pub use $module::$kind; )*

        /// One tool, as written in a scene file (a table with its `kind`)
        /// and as broadcast to the back ends (bincode, which cannot read
        /// self-describing tags: the wire form names the variant by its
        /// index).
        #[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
        #[serde(rename_all = "kebab-case")]
        pub enum Tool {
            $( $(#[doc = $doc])* $kind($kind), )*
        }

        /// The scene-file form of [`Tool`]: `kind = "…"` beside the
        /// parameters.
        #[derive(Serialize, Deserialize)]
        #[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
        enum ToolTable {
            $( $kind($kind), )*
        }

        impl From<ToolTable> for Tool {
            fn from(t: ToolTable) -> Tool {
                match t {
                    $( ToolTable::$kind(p) => Tool::$kind(p), )*
                }
            }
        }

        impl From<Tool> for ToolTable {
            fn from(t: Tool) -> ToolTable {
                match t {
                    $( Tool::$kind(p) => ToolTable::$kind(p), )*
                }
            }
        }

        /// The kinds of enhancer a kernel can be built with, in
        /// registration order.
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
        pub enum EnhancerKind {
            $( $kind, )*
        }

        impl EnhancerKind {
            pub const ALL: [EnhancerKind; [$(EnhancerKind::$kind),*].len()] = [$(EnhancerKind::$kind),*];

            /// The kind's field hints and a new tool of it (the live page's
            /// "add"), its values placed in `range`.
            pub fn page_info(self, range: [f64; 2]) -> serde_json::Value {
                match self {
                    $( EnhancerKind::$kind => page_info::<$kind>(Tool::$kind($kind::new_tool(range))), )*
                }
            }
        }

        /// Every enhancer's declaration, indexed by [`EnhancerKind`].
        pub const ENHANCERS: [EnhancerSpec; EnhancerKind::ALL.len()] = [
            $( EnhancerSpec {
                kind: EnhancerKind::$kind,
                name: <$kind as Enhancer>::NAME,
                needs: <$kind as Enhancer>::NEEDS,
            }, )*
        ];

        impl Tool {
            pub fn enhancer(&self) -> EnhancerKind {
                match self {
                    $( Tool::$kind(_) => EnhancerKind::$kind, )*
                }
            }

            /// The tool's constant state as the kernel reads it
            /// ([`Enhancer::pack`]).
            pub fn pack(&self, ctx: &PackContext) -> [[f32; 4]; 4] {
                match self {
                    $( Tool::$kind(p) => p.pack(ctx), )*
                }
            }

            /// Where the tool's enhancer acts and reads its inputs
            /// ([`Enhancer::region`]).
            pub fn region(&self, ctx: &PackContext) -> Option<[[f64; 3]; 2]> {
                match self {
                    $( Tool::$kind(p) => p.region(ctx), )*
                }
            }

            /// Whether the tool can change anything in the volume's box
            /// ([`Enhancer::acts_on`]); the renderer leaves out the others.
            pub fn acts_on(&self, ctx: &PackContext) -> bool {
                match self {
                    $( Tool::$kind(p) => p.acts_on(ctx), )*
                }
            }

            /// Checks the tool's parameters; `what` names the file and the
            /// table ([`Enhancer::check`]).
            pub fn check(&self, what: &str) -> Result<()> {
                match self {
                    $( Tool::$kind(p) => p.check(&Checker { what }), )*
                }
            }

            /// The bounds a pose set from the live page keeps
            /// ([`Enhancer::bounds`]).
            pub fn bounds(&self, what: &str) -> Result<()> {
                match self {
                    $( Tool::$kind(p) => p.bounds(&Checker { what }), )*
                }
            }

            /// With what the tool takes from the transfer function's control
            /// point values resolved ([`Enhancer::resolved`]).
            pub fn resolved(&self, tf_values: &[f64]) -> Tool {
                match self {
                    $( Tool::$kind(p) => Tool::$kind(p.resolved(tf_values)), )*
                }
            }

            /// The tool's geometry, display space ([`Enhancer::shapes`]).
            pub fn shapes(&self, ctx: &PackContext) -> Vec<Shape> {
                match self {
                    $( Tool::$kind(p) => p.shapes(ctx), )*
                }
            }

            /// The value window the tool empties the rest of the data with,
            /// where it acts fully ([`Enhancer::value_window`]).
            pub fn value_window(&self) -> Option<ValueWindow> {
                match self {
                    $( Tool::$kind(p) => p.value_window(), )*
                }
            }
        }
    };
}

tool_kinds! {
    /// The default enhancer: changes nothing (and compiles to nothing). A
    /// scene may name it to measure what the chain itself costs.
    pass_through::PassThrough,
    /// Clip plane with view-dependent context (G10 §4).
    clip_plane::ClipPlane,
    /// Context-preserving probe (G10 §4, Eqs. 4–5).
    probe::Probe,
    /// View-dependent band picker (G10 §4, Fig. 9).
    band_picker::BandPicker,
    /// Multilevel shading: unsharp masking of the gradient with a coarser
    /// level's (G10 §3, Fig. 5).
    unsharp_gradient::UnsharpGradient,
    /// Multilevel shading: exaggerated shading over the leaf's, its
    /// parent's and its grandparent's normals (G10 §3).
    exaggerated_shading::ExaggeratedShading,
    /// Diagnostic: the gradient of each ray's first sample with extinction.
    gradient_direction::GradientDirection,
    /// Diagnostic: each ray's final direction (refraction's check).
    exit_direction::ExitDirection,
}

/// What an enhancer needs from the kernel and what it does to a ray. The
/// kernel's constants (`NEEDS_GRADIENT`, `TOOL_AUX`, `HAS_BREAKS`,
/// `MODIFIES_OPTICS`) and whether the kernel may skip empty space follow
/// from it (`backend/src/raycast/shader.rs`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Needs {
    /// Reads the sample's gradient ∇s. The kernel computes it (six more
    /// fetches) only for samples where the enhancer's `ENH_active` says it
    /// acts.
    pub gradient: bool,
    /// Reads the sample's pre-integrated importance ι (and refraction ν),
    /// likewise only where `ENH_active`.
    pub importance: bool,
    /// Sets the sample's importance (up to 1, above the transfer
    /// function's largest: MImDA's termination test allows for it).
    pub sets_importance: bool,
    /// Reads the gradients of the leaf's parent and grandparent at the
    /// sample (`gradient_up`, `gradient_up2`: six fetches each), likewise
    /// only where `ENH_active`.
    pub coarse_gradients: bool,
    /// Sets the sample's shade (`shade`), which then replaces the kernel's
    /// own (Phong, or 1 unshaded).
    pub shades: bool,
    /// Adds breaks to the ray (`add_break`): no segment straddles them.
    pub breaks: bool,
    /// Changes a segment's optics (`alpha_scale`, `alpha_mix`,
    /// `color_scale`).
    pub optics: bool,
    /// Can make a ray show something where the transfer function has no
    /// extinction. Such a kernel marches every ray through the volume's
    /// box, with no tile culling or macrocell skipping; every other
    /// enhancer keeps them (a segment with τ̄ = 0 then adds exactly nothing,
    /// whatever the enhancer makes of it).
    pub adds_opacity: bool,
}

impl Needs {
    /// Needs nothing, does nothing: `Needs { breaks: true, ..Needs::NOTHING }`.
    pub const NOTHING: Needs = Needs {
        gradient: false,
        importance: false,
        sets_importance: false,
        coarse_gradients: false,
        shades: false,
        breaks: false,
        optics: false,
        adds_opacity: false,
    };
}

/// A registered kind's declaration as the kernel builder reads it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct EnhancerSpec {
    pub kind: EnhancerKind,
    /// The scene's `kind` and the file `shaders/enhancers/<name>.wgsl`.
    pub name: &'static str,
    pub needs: Needs,
}

impl EnhancerKind {
    /// The kind's declaration.
    pub fn spec(self) -> &'static EnhancerSpec {
        &ENHANCERS[self as usize]
    }

    /// The WGSL file of the enhancer, in `shaders/enhancers/`.
    pub fn file(self) -> &'static str {
        self.spec().name
    }
}

/// A field's hint for the live page: its label, the step of its inputs and
/// which values it takes (the page marks others and does not send them;
/// [`Enhancer::check`] is the rule the server keeps).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Field {
    pub name: &'static str,
    pub label: &'static str,
    pub step: f64,
    pub rule: Rule,
}

/// Which values a field takes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Rule {
    /// Each component in [lo, hi].
    Range(f64, f64),
    /// A non-zero vector.
    Direction,
    /// Components in [lo, hi], non-decreasing, the first below the last.
    Ordered(f64, f64),
}

impl Field {
    pub const fn new(name: &'static str, label: &'static str, step: f64, rule: Rule) -> Field {
        Field {
            name,
            label,
            step,
            rule,
        }
    }
}

/// A value window (G10 §4's band picker): where −axis·v ≥ `cos_full` for
/// a ray direction v, a segment whose values all miss [lo, hi] gets
/// opacity × 0, so data outside the window is empty for such a frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ValueWindow {
    /// Display space, unit.
    pub axis: DVec3,
    pub cos_full: f64,
    pub range: [f64; 2],
}

/// One kind of tool: the struct of its parameters (the scene's table) and
/// what its enhancer `shaders/enhancers/<NAME>.wgsl` needs and does.
pub trait Enhancer:
    Clone + std::fmt::Debug + PartialEq + Serialize + DeserializeOwned + 'static
{
    /// The scene's `kind` and the WGSL file's name.
    const NAME: &'static str;
    /// What it needs from the kernel and does to a ray.
    const NEEDS: Needs;
    /// The live page's hints for its numeric fields (a field without one
    /// gets a plain input).
    const FIELDS: &'static [Field] = &[];

    /// What the page adds: a tool of this kind near the volume's centre,
    /// its data values (if any) placed in the volume's `range`.
    fn new_tool(range: [f64; 2]) -> Self;

    /// The tool's constant state as the kernel reads it (`ToolParams`:
    /// four vec4, meaning per enhancer, written in its WGSL file's header).
    fn pack(&self, _ctx: &PackContext) -> [[f32; 4]; 4] {
        [[0.0; 4]; 4]
    }

    /// Checks the parameters (`c` names the file and table in errors).
    fn check(&self, _c: &Checker) -> Result<()> {
        Ok(())
    }

    /// The bounds a pose set from the live page keeps beyond `check`.
    fn bounds(&self, _c: &Checker) -> Result<()> {
        Ok(())
    }

    /// Where its enhancer acts and reads the gradient or importance
    /// (`ENH_active`), as a box in volume space (data length units): the
    /// kernel computes those inputs only in the tiles whose rays can meet
    /// it (`None`: nowhere). By default, the whole volume for a kind that
    /// reads them.
    fn region(&self, ctx: &PackContext) -> Option<[[f64; 3]; 2]> {
        let n = Self::NEEDS;
        (n.gradient || n.importance || n.coarse_gradients).then_some([[0.0; 3], ctx.extent])
    }

    /// Whether it can change anything in the volume's box; the renderer
    /// leaves a tool that cannot out of the kernel (a scene pays nothing
    /// for a tool moved away).
    fn acts_on(&self, _ctx: &PackContext) -> bool {
        true
    }

    /// With what it takes from the transfer function's control point
    /// values resolved.
    fn resolved(&self, _tf_values: &[f64]) -> Self {
        self.clone()
    }

    /// Its geometry (G10 §5), display space; labels are dropped where the
    /// overlay shows none.
    fn shapes(&self, _ctx: &PackContext) -> Vec<Shape> {
        Vec::new()
    }

    /// The value window it empties the rest of the data with, where it
    /// acts fully.
    fn value_window(&self) -> Option<ValueWindow> {
        None
    }
}

/// A kind's page info: its fields' hints and a new tool's table.
fn page_info<E: Enhancer>(new: Tool) -> serde_json::Value {
    let fields: Vec<serde_json::Value> = E::FIELDS
        .iter()
        .map(|f| {
            let (rule, lo, hi) = match f.rule {
                Rule::Range(lo, hi) => ("range", lo, hi),
                Rule::Direction => ("direction", f64::NEG_INFINITY, f64::INFINITY),
                Rule::Ordered(lo, hi) => ("ordered", lo, hi),
            };
            let bound = |x: f64| x.is_finite().then_some(x);
            serde_json::json!({
                "name": f.name, "label": f.label, "step": f.step,
                "rule": rule, "min": bound(lo), "max": bound(hi),
            })
        })
        .collect();
    serde_json::json!({ "fields": fields, "new": new.table().ok() })
}

/// What checking a tool's parameters needs: the name of its file and table,
/// and the tests every kind's fields use.
pub struct Checker<'a> {
    pub what: &'a str,
}

impl Checker<'_> {
    /// Every component finite.
    pub fn finite(&self, v: &[f64], field: &str) -> Result<()> {
        if !v.iter().all(|x| x.is_finite()) {
            bail!("{}: {field} must be finite (got {v:?})", self.what);
        }
        Ok(())
    }

    /// A finite non-zero vector.
    pub fn direction(&self, v: &[f64; 3], field: &str) -> Result<()> {
        if !v.iter().all(|x| x.is_finite()) || DVec3::from(*v).length() < 1e-12 {
            bail!(
                "{}: {field} must be a finite non-zero vector (got {v:?})",
                self.what
            );
        }
        Ok(())
    }

    /// A pair 0 ≤ lo < hi ≤ 1 (`names` says what they are).
    pub fn unit_pair(&self, b: &[f64; 2], field: &str, names: &str) -> Result<()> {
        let [lo, hi] = *b;
        if !(b.iter().all(|x| x.is_finite()) && (0.0..=1.0).contains(&lo) && lo < hi && hi <= 1.0) {
            bail!(
                "{}: {field} must be [{names}] with 0 ≤ lo < hi ≤ 1 (got {b:?})",
                self.what
            );
        }
        Ok(())
    }

    /// A finite value in [lo, hi].
    pub fn within(&self, v: f64, lo: f64, hi: f64, field: &str) -> Result<()> {
        if !(v.is_finite() && (lo..=hi).contains(&v)) {
            bail!("{}: {field} must be in [{lo}, {hi}] (got {v})", self.what);
        }
        Ok(())
    }

    /// Every component a finite value in [lo, hi].
    pub fn within_all(&self, v: &[f64], lo: f64, hi: f64, field: &str) -> Result<()> {
        for &x in v {
            self.within(x, lo, hi, field)?;
        }
        Ok(())
    }
}

/// What packing a tool's parameters for the kernel needs to know of the
/// frame: where the volume is and how steep its data can be.
#[derive(Clone, Copy, Debug)]
pub struct PackContext {
    pub placement: Placement,
    /// The volume's extent (data length units).
    pub extent: [f64; 3],
    /// ∇_max of G10 Eq. 5's η: the transfer function's value span over the
    /// finest voxel (the steepest a change across one voxel can be), in
    /// data values per data length unit.
    pub gradient_max: f64,
}

impl PackContext {
    /// A display-space point in volume space (data length units).
    pub fn to_volume(&self, x: DVec3) -> DVec3 {
        let k = self.placement.scale(self.extent);
        self.placement.rotation().transpose() * (x - DVec3::from(self.placement.center)) / k
            + DVec3::from(self.extent) * 0.5
    }

    /// A display-space direction in volume space (unit).
    pub fn direction_to_volume(&self, d: [f64; 3]) -> DVec3 {
        self.placement.rotation().transpose() * DVec3::from(d).normalize()
    }

    /// The volume box's eight corners (volume space).
    pub fn corners(&self) -> impl Iterator<Item = DVec3> {
        let e = self.extent;
        (0..8).map(move |i| {
            DVec3::new(
                if i & 1 == 0 { 0.0 } else { e[0] },
                if i & 2 == 0 { 0.0 } else { e[1] },
                if i & 4 == 0 { 0.0 } else { e[2] },
            )
        })
    }
}

impl Tool {
    /// The tool as its scene-file table (JSON: the live page's form).
    pub fn table(&self) -> Result<serde_json::Map<String, serde_json::Value>> {
        match serde_json::to_value(ToolTable::from(self.clone()))? {
            serde_json::Value::Object(m) => Ok(m),
            _ => bail!("a tool is not a table"),
        }
    }

    /// A tool from its scene-file table; `what` names where it came from.
    pub fn from_table(table: serde_json::Value, what: &str) -> Result<Tool> {
        let t: ToolTable = serde_json::from_value(table).with_context(|| what.to_string())?;
        Ok(t.into())
    }

    /// The names of the tool's numeric fields (those a script may key).
    pub fn numeric_fields(&self) -> Vec<String> {
        let mut names: Vec<String> = self
            .table()
            .map(|m| {
                m.into_iter()
                    .filter(|(_, v)| {
                        v.is_number()
                            || v.as_array()
                                .is_some_and(|a| !a.is_empty() && a.iter().all(|x| x.is_number()))
                    })
                    .map(|(k, _)| k)
                    .collect()
            })
            .unwrap_or_default();
        // In name order whatever the map's own order (serde_json keeps
        // insertion order where a dependency turns on `preserve_order`).
        names.sort();
        names
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

/// The cubic smoothstep of GLSL and WGSL.
pub fn smoothstep(lo: f64, hi: f64, x: f64) -> f64 {
    let t = ((x - lo) / (hi - lo)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// The default axis of the probe and the band picker: towards the viewers.
pub(crate) fn default_axis() -> [f64; 3] {
    [0.0, 0.0, 1.0]
}

/// ω_a is 1 within about 18° of the axis and 0 beyond about 46°.
pub(crate) fn default_alignment() -> [f64; 2] {
    [0.7, 0.95]
}

pub(crate) fn one() -> f64 {
    1.0
}

#[cfg(test)]
mod tests {
    use super::*;

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
        let four = vec![Tool::PassThrough(PassThrough {}); 4];
        assert!(check_tools(&four, Path::new("s.toml")).is_err());
    }
}

#[cfg(test)]
mod registration_tests {
    use super::*;

    /// Each registered kind's declaration agrees with itself: the scene's
    /// `kind` of its tables is its WGSL file's name, the tool the page adds
    /// passes its checks, and every field hint names a numeric field.
    #[test]
    fn every_kind_is_declared_consistently() {
        for k in EnhancerKind::ALL {
            assert_eq!(k.spec().kind, k);
            let info = k.page_info([-100.0, 3000.0]);
            let new = Tool::from_table(info["new"].clone(), k.file()).unwrap();
            assert_eq!(new.enhancer(), k);
            assert_eq!(new.table().unwrap()["kind"], k.file());
            new.check(k.file()).unwrap();
            new.bounds(k.file()).unwrap();
            let numeric = new.numeric_fields();
            for f in info["fields"].as_array().unwrap() {
                let name = f["name"].as_str().unwrap();
                assert!(numeric.iter().any(|n| n == name), "{}: {name}", k.file());
            }
        }
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
            Tool::PassThrough(PassThrough {}),
            Tool::ExitDirection(ExitDirection {}),
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
