//! The scene as a Looking Glass quilt (`parallax quilt`): `cols × rows` views
//! in one image, for lenticular light field displays.
//!
//! A quilt is the same light field idea as the projector wall of G10 §3, but
//! sampled by cameras rather than projectors: every camera looks at the same
//! screen rectangle (the display's focal plane, z = 0) through a shifted and
//! sheared (off-axis) frustum, the cameras spread on a horizontal line at the
//! viewing distance over the device's view cone. Each view is therefore a
//! plain perspective view (G10 Eq. 1 with η = 0, the camera as observer):
//! points on the focal plane land on the same pixel in every view, points in
//! front of or behind it shift horizontally from view to view.
//!
//! Layout and name follow the Looking Glass convention: view 0 is the
//! leftmost camera and sits in the bottom-left tile, views run left to right
//! then bottom to top, and the file name carries `_qs{cols}x{rows}a{aspect}`.

use anyhow::{bail, Result};
use parallax_common::camera::View;
use std::path::{Path, PathBuf};

/// Horizontal view cone of Looking Glass devices (degrees).
pub const DEFAULT_CONE_DEG: f64 = 40.0;

/// Width / height of a tile: the aspect written in a quilt's file name.
pub fn tile_aspect(tile: [u32; 2]) -> f64 {
    tile[0] as f64 / tile[1].max(1) as f64
}

/// The views of a quilt, in quilt order (view 0 = the leftmost camera).
///
/// Camera k of n = cols·rows is at (D·tan(−cone/2 + k·cone/(n−1)), 0, D),
/// looking at the screen rectangle of size `screen` centred on the origin:
/// `View { eye, observer: eye, eta: 0, region: screen }`. One view sits at
/// the centre.
pub fn quilt_views(
    screen: [f64; 2],
    distance: f64,
    cone_deg: f64,
    cols: u32,
    rows: u32,
    tile: [u32; 2],
) -> Vec<View> {
    let n = cols as usize * rows as usize;
    let cone = cone_deg.to_radians();
    (0..n)
        .map(|k| {
            let angle = if n > 1 {
                -cone / 2.0 + k as f64 * cone / (n - 1) as f64
            } else {
                0.0
            };
            let eye = [distance * angle.tan(), 0.0, distance];
            View {
                resolution: tile,
                region: [-screen[0] / 2.0, -screen[1] / 2.0, screen[0], screen[1]],
                eye,
                observer: eye,
                eta: 0.0,
            }
        })
        .collect()
}

/// Assembles the quilt image ((cols·tile_w) × (rows·tile_h), row 0 at the
/// top) from the views' images in quilt order: view k goes to column
/// k mod cols of tile row k div cols counted from the bottom, so view 0 is
/// the bottom-left tile and the last view the top-right one.
pub fn assemble(
    cols: u32,
    rows: u32,
    tile: [u32; 2],
    images: &[Vec<[f32; 4]>],
) -> Result<Vec<[f32; 4]>> {
    let n = cols as usize * rows as usize;
    if images.len() != n {
        bail!(
            "a {cols}×{rows} quilt needs {n} views, got {} images",
            images.len()
        );
    }
    let (tw, th) = (tile[0] as usize, tile[1] as usize);
    if let Some((k, img)) = images.iter().enumerate().find(|(_, i)| i.len() != tw * th) {
        bail!(
            "view {k}: {} pixels, a {tw}×{th} tile needs {}",
            img.len(),
            tw * th
        );
    }
    let qw = cols as usize * tw;
    let mut out = vec![[0f32; 4]; qw * rows as usize * th];
    for (k, img) in images.iter().enumerate() {
        let col = k % cols as usize;
        let row_from_bottom = k / cols as usize;
        let top = (rows as usize - 1 - row_from_bottom) * th;
        for j in 0..th {
            let dst = (top + j) * qw + col * tw;
            out[dst..dst + tw].copy_from_slice(&img[j * tw..(j + 1) * tw]);
        }
    }
    Ok(out)
}

/// The aspect as Looking Glass writes it: at most 2 decimals, trailing
/// zeros trimmed (0.75 → "0.75", 1.6 → "1.6", 1.0 → "1").
pub fn format_aspect(aspect: f64) -> String {
    let s = format!("{aspect:.2}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s.is_empty() || s == "-" {
        "0".to_string()
    } else {
        s.to_string()
    }
}

/// `{stem}_qs{cols}x{rows}a{aspect}.png`, e.g. `scene_qs8x6a0.75.png`: the
/// name Looking Glass software reads the quilt layout from.
pub fn quilt_file_name(stem: &str, cols: u32, rows: u32, aspect: f64) -> String {
    format!("{stem}{}.png", quilt_suffix(cols, rows, aspect))
}

/// `_qs{cols}x{rows}a{aspect}`.
pub fn quilt_suffix(cols: u32, rows: u32, aspect: f64) -> String {
    format!("_qs{cols}x{rows}a{}", format_aspect(aspect))
}

/// `path` with the quilt suffix inserted before its extension (`.png` when
/// it has none): `out/scene.png` → `out/scene_qs8x6a0.75.png`.
pub fn quilt_path(path: &Path, cols: u32, rows: u32, aspect: f64) -> PathBuf {
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "quilt".to_string());
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().into_owned())
        .unwrap_or_else(|| "png".to_string());
    path.with_file_name(format!("{stem}{}.{ext}", quilt_suffix(cols, rows, aspect)))
}
