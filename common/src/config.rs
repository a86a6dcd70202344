//! Scene and display files (docs/design.md "Command line", "Display
//! configuration"). Every error names the file and the field.

use crate::camera::{Placement, View, MAX_VIEW_SIDE};
use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

fn read_toml<T: for<'de> Deserialize<'de>>(path: &Path) -> Result<T> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("{}: cannot read", path.display()))?;
    toml::from_str(&text)
        .map_err(|e| anyhow::anyhow!("{}: {}", path.display(), e.to_string().trim_end()))
}

fn resolve(base: &Path, p: &Path) -> PathBuf {
    if p.is_absolute() {
        p.to_path_buf()
    } else {
        base.parent().unwrap_or(Path::new(".")).join(p)
    }
}

fn finite(file: &Path, field: &str, v: &[f64]) -> Result<()> {
    if v.iter().any(|x| !x.is_finite()) {
        bail!("{}: {field} must be finite (got {v:?})", file.display());
    }
    Ok(())
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Shading {
    None,
    Phong,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    Dvr,
    Mimda,
    Iso,
}

/// `[render]` of a scene.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RenderConfig {
    #[serde(default)]
    pub eta: f64,
    #[serde(default = "default_shading")]
    pub shading: Shading,
    #[serde(default = "default_mode")]
    pub mode: Mode,
    #[serde(default)]
    pub gamma: f64,
    /// The largest size, in display pixels, one voxel of a leaf may project
    /// to: a node is adequate when its voxels project to at most this many
    /// pixels (1: a voxel per pixel, G10's setting; 0.5 refines one level
    /// further, 2 one level less).
    #[serde(default = "one")]
    pub accuracy: f64,
    /// Where one voxel can stop a ray (issue 40): a node whose voxel, along
    /// the edge its children halve, has an optical depth above 1 somewhere
    /// in its value range (the transfer function's largest extinction there
    /// × that edge) is adequate only at `accuracy` / `opaque_detail`
    /// pixels; 1 is off. A translucent voxel's error is spread through the
    /// ray; an opaque one's is where the pixel's surface is, and a coarser
    /// level moves that surface by up to half its voxel (its average of
    /// eight children), so the silhouette of the body on a thick-slice CT
    /// under a steep function is one level coarser than the in-plane
    /// detail the view resolves. Default 2: one level finer where the
    /// surface is. A thick CT under CT-Soft-Tissue at 256²: RMSE 1.24e-2 →
    /// 4.30e-3 (docs/performance.md, "Opaque voxels"). Not for isosurfaces
    /// (their nodes follow the isovalue) nor with `multilevel` (whose
    /// samples blend by `accuracy` alone).
    #[serde(default = "two")]
    pub opaque_detail: f64,
    /// Step length as a fraction of the leaf's voxel size.
    #[serde(default = "half")]
    pub step_factor: f64,
    /// Opacity at which rays stop.
    #[serde(default = "early")]
    pub early_termination: f64,
    /// CPU (L2) brick cache, MiB.
    #[serde(default = "cpu_mb")]
    pub cpu_cache_mb: f64,
    /// GPU brick pool, MiB.
    #[serde(default = "gpu_mb")]
    pub gpu_cache_mb: f64,
    /// Bricks uploaded to the GPU per frame at most.
    #[serde(default = "uploads")]
    pub upload_budget: usize,
    /// Visibility feedback culling (G10 §5).
    #[serde(default = "yes")]
    pub visibility_feedback: bool,
    /// Brick interpolation: by the texture unit, or exact (eight loads).
    #[serde(default = "hardware")]
    pub interpolation: Interpolation,
    /// Continuous refraction by Snell's law from the transfer function's
    /// refraction index (G10 §4).
    #[serde(default)]
    pub refraction: bool,
    /// The surface shown with `mode = "iso"` (a data value; G08 §5.3).
    #[serde(default)]
    pub isovalue: Option<f64>,
    /// Adaptive frame reconstruction (G10 §5): one quincunx sub-frame of
    /// each view rendered per frame, the others reconstructed.
    #[serde(default)]
    pub reconstruction: bool,
    /// Isosurfaces: the prediction buffer (B10 §4): each pixel's last hit
    /// distance (or miss) steers its next traversal.
    #[serde(default)]
    pub prediction: bool,
    /// B10 §4.5: the sparse step is the voxel size / κ, κ from the brick's
    /// variance between these two values (lowest variance, highest).
    #[serde(default = "default_kappa")]
    pub kappa: [f64; 2],
    /// B10 §4.4: a full traversal every this many frames (α).
    #[serde(default = "default_full_every")]
    pub full_traversal_every: u32,
    /// Empty-space skipping inside bricks (L12 §4.1): macrocells that the
    /// transfer function leaves empty are stepped over. Changes no pixel;
    /// off only to measure what it saves.
    #[serde(default = "yes")]
    pub macrocells: bool,
    /// L12 §4.4's adaptive step: the step is `step_factor` × the pixel's
    /// footprint 2·t·sin(θ/2) at the leaf's distance t from the eye (0.5:
    /// λ = t·sin(θ/2), Eq. 3) instead of `step_factor` × the leaf's voxel.
    #[serde(default)]
    pub adaptive_step: bool,
    /// Multilevel sampling (G10 §4, Fig. 5): samples blend a leaf's data
    /// with its parent's and grandparent's by how coarse the view needs
    /// them (the footprint refinement uses, with `accuracy`), so where the
    /// cut changes level between bricks the image has no seam.
    #[serde(default)]
    pub multilevel: bool,
    /// The reconstruction filter inside bricks: trilinear, or the smoother
    /// tricubic B-spline of L12 §5.1 (eight trilinear lookups a sample).
    #[serde(default = "trilinear")]
    pub filter: Filter,
    /// Opaque-segment refinement (issue 40), at most R parts: a segment
    /// whose own optical depth d = τ̄·h exceeds 1 while the ray is still
    /// more than 1/256 transparent is marched again in ⌈d⌉ equal parts, at
    /// most R up to `step_factor` 1, R / `step_factor` (rounded) above,
    /// none from 4R/3 up; R = 1 is off. Pre-integration (Engel, Kraus and Ertl 2001) is exact for a
    /// scalar linear between samples; the trilinear field departs from its
    /// chord by O(h²) (h²·|s''|/8), which sets the pixel where one segment
    /// is optically thick: there the colour is where inside it the opacity
    /// accrues. P parts cut that by P²; thin segments are left as they
    /// were. It is Danskin and Hanrahan's (1992) idea of spending samples
    /// where opacity accrues, applied to the segments that need it. A
    /// thick-slice CT under CT-Soft-Tissue at 512²: RMSE 5.1e-2 → 4.6e-3
    /// for 6 % more time at R = 4 (docs/performance.md, "Opaque segments").
    /// Kernels whose function and steps cannot make such a segment leave
    /// it out. Isosurfaces, refraction and registered layers march as
    /// before.
    #[serde(default = "default_refinement")]
    pub refinement: u32,
    /// How a segment's average optics are looked up: "exact" (the
    /// pre-integration table of the transfer function's own breakpoints,
    /// exact for the linear scalar between samples) or "2d" (the classic 2D
    /// table over front and back values, Engel et al. 2001, at most 512²
    /// nodes, bilinear: one texture fetch a sample, faster on devices where
    /// table reads are dear; its error is in `parallax bench sweep`'s
    /// work–precision table). "2d" needs filterable f32 textures and falls
    /// back to "exact" without them. "analytic": the exact integral again,
    /// computed per segment in closed form from the transfer function's
    /// pieces between control points (common/src/tf/closed.rs), no table
    /// read. Its cost grows with the pieces where τ > 0: on a CPU device,
    /// where a texture read is a gather per channel and lane, it beats
    /// the table for a few and may lose for many, docs/performance.md
    /// "Pre-integration per case". A function with more than 16 such pieces
    /// over the data range (or extinctions too large for f32 sums) is
    /// looked up as with "2d".
    ///
    /// "auto" (the default): the fastest way to the exact integral on this
    /// device for this function, as measured (docs/performance.md, "The
    /// default: auto"): the closed form on a CPU device where the function
    /// has one (0.50–0.81 of the table's frame time on lavapipe, 2 to 15
    /// pieces, fine and coarse steps; 28 pieces, beyond the limit, took
    /// 1.22–1.27), else the exact table (on a GPU, the H200, the table was
    /// the faster). Never the 2D table, which is not the exact integral.
    #[serde(default)]
    pub preintegration: Preintegration,
    /// `[render.overlay]`: the tools' geometry and the 3D cursor drawn over
    /// every view (G10 §5; `common/src/overlay.rs`). Off by default.
    #[serde(default)]
    pub overlay: crate::overlay::Overlay,
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Preintegration {
    Exact,
    #[serde(rename = "2d")]
    TwoD,
    Analytic,
    #[default]
    Auto,
}

impl Preintegration {
    /// What "auto" means for a function of `closed_pieces` pieces (`None`:
    /// it has no closed form) on a CPU device or not; any other choice is
    /// kept.
    pub fn resolve(self, closed_pieces: Option<u32>, cpu_device: bool) -> Preintegration {
        match self {
            Preintegration::Auto if cpu_device && closed_pieces.is_some() => {
                Preintegration::Analytic
            }
            Preintegration::Auto => Preintegration::Exact,
            p => p,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Filter {
    Trilinear,
    Tricubic,
}

fn trilinear() -> Filter {
    Filter::Trilinear
}

/// B10 found κ = 0.1…0.3 (steps of 3–10 voxels) good on its data; on the
/// noisy skin of an MRI that costs 25 dB against full traversal, 0.5…1
/// (steps of 1–2 voxels) keeps 33 dB at a 2.3× speed-up (docs/performance.md,
/// "Isosurfaces and the prediction buffer").
fn default_kappa() -> [f64; 2] {
    [0.5, 1.0]
}

fn default_refinement() -> u32 {
    4
}

fn default_full_every() -> u32 {
    10
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Interpolation {
    Hardware,
    Exact,
}

fn hardware() -> Interpolation {
    Interpolation::Hardware
}

fn default_shading() -> Shading {
    Shading::None
}
fn default_mode() -> Mode {
    Mode::Dvr
}
fn one() -> f64 {
    1.0
}
fn half() -> f64 {
    0.5
}
fn two() -> f64 {
    2.0
}
/// 0.999: its error (RMSE 2.5e-4 on Colin27 in `parallax bench sweep`) stays
/// below the default step's (2.9e-4); 0.99 cost 3.1e-3, ten times more.
fn early() -> f64 {
    0.999
}
fn cpu_mb() -> f64 {
    1024.0
}
fn gpu_mb() -> f64 {
    512.0
}
fn uploads() -> usize {
    256
}
fn yes() -> bool {
    true
}

impl RenderConfig {
    /// What a scene with `[[layer]]`s cannot use yet: the layers are
    /// combined in the DVR and MImDA kernels' trilinear, single-level
    /// sampling.
    pub fn check_layered(&self, file: &str) -> Result<()> {
        let refuse = |field: &str, what: &str| -> Result<()> {
            bail!(
                "{file}: {field}: {what} is not available with [[layer]]s yet (DVR and MImDA only)"
            )
        };
        if self.mode == Mode::Iso {
            refuse("render.mode", "the isosurface mode")?;
        }
        if self.refraction {
            refuse("render.refraction", "refraction")?;
        }
        if self.multilevel {
            refuse("render.multilevel", "multilevel sampling")?;
        }
        if self.filter == Filter::Tricubic {
            refuse("render.filter", "tricubic filtering")?;
        }
        Ok(())
    }
}

impl Default for RenderConfig {
    fn default() -> Self {
        toml::from_str("").unwrap()
    }
}

/// A scene file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    /// The octree database (relative to the scene file). With `series`, its
    /// first step (leave `volume` out).
    #[serde(default, with = "crate::paths::bytes")]
    pub volume: PathBuf,
    /// A time series: one database per time step, in order (relative to
    /// the scene file), all on one grid (dimensions, bricks, spacing); a
    /// frame draws the step its state names (`FrameState::step`, moved by
    /// scripts and the live page).
    #[serde(default, with = "crate::paths::list_bytes")]
    pub series: Vec<PathBuf>,
    /// The transfer function file (relative to the scene file).
    #[serde(with = "crate::paths::bytes")]
    pub transfer_function: PathBuf,
    pub placement: Placement,
    #[serde(default)]
    pub render: RenderConfig,
    /// The display to render for when none is given on the command line.
    #[serde(default, with = "crate::paths::opt_bytes")]
    pub display: Option<PathBuf>,
    /// `[[tool]]` tables: the tools, each driving one enhancer (G10 §4).
    #[serde(default, rename = "tool", with = "crate::tools::list")]
    pub tools: Vec<crate::tools::Tool>,
    /// `[[layer]]` tables: volumes registered to `volume`, each with its
    /// own transfer function, combined with it as media (G10 §4).
    #[serde(default, rename = "layer")]
    pub layers: Vec<Layer>,
}

/// The most time steps a scene's `series` may list.
pub const MAX_SERIES: usize = 100_000;

/// The steps of a scene: its series' length, or 1 for one volume.
impl Scene {
    pub fn steps(&self) -> usize {
        self.series.len().max(1)
    }
}

/// The most `[[layer]]`s a scene may add to its volume: the kernel reads
/// the volume and its layers as the four channels of one brick pool.
pub const MAX_LAYERS: usize = 3;

/// `[[layer]]` of a scene: a volume registered to the scene volume, on its
/// grid (the same dimensions, brick size and spacing) or placed in it by
/// an affine `transform`, drawn through its own transfer function. Where
/// layers overlap their extinctions and extinction-weighted emissions add:
/// the exact integral of the summed medium.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Layer {
    /// The layer's octree database (relative to the scene file).
    #[serde(with = "crate::paths::bytes")]
    pub volume: PathBuf,
    /// Its transfer function file (relative to the scene file), for a
    /// volume of values.
    #[serde(default, with = "crate::paths::opt_bytes")]
    pub transfer_function: Option<PathBuf>,
    /// Its colour table (relative to the scene file), for a label volume
    /// (`parallax import --labels`): TOML, 3D Slicer or ITK-SNAP
    /// (`tf::labels`). The layer is sampled at the nearest voxel, and each
    /// label the volume holds must be in the table.
    #[serde(default, with = "crate::paths::opt_bytes")]
    pub labels: Option<PathBuf>,
    /// Scales the layer's extinction and emission, in [0, 1].
    #[serde(default = "one")]
    pub opacity: f64,
    /// Off: the layer is left out (nothing of it is loaded).
    #[serde(default = "yes")]
    pub visible: bool,
    /// The layer's opacity as a function of the view direction (G10 §4).
    #[serde(default)]
    pub view_opacity: Option<ViewOpacity>,
    /// Where a layer on another grid lies in the scene volume
    /// ([`LayerTransform`]). Without it the layer must be on the volume's
    /// grid.
    #[serde(default)]
    pub transform: Option<LayerTransform>,
}

/// A layer's place in the scene volume (`[[layer]] transform`).
#[derive(Clone, Debug, PartialEq)]
pub enum LayerTransform {
    /// `"scanner"`: where the scanner put it: the layer's and the volume's
    /// scanner geometry as their importers read it (DICOM, NIfTI's sform or
    /// qform, NRRD's space), so a segmentation lands on its CT.
    Scanner,
    /// The affine map from the layer's volume space to the scene volume's
    /// (both in data units, from the first voxel's corner; a registration's
    /// moving-to-fixed matrix): three rows `[a, b, c, t]`, or four with
    /// `[0, 0, 0, 1]` last.
    Matrix(Vec<[f64; 4]>),
}

/// The binary form (the wire) is tagged; a scene file's is `"scanner"` or
/// the rows.
#[derive(Serialize, Deserialize)]
enum TaggedTransform {
    Scanner,
    Matrix(Vec<[f64; 4]>),
}

#[derive(Serialize, Deserialize)]
#[serde(untagged)]
enum TextTransform {
    Name(String),
    Matrix(Vec<[f64; 4]>),
}

impl Serialize for LayerTransform {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        match (s.is_human_readable(), self) {
            (true, LayerTransform::Scanner) => TextTransform::Name("scanner".into()).serialize(s),
            (true, LayerTransform::Matrix(m)) => TextTransform::Matrix(m.clone()).serialize(s),
            (false, LayerTransform::Scanner) => TaggedTransform::Scanner.serialize(s),
            (false, LayerTransform::Matrix(m)) => TaggedTransform::Matrix(m.clone()).serialize(s),
        }
    }
}

impl<'de> Deserialize<'de> for LayerTransform {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        use serde::de::Error;
        if !d.is_human_readable() {
            return Ok(match TaggedTransform::deserialize(d)? {
                TaggedTransform::Scanner => LayerTransform::Scanner,
                TaggedTransform::Matrix(m) => LayerTransform::Matrix(m),
            });
        }
        let expected = "\"scanner\" or an affine map's rows [a, b, c, t]";
        match TextTransform::deserialize(d)
            .map_err(|_| D::Error::custom(format!("expected {expected}")))?
        {
            TextTransform::Name(n) if n == "scanner" => Ok(LayerTransform::Scanner),
            TextTransform::Name(n) => Err(D::Error::custom(format!(
                "unknown transform \"{n}\": give {expected}"
            ))),
            TextTransform::Matrix(m) => Ok(LayerTransform::Matrix(m)),
        }
    }
}

impl Layer {
    /// The field that names the layer's function, and its file:
    /// `transfer_function`, or `labels` for a label layer.
    pub fn function_file(&self) -> (&'static str, &Path) {
        match (&self.labels, &self.transfer_function) {
            (Some(l), _) => ("labels", l),
            (None, Some(t)) => ("transfer_function", t),
            (None, None) => ("transfer_function", Path::new("")),
        }
    }

    /// The layer's `transform` matrix as its linear part (rows) and
    /// translation: layer space → scene volume space. `None` without one,
    /// for `"scanner"` (the renderer composes the databases' geometry), or
    /// for a malformed one (which `Scene::load` refuses).
    pub fn affine(&self) -> Option<([[f64; 3]; 3], [f64; 3])> {
        let Some(LayerTransform::Matrix(t)) = &self.transform else {
            return None;
        };
        if !(3..=4).contains(&t.len()) {
            return None;
        }
        let m = std::array::from_fn(|r| [t[r][0], t[r][1], t[r][2]]);
        Some((m, [t[0][3], t[1][3], t[2][3]]))
    }

    /// A label layer (its function is a colour table).
    pub fn is_labels(&self) -> bool {
        self.labels.is_some()
    }

    /// The layer's transfer function: its file's, or its colour table's
    /// steps (`LabelTable::transfer_function`).
    pub fn load_function(&self) -> Result<crate::tf::TransferFunction> {
        self.load_function_from(self.function_file().1)
    }

    /// The function in `file` as this layer reads it: a transfer function
    /// (`[[point]]`s; a recording writes a label layer's edited function
    /// so), or a label layer's colour table.
    pub fn load_function_from(&self, file: &Path) -> Result<crate::tf::TransferFunction> {
        let text = std::fs::read_to_string(file)
            .with_context(|| format!("{}: cannot read", file.display()))?;
        let name = file.display().to_string();
        if self.is_labels() && !text.contains("[[point]]") {
            Ok(crate::tf::labels::LabelTable::parse(&text, &name)?.transfer_function())
        } else {
            crate::tf::TransferFunction::from_toml_str(&text, &name)
        }
    }
}

/// View-dependent layer opacity (G10 §4: "adaptively showing different
/// registered layers of information by controlling a layer's opacity as a
/// function of the view direction"): with θ the angle between a ray's
/// direction and `axis` (display space), the layer's opacity is scaled by
/// smoothstep from `angles_deg[0]` to `angles_deg[1]` of θ (falling where
/// the first is the larger), so that viewers on one side of a display see
/// the layer and those on the other side do not.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ViewOpacity {
    pub axis: [f64; 3],
    pub angles_deg: [f64; 2],
}

impl ViewOpacity {
    /// The factor for a ray at angle `theta_deg` to the axis.
    pub fn factor(&self, theta_deg: f64) -> f64 {
        let [a, b] = self.angles_deg;
        let t = if a == b {
            if theta_deg >= a {
                1.0
            } else {
                0.0
            }
        } else {
            ((theta_deg - a) / (b - a)).clamp(0.0, 1.0)
        };
        t * t * (3.0 - 2.0 * t)
    }
}

/// Checks a layer's `transform`: three rows of four numbers, or four with
/// `[0, 0, 0, 1]` last, finite, its linear part invertible.
fn check_transform(file: &Path, field: &str, t: &[[f64; 4]]) -> Result<()> {
    let f = file.display();
    if !(3..=4).contains(&t.len()) {
        bail!(
            "{f}: {field}: an affine map is three rows [a, b, c, t] (or four, the last [0, 0, 0, 1]); got {} rows",
            t.len()
        );
    }
    finite(file, field, t.as_flattened())?;
    if t.len() == 4 && t[3] != [0.0, 0.0, 0.0, 1.0] {
        bail!(
            "{f}: {field}: the fourth row must be [0, 0, 0, 1] (an affine map; got {:?})",
            t[3]
        );
    }
    let m: [[f64; 3]; 3] = std::array::from_fn(|r| [t[r][0], t[r][1], t[r][2]]);
    let det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
    let scale = m.as_flattened().iter().fold(0.0f64, |a, x| a.max(x.abs()));
    if det.abs() <= 1e-9 * scale.powi(3) {
        bail!("{f}: {field}: the linear part is singular (determinant {det:.3e}): it would flatten the layer");
    }
    Ok(())
}

/// Checks a scene's `[[layer]]`s: their number, opacity, view opacity, and
/// their transfer functions (the databases are opened, and their grids
/// checked, by the back ends).
fn check_layers(file: &Path, layers: &[Layer]) -> Result<()> {
    let f = file.display();
    if layers.len() > MAX_LAYERS {
        bail!(
            "{f}: layer: {} layers; the kernel combines at most {MAX_LAYERS} with the scene's volume",
            layers.len()
        );
    }
    for (i, l) in layers.iter().enumerate() {
        if l.labels.is_some() == l.transfer_function.is_some() {
            bail!(
                "{f}: layer[{i}]: give either transfer_function (a volume of values) or labels (a label volume's colour table)"
            );
        }
        l.load_function()
            .with_context(|| format!("{f}: layer[{i}].{}", l.function_file().0))?;
        if !(0.0..=1.0).contains(&l.opacity) {
            bail!(
                "{f}: layer[{i}].opacity must be in [0, 1] (got {})",
                l.opacity
            );
        }
        if let Some(LayerTransform::Matrix(t)) = &l.transform {
            check_transform(file, &format!("layer[{i}].transform"), t)?;
        }
        if let Some(v) = &l.view_opacity {
            finite(file, &format!("layer[{i}].view_opacity.axis"), &v.axis)?;
            let n = v.axis.iter().map(|x| x * x).sum::<f64>().sqrt();
            if n <= 1e-9 {
                bail!("{f}: layer[{i}].view_opacity.axis must not be zero");
            }
            if !v
                .angles_deg
                .iter()
                .all(|a| a.is_finite() && (0.0..=180.0).contains(a))
            {
                bail!(
                    "{f}: layer[{i}].view_opacity.angles_deg must be two angles in [0, 180] (got {:?})",
                    v.angles_deg
                );
            }
        }
    }
    Ok(())
}

impl Scene {
    pub fn load(path: &Path) -> Result<Self> {
        let mut s: Scene = read_toml(path)?;
        let f = path;
        match (s.volume.as_os_str().is_empty(), s.series.first()) {
            (true, None) => bail!("{}: volume: missing (the scene's database)", f.display()),
            (false, Some(_)) => bail!(
                "{}: give either volume (one database) or series (one per time step), not both",
                f.display()
            ),
            (true, Some(first)) => s.volume = first.clone(),
            (false, None) => {}
        }
        if s.series.len() > MAX_SERIES {
            bail!(
                "{}: series: {} steps; a series has at most {MAX_SERIES}",
                f.display(),
                s.series.len()
            );
        }
        s.volume = resolve(path, &s.volume);
        for p in &mut s.series {
            *p = resolve(path, p);
        }
        s.transfer_function = resolve(path, &s.transfer_function);
        s.display = s.display.map(|d| resolve(path, &d));
        for l in &mut s.layers {
            l.volume = resolve(path, &l.volume);
            l.transfer_function = l.transfer_function.as_ref().map(|t| resolve(path, t));
            l.labels = l.labels.as_ref().map(|t| resolve(path, t));
        }
        finite(f, "placement.center", &s.placement.center)?;
        finite(f, "placement.rotation_deg", &s.placement.rotation_deg)?;
        let r = &s.render;
        if !(s.placement.size.is_finite() && s.placement.size > 0.0) {
            bail!(
                "{}: placement.size must be > 0 (got {})",
                f.display(),
                s.placement.size
            );
        }
        if !(0.0..=1.0).contains(&r.eta) {
            bail!(
                "{}: render.eta must be in [0, 1] (0: one perspective view, 1: full parallax; got {})",
                f.display(),
                r.eta
            );
        }
        if r.upload_budget == 0 {
            bail!(
                "{}: render.upload_budget must be at least 1 brick per frame",
                f.display()
            );
        }
        if !(0.0..=1.0).contains(&r.gamma) {
            bail!(
                "{}: render.gamma must be in [0, 1] (got {})",
                f.display(),
                r.gamma
            );
        }
        if !(r.accuracy.is_finite() && r.accuracy > 0.0) {
            bail!(
                "{}: render.accuracy must be > 0 (got {})",
                f.display(),
                r.accuracy
            );
        }
        if !(r.step_factor.is_finite() && r.step_factor > 0.0 && r.step_factor <= 8.0) {
            bail!(
                "{}: render.step_factor must be in (0, 8] (got {})",
                f.display(),
                r.step_factor
            );
        }
        if !(r.opaque_detail.is_finite() && (1.0..=16.0).contains(&r.opaque_detail)) {
            bail!(
                "{}: render.opaque_detail must be in [1, 16] (1: off; got {})",
                f.display(),
                r.opaque_detail
            );
        }
        if !(1..=16).contains(&r.refinement) {
            bail!(
                "{}: render.refinement must be in 1..=16 parts (1: off; got {})",
                f.display(),
                r.refinement
            );
        }
        if !(r.early_termination > 0.0 && r.early_termination <= 1.0) {
            bail!(
                "{}: render.early_termination must be in (0, 1] (got {})",
                f.display(),
                r.early_termination
            );
        }
        for (name, v) in [
            ("render.cpu_cache_mb", r.cpu_cache_mb),
            ("render.gpu_cache_mb", r.gpu_cache_mb),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                bail!("{}: {name} must be ≥ 0 (got {v})", f.display());
            }
        }
        match (r.mode, r.isovalue) {
            (Mode::Iso, None) => bail!(
                "{}: render.mode = \"iso\" needs render.isovalue (the data value of the surface)",
                f.display()
            ),
            (Mode::Iso, Some(v)) if !v.is_finite() => bail!(
                "{}: render.isovalue must be a finite data value (got {v})",
                f.display()
            ),
            (Mode::Iso, _) if r.refraction || r.gamma != 0.0 => bail!(
                "{}: render.mode = \"iso\" shows a surface: render.refraction and render.gamma do not apply",
                f.display()
            ),
            (Mode::Dvr | Mode::Mimda, Some(_)) => bail!(
                "{}: render.isovalue applies to mode = \"iso\"",
                f.display()
            ),
            (Mode::Dvr | Mode::Mimda, _) if r.prediction => bail!(
                "{}: render.prediction (the prediction buffer of hit distances) applies to mode = \"iso\"",
                f.display()
            ),
            _ => {}
        }
        match r.mode {
            Mode::Dvr if r.gamma != 0.0 => bail!(
                "{}: render.gamma = {} applies to mode = \"mimda\" (G10 Eq. 3); with \"dvr\" it must be 0",
                f.display(),
                r.gamma
            ),
            _ => {}
        }
        if !(r.kappa.iter().all(|k| k.is_finite() && *k > 0.0) && r.kappa[0] <= r.kappa[1]) {
            bail!(
                "{}: render.kappa = {:?}: expected two positive values, low ≤ high",
                f.display(),
                r.kappa
            );
        }
        if r.full_traversal_every == 0 {
            bail!(
                "{}: render.full_traversal_every must be at least 1",
                f.display()
            );
        }
        crate::tools::check_tools(&s.tools, f)?;
        check_layers(f, &s.layers)?;
        if !s.layers.is_empty() {
            r.check_layered(&f.display().to_string())?;
        }
        r.overlay.check(&f.display().to_string(), r.refraction)?;
        Ok(s)
    }
}

/// `[screen]` of a display.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Screen {
    /// Width and height (m), centred on the origin.
    pub size: [f64; 2],
    /// s0 (m).
    pub pixel_size: f64,
    /// Φ (degrees).
    #[serde(default)]
    pub angular_accuracy_deg: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Observer {
    pub position: [f64; 3],
}

/// `[observer]` as written in a file. The projector list may also stand
/// here: in TOML, a `projectors = …` line written after `[observer]` belongs
/// to that table (as in the docs/design.md example).
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ObserverFile {
    position: [f64; 3],
    #[serde(default)]
    projectors: Option<ProjectorList>,
}

#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(untagged)]
enum ProjectorList {
    Folder(PathBuf),
    Files(Vec<PathBuf>),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct DisplayFile {
    screen: Screen,
    observer: ObserverFile,
    #[serde(default)]
    projectors: Option<ProjectorList>,
    #[serde(default)]
    present: crate::present::Present,
    #[serde(default)]
    looking_glass: Option<crate::lenticular::LookingGlass>,
}

/// One projector (or a window).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Projector {
    pub id: String,
    /// E (m).
    pub position: [f64; 3],
    pub resolution: [u32; 2],
    /// [x0, y0, w, h] (m); default: the whole screen.
    #[serde(default)]
    pub region: Option<[f64; 4]>,
    /// The back-end rank that drives it (default: contiguous blocks).
    #[serde(default)]
    pub rank: Option<u32>,
    /// The GPU adapter its back end renders with (a name, or `#N`); default:
    /// by the back end's node-local rank (backend/src/gpu.rs).
    #[serde(default)]
    pub adapter: Option<String>,
    /// Its warp and blend map (backend/src/calibrate.rs), applied to its
    /// image before it is written or presented.
    #[serde(default)]
    pub calibration: Option<Calibration>,
}

/// `[calibration]` of a projector file: a homography or a mesh (an MPCDI
/// 2D warp grid, `.pfm`), and an intensity blend map (`.png`) with its
/// embedded gamma. File names are relative to the projector file; loading
/// the display makes them absolute.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Calibration {
    #[serde(default)]
    pub homography: Option<[[f64; 3]; 3]>,
    #[serde(default)]
    pub mesh: Option<String>,
    #[serde(default)]
    pub blend: Option<String>,
    #[serde(default)]
    pub blend_gamma: Option<f64>,
}

/// A display: screen, observer, projectors, and how their images reach
/// the outputs (`--present`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Display {
    pub screen: Screen,
    pub observer: Observer,
    pub projectors: Vec<Projector>,
    #[serde(default)]
    pub present: crate::present::Present,
    /// A Looking Glass: the projectors are its views, in quilt order, and
    /// its panel image interleaves them (`panel.png`; on its window with
    /// `--present`).
    #[serde(default)]
    pub looking_glass: Option<crate::lenticular::LookingGlass>,
}

impl Display {
    pub fn load(path: &Path) -> Result<Self> {
        let mut d: DisplayFile = read_toml(path)?;
        let f = path.display();
        let list = match (d.projectors.take(), d.observer.projectors.take()) {
            (Some(l), None) | (None, Some(l)) => l,
            (None, None) => {
                bail!("{f}: projectors: missing (a folder or a list of projector files)")
            }
            (Some(_), Some(_)) => bail!("{f}: projectors: given twice"),
        };
        let s = d.screen;
        if !(s.size.iter().all(|x| x.is_finite() && *x > 0.0)) {
            bail!(
                "{f}: screen.size must be two positive lengths (got {:?})",
                s.size
            );
        }
        if !(s.pixel_size.is_finite() && s.pixel_size > 0.0) {
            bail!("{f}: screen.pixel_size must be > 0 (got {})", s.pixel_size);
        }
        if !(0.0..90.0).contains(&s.angular_accuracy_deg) {
            bail!(
                "{f}: screen.angular_accuracy_deg must be in [0, 90) (got {})",
                s.angular_accuracy_deg
            );
        }
        finite(path, "observer.position", &d.observer.position)?;
        if d.observer.position[2].abs() < 1e-9 {
            bail!("{f}: observer.position must be off the screen plane (z ≠ 0)");
        }
        let files: Vec<PathBuf> = match &list {
            ProjectorList::Folder(dir) => {
                let dir = resolve(path, dir);
                let mut v: Vec<PathBuf> = std::fs::read_dir(&dir)
                    .with_context(|| {
                        format!("{f}: projectors: cannot read folder {}", dir.display())
                    })?
                    .filter_map(|e| e.ok().map(|e| e.path()))
                    .filter(|p| p.extension().is_some_and(|e| e == "toml"))
                    .collect();
                v.sort();
                v
            }
            ProjectorList::Files(list) => list.iter().map(|p| resolve(path, p)).collect(),
        };
        if files.is_empty() {
            bail!("{f}: projectors: no projector files");
        }
        let mut projectors = Vec::with_capacity(files.len());
        for pf in &files {
            let p: Projector = read_toml(pf)?;
            let pn = pf.display();
            finite(pf, "position", &p.position)?;
            if p.position[2].abs() < 1e-9 {
                bail!("{pn}: position: a projector on the screen plane (z = 0) has no rays through the screen");
            }
            crate::paths::check_file_component(&p.id, &format!("{pn}: id"))?;
            if p.resolution.contains(&0) || p.resolution.iter().any(|&r| r > MAX_VIEW_SIDE) {
                bail!(
                    "{pn}: resolution must be from 1×1 to {MAX_VIEW_SIDE}×{MAX_VIEW_SIDE} (got {:?})",
                    p.resolution
                );
            }
            if let Some(r) = p.region {
                finite(pf, "region", &r)?;
                if r[2] <= 0.0 || r[3] <= 0.0 {
                    bail!("{pn}: region width and height must be > 0 (got {r:?})");
                }
            }
            let mut p = p;
            if let Some(c) = p.calibration.as_mut() {
                for f in [&mut c.mesh, &mut c.blend].into_iter().flatten() {
                    let abs = resolve(pf, Path::new(f.as_str()));
                    *f = abs
                        .to_str()
                        .with_context(|| {
                            format!("{pn}: calibration: '{}' is not UTF-8", abs.display())
                        })?
                        .to_string();
                }
            }
            if let Some(q) = projectors.iter().find(|q: &&Projector| q.id == p.id) {
                bail!(
                    "{pn}: id '{}' is used by another projector too ({})",
                    p.id,
                    q.id
                );
            }
            projectors.push(p);
        }
        let display = Display {
            screen: s,
            observer: Observer {
                position: d.observer.position,
            },
            projectors,
            present: d.present,
            looking_glass: d.looking_glass,
        };
        display.windows(&f.to_string())?;
        if let Some(lg) = &display.looking_glass {
            lg.check(&format!("{f}: looking_glass"))?;
            let n = display.projectors.len();
            if n != lg.views() as usize {
                bail!(
                    "{f}: looking_glass: a quilt of {} views but {n} projectors",
                    lg.views()
                );
            }
            if display
                .projectors
                .iter()
                .any(|p| p.resolution != display.projectors[0].resolution)
            {
                bail!("{f}: looking_glass: every view (projector) must have the same resolution");
            }
        }
        Ok(display)
    }

    /// The windows `--present` opens (checked when the file is loaded;
    /// `what` names the display in errors).
    pub fn windows(&self, what: &str) -> Result<Vec<crate::present::Window>> {
        let ids: Vec<String> = self.projectors.iter().map(|p| p.id.clone()).collect();
        let res: Vec<[u32; 2]> = self.projectors.iter().map(|p| p.resolution).collect();
        self.present.windows(&ids, &res, what)
    }

    /// Which projectors each back end renders: `result[r]` lists the
    /// projector indices of back-end rank r + 1. A projector's `rank` field
    /// pins it; the others are dealt out in contiguous blocks.
    pub fn assignment(&self, backends: usize) -> Result<Vec<Vec<usize>>> {
        let p = self.projectors.len();
        if backends == 0 {
            bail!("no back-end ranks to render with");
        }
        if backends > p {
            bail!("{backends} back-end ranks but only {p} projectors: every back end needs at least one projector");
        }
        let mut out = vec![Vec::new(); backends];
        for (i, pr) in self.projectors.iter().enumerate() {
            let r = match pr.rank {
                Some(r) => {
                    if r == 0 || r as usize > backends {
                        bail!(
                            "projector '{}': rank {r} does not exist (back-end ranks are 1..={backends})",
                            pr.id
                        );
                    }
                    r as usize - 1
                }
                None => i * backends / p,
            };
            out[r].push(i);
        }
        if let Some(r) = out.iter().position(|v| v.is_empty()) {
            bail!("back-end rank {} has no projector to render", r + 1);
        }
        Ok(out)
    }

    /// The view of each projector for a given η.
    pub fn views(&self, eta: f64) -> Vec<View> {
        let [sw, sh] = self.screen.size;
        self.projectors
            .iter()
            .map(|p| View {
                resolution: p.resolution,
                region: p.region.unwrap_or([-sw / 2.0, -sh / 2.0, sw, sh]),
                eye: p.position,
                observer: self.observer.position,
                eta,
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
        let p = dir.join(name);
        if let Some(parent) = p.parent() {
            std::fs::create_dir_all(parent).unwrap();
        }
        std::fs::write(&p, text).unwrap();
        p
    }

    #[test]
    fn auto_preintegration_takes_the_closed_form_on_cpu_devices_only() {
        use Preintegration::*;
        assert_eq!(RenderConfig::default().preintegration, Auto);
        let parsed: RenderConfig = toml::from_str("preintegration = \"auto\"").unwrap();
        assert_eq!(parsed.preintegration, Auto);
        assert_eq!(Auto.resolve(Some(15), true), Analytic);
        assert_eq!(Auto.resolve(None, true), Exact, "no closed form: the table");
        assert_eq!(Auto.resolve(Some(2), false), Exact, "a GPU: the table");
        for p in [Exact, TwoD, Analytic] {
            assert_eq!(p.resolve(Some(2), true), p, "a choice is kept");
            assert_eq!(p.resolve(None, false), p);
        }
    }

    const DISPLAY: &str = "[screen]\nsize = [0.4, 0.3]\npixel_size = 0.001\n[observer]\nposition = [0, 0, 1]\nprojectors = \"p/\"\n";

    #[test]
    fn display_and_scene_load() {
        let d = tempfile::tempdir().unwrap();
        let disp = write(d.path(), "d.toml", DISPLAY);
        write(
            d.path(),
            "p/a.toml",
            "id = \"a\"\nposition = [0, 0, 1]\nresolution = [64, 48]\n",
        );
        let display = Display::load(&disp).unwrap();
        assert_eq!(display.projectors.len(), 1);
        let v = display.views(0.0);
        assert_eq!(v[0].region, [-0.2, -0.15, 0.4, 0.3]);
        let scene = write(
            d.path(),
            "s.toml",
            "volume = \"v.pxo\"\ntransfer_function = \"tf.toml\"\n[placement]\ncenter = [0, 0, 0]\nsize = 0.2\n[render]\nshading = \"phong\"\n",
        );
        let s = Scene::load(&scene).unwrap();
        assert_eq!(s.volume, d.path().join("v.pxo"));
        assert_eq!(s.render.shading, Shading::Phong);
        assert_eq!(s.render.accuracy, 1.0);
    }

    #[test]
    fn bad_files_name_file_and_field() {
        let d = tempfile::tempdir().unwrap();
        let cases = [
            ("transfer_function = \"t\"\n[placement]\ncenter = [0, 0, 0]\nsize = 0.2\n", "volume: missing"),
            ("volume = \"v\"\ntransfer_function = \"t\"\n[placement]\ncenter = [0, 0, 0]\nsize = -1\n", "placement.size"),
            ("volume = \"v\"\ntransfer_function = \"t\"\n[placement]\ncenter = [0, 0, 0]\nsize = 1\n[render]\naccuracy = 0\n", "render.accuracy"),
            ("volume = \"v\"\ntransfer_function = \"t\"\n[placement]\ncenter = [0, 0, 0]\nsize = 1\n[render]\nstepfactor = 1\n", "stepfactor"),
            ("volume = \"v\"\ntransfer_function = \"t\"\n[placement]\ncenter = [0, 0, 0]\nsize = 1\n[render]\nopaque_detail = 0.5\n", "render.opaque_detail"),
            ("volume = \"v\"\ntransfer_function = \"t\"\n[placement]\ncenter = [0, nan, 0]\nsize = 1\n", "placement.center"),
            ("volume = \"v\"\ntransfer_function = \"t\"\n[placement]\ncenter = [0, 0, 0]\nsize = 1\n[render]\neta = 1.5\n", "render.eta"),
            ("volume = \"v\"\ntransfer_function = \"t\"\n[placement]\ncenter = [0, 0, 0]\nsize = 1\n[render]\nupload_budget = 0\n", "render.upload_budget"),
        ];
        for (text, field) in cases {
            let p = write(d.path(), "bad.toml", text);
            let e = format!("{:#}", Scene::load(&p).unwrap_err());
            assert!(e.contains("bad.toml") && e.contains(field), "{e}");
        }
        let disp = write(d.path(), "d.toml", DISPLAY);
        write(
            d.path(),
            "p/a.toml",
            "id = \"a\"\nposition = [0, 0, 0]\nresolution = [64, 48]\n",
        );
        let e = format!("{:#}", Display::load(&disp).unwrap_err());
        assert!(e.contains("a.toml") && e.contains("position"), "{e}");
        write(
            d.path(),
            "p/a.toml",
            "id = \"a\"\nposition = [0, 0, 1]\nresolution = [64, 48]\n",
        );
        write(
            d.path(),
            "p/b.toml",
            "id = \"a\"\nposition = [0, 0, 1]\nresolution = [64, 48]\n",
        );
        let e = format!("{:#}", Display::load(&disp).unwrap_err());
        assert!(e.contains("b.toml") && e.contains("id"), "{e}");
        std::fs::remove_dir_all(d.path().join("p")).unwrap();
        let e = format!("{:#}", Display::load(&disp).unwrap_err());
        assert!(e.contains("d.toml") && e.contains("projectors"), "{e}");
    }

    /// `[[layer]]`s resolve against the scene file; too many, a missing
    /// file, a bad opacity or view opacity, and a render mode the layers do
    /// not take are refused naming the scene file and the field.
    #[test]
    fn layers_load_and_bad_ones_name_the_field() {
        let d = tempfile::tempdir().unwrap();
        write(d.path(), "l.pxo", "");
        write(
            d.path(),
            "tf.toml",
            "[[point]]\nvalue = 0\ncolor = [1, 1, 1]\nextinction = 1\n",
        );
        let head = "volume = \"v\"\ntransfer_function = \"tf.toml\"\n[placement]\ncenter = [0, 0, 0]\nsize = 1\n";
        let layer = "[[layer]]\nvolume = \"l.pxo\"\ntransfer_function = \"tf.toml\"\n";
        let good = write(
            d.path(),
            "s.toml",
            &format!("{head}{layer}view_opacity = {{ axis = [0, 0, 1], angles_deg = [30, 60] }}\n"),
        );
        let s = Scene::load(&good).unwrap();
        assert_eq!(s.layers.len(), 1);
        assert_eq!(s.layers[0].volume, d.path().join("l.pxo"));
        assert_eq!(s.layers[0].opacity, 1.0);
        let v = s.layers[0].view_opacity.unwrap();
        assert_eq!(
            (v.factor(20.0), v.factor(45.0), v.factor(90.0)),
            (0.0, 0.5, 1.0)
        );
        // A label layer: its colour table resolves against the scene too.
        write(
            d.path(),
            "labels.txt",
            "0 clear 0 0 0 0\n1 one 255 0 0 255\n",
        );
        let labels = "[[layer]]\nvolume = \"l.pxo\"\nlabels = \"labels.txt\"\n";
        let s = Scene::load(&write(d.path(), "s2.toml", &format!("{head}{labels}"))).unwrap();
        assert!(s.layers[0].is_labels());
        assert_eq!(s.layers[0].function_file().1, d.path().join("labels.txt"));
        assert_eq!(s.layers[0].load_function().unwrap().points().len(), 2);
        // A layer on another grid: three rows, or four ending [0, 0, 0, 1].
        for rows in [
            "[[0, 1, 0, 5], [-1, 0, 0, 2.5], [0, 0, 2, 0]]",
            "[[0, 1, 0, 5], [-1, 0, 0, 2.5], [0, 0, 2, 0], [0, 0, 0, 1]]",
        ] {
            let text = format!("{head}{labels}transform = {rows}\n");
            let s = Scene::load(&write(d.path(), "s3.toml", &text)).unwrap();
            let (m, t) = s.layers[0].affine().unwrap();
            assert_eq!(m, [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 2.0]]);
            assert_eq!(t, [5.0, 2.5, 0.0]);
        }
        let text = format!("{head}{labels}transform = \"scanner\"\n");
        let s = Scene::load(&write(d.path(), "s4.toml", &text)).unwrap();
        assert_eq!(s.layers[0].transform, Some(LayerTransform::Scanner));
        assert!(s.layers[0].affine().is_none());
        let cases = [
            (
                format!("{layer}transform = \"world\"\n"),
                "unknown transform \"world\"",
            ),
            (
                format!("{layer}transform = 3\n"),
                "expected \"scanner\" or an affine map's rows",
            ),
            (
                format!("{layer}transform = [[1, 0, 0, 0], [0, 1, 0, 0]]\n"),
                "layer[0].transform: an affine map is three rows",
            ),
            (
                format!(
                    "{layer}transform = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [1, 0, 0, 1]]\n"
                ),
                "layer[0].transform: the fourth row",
            ),
            (
                format!("{layer}transform = [[1, 0, 0, 0], [0, 1, 0, 0], [1, 1, 0, 0]]\n"),
                "layer[0].transform: the linear part is singular",
            ),
            (
                format!("{layer}transform = [[1, 0, 0, nan], [0, 1, 0, 0], [0, 0, 1, 0]]\n"),
                "layer[0].transform must be finite",
            ),
            (
                format!("{labels}transfer_function = \"tf.toml\"\n"),
                "layer[0]: give either transfer_function",
            ),
            (
                "[[layer]]\nvolume = \"l.pxo\"\n".to_string(),
                "layer[0]: give either transfer_function",
            ),
            (labels.replace("labels.txt", "none.txt"), "layer[0].labels"),
            (layer.repeat(4), "layer: 4 layers"),
            (
                layer.replace("\"tf.toml", "\"none.toml"),
                "layer[0].transfer_function",
            ),
            (format!("{layer}opacity = 2\n"), "layer[0].opacity"),
            (
                format!("{layer}view_opacity = {{ axis = [0, 0, 0], angles_deg = [0, 1] }}\n"),
                "layer[0].view_opacity.axis",
            ),
            (
                format!("{layer}view_opacity = {{ axis = [0, 0, 1], angles_deg = [0, 200] }}\n"),
                "layer[0].view_opacity.angles_deg",
            ),
            (
                format!("[render]\nmode = \"iso\"\nisovalue = 0.5\n{layer}"),
                "render.mode",
            ),
            (
                format!("[render]\nmultilevel = true\n{layer}"),
                "render.multilevel",
            ),
        ];
        for (text, field) in cases {
            let p = write(d.path(), "bad.toml", &format!("{head}{text}"));
            let e = format!("{:#}", Scene::load(&p).unwrap_err());
            assert!(e.contains("bad.toml") && e.contains(field), "{field}: {e}");
        }
    }
}
