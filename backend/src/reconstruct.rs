//! Adaptive frame reconstruction (G10 §5): each view's pixels form four
//! sub-frames on a quincunx lattice (one pixel of every 2×2 quad each); one
//! sub-frame is rendered per frame and the others are reconstructed by a
//! spatio-temporal filter. This is the filter on the CPU, which the
//! renderer runs on CPU devices; on a GPU it runs the same filter there
//! (`shaders/reconstruct.wgsl`, `raycast::subframes`), tested against this.
//!
//! For a pixel Q that was not rendered this frame, with cross neighbours
//! A, B, C, D (opposite pairs A–C and B–D):
//!
//! * the spatial estimate Q^spatial averages the opposite pair with the
//!   smaller colour difference;
//! * the temporal change ΔQ is the largest colour change among A…D;
//! * Q' = Q_{t−1} + smoothstep(ΔQ, Δl, Δh)·(Q^spatial − Q_{t−1}).
//!
//! As in the paper the pixels diagonal to the rendered ones are done first,
//! from their four diagonal neighbours (all just rendered), then the
//! horizontal and vertical ones from their four axis neighbours (rendered or
//! just reconstructed).
//!
//! Two choices make a static view converge to exactly the full render: Q_{t−1}
//! is the pixel's own most recent rendering (not a previous reconstruction),
//! and a neighbour's colour change is measured between its two most recent
//! renderings (zero while it has only one). A static view is therefore the
//! full render from its fourth frame on when it starts from an empty
//! history, and at most eight frames after its last change otherwise (by
//! then every pixel has been rendered twice since). When the history is
//! invalid (the first frame, a jump
//! of the placement, a new transfer function, new tools, other render
//! settings) every pixel without a rendering since takes the spatial
//! estimate.

/// Sub-frames, and the 2×2-quad offset of each in rendering order: the
/// diagonal pairs first, so that two frames already cover a quincunx.
pub const SUBFRAMES: u32 = 4;
pub const OFFSETS: [[u32; 2]; 4] = [[0, 0], [1, 1], [1, 0], [0, 1]];

/// Colour change (largest over RGBA, premultiplied, linear) below which a
/// pixel keeps its own last rendering, and above which it takes the spatial
/// estimate; in between the smoothstep blends.
pub const DELTA_LOW: f32 = 0.004;
pub const DELTA_HIGH: f32 = 0.04;

/// The sub-frame rendered at frame `frame`.
pub fn subframe_of(frame: u64) -> u32 {
    (frame % SUBFRAMES as u64) as u32
}

/// Whether pixel (x, y) belongs to sub-frame `k`.
pub fn in_subframe(x: u32, y: u32, k: u32) -> bool {
    let [ox, oy] = OFFSETS[k as usize];
    x % 2 == ox && y % 2 == oy
}

use rayon::prelude::*;

type Rgba = [f32; 4];

/// One reconstruction phase: the quad offsets of its pixels, and their four
/// neighbours as two opposite pairs.
type Phase<'a> = (&'a [(usize, usize)], [[isize; 2]; 4]);

fn smoothstep(x: f32, lo: f32, hi: f32) -> f32 {
    let t = ((x - lo) / (hi - lo)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

fn diff(a: &Rgba, b: &Rgba) -> f32 {
    (0..4).map(|c| (a[c] - b[c]).abs()).fold(0.0, f32::max)
}

fn mean(a: &Rgba, b: &Rgba) -> Rgba {
    std::array::from_fn(|c| 0.5 * (a[c] + b[c]))
}

/// One view's history.
#[derive(Clone, Debug)]
pub struct ViewHistory {
    width: u32,
    height: u32,
    /// Each pixel's most recent rendering, and the colour change from the
    /// one before it (valid once `renders` is 2).
    last: Vec<Rgba>,
    change: Vec<f32>,
    /// Renderings since the history was last invalidated (saturating at 2).
    renders: Vec<u8>,
}

impl ViewHistory {
    pub fn new(width: u32, height: u32) -> Self {
        let n = width as usize * height as usize;
        ViewHistory {
            width,
            height,
            last: vec![[0.0; 4]; n],
            change: vec![0.0; n],
            renders: vec![0; n],
        }
    }

    pub fn size(&self) -> [u32; 2] {
        [self.width, self.height]
    }

    /// Forgets every rendering (the scene changed in a way the filter must
    /// not blend across).
    pub fn invalidate(&mut self) {
        self.renders.iter_mut().for_each(|r| *r = 0);
    }

    /// Takes the pixels of sub-frame `k` from `rendered` (a full-size image
    /// whose other pixels are ignored) and returns the reconstructed image.
    pub fn update(&mut self, k: u32, rendered: &[Rgba]) -> Vec<Rgba> {
        let (w, h) = (self.width as usize, self.height as usize);
        assert_eq!(rendered.len(), w * h, "image size");
        let mut out = vec![[0.0f32; 4]; w * h];
        let [ox, oy] = OFFSETS[k as usize].map(|o| o as usize);
        for y in (oy..h).step_by(2) {
            for x in (ox..w).step_by(2) {
                let i = y * w + x;
                if self.renders[i] > 0 {
                    self.change[i] = diff(&rendered[i], &self.last[i]);
                }
                self.last[i] = rendered[i];
                self.renders[i] = (self.renders[i] + 1).min(2);
                out[i] = rendered[i];
            }
        }
        let phases: [Phase; 2] = [
            // Diagonal to the rendered pixels, from the four diagonal ones.
            (&[(ox ^ 1, oy ^ 1)], [[-1, -1], [1, 1], [1, -1], [-1, 1]]),
            // Then the others, from their four axis neighbours.
            (
                &[(ox ^ 1, oy), (ox, oy ^ 1)],
                [[-1, 0], [1, 0], [0, -1], [0, 1]],
            ),
        ];
        // A pixel of a phase reads only rendered pixels and those of the
        // phases before, never one of its own: each phase's rows are
        // filtered in parallel and written after, the same image as in
        // raster order.
        for &(starts, nb) in &phases {
            for &(sx, sy) in starts {
                let rows: Vec<Vec<Rgba>> = (sy..h)
                    .step_by(2)
                    .collect::<Vec<_>>()
                    .into_par_iter()
                    .map(|y| {
                        (sx..w)
                            .step_by(2)
                            .map(|x| self.filtered(&out, x, y, nb))
                            .collect()
                    })
                    .collect();
                for (y, row) in (sy..h).step_by(2).zip(rows) {
                    for (x, q) in (sx..w).step_by(2).zip(row) {
                        out[y * w + x] = q;
                    }
                }
            }
        }
        out
    }

    /// The change between pixel `i`'s two latest renderings.
    fn change(&self, i: usize) -> f32 {
        if self.renders[i] >= 2 {
            self.change[i]
        } else {
            0.0
        }
    }

    /// Pixel (x, y), not rendered this frame, from its neighbours `nb`
    /// (two opposite pairs) in `out` and its own history.
    fn filtered(&self, out: &[Rgba], x: usize, y: usize, nb: [[isize; 2]; 4]) -> Rgba {
        let (w, h) = (self.width as usize, self.height as usize);
        let i = y * w + x;
        let at = |d: [isize; 2]| -> Option<usize> {
            let (nx, ny) = (x as isize + d[0], y as isize + d[1]);
            (nx >= 0 && ny >= 0 && (nx as usize) < w && (ny as usize) < h)
                .then(|| ny as usize * w + nx as usize)
        };
        let n: [Option<usize>; 4] = nb.map(at);
        // Opposite pairs: (0, 1) and (2, 3).
        let pair = |a: Option<usize>, b: Option<usize>| match (a, b) {
            (Some(a), Some(b)) => Some((mean(&out[a], &out[b]), diff(&out[a], &out[b]))),
            (Some(a), None) | (None, Some(a)) => Some((out[a], f32::INFINITY)),
            (None, None) => None,
        };
        let spatial = match (pair(n[0], n[1]), pair(n[2], n[3])) {
            (Some((p, dp)), Some((q, dq))) => {
                if dq < dp {
                    q
                } else {
                    p
                }
            }
            (Some((p, _)), None) | (None, Some((p, _))) => p,
            // A 1-pixel image side: nothing around.
            (None, None) => self.last[i],
        };
        if self.renders[i] == 0 {
            return spatial;
        }
        let dq = n
            .iter()
            .flatten()
            .map(|&j| self.change(j))
            .fold(0.0, f32::max);
        let s = smoothstep(dq, DELTA_LOW, DELTA_HIGH);
        let q = self.last[i];
        if s == 0.0 {
            q
        } else {
            std::array::from_fn(|c| q[c] + s * (spatial[c] - q[c]))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(w: u32, h: u32, f: impl Fn(u32, u32) -> Rgba) -> Vec<Rgba> {
        (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .map(|(x, y)| f(x, y))
            .collect()
    }

    #[test]
    fn every_pixel_is_in_exactly_one_subframe() {
        for y in 0..4 {
            for x in 0..4 {
                assert_eq!((0..4).filter(|&k| in_subframe(x, y, k)).count(), 1);
            }
        }
        assert_eq!(subframe_of(9), 1);
    }

    #[test]
    fn a_static_view_converges_exactly_in_four_frames() {
        let (w, h) = (13, 9);
        let full = image(w, h, |x, y| {
            let v = ((x * 7 + y * 13) % 17) as f32 / 17.0;
            [v, v * 0.5, 1.0 - v, 0.5 + 0.5 * v]
        });
        let mut hist = ViewHistory::new(w, h);
        let mut outs = Vec::new();
        for f in 0..6 {
            outs.push(hist.update(subframe_of(f), &full));
        }
        assert_ne!(outs[0], full, "one sub-frame alone is an estimate");
        assert!(outs[3] == full && outs[5] == full, "not the full render");
    }

    #[test]
    fn a_change_is_followed_spatially_and_a_still_area_keeps_its_detail() {
        let (w, h) = (16, 16);
        let a = image(w, h, |x, _| if x < 8 { [1.0; 4] } else { [0.0; 4] });
        // The left half turns dark; the right half stays.
        let b = image(w, h, |x, _| if x < 8 { [0.2; 4] } else { [0.0; 4] });
        let mut hist = ViewHistory::new(w, h);
        for f in 0..8 {
            hist.update(subframe_of(f), &a);
        }
        let out = hist.update(subframe_of(8), &b);
        // Sub-frame 0 shows the change; their diagonal neighbours in the
        // left half follow it (their neighbours changed), not stale 1.0.
        let i = 3 * w as usize + 3;
        assert!(out[i][0] < 0.5, "{:?}", out[i]);
        // The right half is unchanged and exact.
        for y in 0..h {
            for x in 10..w {
                assert_eq!(out[(y * w + x) as usize], [0.0; 4]);
            }
        }
        // At most eight frames after the change the image is exactly b.
        let mut last = out;
        for f in 9..16 {
            last = hist.update(subframe_of(f), &b);
        }
        let wrong = last.iter().zip(&b).filter(|(p, q)| p != q).count();
        assert_eq!(wrong, 0, "{wrong} pixels differ from the full render");
    }

    #[test]
    fn invalidated_history_starts_from_the_spatial_estimate() {
        let (w, h) = (8, 8);
        let a = image(w, h, |_, _| [1.0; 4]);
        let b = image(w, h, |_, _| [0.25; 4]);
        let mut hist = ViewHistory::new(w, h);
        for f in 0..4 {
            hist.update(subframe_of(f), &a);
        }
        hist.invalidate();
        let out = hist.update(0, &b);
        assert!(
            out.iter().all(|p| *p == [0.25; 4]),
            "no pixel keeps the old image"
        );
    }

    #[test]
    fn odd_sizes_and_thin_images_have_no_gaps() {
        for (w, h) in [(1, 1), (1, 5), (5, 1), (2, 3), (7, 7)] {
            let full = image(w, h, |x, y| [x as f32, y as f32, 0.5, 1.0]);
            let mut hist = ViewHistory::new(w, h);
            for f in 0..4 {
                let out = hist.update(subframe_of(f), &full);
                assert!(out.iter().flatten().all(|v| v.is_finite()), "{w}×{h}");
            }
            let out = hist.update(0, &full);
            assert!(out == full, "{w}×{h}: not the full render");
        }
    }
}
