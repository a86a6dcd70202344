//! How a display's images reach its outputs (`[present]` of a display file,
//! G10 §5: "each back-end process controls a frame-buffer portion"): each
//! output is a borderless window on the X screen, placed by the output's
//! name or by position and size, showing one or more projectors' images at
//! their viewports (a light field display's board drives several projectors
//! through one large framebuffer). Without outputs every projector gets a
//! window of its own, tiled over the screen in projector order.

use anyhow::{bail, Result};
use serde::{Deserialize, Serialize};

/// When a presented frame reaches the screen.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum PresentMode {
    /// At the next vertical blank (vsync, no tearing).
    #[default]
    Fifo,
    /// At once (tearing possible).
    Immediate,
    /// At the next vertical blank, replacing a frame still waiting.
    Mailbox,
}

/// One output: a window and the projectors it shows.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Output {
    /// The output (RandR name, as `xrandr` lists it) whose place and size
    /// the window takes, unless `rect` gives them.
    #[serde(default)]
    pub name: Option<String>,
    /// [x, y, width, height] of the window on the X screen (pixels).
    #[serde(default)]
    pub rect: Option<[i64; 4]>,
    /// The projectors (ids) the output shows.
    pub projectors: Vec<String>,
    /// [x, y] of each projector's image inside the window (pixels); default:
    /// side by side from the top left, in the order of `projectors`.
    #[serde(default)]
    pub viewports: Option<Vec<[u32; 2]>>,
}

/// `[present]`: the present mode and the outputs.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Present {
    #[serde(default)]
    pub mode: PresentMode,
    #[serde(default, rename = "output")]
    pub outputs: Vec<Output>,
}

/// Where a window goes.
#[derive(Clone, Debug, PartialEq)]
pub enum Place {
    /// [x, y] and [width, height] on the X screen.
    Rect([i32; 2], [u32; 2]),
    /// Where the named output is, at its size.
    Named(String),
}

/// A window to open: where, and each projector's (index, [x, y]) in it.
#[derive(Clone, Debug, PartialEq)]
pub struct Window {
    /// For messages: the output's name, or `window N`.
    pub label: String,
    pub place: Place,
    pub tiles: Vec<(usize, [u32; 2])>,
}

impl Window {
    /// The smallest [width, height] that holds every tile.
    pub fn extent(&self, resolutions: &[[u32; 2]]) -> [u32; 2] {
        self.tiles.iter().fold([0, 0], |[w, h], &(p, [x, y])| {
            let [pw, ph] = resolutions[p];
            [w.max(x + pw), h.max(y + ph)]
        })
    }
}

impl Present {
    /// The windows of the display whose projectors have these ids and
    /// resolutions; `what` names the display file in errors.
    pub fn windows(
        &self,
        ids: &[String],
        resolutions: &[[u32; 2]],
        what: &str,
    ) -> Result<Vec<Window>> {
        if self.outputs.is_empty() {
            return Ok(default_grid(resolutions));
        }
        let mut shown = vec![false; ids.len()];
        let mut windows = Vec::with_capacity(self.outputs.len());
        for (k, o) in self.outputs.iter().enumerate() {
            let at = format!("{what}: present.output[{k}]");
            let mut tiles = Vec::with_capacity(o.projectors.len());
            let mut x = 0u32;
            if let Some(v) = &o.viewports {
                if v.len() != o.projectors.len() {
                    bail!(
                        "{at}.viewports: {} viewports for {} projectors",
                        v.len(),
                        o.projectors.len()
                    );
                }
            }
            for (j, id) in o.projectors.iter().enumerate() {
                let Some(p) = ids.iter().position(|i| i == id) else {
                    bail!("{at}.projectors: no projector '{id}' in the display");
                };
                if std::mem::replace(&mut shown[p], true) {
                    bail!("{at}.projectors: projector '{id}' is shown by two outputs");
                }
                let offset = match &o.viewports {
                    Some(v) => v[j],
                    None => [x, 0],
                };
                x += resolutions[p][0];
                tiles.push((p, offset));
            }
            let label = o.name.clone().unwrap_or_else(|| format!("window {k}"));
            let place = match (&o.rect, &o.name) {
                (Some(r), _) => {
                    if r[2] <= 0 || r[3] <= 0 || r.iter().any(|v| v.abs() > 1 << 15) {
                        bail!("{at}.rect: [x, y, width, height] with a positive size within ±32768 pixels (got {r:?})");
                    }
                    Place::Rect([r[0] as i32, r[1] as i32], [r[2] as u32, r[3] as u32])
                }
                (None, Some(n)) => Place::Named(n.clone()),
                (None, None) => bail!("{at}: give the output's name or its rect"),
            };
            let w = Window {
                label,
                place,
                tiles,
            };
            if let Place::Rect(_, size) = w.place {
                let [ew, eh] = w.extent(resolutions);
                if ew > size[0] || eh > size[1] {
                    bail!(
                        "{at}: the projectors' images need {ew}×{eh} pixels, the window has {}×{}",
                        size[0],
                        size[1]
                    );
                }
            }
            windows.push(w);
        }
        Ok(windows)
    }
}

/// Every projector in a window of its own, on a grid of ⌈√n⌉ columns whose
/// cells are as large as the largest projector image.
fn default_grid(resolutions: &[[u32; 2]]) -> Vec<Window> {
    let n = resolutions.len();
    let cols = (n as f64).sqrt().ceil().max(1.0) as usize;
    let cw = resolutions.iter().map(|r| r[0]).max().unwrap_or(1);
    let ch = resolutions.iter().map(|r| r[1]).max().unwrap_or(1);
    resolutions
        .iter()
        .enumerate()
        .map(|(p, &r)| {
            let (c, row) = ((p % cols) as u32, (p / cols) as u32);
            Window {
                label: format!("window {p}"),
                place: Place::Rect([(c * cw) as i32, (row * ch) as i32], r),
                tiles: vec![(p, [0, 0])],
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ids(n: usize) -> Vec<String> {
        (0..n).map(|i| format!("p{i:02}")).collect()
    }

    #[test]
    fn without_outputs_every_projector_gets_a_tile_of_a_grid() {
        let w = Present::default()
            .windows(&ids(5), &[[160, 90]; 5], "d")
            .unwrap();
        assert_eq!(w.len(), 5);
        // ⌈√5⌉ = 3 columns.
        assert_eq!(w[4].place, Place::Rect([160, 90], [160, 90]));
        assert_eq!(w[2].place, Place::Rect([320, 0], [160, 90]));
    }

    #[test]
    fn outputs_place_projectors_side_by_side_or_at_their_viewports() {
        let p = Present {
            mode: PresentMode::Immediate,
            outputs: vec![
                Output {
                    name: Some("DP-1".into()),
                    rect: Some([100, 0, 400, 100]),
                    projectors: vec!["p01".into(), "p00".into()],
                    viewports: None,
                },
                Output {
                    name: Some("HDMI-0".into()),
                    rect: None,
                    projectors: vec!["p02".into()],
                    viewports: Some(vec![[7, 9]]),
                },
            ],
        };
        let w = p.windows(&ids(3), &[[160, 90]; 3], "d").unwrap();
        assert_eq!(w[0].tiles, vec![(1, [0, 0]), (0, [160, 0])]);
        assert_eq!(w[0].place, Place::Rect([100, 0], [400, 100]));
        assert_eq!(w[1].place, Place::Named("HDMI-0".into()));
        assert_eq!(w[1].tiles, vec![(2, [7, 9])]);
        assert_eq!(w[1].extent(&[[160, 90]; 3]), [167, 99]);
    }

    #[test]
    fn bad_outputs_are_refused_naming_the_field() {
        let out = |rect, projectors: &[&str], viewports| Present {
            mode: PresentMode::Fifo,
            outputs: vec![Output {
                name: None,
                rect,
                projectors: projectors.iter().map(|s| s.to_string()).collect(),
                viewports,
            }],
        };
        let err = |p: Present| {
            p.windows(&ids(2), &[[160, 90]; 2], "d.toml")
                .unwrap_err()
                .to_string()
        };
        assert!(err(out(None, &["p00"], None))
            .contains("present.output[0]: give the output's name or its rect"));
        assert!(err(out(Some([0, 0, 100, 90]), &["p00"], None)).contains("need 160×90 pixels"));
        assert!(err(out(Some([0, 0, 0, 90]), &["p00"], None)).contains("present.output[0].rect"));
        assert!(err(out(Some([0, 0, 400, 90]), &["p07"], None)).contains("no projector 'p07'"));
        assert!(
            err(out(Some([0, 0, 400, 90]), &["p00", "p00"], None)).contains("shown by two outputs")
        );
        assert!(err(out(Some([0, 0, 400, 90]), &["p00"], Some(vec![])))
            .contains("viewports: 0 viewports for 1"));
    }
}
