//! Tools and the enhancers they drive (G10 §4 "Flexible ray traversal and
//! compositing", §5 "Custom compositing behavior"): each tool is a `[[tool]]`
//! table of the scene, with its pose in display space and its parameters.
//! The front end broadcasts them (re-sent only when they change); each back
//! end turns every tool into one enhancer of the ray caster's chain (at most
//! [`MAX_ENHANCERS`], each receiving the previous one's output).
//!
//! What each kind of enhancer needs and does is declared once, in
//! [`ENHANCERS`] (beside its WGSL file `shaders/enhancers/<name>.wgsl`): the
//! kernel's constants, the culling of empty space and the packing of its
//! parameters follow from that declaration.
//!
//! Adding a kind: its WGSL file (found by name: `backend/build.rs` lists
//! the folder), its line in `tool_kinds!` (the `Tool` variant, the scene's
//! `kind`, the wire form and `EnhancerKind` follow), its `ENHANCERS`
//! entry, and the arms of [`Tool::pack`] and [`Tool::check`] for its
//! parameters. The live page, scripts and the naga test take it from
//! there.
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

/// The kinds of tool, each once: its variant (with the struct of its
/// parameters, if it has any), in the order of [`ENHANCERS`].
/// `tool_kinds!` makes [`Tool`], its scene-file form `ToolTable`, the
/// conversions between them, [`EnhancerKind`] (with `ALL`) and
/// [`Tool::enhancer`] from this one list.
macro_rules! tool_kinds {
    ($( $(#[doc = $doc:literal])* $kind:ident $(($params:ident))? ),* $(,)?) => {
        /// One tool, as written in a scene file (a table with its `kind`)
        /// and as broadcast to the back ends (bincode, which cannot read
        /// self-describing tags: the wire form names the variant by its
        /// index).
        #[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
        #[serde(rename_all = "kebab-case")]
        pub enum Tool {
            $( $(#[doc = $doc])* $kind $(($params))?, )*
        }

        /// The scene-file form of [`Tool`]: `kind = "…"` beside the
        /// parameters.
        #[derive(Serialize, Deserialize)]
        #[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
        enum ToolTable {
            $( $kind $(($params))?, )*
        }

        impl From<ToolTable> for Tool {
            fn from(t: ToolTable) -> Tool {
                match t {
                    $( tool_kinds!(@bind p ToolTable $kind $(($params))?) => tool_kinds!(@bind p Tool $kind $(($params))?), )*
                }
            }
        }

        impl From<Tool> for ToolTable {
            fn from(t: Tool) -> ToolTable {
                match t {
                    $( tool_kinds!(@bind p Tool $kind $(($params))?) => tool_kinds!(@bind p ToolTable $kind $(($params))?), )*
                }
            }
        }

        /// The kinds of enhancer a kernel can be built with, in
        /// [`ENHANCERS`] order.
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
        pub enum EnhancerKind {
            $( $kind, )*
        }

        impl EnhancerKind {
            pub const ALL: [EnhancerKind; [$(EnhancerKind::$kind),*].len()] = [$(EnhancerKind::$kind),*];
        }

        impl Tool {
            pub fn enhancer(&self) -> EnhancerKind {
                match self {
                    $( tool_kinds!(@any Tool $kind $(($params))?) => EnhancerKind::$kind, )*
                }
            }
        }
    };
    (@bind $v:ident $enum:ident $kind:ident ($params:ident)) => { $enum::$kind($v) };
    (@bind $v:ident $enum:ident $kind:ident) => { $enum::$kind };
    (@any $enum:ident $kind:ident ($params:ident)) => { $enum::$kind(_) };
    (@any $enum:ident $kind:ident) => { $enum::$kind };
}

tool_kinds! {
    /// The default enhancer: changes nothing (and compiles to nothing). A
    /// scene may name it to measure what the chain itself costs.
    PassThrough,
    /// Clip plane with view-dependent context (G10 §4).
    ClipPlane(ClipPlane),
    /// Context-preserving probe (G10 §4, Eqs. 4–5).
    Probe(Probe),
    /// View-dependent band picker (G10 §4, Fig. 9).
    BandPicker(BandPicker),
    /// Multilevel shading: unsharp masking of the gradient with a coarser
    /// level's (G10 §3, Fig. 5).
    UnsharpGradient(UnsharpGradient),
    /// Multilevel shading: exaggerated shading over the leaf's, its
    /// parent's and its grandparent's normals (G10 §3).
    ExaggeratedShading(ExaggeratedShading),
    /// Diagnostic: each pixel shows the gradient of its ray's first sample
    /// with extinction, as the chain's earlier enhancers leave it (volume
    /// space, its direction's x/y/z as red/green/blue from [−1, 1]),
    /// opaque; transparent where the ray meets no extinction.
    GradientDirection,
    /// Diagnostic: each pixel shows its ray's final direction (volume
    /// space, x/y/z as red/green/blue from [−1, 1]), opaque — how
    /// refraction is checked against Snell's law.
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

/// G10 §4 "Context-preserving probe": a sphere in display space whose
/// enhancer multiplies a sample's opacity by μ(α) and its colour by μ(i)
/// (Eqs. 4–5). With s the sample's distance along the ray from the plane
/// through the centre facing the ray (negative in front), ω_d = 1 − (s/r)²
/// (one on that plane, zero a radius away) and
///   in front (s < 0):  μ(α) = lerp(0, η, ω_d),  μ(i) = 1 − η,
///   behind   (s ≥ 0):  μ(α) = lerp(η, 1, 1 − ω_d),  μ(i) = lerp(1 − η, 1, 1 − ω_d),
/// η = ω_a · smoothstep(g_l, g_h, ι·‖∇s‖/∇_max) · (1 − |∇s·v|/‖∇s‖)⁴,
/// ω_a = smoothstep(a_l, a_h, max(0, −a·v)) for the ray direction v and the
/// probe's axis a (pointing towards the viewers who see its edges). Samples
/// outside the sphere are untouched. G10 writes (1 − ∇s·v/‖∇s‖)⁴ without
/// the absolute value; the gradient's sign says only which side of a
/// surface is denser, so both sides are treated alike here (η stays ≤ 1).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Probe {
    /// The sphere's centre (m, display space).
    pub center: [f64; 3],
    /// Its radius (m).
    pub radius: f64,
    /// The tool's axis: looking against it, contextual edges show.
    #[serde(default = "default_axis")]
    pub axis: [f64; 3],
    /// a_l, a_h of ω_a, over the cosine between the view and the axis.
    #[serde(default = "default_alignment")]
    pub alignment: [f64; 2],
    /// g_l, g_h of η's gradient filter, over ι·‖∇s‖/∇_max.
    #[serde(default = "default_gradient")]
    pub gradient: [f64; 2],
}

/// G10 §4 "Band picker": a band of data values, the trapezoid of four
/// ordered values b₀ ≤ b₁ ≤ b₂ ≤ b₃ (0 below b₀ and above b₃, 1 on [b₁, b₂]).
/// For a segment whose values span [s_lo, s_hi], w is the trapezoid's
/// largest value on that span; with ω_a = smoothstep(a_l, a_h, max(0,
/// −a·v)) of the ray direction v and the tool's axis a,
///   importance ← lerp(ι, w, ω_a)   (1 in the band, 0 outside: MImDA lets
///                                   the band shine through),
///   opacity    × 1 − ω_a·(1 − w)   (the other bands vanish looking along
///                                   the axis and return looking across).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BandPicker {
    /// b₀ … b₃, data values (ignored where `points` is given).
    #[serde(default)]
    pub band: [f64; 4],
    /// The band taken from the scene's transfer function by index: its
    /// control points i ..= j are the plateau [b₁, b₂], their neighbours
    /// i − 1 and j + 1 the ramps' feet b₀ and b₃ (a peak of the function,
    /// one tissue class, is `[i, i]`). Indices past the function's last
    /// point take the last.
    #[serde(default)]
    pub points: Option<[usize; 2]>,
    /// Looking against it, only the band is seen.
    #[serde(default = "default_axis")]
    pub axis: [f64; 3],
    /// a_l, a_h of ω_a, over the cosine between the view and the axis.
    #[serde(default = "default_alignment")]
    pub alignment: [f64; 2],
}

/// G10 §3 "multilevel shading effects, such as … normal unsharp masking":
/// where a segment has extinction, its gradient g becomes
///   g + λ·(g − g_c),
/// g_c the gradient of a coarser level's data at the same point (the
/// leaf's parent for `level` 1, its grandparent for 2; the finer one where
/// that level is not resident). The gradient is linear in the data, so this
/// is the gradient of the unsharp-masked volume s + λ·(s − s_c): detail
/// finer than the coarser level's voxel is amplified by 1 + λ, the shape it
/// sits on is kept. Shading and every later enhancer see the masked
/// gradient. λ = 0 is plain shading, bit for bit.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UnsharpGradient {
    /// λ, in [0, 10].
    #[serde(default = "one")]
    pub strength: f64,
    /// How many levels coarser the smooth gradient is: 1 or 2.
    #[serde(default = "one_level")]
    pub level: u32,
}

/// G10 §3 "exaggerated shading [Rusinkiewicz, Burns and DeCarlo 2006]":
/// with n₀, n₁, n₂ the outward normals −∇s/‖∇s‖ of the leaf, its parent and
/// its grandparent at a sample, l the light (display space, towards the
/// light) and l_i = l − (l·n_i)n_i normalised (the light turned into the
/// plane of the next coarser scale),
///   E = ½ + ½·(k₀·clamp(a·n₀·l₁) + k₁·clamp(a·n₁·l₂) + k_b·clamp(n₂·l)),
/// clamp to [−1, 1], weights k normalised to sum 1 (their Eq. 2: each term
/// shades a scale's detail relative to the next coarser one, lit from the
/// side whatever the surface's orientation; the base term is the coarse
/// shape lit as usual). The shade is ambient + diffuse·E of the scene's
/// material, blended with the plain shade (Phong, or none where the scene
/// is unshaded) by `strength`: 0 is plain shading, bit for bit. The light
/// is fixed in display space, so every viewer of a light field display sees
/// the same shading.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExaggeratedShading {
    /// Blend from the plain shade (0) to exaggerated shading (1).
    #[serde(default = "one")]
    pub strength: f64,
    /// a, how sharply the detail terms switch from dark to light, (0, 1000].
    #[serde(default = "default_contrast")]
    pub contrast: f64,
    /// Towards the light, display space.
    #[serde(default = "default_light")]
    pub light: [f64; 3],
    /// k₀, k₁, k_b: the finest detail, the middle scale, the base shape.
    #[serde(default = "default_weights")]
    pub weights: [f64; 3],
}

fn one() -> f64 {
    1.0
}

fn one_level() -> u32 {
    1
}

fn default_contrast() -> f64 {
    4.0
}

fn default_light() -> [f64; 3] {
    [-0.4, 0.6, 1.0]
}

fn default_weights() -> [f64; 3] {
    [0.3, 0.3, 0.4]
}

impl Default for UnsharpGradient {
    fn default() -> Self {
        UnsharpGradient {
            strength: one(),
            level: one_level(),
        }
    }
}

impl Default for ExaggeratedShading {
    fn default() -> Self {
        ExaggeratedShading {
            strength: one(),
            contrast: default_contrast(),
            light: default_light(),
            weights: default_weights(),
        }
    }
}

fn default_axis() -> [f64; 3] {
    [0.0, 0.0, 1.0]
}

/// ω_a is 1 within about 18° of the axis and 0 beyond about 46°.
fn default_alignment() -> [f64; 2] {
    [0.7, 0.95]
}

fn default_gradient() -> [f64; 2] {
    [0.02, 0.2]
}

impl BandPicker {
    /// The band's four data values: `band`, or taken from the values of
    /// the transfer function's control points (`points`).
    pub fn values(&self, tf_values: &[f64]) -> [f64; 4] {
        match self.points {
            Some([i, j]) if !tf_values.is_empty() => {
                let last = tf_values.len() - 1;
                let (i, j) = (i.min(last), j.min(last));
                [
                    tf_values[i.saturating_sub(1)],
                    tf_values[i],
                    tf_values[j],
                    tf_values[(j + 1).min(last)],
                ]
            }
            _ => self.band,
        }
    }

    /// With `points` resolved against the transfer function's values: the
    /// band the kernel and the overlay use.
    pub fn resolved(&self, tf_values: &[f64]) -> BandPicker {
        BandPicker {
            band: self.values(tf_values),
            ..*self
        }
    }
}

impl Probe {
    /// The sphere's centre and radius in volume space (data length units).
    pub fn in_volume(&self, ctx: &PackContext) -> (DVec3, f64) {
        let k = ctx.placement.scale(ctx.extent);
        let rt = ctx.placement.rotation().transpose();
        let centre = rt * (DVec3::from(self.center) - DVec3::from(ctx.placement.center)) / k
            + DVec3::from(ctx.extent) * 0.5;
        (centre, self.radius / k)
    }

    /// A probe at `center` of `radius` with the default axis and filters.
    pub fn new(center: [f64; 3], radius: f64) -> Probe {
        Probe {
            center,
            radius,
            axis: default_axis(),
            alignment: default_alignment(),
            gradient: default_gradient(),
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

/// What an enhancer needs from the kernel and what it does to a ray: the
/// one declaration of a kind beside its WGSL file. The kernel's constants
/// (`NEEDS_GRADIENT`, `TOOL_AUX`, `HAS_BREAKS`, `MODIFIES_OPTICS`) and
/// whether the kernel may skip empty space follow from it
/// (`backend/src/raycast/shader.rs`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct EnhancerSpec {
    pub kind: EnhancerKind,
    /// The scene's `kind` and the file `shaders/enhancers/<name>.wgsl`.
    pub name: &'static str,
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

/// Every enhancer, indexed by [`EnhancerKind`].
pub const ENHANCERS: [EnhancerSpec; 8] = [
    EnhancerSpec {
        kind: EnhancerKind::PassThrough,
        name: "pass-through",
        gradient: false,
        importance: false,
        sets_importance: false,
        coarse_gradients: false,
        shades: false,
        breaks: false,
        optics: false,
        adds_opacity: false,
    },
    EnhancerSpec {
        kind: EnhancerKind::ClipPlane,
        name: "clip-plane",
        gradient: false,
        importance: false,
        sets_importance: false,
        coarse_gradients: false,
        shades: false,
        breaks: true,
        optics: true,
        // The emphasis band blends towards full opacity only where τ̄ > 0.
        adds_opacity: false,
    },
    EnhancerSpec {
        kind: EnhancerKind::Probe,
        name: "probe",
        gradient: true,
        importance: true,
        sets_importance: false,
        coarse_gradients: false,
        shades: false,
        breaks: true,
        optics: true,
        // μ(α) and μ(i) are at most 1 (Eqs. 4–5).
        adds_opacity: false,
    },
    EnhancerSpec {
        kind: EnhancerKind::BandPicker,
        name: "band-picker",
        gradient: false,
        // It sets the importance; it does not read it.
        importance: false,
        sets_importance: true,
        coarse_gradients: false,
        shades: false,
        breaks: false,
        optics: true,
        // Its factor on opacity is at most 1.
        adds_opacity: false,
    },
    EnhancerSpec {
        kind: EnhancerKind::UnsharpGradient,
        name: "unsharp-gradient",
        gradient: true,
        importance: false,
        sets_importance: false,
        coarse_gradients: true,
        shades: false,
        breaks: false,
        optics: false,
        adds_opacity: false,
    },
    EnhancerSpec {
        kind: EnhancerKind::ExaggeratedShading,
        name: "exaggerated-shading",
        gradient: true,
        importance: false,
        sets_importance: false,
        coarse_gradients: true,
        shades: true,
        breaks: false,
        optics: false,
        // It shades segments with extinction only.
        adds_opacity: false,
    },
    EnhancerSpec {
        kind: EnhancerKind::GradientDirection,
        name: "gradient-direction",
        gradient: true,
        importance: false,
        sets_importance: false,
        coarse_gradients: false,
        shades: false,
        breaks: false,
        optics: false,
        // It shows only rays that meet extinction.
        adds_opacity: false,
    },
    EnhancerSpec {
        kind: EnhancerKind::ExitDirection,
        name: "exit-direction",
        gradient: false,
        importance: false,
        sets_importance: false,
        coarse_gradients: false,
        shades: false,
        breaks: false,
        optics: false,
        adds_opacity: true,
    },
];

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

impl Tool {
    /// The tool's constant state as the kernel reads it (`ToolParams`:
    /// four vec4, meaning per enhancer, written in its WGSL file's header).
    pub fn pack(&self, ctx: &PackContext) -> [[f32; 4]; 4] {
        let f = |x: f64| x as f32;
        match self {
            Tool::PassThrough | Tool::ExitDirection | Tool::GradientDirection => [[0.0; 4]; 4],
            Tool::UnsharpGradient(u) => [
                [f(u.strength), u.level as f32, 0.0, 0.0],
                [0.0; 4],
                [0.0; 4],
                [0.0; 4],
            ],
            Tool::ExaggeratedShading(e) => {
                let l = ctx.placement.rotation().transpose() * DVec3::from(e.light).normalize();
                let sum: f64 = e.weights.iter().sum();
                let k = e.weights.map(|w| f(w / sum));
                [
                    [f(l.x), f(l.y), f(l.z), f(e.strength)],
                    [k[0], k[1], k[2], f(e.contrast)],
                    [0.0; 4],
                    [0.0; 4],
                ]
            }
            Tool::ClipPlane(c) => {
                let v = c.in_volume(&ctx.placement, ctx.extent);
                [
                    [f(v.normal.x), f(v.normal.y), f(v.normal.z), f(v.offset)],
                    [f(v.unit.x), f(v.unit.y), f(v.unit.z), f(c.thickness)],
                    [f(c.context[0]), f(c.context[1]), 0.0, 0.0],
                    [0.0; 4],
                ]
            }
            Tool::Probe(p) => {
                let (centre, r) = p.in_volume(ctx);
                let axis = ctx.placement.rotation().transpose() * DVec3::from(p.axis).normalize();
                [
                    [f(centre.x), f(centre.y), f(centre.z), f(r)],
                    [
                        f(axis.x),
                        f(axis.y),
                        f(axis.z),
                        f(ctx.gradient_max.max(1e-30)),
                    ],
                    [
                        f(p.alignment[0]),
                        f(p.alignment[1]),
                        f(p.gradient[0]),
                        f(p.gradient[1]),
                    ],
                    [0.0; 4],
                ]
            }
            Tool::BandPicker(b) => {
                let axis = ctx.placement.rotation().transpose() * DVec3::from(b.axis).normalize();
                [
                    b.band.map(f),
                    [f(axis.x), f(axis.y), f(axis.z), 0.0],
                    [f(b.alignment[0]), f(b.alignment[1]), 0.0, 0.0],
                    [0.0; 4],
                ]
            }
        }
    }

    /// Where the tool's enhancer acts and reads the gradient or importance
    /// (`ENH_active`), as a box in volume space (data length units): the
    /// kernel computes those inputs only in the tiles whose rays can meet
    /// it (`None`: nowhere, or for an enhancer that reads them and declares
    /// no region, the whole volume).
    pub fn region(&self, ctx: &PackContext) -> Option<[[f64; 3]; 2]> {
        match self {
            Tool::Probe(p) => {
                let (c, r) = p.in_volume(ctx);
                Some([(c - r).to_array(), (c + r).to_array()])
            }
            t if t.enhancer().spec().gradient || t.enhancer().spec().importance => {
                Some([[0.0; 3], ctx.extent])
            }
            _ => None,
        }
    }

    /// Whether the tool can change anything in the volume's box: a clip
    /// plane whose cut-away side and band miss the box, a probe whose
    /// sphere misses it, or multilevel shading at strength 0 changes no ray (its breaks fall outside the box,
    /// where a ray integrates nothing), and the renderer leaves it out of
    /// the kernel.
    pub fn acts_on(&self, ctx: &PackContext) -> bool {
        let corners = (0..8).map(|i| {
            DVec3::new(
                if i & 1 == 0 { 0.0 } else { ctx.extent[0] },
                if i & 2 == 0 { 0.0 } else { ctx.extent[1] },
                if i & 4 == 0 { 0.0 } else { ctx.extent[2] },
            )
        });
        match self {
            Tool::ClipPlane(c) => {
                let v = c.in_volume(&ctx.placement, ctx.extent);
                corners
                    .map(|q| v.normal.dot(q) + v.offset)
                    .fold(f64::NEG_INFINITY, f64::max)
                    > -c.thickness
            }
            Tool::Probe(p) => {
                let (c, r) = p.in_volume(ctx);
                let nearest = c.clamp(DVec3::ZERO, DVec3::from(ctx.extent));
                (nearest - c).length() < r
            }
            // At strength 0 multilevel shading is plain shading: left out,
            // it costs nothing (in the kernel it would read two coarser
            // gradients a shaded segment).
            Tool::UnsharpGradient(u) => u.strength > 0.0,
            Tool::ExaggeratedShading(e) => e.strength > 0.0,
            Tool::PassThrough
            | Tool::BandPicker(_)
            | Tool::GradientDirection
            | Tool::ExitDirection => true,
        }
    }

    /// Checks a tool's parameters; `what` names the file and the table.
    pub fn check(&self, what: &str) -> Result<()> {
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        let direction = |v: &[f64; 3], field: &str| -> Result<()> {
            if !finite(v) || DVec3::from(*v).length() < 1e-12 {
                bail!("{what}: {field} must be a finite non-zero vector (got {v:?})");
            }
            Ok(())
        };
        let band = |b: &[f64; 2], field: &str, names: &str| -> Result<()> {
            let [lo, hi] = *b;
            if !(finite(b) && (0.0..=1.0).contains(&lo) && lo < hi && hi <= 1.0) {
                bail!("{what}: {field} must be [{names}] with 0 ≤ lo < hi ≤ 1 (got {b:?})");
            }
            Ok(())
        };
        let within = |v: f64, lo: f64, hi: f64, field: &str| -> Result<()> {
            if !(v.is_finite() && (lo..=hi).contains(&v)) {
                bail!("{what}: {field} must be in [{lo}, {hi}] (got {v})");
            }
            Ok(())
        };
        match self {
            Tool::PassThrough | Tool::ExitDirection | Tool::GradientDirection => Ok(()),
            Tool::UnsharpGradient(u) => {
                within(u.strength, 0.0, 10.0, "strength")?;
                if !(1..=2).contains(&u.level) {
                    bail!("{what}: level must be 1 or 2 (got {})", u.level);
                }
                Ok(())
            }
            Tool::ExaggeratedShading(e) => {
                within(e.strength, 0.0, 1.0, "strength")?;
                if !(e.contrast.is_finite() && e.contrast > 0.0 && e.contrast <= 1000.0) {
                    bail!("{what}: contrast must be in (0, 1000] (got {})", e.contrast);
                }
                direction(&e.light, "light")?;
                if !(finite(&e.weights)
                    && e.weights.iter().all(|&w| (0.0..=1e3).contains(&w))
                    && e.weights.iter().sum::<f64>() > 1e-9)
                {
                    bail!(
                        "{what}: weights must be three finite values in [0, 1000], not all 0 (got {:?})",
                        e.weights
                    );
                }
                Ok(())
            }
            Tool::ClipPlane(c) => {
                if !finite(&c.point) {
                    bail!("{what}: point must be finite (got {:?})", c.point);
                }
                direction(&c.normal, "normal")?;
                if !(c.thickness.is_finite() && c.thickness >= 0.0) {
                    bail!("{what}: thickness must be ≥ 0 (got {})", c.thickness);
                }
                band(&c.context, "context", "f_l, f_h")
            }
            Tool::Probe(p) => {
                if !finite(&p.center) || p.center.iter().any(|x| x.abs() > 10.0) {
                    bail!(
                        "{what}: center must be finite and within 10 m (got {:?})",
                        p.center
                    );
                }
                if !(p.radius.is_finite() && p.radius > 0.0 && p.radius <= 10.0) {
                    bail!("{what}: radius must be in (0, 10] m (got {})", p.radius);
                }
                direction(&p.axis, "axis")?;
                band(&p.alignment, "alignment", "a_l, a_h")?;
                band(&p.gradient, "gradient", "g_l, g_h")
            }
            Tool::BandPicker(b) if b.points.is_some() => {
                let [i, j] = b.points.unwrap_or_default();
                if i > j || j > 4096 {
                    bail!(
                        "{what}: points must be two control point indices i ≤ j of the transfer function (got {:?})",
                        [i, j]
                    );
                }
                direction(&b.axis, "axis")?;
                band(&b.alignment, "alignment", "a_l, a_h")
            }
            Tool::BandPicker(b) => {
                let v = b.band;
                if !(finite(&v) && v[0] <= v[1] && v[1] <= v[2] && v[2] <= v[3] && v[0] < v[3]) {
                    bail!(
                        "{what}: band must be four ordered finite data values b0 ≤ b1 ≤ b2 ≤ b3 with b0 < b3 (got {v:?})"
                    );
                }
                direction(&b.axis, "axis")?;
                band(&b.alignment, "alignment", "a_l, a_h")
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
mod band_tests {
    use super::*;

    #[test]
    fn a_band_by_index_takes_the_points_and_their_neighbours() {
        let b = BandPicker {
            band: [0.0; 4],
            points: Some([1, 2]),
            axis: [0.0, 0.0, 1.0],
            alignment: [0.7, 0.95],
        };
        let v = [0.0, 25.0, 75.0, 105.0, 125.0];
        assert_eq!(b.values(&v), [0.0, 25.0, 75.0, 105.0]);
        // At the ends the feet are the end points; past the end, the last.
        let first = BandPicker {
            points: Some([0, 0]),
            ..b
        };
        assert_eq!(first.values(&v), [0.0, 0.0, 0.0, 25.0]);
        let past = BandPicker {
            points: Some([7, 9]),
            ..b
        };
        assert_eq!(past.values(&v), [105.0, 125.0, 125.0, 125.0]);
        let bad = Tool::BandPicker(BandPicker {
            points: Some([3, 1]),
            ..b
        });
        assert!(bad
            .check("s.toml")
            .unwrap_err()
            .to_string()
            .contains("points"));
        // Parsed from a scene without a band.
        let t: ToolTable = toml::from_str("kind = \"band-picker\"\npoints = [3, 3]\n").unwrap();
        let Tool::BandPicker(p) = Tool::from(t) else {
            panic!("not a band picker")
        };
        assert_eq!(p.values(&v), [75.0, 105.0, 105.0, 125.0]);
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
