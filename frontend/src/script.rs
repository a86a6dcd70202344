//! Interaction scripts: keyframes of placement, observer, η and transfer
//! function over time, interpolated per frame — the inspection sequences
//! the papers measure (G10 §6, G08 §7).
//!
//! ```toml
//! frames = 90                       # optional; default: last key + 1
//! [[key]]
//! frame = 0
//! placement = { center = [0, 0, 0], rotation_deg = [-90, 180, 0], size = 0.25 }
//! observer = [0, 0, 2]
//! eta = 1.0
//! transfer_function = "../tf/colin27-skin.toml"
//! [[key]]
//! frame = 60
//! placement = { rotation_deg = [-90, 270, 0] }
//! ```
//!
//! A key may also move the scene's tools and change their parameters (each
//! `[[key.tool]]` names the scene's tool by its index and keys any numeric
//! field of its table by name, as the scene writes it), and set MImDA's γ:
//!
//! ```toml
//! [[key]]
//! frame = 30
//! gamma = 0.8
//! tool = [{ index = 0, point = [0, 0, 0.05], normal = [0.3, 0, 1], thickness = 0.004 }]
//! ```
//!
//! `accuracy` and `step_factor` set the render knobs of the same names.
//! `time` moves through a scene's `series`: the step drawn is the whole
//! part of its interpolated value, so keys `{ frame = 0, time = 0 }` and
//! `{ frame = 190, time = 19 }` play 20 steps at 10 frames a step.
//!
//! Numbers are interpolated linearly between the keys that set them and held
//! after the last (a tool's normal is renormalised); a transfer function
//! switches at its key.

use anyhow::{bail, Context, Result};
use parallax_common::camera::Placement;
use parallax_common::config::MAX_SERIES;
use parallax_common::tools::Tool;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// A script file as read and as written (a recorded live session).
#[derive(Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScriptFile {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub frames: Option<u64>,
    #[serde(default)]
    pub key: Vec<Key>,
}

impl ScriptFile {
    /// Writes the script as TOML (atomically: an existing file is replaced
    /// only by a complete one).
    pub fn write(&self, path: &Path) -> Result<()> {
        let text = toml::to_string(self).context("cannot write a script")?;
        parallax_common::atomic::write(path, text.as_bytes())
    }
}

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlacementKey {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub center: Option<[f64; 3]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rotation_deg: Option<[f64; 3]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub size: Option<f64>,
}

impl PlacementKey {
    fn is_empty(&self) -> bool {
        *self == PlacementKey::default()
    }
}

/// One keyframe: the values it sets at `frame` (the others interpolate).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Key {
    pub frame: u64,
    #[serde(default, skip_serializing_if = "PlacementKey::is_empty")]
    pub placement: PlacementKey,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub observer: Option<[f64; 3]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub eta: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gamma: Option<f64>,
    /// `render.accuracy` (pixels per voxel, as in the scene).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub accuracy: Option<f64>,
    /// `render.step_factor`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub step_factor: Option<f64>,
    /// The time step of the scene's `series` (interpolated; its whole part
    /// is drawn).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub time: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub transfer_function: Option<PathBuf>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub tool: Vec<ToolKey>,
    /// The whole tool set from this frame on, `[[tool]]` tables (replaces
    /// the scene's; a recording writes it, since a live page may add and
    /// remove tools). `tool` keys then index this set.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tools: Option<ToolSet>,
    /// The 3D cursor of the overlay (m, display space; interpolated).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cursor: Option<[f64; 3]>,
    /// Whether the tools' geometry and the cursor are drawn (from this
    /// frame on).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub overlay: Option<bool>,
    /// The scene's registered layers from this frame on: each one's
    /// `visible` and `opacity`, in `[[layer]]` order.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub layers: Option<Vec<parallax_common::protocol::LayerControl>>,
    /// Layers' functions from this frame on: `{ index, file }`, the file a
    /// transfer function, or a label layer's colour table (relative to the
    /// script).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub layer_functions: Vec<LayerFunctionKey>,
}

/// A layer's function switched by a script key.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LayerFunctionKey {
    /// The layer's place among the scene's `[[layer]]`s.
    pub index: usize,
    pub file: PathBuf,
}

/// A tool set as a script writes it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct ToolSet(#[serde(with = "parallax_common::tools::list")] pub Vec<Tool>);

/// A tool's keyed fields at one key: any numeric field of its table, by
/// name (a clip plane's `point`, a probe's `center` and `radius`, a band
/// picker's `band` …), a number or a list of numbers.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ToolKey {
    pub index: usize,
    #[serde(flatten)]
    pub fields: std::collections::BTreeMap<String, Numbers>,
}

/// A keyed field's value.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Numbers {
    One(f64),
    Many(Vec<f64>),
}

impl Numbers {
    fn values(&self) -> Vec<f64> {
        match self {
            Numbers::One(x) => vec![*x],
            Numbers::Many(v) => v.clone(),
        }
    }
}

/// The keyframed fields of one tool, by name.
type ToolTracks = std::collections::BTreeMap<String, Track<Vec<f64>>>;

/// One numeric track: (frame, value) keys in frame order.
#[derive(Clone, Debug, Default)]
struct Track<V> {
    keys: Vec<(u64, V)>,
}

/// A value a track interpolates.
trait Lerp: Clone {
    fn lerp(a: &Self, b: &Self, t: f64) -> Self;
}

impl<const N: usize> Lerp for [f64; N] {
    fn lerp(a: &Self, b: &Self, t: f64) -> Self {
        std::array::from_fn(|c| a[c] + t * (b[c] - a[c]))
    }
}

impl Lerp for Vec<f64> {
    fn lerp(a: &Self, b: &Self, t: f64) -> Self {
        a.iter().zip(b).map(|(x, y)| x + t * (y - x)).collect()
    }
}

impl<V: Lerp> Track<V> {
    fn at(&self, frame: u64, default: V) -> V {
        self.get(frame).unwrap_or(default)
    }

    /// The value at `frame`: interpolated between the keys around it, the
    /// first before it, the last after it; None without keys.
    fn get(&self, frame: u64) -> Option<V> {
        let k = &self.keys;
        Some(match k.iter().position(|(f, _)| *f > frame) {
            None => k.last()?.1.clone(),
            Some(0) => k[0].1.clone(),
            Some(i) => {
                let ((f0, a), (f1, b)) = (&k[i - 1], &k[i]);
                let t = (frame - f0) as f64 / (f1 - f0) as f64;
                V::lerp(a, b, t)
            }
        })
    }
}

/// A loaded script.
#[derive(Clone, Debug)]
pub struct Script {
    pub frames: u64,
    center: Track<[f64; 3]>,
    rotation: Track<[f64; 3]>,
    size: Track<[f64; 1]>,
    observer: Track<[f64; 3]>,
    eta: Track<[f64; 1]>,
    gamma: Track<[f64; 1]>,
    accuracy: Track<[f64; 1]>,
    step_factor: Track<[f64; 1]>,
    time: Track<[f64; 1]>,
    cursor: Track<[f64; 3]>,
    /// (first frame, on) of each overlay switch.
    overlay: Vec<(u64, bool)>,
    /// (first frame, controls) of each change of the layers.
    layers: Vec<(u64, Vec<parallax_common::protocol::LayerControl>)>,
    /// (first frame, file) of each transfer function switch.
    tfs: Vec<(u64, PathBuf)>,
    /// (first frame, layer, file) of each layer function switch.
    layer_tfs: Vec<(u64, usize, PathBuf)>,
    /// Per tool index of the scene (or of the tool set in force).
    tools: Vec<ToolTracks>,
    /// (first frame, tools) of each tool set switch.
    tool_sets: Vec<(u64, Vec<Tool>)>,
    name: String,
}

/// What the script says for one frame.
#[derive(Clone, Debug, PartialEq)]
pub struct ScriptState {
    pub placement: Placement,
    pub observer: [f64; 3],
    pub eta: f64,
    /// The transfer function file in force (None: the scene's), and the
    /// index of its switch (changes exactly when the file does).
    pub tf: Option<(usize, PathBuf)>,
}

impl Script {
    pub fn load(path: &Path) -> Result<Self> {
        let name = path.display();
        let text = std::fs::read_to_string(path).with_context(|| format!("{name}: cannot read"))?;
        let f: ScriptFile = toml::from_str(&text)
            .map_err(|e| anyhow::anyhow!("{name}: {}", e.to_string().trim_end()))?;
        if f.key.is_empty() {
            bail!("{name}: key: a script needs at least one [[key]]");
        }
        let mut s = Script {
            frames: 0,
            center: Track::default(),
            rotation: Track::default(),
            size: Track::default(),
            observer: Track::default(),
            eta: Track::default(),
            gamma: Track::default(),
            accuracy: Track::default(),
            step_factor: Track::default(),
            time: Track::default(),
            cursor: Track::default(),
            overlay: Vec::new(),
            layers: Vec::new(),
            tfs: Vec::new(),
            layer_tfs: Vec::new(),
            tools: Vec::new(),
            tool_sets: Vec::new(),
            name: name.to_string(),
        };
        let mut last = None;
        for (i, k) in f.key.iter().enumerate() {
            let at = format!("{name}: key {} (frame {})", i + 1, k.frame);
            if last.is_some_and(|l| k.frame <= l) {
                bail!("{at}: frame: keys must be in increasing frame order");
            }
            last = Some(k.frame);
            let finite = |field: &str, v: &[f64]| -> Result<()> {
                if v.iter().all(|x| x.is_finite()) {
                    Ok(())
                } else {
                    bail!("{at}: {field} must be finite (got {v:?})")
                }
            };
            if let Some(c) = k.placement.center {
                finite("placement.center", &c)?;
                s.center.keys.push((k.frame, c));
            }
            if let Some(r) = k.placement.rotation_deg {
                finite("placement.rotation_deg", &r)?;
                s.rotation.keys.push((k.frame, r));
            }
            if let Some(z) = k.placement.size {
                if !(z.is_finite() && z > 0.0) {
                    bail!("{at}: placement.size must be > 0 (got {z})");
                }
                s.size.keys.push((k.frame, [z]));
            }
            if let Some(o) = k.observer {
                finite("observer", &o)?;
                if o[2].abs() < 1e-9 {
                    bail!("{at}: observer must be off the screen plane (z ≠ 0)");
                }
                s.observer.keys.push((k.frame, o));
            }
            if let Some(e) = k.eta {
                if !(0.0..=1.0).contains(&e) {
                    bail!("{at}: eta must be in [0, 1] (got {e})");
                }
                s.eta.keys.push((k.frame, [e]));
            }
            if let Some(c) = k.cursor {
                if !c.iter().all(|x| x.is_finite() && x.abs() <= 10.0) {
                    bail!("{at}: cursor must be finite and within 10 m (got {c:?})");
                }
                s.cursor.keys.push((k.frame, c));
            }
            if let Some(l) = &k.layers {
                if let Some(c) = l.iter().find(|c| !(0.0..=1.0).contains(&c.opacity)) {
                    bail!(
                        "{at}: layers: opacity must be in [0, 1] (got {})",
                        c.opacity
                    );
                }
                s.layers.push((k.frame, l.clone()));
            }
            if let Some(on) = k.overlay {
                s.overlay.push((k.frame, on));
            }
            if let Some(g) = k.gamma {
                if !(0.0..=1.0).contains(&g) {
                    bail!("{at}: gamma must be in [0, 1] (got {g})");
                }
                s.gamma.keys.push((k.frame, [g]));
            }
            if let Some(a) = k.accuracy {
                if !(a.is_finite() && a > 0.0) {
                    bail!("{at}: accuracy must be > 0 (got {a})");
                }
                s.accuracy.keys.push((k.frame, [a]));
            }
            if let Some(f) = k.step_factor {
                if !(f.is_finite() && f > 0.0) {
                    bail!("{at}: step_factor must be > 0 (got {f})");
                }
                s.step_factor.keys.push((k.frame, [f]));
            }
            if let Some(t) = k.time {
                if !(t.is_finite() && (0.0..=MAX_SERIES as f64).contains(&t)) {
                    bail!("{at}: time must be a step from 0 to {MAX_SERIES} (got {t})");
                }
                s.time.keys.push((k.frame, [t]));
            }
            if let Some(ToolSet(set)) = &k.tools {
                parallax_common::tools::check_tools(set, Path::new(&format!("{at}: tools")))?;
                s.tool_sets.push((k.frame, set.clone()));
            }
            for t in &k.tool {
                let at = format!("{at}: tool {}", t.index);
                if s.tools.len() <= t.index {
                    s.tools.resize(t.index + 1, ToolTracks::default());
                }
                for (field, value) in &t.fields {
                    let v = value.values();
                    if field == "kind" || v.is_empty() || v.len() > 4 {
                        bail!("{at}: {field}: a key sets a numeric field of the tool (a number or up to four)");
                    }
                    if !v.iter().all(|x| x.is_finite()) {
                        bail!("{at}: {field} must be finite (got {v:?})");
                    }
                    let track = s.tools[t.index].entry(field.clone()).or_default();
                    if let Some((_, first)) = track.keys.first() {
                        if first.len() != v.len() {
                            bail!(
                                "{at}: {field}: {} value(s), its earlier keys have {}",
                                v.len(),
                                first.len()
                            );
                        }
                    }
                    track.keys.push((k.frame, v));
                }
            }
            let beside = |t: &PathBuf| {
                if t.is_absolute() {
                    t.clone()
                } else {
                    path.parent().unwrap_or(Path::new(".")).join(t)
                }
            };
            if let Some(t) = &k.transfer_function {
                s.tfs.push((k.frame, beside(t)));
            }
            for l in &k.layer_functions {
                if l.index >= parallax_common::config::MAX_LAYERS {
                    bail!(
                        "{at}: layer_functions: index {} (a scene has at most {} layers)",
                        l.index,
                        parallax_common::config::MAX_LAYERS
                    );
                }
                s.layer_tfs.push((k.frame, l.index, beside(&l.file)));
            }
        }
        s.frames = f.frames.unwrap_or(last.unwrap() + 1);
        Ok(s)
    }

    /// MImDA's γ at `frame` (the scene's where the script sets none).
    /// The overlay's cursor at `frame` (the scene's where no key sets it).
    pub fn cursor(&self, frame: u64, scene: Option<[f64; 3]>) -> Option<[f64; 3]> {
        if self.cursor.keys.is_empty() {
            scene
        } else {
            Some(self.cursor.at(frame, scene.unwrap_or([0.0; 3])))
        }
    }

    /// Whether the overlay is drawn at `frame`.
    pub fn overlay(&self, frame: u64, scene: bool) -> bool {
        self.overlay
            .iter()
            .rev()
            .find(|(f, _)| *f <= frame)
            .map_or(scene, |(_, on)| *on)
    }

    /// The layers' function files at `frame` (`None`: the scene's), for
    /// `count` layers.
    pub fn layer_functions(&self, frame: u64, count: usize) -> Vec<Option<PathBuf>> {
        let mut out = vec![None; count];
        for (f, i, p) in &self.layer_tfs {
            if *f <= frame {
                if let Some(o) = out.get_mut(*i) {
                    *o = Some(p.clone());
                }
            }
        }
        out
    }

    /// The layer indices the script's keys name, for checking against a
    /// scene.
    pub fn layer_indices(&self) -> impl Iterator<Item = usize> + '_ {
        self.layer_tfs.iter().map(|(_, i, _)| *i)
    }

    /// The registered layers' controls at `frame` (empty: the scene's).
    pub fn layers(&self, frame: u64) -> Vec<parallax_common::protocol::LayerControl> {
        self.layers
            .iter()
            .rev()
            .find(|(f, _)| *f <= frame)
            .map_or_else(Vec::new, |(_, l)| l.clone())
    }

    pub fn gamma(&self, frame: u64, scene: f64) -> f64 {
        self.gamma.at(frame, [scene])[0]
    }

    /// `render.accuracy` at `frame` (the scene's where the script sets none).
    pub fn accuracy(&self, frame: u64, scene: f64) -> f64 {
        self.accuracy.at(frame, [scene])[0]
    }

    /// `render.step_factor` at `frame` (the scene's where the script sets
    /// none).
    pub fn step_factor(&self, frame: u64, scene: f64) -> f64 {
        self.step_factor.at(frame, [scene])[0]
    }

    /// The time step at `frame`: the whole part of the keys' interpolated
    /// value (0 where the script sets none).
    pub fn time(&self, frame: u64) -> u32 {
        (self.time.at(frame, [0.0])[0] + 1e-9).floor() as u32
    }

    /// The last time step the script reaches (0 without `time` keys).
    pub fn last_time(&self) -> u32 {
        self.time
            .keys
            .iter()
            .map(|(_, [t])| (t + 1e-9).floor() as u32)
            .max()
            .unwrap_or(0)
    }

    /// The tools at `frame`: the scene's (or the tool set in force),
    /// moved and changed as the keys say.
    pub fn tools(&self, frame: u64, scene: &[Tool]) -> Result<Vec<Tool>> {
        let scene = self
            .tool_sets
            .iter()
            .rev()
            .find(|(f, _)| *f <= frame)
            .map_or(scene, |(_, set)| set.as_slice());
        if self.tools.len() > scene.len() {
            bail!(
                "{}: tool {}: the scene has only {} tool(s)",
                self.name,
                self.tools.len() - 1,
                scene.len()
            );
        }
        let mut out = scene.to_vec();
        for (i, (t, tr)) in out.iter_mut().zip(&self.tools).enumerate() {
            if tr.is_empty() {
                continue;
            }
            let kind = t.enhancer().file();
            let what = format!("{}: tool {i} ({kind}) at frame {frame}", self.name);
            let mut table = t.table()?;
            for (field, track) in tr {
                let Some(v) = track.get(frame) else { continue };
                let slot = table.get_mut(field).filter(|old| {
                    old.as_array().map_or(v.len() == 1 && old.is_number(), |a| {
                        a.len() == v.len() && a.iter().all(|x| x.is_number())
                    })
                });
                let Some(slot) = slot else {
                    bail!(
                        "{what}: {field}: a {kind} has no field of {} number(s) by that name (its numeric fields: {})",
                        v.len(),
                        t.numeric_fields().join(", ")
                    );
                };
                // Integer fields (a level) keep integers where the value is one.
                let number = |x: f64, old: &serde_json::Value| {
                    if (old.is_i64() || old.is_u64()) && x.fract() == 0.0 && x.abs() < 1e15 {
                        serde_json::json!(x as i64)
                    } else {
                        serde_json::json!(x)
                    }
                };
                *slot = match slot.as_array() {
                    None => number(v[0], slot),
                    Some(a) => a.iter().zip(&v).map(|(o, &x)| number(x, o)).collect(),
                };
            }
            *t = Tool::from_table(table.into(), &what)?;
            t.check(&what)?;
        }
        Ok(out)
    }

    /// The state of `frame`, with the scene's values where the script sets none.
    pub fn at(
        &self,
        frame: u64,
        placement: &Placement,
        observer: [f64; 3],
        eta: f64,
    ) -> ScriptState {
        let tf = self
            .tfs
            .iter()
            .enumerate()
            .rev()
            .find(|(_, (f, _))| *f <= frame)
            .map(|(i, (_, p))| (i, p.clone()));
        ScriptState {
            placement: Placement {
                center: self.center.at(frame, placement.center),
                rotation_deg: self.rotation.at(frame, placement.rotation_deg),
                size: self.size.at(frame, [placement.size])[0],
            },
            observer: self.observer.at(frame, observer),
            eta: self.eta.at(frame, [eta])[0],
            tf,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn load(text: &str) -> Result<Script> {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("s.toml");
        std::fs::write(&p, text).unwrap();
        Script::load(&p)
    }

    #[test]
    fn keys_interpolate_and_hold() {
        let s = load(
            "[[key]]\nframe = 0\nplacement = { rotation_deg = [0, 0, 0] }\neta = 0.0\ntransfer_function = \"a.toml\"\n\
             [[key]]\nframe = 10\nplacement = { rotation_deg = [0, 90, 0], size = 0.5 }\neta = 1.0\n\
             [[key]]\nframe = 20\ntransfer_function = \"b.toml\"\n",
        )
        .unwrap();
        assert_eq!(s.frames, 21);
        let base = Placement {
            center: [0.0, 0.0, 0.1],
            rotation_deg: [5.0, 5.0, 5.0],
            size: 0.25,
        };
        let st = s.at(5, &base, [0.0, 0.0, 2.0], 0.3);
        assert_eq!(st.placement.rotation_deg, [0.0, 45.0, 0.0]);
        assert_eq!(st.placement.center, [0.0, 0.0, 0.1]); // not scripted: the scene's
        assert_eq!(st.placement.size, 0.5); // before its first key: held
        assert_eq!(st.eta, 0.5);
        assert_eq!(st.observer, [0.0, 0.0, 2.0]);
        assert_eq!(st.tf.as_ref().unwrap().0, 0);
        let st = s.at(25, &base, [0.0, 0.0, 2.0], 0.3);
        assert_eq!(st.placement.rotation_deg, [0.0, 90.0, 0.0]);
        assert_eq!(st.eta, 1.0);
        assert!(st.tf.unwrap().1.ends_with("b.toml"));
    }

    #[test]
    fn bad_scripts_name_file_key_and_field() {
        for (text, field) in [
            ("", "key"),
            ("[[key]]\nframe = 3\n[[key]]\nframe = 2\n", "frame"),
            (
                "[[key]]\nframe = 0\nplacement = { size = -1 }\n",
                "placement.size",
            ),
            ("[[key]]\nframe = 0\nobserver = [0, 0, 0]\n", "observer"),
            ("[[key]]\nframe = 0\neta = nan\n", "eta"),
            ("[[key]]\nframe = 0\nspin = 1\n", "spin"),
            ("[[key]]\nframe = 0\ngamma = 2\n", "gamma"),
            (
                "[[key]]\nframe = 0\ntool = [{ index = 0, normal = [0, nan, 0] }]\n",
                "normal",
            ),
            (
                "[[key]]\nframe = 0\ntool = [{ index = 0, normal = [0, 1] }]\n[[key]]\nframe = 1\ntool = [{ index = 0, normal = [0, 0, 1] }]\n",
                "normal: 3 value(s)",
            ),
        ] {
            let e = format!("{:#}", load(text).unwrap_err());
            assert!(e.contains("s.toml") && e.contains(field), "{e}");
        }
    }

    #[test]
    fn layer_functions_switch_from_their_frame() {
        let s = load(
            "[[key]]\nframe = 0\nlayer_functions = [{ index = 1, file = \"a.toml\" }]\n\
             [[key]]\nframe = 10\nlayer_functions = [{ index = 0, file = \"/b.txt\" }, { index = 1, file = \"c.toml\" }]\n",
        )
        .unwrap();
        let at = |f| s.layer_functions(f, 2);
        assert_eq!(at(0)[0], None);
        assert!(at(9)[1].as_ref().unwrap().ends_with("a.toml"));
        assert_eq!(at(10)[0].as_deref(), Some(Path::new("/b.txt")));
        assert!(at(10)[1].as_ref().unwrap().ends_with("c.toml"));
        assert_eq!(s.layer_indices().max(), Some(1));
        let e = format!(
            "{:#}",
            load("[[key]]\nframe = 0\nlayer_functions = [{ index = 3, file = \"a.toml\" }]\n")
                .unwrap_err()
        );
        assert!(
            e.contains("s.toml") && e.contains("layer_functions: index 3"),
            "{e}"
        );
    }
}

#[cfg(test)]
mod tool_tests {
    use super::*;
    use parallax_common::tools::ClipPlane;

    #[test]
    fn tools_and_gamma_are_keyframed() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("s.toml");
        std::fs::write(
            &p,
            "[[key]]\nframe = 0\ngamma = 0\ntool = [{ index = 0, point = [0, 0, 0], normal = [0, 0, 1] }]\n\
             [[key]]\nframe = 10\ngamma = 1\ntool = [{ index = 0, point = [0, 0, 0.1], normal = [1, 0, 0], thickness = 0.01 }]\n",
        )
        .unwrap();
        let s = Script::load(&p).unwrap();
        let scene = vec![Tool::ClipPlane(ClipPlane {
            point: [0.0; 3],
            normal: [0.0, 0.0, 1.0],
            thickness: 0.0,
            context: [0.3, 0.7],
        })];
        let t = s.tools(5, &scene).unwrap();
        let Tool::ClipPlane(c) = t[0] else { panic!() };
        assert!((c.point[2] - 0.05).abs() < 1e-12);
        assert_eq!(c.normal, [0.5, 0.0, 0.5]);
        assert_eq!(c.thickness, 0.01); // its only key, held before it
        assert_eq!(s.gamma(5, 0.3), 0.5);
        assert_eq!(s.gamma(50, 0.3), 1.0);
        // A key for a tool the scene does not have.
        assert!(s.tools(0, &[]).unwrap_err().to_string().contains("s.toml"));
    }

    #[test]
    fn any_numeric_field_of_any_kind_is_keyed_by_name() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("s.toml");
        std::fs::write(
            &p,
            "[[key]]\nframe = 0\ntool = [{ index = 0, band = [10, 20, 30, 40] }, { index = 1, strength = 0, level = 2 }]\n\
             [[key]]\nframe = 4\ntool = [{ index = 0, band = [50, 60, 70, 80], alignment = [0.5, 0.9] }, { index = 1, strength = 2 }]\n",
        )
        .unwrap();
        let s = Script::load(&p).unwrap();
        #[derive(Deserialize)]
        struct W {
            t: ToolSet,
        }
        let w: W = toml::from_str(
            "t = [{ kind = \"band-picker\", band = [0, 1, 2, 3] }, { kind = \"unsharp-gradient\" }]",
        )
        .unwrap();
        let scene = w.t.0;
        let t = s.tools(1, &scene).unwrap();
        let Tool::BandPicker(b) = t[0] else { panic!() };
        assert_eq!(b.band, [20.0, 30.0, 40.0, 50.0]);
        assert_eq!(b.alignment, [0.5, 0.9]);
        let Tool::UnsharpGradient(u) = t[1] else {
            panic!()
        };
        assert_eq!((u.strength, u.level), (0.5, 2));
        // A field of another length than the tool's is refused by name.
        std::fs::write(
            &p,
            "[[key]]\nframe = 0\ntool = [{ index = 1, strength = [1, 2] }]\n",
        )
        .unwrap();
        let e = Script::load(&p).unwrap().tools(0, &scene).unwrap_err();
        assert!(
            e.to_string()
                .contains("tool 1 (unsharp-gradient) at frame 0: strength"),
            "{e}"
        );
    }

    #[test]
    fn a_tool_set_replaces_the_scene_tools_from_its_frame() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("s.toml");
        std::fs::write(
            &p,
            "[[key]]\nframe = 0\n[[key]]\nframe = 4\ntools = [{ kind = \"probe\", center = [0, 0, 0], radius = 0.02 }, { kind = \"pass-through\" }]\n",
        )
        .unwrap();
        let s = Script::load(&p).unwrap();
        let scene = vec![Tool::PassThrough(Default::default())];
        assert_eq!(s.tools(3, &scene).unwrap(), scene);
        let t = s.tools(4, &scene).unwrap();
        assert_eq!(t.len(), 2);
        assert!(matches!(t[0], Tool::Probe(p) if p.radius == 0.02));
        std::fs::write(
            &p,
            "[[key]]\nframe = 0\ntools = [{ kind = \"probe\", center = [0, 0, 0], radius = -1 }]\n",
        )
        .unwrap();
        let e = Script::load(&p).unwrap_err().to_string();
        assert!(e.contains("s.toml: key 1") && e.contains("radius"), "{e}");
    }

    #[test]
    fn a_probe_is_keyframed_and_keys_it_lacks_are_refused() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("s.toml");
        std::fs::write(
            &p,
            "[[key]]\nframe = 0\ntool = [{ index = 0, center = [0, 0, 0], radius = 0.02 }]\n\
             [[key]]\nframe = 10\ntool = [{ index = 0, center = [0.1, 0, 0], radius = 0.04, axis = [1, 0, 0] }]\n",
        )
        .unwrap();
        let s = Script::load(&p).unwrap();
        let scene = vec![Tool::Probe(parallax_common::tools::Probe::new(
            [0.0; 3], 0.05,
        ))];
        let t = s.tools(5, &scene).unwrap();
        let Tool::Probe(probe) = t[0] else { panic!() };
        assert!((probe.center[0] - 0.05).abs() < 1e-12);
        assert!((probe.radius - 0.03).abs() < 1e-12);
        assert_eq!(probe.axis, [1.0, 0.0, 0.0]); // its only key, held before it
        std::fs::write(
            &p,
            "[[key]]\nframe = 0\ntool = [{ index = 0, normal = [0, 0, 1] }]\n",
        )
        .unwrap();
        let e = Script::load(&p)
            .unwrap()
            .tools(0, &scene)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("s.toml: tool 0 (probe)")
                && e.contains("normal")
                && e.contains("center, gradient, radius"),
            "{e}"
        );
    }
}
