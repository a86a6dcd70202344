//! Transfer-function presets from ParaView and 3D Slicer, converted to
//! Parallax transfer functions (docs/design.md "Transfer function").
//!
//! Formats read (recognised from the text, see [`PresetFormat::detect`]):
//!
//! * ParaView colour-map presets (`.json`): an array of preset objects (or one
//!   object) with `Name`, `ColorSpace`, `RGBPoints` = [x, r, g, b, …] and
//!   optionally `Points` = [x, α, midpoint, sharpness, …] (opacity, present
//!   when a transfer function was exported with its opacity). ParaView reads
//!   these with jsoncpp, which accepts comments and trailing commas (its own
//!   `ColorMaps.json` ends with one); so does this reader.
//! * 3D Slicer's `presets.xml` (and scene files): `<VolumeProperty>` elements
//!   whose attributes `scalarOpacity = "N x0 α0 x1 α1 …"` and
//!   `colorTransfer = "N x0 r0 g0 b0 …"` hold the transfer functions. N counts
//!   the numbers that follow (2 per opacity point, 4 per colour point), not
//!   the points.
//! * Slicer's legacy `.vp` text file: nine lines (interpolation, shade,
//!   diffuse, ambient, specular, specular power, scalar opacity, gradient
//!   opacity, colour), the last three in the same "N values…" form.
//! * Slicer's `.vp.json` (Slicer ≥ 5.9): `volumeProperties[0].components[0]`
//!   with `scalarOpacity`, `rgbTransferFunction` and
//!   `scalarOpacityUnitDistance`.
//!
//! # Conversion
//!
//! * **Opacity → extinction.** VTK's opacity α is the opacity of a slab one
//!   *scalar opacity unit distance* u thick (a sample d apart gets
//!   1 − (1 − α)^(d/u)), so the extinction is τ = −ln(1 − α)/u per data length
//!   unit, exactly the emission–absorption model Parallax integrates. u is VTK's
//!   default 1 world unit (mm in Slicer, which never changes it), the
//!   `scalarOpacityUnitDistance` of a `.vp.json`, or [`ImportOptions::unit`].
//!   ParaView derives its default from the data set's cell size, so a ParaView
//!   opacity needs the value shown as "Scalar Opacity Unit Distance" in its
//!   display properties. α is clamped to [0, [`MAX_ALPHA`]], so α = 1 gives
//!   the finite τ = ln(10⁶)/u ≈ 13.8/u.
//! * **Colour.** ParaView and Slicer colours are display values: VTK blends
//!   them as they are and shows the result on an sRGB screen. Parallax colours
//!   are linear and its images are sRGB-encoded, so by default colours are
//!   decoded with the sRGB transfer curve ([`srgb_to_linear`]); a flat,
//!   opaque region then shows the same colour in Parallax as in VTK.
//!   [`ImportOptions::linearize`] = false copies them unchanged.
//! * **Curves between breakpoints.** VTK interpolates colour in the preset's
//!   colour space (RGB, HSV, Lab, Moreland's diverging Msh, or steps) and α
//!   linearly (or along VTK's midpoint/sharpness curve); Parallax
//!   interpolates τ and linear colour linearly. The converter evaluates the
//!   VTK curves exactly at the union of all breakpoints (a step — two points
//!   at one abscissa — is kept as a step) and, unless
//!   [`ImportOptions::tolerance`] is `None`, adds points by bisection until α,
//!   and the displayed colour wherever α > 0, stay within the tolerance of
//!   VTK's curves.
//! * **Missing opacity.** A ParaView colour map without `Points` (every
//!   colour map that ParaView ships) has no opacity:
//!   [`ImportOptions::missing_opacity`] supplies one, by default ParaView's own
//!   default for a new array, α rising linearly from 0 to 1 over the colour
//!   map.
//! * **Range.** ParaView stretches a preset over the data range when it
//!   applies it (its colour maps are stored over [0, 1], [−1, 1] or other
//!   nominal ranges); [`ImportOptions::range`] does the same, mapping the
//!   first and last colour abscissae, and separately the first and last
//!   opacity abscissae, onto it. Without a range the abscissae are kept (the
//!   right thing for Slicer presets, in Hounsfield units for CT), and a
//!   ParaView map over exactly [0, 1] or [−1, 1] is refused as surely
//!   normalised.
//! * **Dropped.** Gradient opacity, shading parameters and NaN colours have no
//!   place in a 1-D transfer function; what was dropped is listed in the
//!   header comment of the written file ([`ImportedPreset::notes`]).

use std::fmt::Write as _;
use std::path::Path;
use std::str::FromStr;

use anyhow::{anyhow, bail, Context, Result};
use serde_json::{Map, Value};

use parallax_common::tf::{ControlPoint, TransferFunction, DEFAULT_IMPORTANCE, DEFAULT_REFRACTION};

// The opacity → extinction conversion and the sRGB decoding curve are
// shared with label colour tables (`parallax_common::tf::labels`).
pub use parallax_common::tf::{alpha_to_extinction, srgb_to_linear, MAX_ALPHA};

/// Default of [`ImportOptions::tolerance`]: α and displayed colour within
/// 0.005 (about 1.3 steps of 8 bits) of the source curves.
pub const DEFAULT_TOLERANCE: f64 = 0.005;

/// Bisection depth per source interval (at most 2⁸ − 1 added points).
const MAX_REFINE_DEPTH: u32 = 8;

// ------------------------------------------------------------------ API types

/// The preset formats this module reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PresetFormat {
    /// ParaView colour-map presets (`.json`).
    ParaViewJson,
    /// 3D Slicer `presets.xml` (or a scene holding `<VolumeProperty>` nodes).
    SlicerPresetsXml,
    /// 3D Slicer legacy volume property text file (`.vp`).
    SlicerVp,
    /// 3D Slicer volume property JSON (`.vp.json`).
    SlicerVpJson,
}

impl PresetFormat {
    /// Recognises the format from the text: `<` starts XML, `[` a ParaView
    /// array, `{` a ParaView object or (with `volumeProperties`) a Slicer
    /// `.vp.json`; anything else is read as a `.vp` file.
    pub fn detect(text: &str) -> PresetFormat {
        let t = text.trim_start_matches('\u{feff}').trim_start();
        match t.as_bytes().first() {
            Some(b'<') => PresetFormat::SlicerPresetsXml,
            Some(b'[') => PresetFormat::ParaViewJson,
            Some(b'{') => {
                if t.contains("\"volumeProperties\"") {
                    PresetFormat::SlicerVpJson
                } else {
                    PresetFormat::ParaViewJson
                }
            }
            _ => PresetFormat::SlicerVp,
        }
    }

    /// A few words for messages and file headers.
    pub fn description(self) -> &'static str {
        match self {
            PresetFormat::ParaViewJson => "ParaView colour-map preset",
            PresetFormat::SlicerPresetsXml => "3D Slicer volume-rendering preset",
            PresetFormat::SlicerVp => "3D Slicer volume property (.vp)",
            PresetFormat::SlicerVpJson => "3D Slicer volume property (.vp.json)",
        }
    }
}

/// The opacity used when a preset has none (ParaView colour maps).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MissingOpacity {
    /// α linear from `low` at the first colour abscissa to `high` at the last
    /// (after [`ImportOptions::range`]); ParaView's default for a new array is
    /// `low = 0, high = 1`.
    Ramp { low: f64, high: f64 },
    /// The same α everywhere.
    Constant(f64),
    /// No default: a preset without opacity is an error.
    Reject,
}

impl Default for MissingOpacity {
    fn default() -> Self {
        MissingOpacity::Ramp {
            low: 0.0,
            high: 1.0,
        }
    }
}

impl FromStr for MissingOpacity {
    type Err = anyhow::Error;

    /// `ramp` (α 0 → 1), `ramp:LOW,HIGH`, `const:A` (or `constant:A`), or
    /// `reject`; every α in [0, 1].
    fn from_str(s: &str) -> Result<Self> {
        let t = s.trim();
        let alpha = |v: &str| -> Result<f64> {
            let a: f64 = v
                .trim()
                .parse()
                .map_err(|_| anyhow!("opacity {v:?} is not a number"))?;
            if !(0.0..=1.0).contains(&a) {
                bail!("opacity {a} is outside [0, 1]");
            }
            Ok(a)
        };
        if t.eq_ignore_ascii_case("ramp") {
            return Ok(MissingOpacity::default());
        }
        if t.eq_ignore_ascii_case("reject") {
            return Ok(MissingOpacity::Reject);
        }
        if let Some(rest) = t.strip_prefix("ramp:") {
            let (lo, hi) = rest
                .split_once(',')
                .ok_or_else(|| anyhow!("{s:?}: expected ramp:LOW,HIGH (e.g. ramp:0,1)"))?;
            return Ok(MissingOpacity::Ramp {
                low: alpha(lo)?,
                high: alpha(hi)?,
            });
        }
        if let Some(rest) = t
            .strip_prefix("const:")
            .or_else(|| t.strip_prefix("constant:"))
        {
            return Ok(MissingOpacity::Constant(alpha(rest)?));
        }
        bail!("{s:?}: expected `ramp`, `ramp:LOW,HIGH`, `const:ALPHA` or `reject`")
    }
}

impl std::fmt::Display for MissingOpacity {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            MissingOpacity::Ramp { low, high } => write!(f, "ramp:{low},{high}"),
            MissingOpacity::Constant(a) => write!(f, "const:{a}"),
            MissingOpacity::Reject => write!(f, "reject"),
        }
    }
}

/// How a preset is converted (module docs, "Conversion").
#[derive(Clone, Debug, PartialEq)]
pub struct ImportOptions {
    /// Data range [lo, hi] to stretch the preset over, as ParaView does when
    /// it applies a preset: colour abscissae first..last and opacity
    /// abscissae first..last are each mapped onto it. `None` keeps the
    /// preset's own values.
    pub range: Option<(f64, f64)>,
    /// VTK's scalar opacity unit distance u in data length units (α is the
    /// opacity of a slab u thick). `None`: the file's value (`.vp.json`),
    /// else 1.
    pub unit: Option<f64>,
    /// Opacity for a preset that has none.
    pub missing_opacity: MissingOpacity,
    /// Decode sRGB display colours to linear RGB (default true).
    pub linearize: bool,
    /// Add points until α, and the displayed colour wherever α > 0, are
    /// within this of the source curves; `None` gives exactly one point per
    /// source breakpoint.
    pub tolerance: Option<f64>,
}

impl Default for ImportOptions {
    fn default() -> Self {
        ImportOptions {
            range: None,
            unit: None,
            missing_opacity: MissingOpacity::default(),
            linearize: true,
            tolerance: Some(DEFAULT_TOLERANCE),
        }
    }
}

impl ImportOptions {
    fn validate(&self) -> Result<()> {
        if let Some((lo, hi)) = self.range {
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                bail!("range must be finite with min < max (got {lo}..{hi})");
            }
        }
        if let Some(u) = self.unit {
            if !(u.is_finite() && u > 0.0) {
                bail!("opacity unit distance must be finite and > 0 (got {u})");
            }
        }
        if let Some(t) = self.tolerance {
            if !(t.is_finite() && t > 0.0) {
                bail!("tolerance must be finite and > 0 (got {t})");
            }
        }
        match self.missing_opacity {
            MissingOpacity::Ramp { low, high }
                if !((0.0..=1.0).contains(&low) && (0.0..=1.0).contains(&high)) =>
            {
                bail!("default opacity ramp must stay in [0, 1] (got {low}..{high})")
            }
            MissingOpacity::Constant(a) if !(0.0..=1.0).contains(&a) => {
                bail!("default opacity must be in [0, 1] (got {a})")
            }
            _ => Ok(()),
        }
    }
}

/// A converted preset.
#[derive(Clone, Debug, PartialEq)]
pub struct ImportedPreset {
    /// The preset's name (the file name for a `.vp` / `.vp.json`).
    pub name: String,
    pub format: PresetFormat,
    /// Where it came from (the label given to the importer, a file name).
    pub origin: String,
    pub tf: TransferFunction,
    /// The opacity unit distance used.
    pub unit: f64,
    /// The options it was converted with.
    pub options: ImportOptions,
    /// What the conversion dropped or approximated, one sentence each.
    pub notes: Vec<String>,
}

impl ImportedPreset {
    /// The header of the written file: source, conversion, notes (one
    /// sentence a line, without the `# `).
    pub fn header_lines(&self) -> Vec<String> {
        let u = self.unit;
        let mut h = vec![format!(
            "{} \"{}\", from {}.",
            self.format.description(),
            self.name,
            self.origin
        )];
        h.push(format!(
            "Opacity: VTK's α over its scalar opacity unit distance u = {u} (data length units) \
             became extinction τ = −ln(1 − α)/u; α = 1 was taken as 1 − 1e-6."
        ));
        h.push(if self.options.linearize {
            "Colours: sRGB display values decoded to linear RGB.".to_string()
        } else {
            "Colours: copied unchanged.".to_string()
        });
        if let Some((lo, hi)) = self.options.range {
            h.push(format!(
                "Values: the preset's colour and opacity abscissae each stretched onto [{lo}, {hi}]."
            ));
        }
        h.push(match self.options.tolerance {
            Some(t) => format!(
                "Points: every source breakpoint, and more where needed to keep α (and the \
                 displayed colour where α > 0) within {t} of the source curves."
            ),
            None => "Points: one per source breakpoint.".to_string(),
        });
        h.extend(self.notes.iter().cloned());
        h
    }

    /// The transfer function as TOML, in the format
    /// [`TransferFunction::load`] reads, headed by [`Self::header_lines`].
    pub fn to_toml(&self) -> String {
        tf_to_toml(&self.tf, &self.header_lines())
    }
}

// ------------------------------------------------------------- entry points

/// Converts a preset of any supported format (recognised from the text).
/// `origin` (usually the file name) starts every error message; `name`
/// selects a preset in a multi-preset file (ParaView JSON, `presets.xml`):
/// an exact name, else a unique case-insensitive match, else `#N` for the
/// N-th preset (1-based). Without a name a file must hold exactly one
/// preset; errors list the names.
pub fn import_preset(
    text: &str,
    origin: &str,
    name: Option<&str>,
    opts: &ImportOptions,
) -> Result<ImportedPreset> {
    match PresetFormat::detect(text) {
        PresetFormat::ParaViewJson => import_paraview(text, origin, name, opts),
        PresetFormat::SlicerPresetsXml => import_slicer_xml(text, origin, name, opts),
        f @ (PresetFormat::SlicerVp | PresetFormat::SlicerVpJson) => {
            if let Some(n) = name {
                bail!(
                    "{origin}: a {} holds one transfer function; a preset name ({n:?}) \
                     applies to presets.xml and ParaView JSON files",
                    f.description()
                );
            }
            if f == PresetFormat::SlicerVp {
                import_slicer_vp(text, origin, opts)
            } else {
                import_slicer_vp_json(text, origin, opts)
            }
        }
    }
}

/// [`import_preset`] on a file; errors start with the file name.
pub fn import_preset_file(
    path: impl AsRef<Path>,
    name: Option<&str>,
    opts: &ImportOptions,
) -> Result<ImportedPreset> {
    let path = path.as_ref();
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("{}: cannot read preset file", path.display()))?;
    import_preset(&text, &path.display().to_string(), name, opts)
}

/// The names of the presets in a file of any supported format, in file
/// order (one name, from `origin`, for a `.vp` / `.vp.json`).
pub fn preset_names(text: &str, origin: &str) -> Result<Vec<String>> {
    match PresetFormat::detect(text) {
        PresetFormat::ParaViewJson => {
            let root = parse_json(text, origin)?;
            Ok(paraview_entries(&root, origin)?
                .into_iter()
                .map(|(n, _)| n)
                .collect())
        }
        PresetFormat::SlicerPresetsXml => Ok(slicer_xml_properties(text, origin)?
            .into_iter()
            .map(|(n, _)| n)
            .collect()),
        PresetFormat::SlicerVp | PresetFormat::SlicerVpJson => Ok(vec![file_stem(origin)]),
    }
}

/// Converts one preset of a ParaView colour-map JSON file
/// ([`import_preset`] for `origin` and `name`).
pub fn import_paraview(
    text: &str,
    origin: &str,
    name: Option<&str>,
    opts: &ImportOptions,
) -> Result<ImportedPreset> {
    let root = parse_json(text, origin)?;
    let entries = paraview_entries(&root, origin)?;
    let names: Vec<String> = entries.iter().map(|(n, _)| n.clone()).collect();
    let i = select_preset(&names, name, origin)?;
    let (name, obj) = &entries[i];
    let src = paraview_source(name, obj, origin)?;
    convert(src, PresetFormat::ParaViewJson, origin, opts)
}

/// Converts one `<VolumeProperty>` of a 3D Slicer `presets.xml`
/// ([`import_preset`] for `origin` and `name`).
pub fn import_slicer_xml(
    text: &str,
    origin: &str,
    name: Option<&str>,
    opts: &ImportOptions,
) -> Result<ImportedPreset> {
    let props = slicer_xml_properties(text, origin)?;
    let names: Vec<String> = props.iter().map(|(n, _)| n.clone()).collect();
    let i = select_preset(&names, name, origin)?;
    let (name, el) = &props[i];
    let ctx = format!("{origin}: preset {name:?}");
    let notes = slicer_shading_note(
        el.attr("shade"),
        [
            ("ambient", el.attr("ambient")),
            ("diffuse", el.attr("diffuse")),
            ("specular", el.attr("specular")),
            ("specularPower", el.attr("specularPower")),
        ],
    );
    let src = slicer_source(
        name,
        [
            ("scalarOpacity", el.attr("scalarOpacity")),
            ("gradientOpacity", el.attr("gradientOpacity")),
            ("colorTransfer", el.attr("colorTransfer")),
        ],
        &ctx,
        notes,
    )?;
    convert(src, PresetFormat::SlicerPresetsXml, origin, opts)
}

/// Converts a 3D Slicer legacy `.vp` file; the preset is named after
/// `origin`'s file name.
pub fn import_slicer_vp(text: &str, origin: &str, opts: &ImportOptions) -> Result<ImportedPreset> {
    const LINES: [&str; 9] = [
        "interpolation",
        "shade",
        "diffuse",
        "ambient",
        "specular",
        "specular power",
        "scalar opacity",
        "gradient opacity",
        "colour",
    ];
    let text = text.trim_start_matches('\u{feff}');
    let lines: Vec<&str> = text.lines().map(str::trim).collect();
    let used = lines
        .iter()
        .rposition(|l| !l.is_empty())
        .map_or(0, |i| i + 1);
    if used < 9 {
        bail!(
            "{origin}: a .vp file has 9 lines ({}); found {used}",
            LINES.join(", ")
        );
    }
    if used > 9 {
        bail!(
            "{origin}: line {used}: a .vp file has 9 lines ({}); unexpected text after the colour line",
            LINES.join(", ")
        );
    }
    for (i, what) in LINES.iter().enumerate().take(6) {
        let l = lines[i];
        if !l.is_empty() && !l.parse::<f64>().is_ok_and(f64::is_finite) {
            bail!(
                "{origin}: line {} ({what}): expected a number, got {l:?} (is this a .vp file?)",
                i + 1
            );
        }
    }
    let name = file_stem(origin);
    fn opt(l: &str) -> Option<&str> {
        (!l.is_empty()).then_some(l)
    }
    let shading = slicer_shading_note(
        opt(lines[1]),
        [
            ("ambient", opt(lines[3])),
            ("diffuse", opt(lines[2])),
            ("specular", opt(lines[4])),
            ("specularPower", opt(lines[5])),
        ],
    );
    let src = slicer_source(
        &name,
        [
            ("line 7 (scalar opacity)", opt(lines[6])),
            ("line 8 (gradient opacity)", opt(lines[7])),
            ("line 9 (colour)", opt(lines[8])),
        ],
        origin,
        shading,
    )?;
    convert(src, PresetFormat::SlicerVp, origin, opts)
}

/// Converts a 3D Slicer `.vp.json` file (its first volume property and first
/// component, as Slicer reads it); the preset is named after `origin`'s file
/// name. Points are stably sorted by x, as Slicer does.
pub fn import_slicer_vp_json(
    text: &str,
    origin: &str,
    opts: &ImportOptions,
) -> Result<ImportedPreset> {
    let root = parse_json(text, origin)?;
    let src = slicer_vp_json_source(&root, origin)?;
    convert(src, PresetFormat::SlicerVpJson, origin, opts)
}

/// The sRGB encoding curve: linear → display value, [0, 1].
pub fn linear_to_srgb(c: f64) -> f64 {
    let c = c.clamp(0.0, 1.0);
    if c <= 0.0031308 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

/// Writes a transfer function as TOML in the format
/// [`TransferFunction::load`] reads: `header` lines as `# ` comments, then
/// one `[[point]]` table per control point. Numbers are written in their
/// shortest exact form, so reading the text back gives the same points bit
/// for bit. Importance and refraction are written only where they differ
/// from the defaults.
pub fn tf_to_toml(tf: &TransferFunction, header: &[String]) -> String {
    let mut s = String::new();
    for line in header {
        for l in line.lines() {
            if l.trim().is_empty() {
                s.push_str("#\n");
            } else {
                let _ = writeln!(s, "# {l}");
            }
        }
    }
    for p in tf.points() {
        if !s.is_empty() {
            s.push('\n');
        }
        s.push_str("[[point]]\n");
        let _ = writeln!(s, "value = {}", toml_float(p.value));
        let _ = writeln!(
            s,
            "color = [{}, {}, {}]",
            toml_float(p.color[0]),
            toml_float(p.color[1]),
            toml_float(p.color[2])
        );
        let _ = writeln!(s, "extinction = {}", toml_float(p.extinction));
        if p.importance != DEFAULT_IMPORTANCE {
            let _ = writeln!(s, "importance = {}", toml_float(p.importance));
        }
        if p.refraction != DEFAULT_REFRACTION {
            let _ = writeln!(s, "refraction = {}", toml_float(p.refraction));
        }
    }
    s
}

/// Rust's `Debug` form of an f64 is its shortest round-trip representation
/// and always a valid TOML float ("0.0", "-3024.0", "1e-7", "1e30").
fn toml_float(v: f64) -> String {
    format!("{v:?}")
}

// ----------------------------------------------------------- internal model

/// The interpolation space of a colour function (VTK's ColorSpace).
#[derive(Clone, Copy, Debug, PartialEq)]
enum ColorSpace {
    Rgb,
    Hsv {
        wrap: bool,
    },
    Lab,
    Diverging,
    /// Piecewise constant: (xᵢ, xᵢ₊₁] takes the colour of node i + 1.
    Step,
}

/// One VTK node: the segment to its right follows `midpoint` and
/// `sharpness` (VTK defaults 0.5 and 0: linear).
#[derive(Clone, Copy, Debug)]
struct Node<V> {
    x: f64,
    v: V,
    midpoint: f64,
    sharpness: f64,
}

impl<V> Node<V> {
    fn linear(x: f64, v: V) -> Self {
        Node {
            x,
            v,
            midpoint: 0.5,
            sharpness: 0.0,
        }
    }
}

/// A preset as read, before conversion; colours are display values.
struct Source {
    name: String,
    color: Vec<Node<[f64; 3]>>,
    space: ColorSpace,
    opacity: Option<Vec<Node<f64>>>,
    /// Opacity unit distance given by the file.
    unit: Option<f64>,
    /// Refuse to keep abscissae spanning exactly [0, 1] or [−1, 1] without a
    /// range (ParaView's normalised colour maps).
    normalized_check: bool,
    notes: Vec<String>,
}

mod convert;
mod paraview;
mod parse;
mod slicer;
mod vtk;
#[allow(unused_imports)]
use convert::*;
#[allow(unused_imports)]
use paraview::*;
#[allow(unused_imports)]
use parse::*;
#[allow(unused_imports)]
use slicer::*;
#[allow(unused_imports)]
use vtk::*;

#[cfg(test)]
mod tests;
