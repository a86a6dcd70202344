//! Colour tables of label volumes (a layer's `labels`, docs/design.md
//! "Registered layers"): a segmentation's voxels are whole numbers naming
//! tissues, and each label has a colour and an opacity. Three formats read:
//!
//! * Parallax's own TOML, `[[label]]` tables of `value`, `name`, `color`
//!   (linear RGB, [0, 1]) and `extinction` (per data length unit) or
//!   `opacity` (α of one data length unit);
//! * a 3D Slicer colour table (`.ctbl`, `.txt`): lines `value name R G B A`,
//!   components 0–255;
//! * an ITK-SNAP label description file: lines `value R G B A VIS MSH
//!   "name"`, R G B 0–255, A in [0, 1], VIS 0 hides the label.
//!
//! Slicer and ITK-SNAP colours are display (sRGB) values, decoded to
//! linear; their opacity α is that of one data length unit (mm), τ =
//! −ln(1 − α) ([`alpha_to_extinction`], as VTK presets convert). Lines
//! starting with `#` and blank lines are comments.
//!
//! A table becomes a transfer function with a point at each label
//! ([`LabelTable::transfer_function`]), which the live page edits like any
//! other: a pre-integration table with a node at each whole number holds
//! each label's optics exactly there, where the kernel reads a label
//! layer's nearest voxel (shaders/shared/layers.wgsl `label_average`).
//! Which bricks a label layer needs is told by [`label_steps`], each
//! label's optics over [label − ½, label + ½) and nothing else, so a brick
//! of background is never read. A label the volume holds and the table
//! lacks is an error ([`LabelTable::check`]), never a colour.

use std::path::Path;

use anyhow::{bail, Context, Result};
use serde::Deserialize;

use super::{alpha_to_extinction, srgb_to_linear, ControlPoint, TransferFunction, MAX_EXTINCTION};

/// One label of a colour table.
#[derive(Clone, Debug, PartialEq)]
pub struct Label {
    pub value: u32,
    pub name: String,
    /// Linear RGB, [0, 1].
    pub color: [f64; 3],
    /// Extinction τ per data length unit.
    pub extinction: f64,
}

/// A label volume's colour table: labels in ascending order, each once.
#[derive(Clone, Debug, PartialEq)]
pub struct LabelTable {
    labels: Vec<Label>,
}

/// The formats a colour table may be written in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LabelFormat {
    Toml,
    Slicer,
    ItkSnap,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTable {
    #[serde(default)]
    label: Vec<RawLabel>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLabel {
    value: Option<i64>,
    #[serde(default)]
    name: String,
    color: Option<Vec<f64>>,
    extinction: Option<f64>,
    opacity: Option<f64>,
}

impl LabelTable {
    /// Reads a colour table, its format told by its content; errors name
    /// the file and the line or entry.
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("{}: cannot read the colour table", path.display()))?;
        Self::parse(&text, &path.display().to_string())
    }

    /// The format of a colour table's text: TOML where it has `[[label]]`
    /// tables, ITK-SNAP where a data line has a quoted name, else Slicer.
    pub fn detect(text: &str) -> LabelFormat {
        let data = || {
            text.lines()
                .map(str::trim)
                .filter(|l| !l.is_empty() && !l.starts_with('#'))
        };
        if data().any(|l| l.starts_with("[[label]]")) {
            LabelFormat::Toml
        } else if data().any(|l| l.contains('"')) {
            LabelFormat::ItkSnap
        } else {
            LabelFormat::Slicer
        }
    }

    /// Parses a colour table's text (`file` names it in errors).
    pub fn parse(text: &str, file: &str) -> Result<Self> {
        let labels = match Self::detect(text) {
            LabelFormat::Toml => parse_toml(text, file)?,
            f => parse_lines(text, file, f)?,
        };
        Self::new(labels).with_context(|| format!("{file}: colour table"))
    }

    /// A table of `labels` (any order; each value once, every colour in
    /// [0, 1] and extinction in [0, MAX_EXTINCTION]).
    pub fn new(mut labels: Vec<Label>) -> Result<Self> {
        if labels.is_empty() {
            bail!("no labels");
        }
        for l in &labels {
            if !l.color.iter().all(|c| (0.0..=1.0).contains(c)) {
                bail!(
                    "label {} ({}): colour {:?} is not in [0, 1]",
                    l.value,
                    l.name,
                    l.color
                );
            }
            if !(0.0..=MAX_EXTINCTION).contains(&l.extinction) {
                bail!(
                    "label {} ({}): extinction {} is not in [0, {MAX_EXTINCTION:e}]",
                    l.value,
                    l.name,
                    l.extinction
                );
            }
        }
        labels.sort_by_key(|l| l.value);
        if let Some(w) = labels.windows(2).find(|w| w[0].value == w[1].value) {
            bail!(
                "label {} is listed twice ({:?} and {:?})",
                w[0].value,
                w[0].name,
                w[1].name
            );
        }
        Ok(LabelTable { labels })
    }

    pub fn labels(&self) -> &[Label] {
        &self.labels
    }

    pub fn get(&self, value: u32) -> Option<&Label> {
        self.labels
            .binary_search_by_key(&value, |l| l.value)
            .ok()
            .map(|i| &self.labels[i])
    }

    /// The table as a transfer function: a point at each label with its
    /// colour and extinction (what lies between labels is never drawn).
    pub fn transfer_function(&self) -> TransferFunction {
        let points = self
            .labels
            .iter()
            .map(|l| ControlPoint::new(l.value as f64, l.color, l.extinction))
            .collect();
        TransferFunction::from_points(points)
            .expect("a label table's points are a valid transfer function")
    }
}

/// Checks that a label layer's function `tf` (a colour table's, with a
/// point at each label it lists) lists every label a volume holds
/// (`present`): an unknown label is an error naming it, never a colour.
pub fn check_labels(tf: &TransferFunction, present: &[u32]) -> Result<()> {
    let listed = |v: u32| {
        tf.points()
            .binary_search_by(|p| p.value.total_cmp(&(v as f64)))
            .is_ok()
    };
    let missing: Vec<u32> = present.iter().copied().filter(|&v| !listed(v)).collect();
    if let Some(first) = missing.first() {
        bail!(
            "the volume holds label {first}{}, which the colour table does not list (it lists {})",
            match missing.len() {
                1 => String::new(),
                n => format!(" and {} more unknown labels", n - 1),
            },
            tf.points().len()
        );
    }
    Ok(())
}

/// A label layer's function `tf` as steps over the labels `lo..=hi`: each
/// label l's optics (`tf` at l) over [l − ½, l + ½), the optics a voxel of
/// that label has. Its emptiness table (4 bins a label, over [lo − ½,
/// hi + ½]) tells exactly which ranges of labels draw nothing.
pub fn label_steps(tf: &TransferFunction, lo: u32, hi: u32) -> TransferFunction {
    let mut points = Vec::with_capacity(4 * (hi - lo) as usize + 4);
    for l in lo..=hi {
        let o = tf.eval(l as f64);
        let (a, b) = (l as f64 - 0.5, l as f64 + 0.5);
        let p = |v, tau| ControlPoint::new(v, o.color, tau);
        points.extend([p(a, 0.0), p(a, o.tau), p(b, o.tau), p(b, 0.0)]);
    }
    TransferFunction::from_points(points).expect("a label function's steps are valid")
}

fn parse_toml(text: &str, file: &str) -> Result<Vec<Label>> {
    let raw: RawTable =
        toml::from_str(text).with_context(|| format!("{file}: not a colour table"))?;
    raw.label
        .into_iter()
        .enumerate()
        .map(|(i, r)| {
            let at = |f: &str| format!("{file}: label[{i}].{f}");
            let value = r.value.with_context(|| at("value") + " is missing")?;
            let value = u32::try_from(value).map_err(|_| {
                anyhow::anyhow!(
                    "{}: {value} is not a label (0 to {})",
                    at("value"),
                    u32::MAX
                )
            })?;
            let color = match r.color.as_deref() {
                Some(&[r, g, b]) => [r, g, b],
                Some(c) => bail!("{}: three components, not {}", at("color"), c.len()),
                None => bail!("{} is missing", at("color")),
            };
            let extinction = match (r.extinction, r.opacity) {
                (Some(t), None) => t,
                (None, Some(a)) if (0.0..=1.0).contains(&a) => alpha_to_extinction(a, 1.0),
                (None, Some(a)) => bail!("{}: {a} is not in [0, 1]", at("opacity")),
                _ => bail!("{}: give one of extinction and opacity", at("extinction")),
            };
            Ok(Label {
                value,
                name: r.name,
                color,
                extinction,
            })
        })
        .collect()
}

/// Slicer (`value name R G B A`) and ITK-SNAP (`value R G B A VIS MSH
/// "name"`) lines.
fn parse_lines(text: &str, file: &str, format: LabelFormat) -> Result<Vec<Label>> {
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let at = || format!("{file}: line {}", n + 1);
        let (fields, name): (Vec<&str>, String) = match format {
            LabelFormat::ItkSnap => {
                let q = line.find('"').unwrap_or(line.len());
                let name = line[q..].trim().trim_matches('"').to_string();
                (line[..q].split_whitespace().collect(), name)
            }
            _ => {
                let f: Vec<&str> = line.split_whitespace().collect();
                let name = f.get(1).copied().unwrap_or("").to_string();
                let mut numbers = f;
                if numbers.len() > 1 {
                    numbers.remove(1);
                }
                (numbers, name)
            }
        };
        let want = if format == LabelFormat::ItkSnap { 7 } else { 5 };
        if fields.len() != want {
            bail!(
                "{}: {} numbers where a {} colour table has {want}: {line:?}",
                at(),
                fields.len(),
                if format == LabelFormat::ItkSnap {
                    "ITK-SNAP (value R G B A VIS MSH \"name\")"
                } else {
                    "Slicer (value name R G B A)"
                }
            );
        }
        let num = |k: usize, what: &str| -> Result<f64> {
            fields[k]
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .with_context(|| format!("{}: {what} {:?} is not a number", at(), fields[k]))
        };
        let value = num(0, "label")?;
        if !(value >= 0.0 && value <= u32::MAX as f64 && value.fract() == 0.0) {
            bail!("{}: {value} is not a label (0 to {})", at(), u32::MAX);
        }
        let mut rgb = [0.0; 3];
        for (k, c) in rgb.iter_mut().enumerate() {
            let v = num(1 + k, "colour component")?;
            if !(0.0..=255.0).contains(&v) {
                bail!("{}: colour component {v} is not in 0–255", at());
            }
            *c = srgb_to_linear(v / 255.0);
        }
        let a = num(4, "opacity")?;
        let alpha = match format {
            LabelFormat::ItkSnap if (0.0..=1.0).contains(&a) => a,
            LabelFormat::ItkSnap => bail!("{}: opacity {a} is not in [0, 1]", at()),
            _ if (0.0..=255.0).contains(&a) => a / 255.0,
            _ => bail!("{}: opacity {a} is not in 0–255", at()),
        };
        let visible = format != LabelFormat::ItkSnap || num(5, "visibility")? != 0.0;
        out.push(Label {
            value: value as u32,
            name,
            color: rgb,
            extinction: if visible {
                alpha_to_extinction(alpha, 1.0)
            } else {
                0.0
            },
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tf::{Channel, PreintTable};

    const ITK: &str = "# ITK-SnAP Label Description File\n\
        # Columns = IDX -R- -G- -B- -A-- VIS MSH LABEL\n\
            0     0    0    0        0  0  0    \"Clear Label\"\n\
            1   255    0    0      0.5  1  1    \"Label 1\"\n\
            3     0  255    0        1  1  1    \"Label 3\"\n\
            4     0    0  255        1  0  1    \"Hidden\"\n";

    #[test]
    fn a_table_with_a_node_at_each_label_holds_its_optics_there() {
        let t = LabelTable::parse(ITK, "itk.txt").unwrap();
        assert_eq!(LabelTable::detect(ITK), LabelFormat::ItkSnap);
        let tf = t.transfer_function();
        let table = PreintTable::new(&tf, 0.0, 5.0, 5).unwrap();
        let (planar, layout) = table.gpu_layout();
        let node = |ch: usize, j: usize| planar[ch * layout.channel_stride as usize + j];
        let tau = Channel::Tau.index();
        assert_eq!(node(tau, 0), 0.0);
        assert_eq!(node(tau, 1), 2f64.ln() as f32);
        assert_eq!(node(Channel::EmissionR.index(), 1), 2f64.ln() as f32);
        assert_eq!(node(Channel::EmissionG.index(), 1), 0.0);
        assert_eq!(node(tau, 3), 1e6f64.ln() as f32);
        assert_eq!(node(Channel::EmissionG.index(), 3), 1e6f64.ln() as f32);
        assert_eq!(node(tau, 4), 0.0, "VIS 0 hides a label");
    }

    #[test]
    fn slicer_and_toml_tables_read_and_bad_ones_name_the_line() {
        let slicer = "# Color table file\n0 Background 0 0 0 0\n2 bone 255 255 255 255\n1 muscle 128 0 0 51\n";
        assert_eq!(LabelTable::detect(slicer), LabelFormat::Slicer);
        let t = LabelTable::parse(slicer, "s.ctbl").unwrap();
        let values: Vec<u32> = t.labels().iter().map(|l| l.value).collect();
        assert_eq!(values, [0, 1, 2], "sorted");
        let m = t.get(1).unwrap();
        assert_eq!(m.name, "muscle");
        assert!((m.color[0] - srgb_to_linear(128.0 / 255.0)).abs() < 1e-12);
        assert!((m.extinction - alpha_to_extinction(0.2, 1.0)).abs() < 1e-12);
        assert_eq!(t.get(0).unwrap().extinction, 0.0);
        let toml = "[[label]]\nvalue = 4\nname = \"tumour\"\ncolor = [1, 0, 0]\nextinction = 2.5\n";
        assert_eq!(LabelTable::detect(toml), LabelFormat::Toml);
        let t = LabelTable::parse(toml, "t.toml").unwrap();
        assert_eq!(t.get(4).unwrap().extinction, 2.5);
        assert!(check_labels(&t.transfer_function(), &[4]).is_ok());
        let e = format!(
            "{:#}",
            check_labels(&t.transfer_function(), &[0, 4, 9]).unwrap_err()
        );
        assert!(e.contains("label 0") && e.contains("1 more"), "{e}");
        for (text, want) in [
            ("0 a 0 0 0\n", "s.ctbl: line 1: 4 numbers"),
            ("0 a 0 0 0 0\n1.5 b 0 0 0 0\n", "line 2: 1.5 is not a label"),
            ("0 a 0 0 0 0\n0 b 1 1 1 1\n", "label 0 is listed twice"),
            ("0 a 0 0 x 0\n", "colour component \"x\""),
            ("0 0 0 0 2 1 1 \"a\"\n", "opacity 2 is not in [0, 1]"),
            (
                "[[label]]\nvalue = -1\ncolor = [0, 0, 0]\nopacity = 1\n",
                "label[0].value",
            ),
            (
                "[[label]]\nvalue = 1\ncolor = [0, 0, 0]\n",
                "give one of extinction and opacity",
            ),
            (
                "[[label]]\nvalue = 1\ncolor = [0, 2, 0]\nopacity = 1\n",
                "colour [0.0, 2.0, 0.0]",
            ),
            ("# nothing\n", "no labels"),
        ] {
            let e = format!("{:#}", LabelTable::parse(text, "s.ctbl").unwrap_err());
            assert!(e.contains(want), "{want:?} in {e}");
        }
    }

    #[test]
    fn label_steps_say_exactly_which_ranges_draw_nothing() {
        let t = LabelTable::parse(ITK, "itk.txt").unwrap();
        let steps = label_steps(&t.transfer_function(), 0, 4);
        let e = crate::tf::EmptinessTable::new(&steps, -0.5, 4.5, 20).unwrap();
        assert!(e.is_empty(0.0, 0.0), "the background draws nothing");
        assert!(!e.is_empty(0.0, 1.0));
        assert!(e.is_empty(4.0, 4.0), "a hidden label draws nothing");
        assert!(!e.is_empty(3.0, 4.0));
    }
}
