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
//! Numbers are interpolated linearly between the keys that set them and held
//! after the last; a transfer function switches at its key.

use anyhow::{bail, Context, Result};
use parallax_common::camera::Placement;
use serde::Deserialize;
use std::path::{Path, PathBuf};

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ScriptFile {
    frames: Option<u64>,
    #[serde(default)]
    key: Vec<Key>,
}

#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct PlacementKey {
    center: Option<[f64; 3]>,
    rotation_deg: Option<[f64; 3]>,
    size: Option<f64>,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Key {
    frame: u64,
    #[serde(default)]
    placement: PlacementKey,
    observer: Option<[f64; 3]>,
    eta: Option<f64>,
    transfer_function: Option<PathBuf>,
}

/// One numeric track: (frame, value) keys in frame order.
#[derive(Clone, Debug, Default)]
struct Track<const N: usize> {
    keys: Vec<(u64, [f64; N])>,
}

impl<const N: usize> Track<N> {
    fn at(&self, frame: u64, default: [f64; N]) -> [f64; N] {
        let k = &self.keys;
        match k.iter().position(|&(f, _)| f > frame) {
            None => k.last().map_or(default, |&(_, v)| v),
            Some(0) => k[0].1,
            Some(i) => {
                let ((f0, a), (f1, b)) = (k[i - 1], k[i]);
                let t = (frame - f0) as f64 / (f1 - f0) as f64;
                std::array::from_fn(|c| a[c] + t * (b[c] - a[c]))
            }
        }
    }
}

/// A loaded script.
#[derive(Clone, Debug)]
pub struct Script {
    pub frames: u64,
    center: Track<3>,
    rotation: Track<3>,
    size: Track<1>,
    observer: Track<3>,
    eta: Track<1>,
    /// (first frame, file) of each transfer function switch.
    tfs: Vec<(u64, PathBuf)>,
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
            tfs: Vec::new(),
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
                finite("eta", &[e])?;
                s.eta.keys.push((k.frame, [e]));
            }
            if let Some(t) = &k.transfer_function {
                let p = if t.is_absolute() {
                    t.clone()
                } else {
                    path.parent().unwrap_or(Path::new(".")).join(t)
                };
                s.tfs.push((k.frame, p));
            }
        }
        s.frames = f.frames.unwrap_or(last.unwrap() + 1);
        Ok(s)
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
        ] {
            let e = format!("{:#}", load(text).unwrap_err());
            assert!(e.contains("s.toml") && e.contains(field), "{e}");
        }
    }
}
