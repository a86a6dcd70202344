//! Macrocells (L12 §4.1): each brick's B³ core cut into C³ cells of M³
//! voxels, each with the range of the values that trilinear interpolation
//! anywhere inside it reads (its voxels and one more on every side). The
//! importer computes them from the brick as stored (the decoded values the
//! renderer interpolates) and appends them to the brick's blob (format 4),
//! two bytes a cell: the range as codes of the brick's own [min, max],
//! rounded outwards, so a decoded cell range always holds every value
//! interpolation there can give. The ray caster steps over the cells that
//! the transfer function leaves empty.

use super::layout::OVERLAP;

/// A decoded brick: its (B+4)³ values, x fastest, and its macrocell ranges
/// when the database stores them (format 4).
#[derive(Clone, Debug, PartialEq)]
pub struct Brick {
    pub values: Vec<f32>,
    /// C³ (lo, hi) data-value ranges, x fastest; lo > hi for a cell with no
    /// data at all.
    pub cells: Option<Vec<[f32; 2]>>,
    /// In a scene with registered layers, the same node's bricks of the
    /// layers (the loader reads them together); `None` otherwise.
    pub layered: Option<LayerBricks>,
}

/// A node's bricks of a scene's registered layers (`[[layer]]`), read with
/// the scene volume's.
#[derive(Clone, Debug, PartialEq)]
pub struct LayerBricks {
    /// Whether the brick's `values` are the scene volume's (false: only
    /// layers store this node, and `values` are zeros).
    pub main: bool,
    /// Each layer's (B+4)³ values where it stores the node.
    pub layers: Vec<Option<Vec<f32>>>,
}

impl LayerBricks {
    /// Which channels hold data: bit 0 the scene volume, bit k layer k.
    pub fn mask(&self) -> u32 {
        self.layers
            .iter()
            .enumerate()
            .filter(|(_, l)| l.is_some())
            .fold(self.main as u32, |m, (k, _)| m | 2 << k)
    }
}

impl Brick {
    /// Bytes the brick takes in memory.
    pub fn bytes(&self) -> u64 {
        let layers = self.layered.as_ref().map_or(0, |l| {
            l.layers
                .iter()
                .flatten()
                .map(|v| std::mem::size_of_val(v.as_slice()))
                .sum::<usize>()
        });
        (std::mem::size_of_val(self.values.as_slice())
            + layers
            + self
                .cells
                .as_ref()
                .map_or(0, |c| std::mem::size_of_val(c.as_slice()))) as u64
    }
}

/// The cell size for bricks of side `b`: 4 voxels, doubled until at most 8
/// cells per axis. Returns (cells per axis C, voxels per cell side M); C = 0
/// when M does not divide `b` (no macrocells).
pub fn layout(b: usize) -> (usize, usize) {
    let mut m = 4;
    while b / m > 8 {
        m *= 2;
    }
    if b >= m && b.is_multiple_of(m) {
        (b / m, m)
    } else {
        (0, m)
    }
}

/// Bytes of a brick's stored cell block.
pub fn stored_len(b: usize) -> usize {
    let (c, _) = layout(b);
    2 * c * c * c
}

/// The cell ranges of a brick of side `b` from its stored values
/// (`value(i)`: the data value of stored voxel i, `None` for no data).
pub fn ranges(b: usize, value: impl Fn(usize) -> Option<f64>) -> Vec<[f32; 2]> {
    let s = b + 2 * OVERLAP;
    // Rounding to f32 keeps the order, so the extremes are those of the
    // values as given.
    let values: Vec<f32> = (0..s * s * s)
        .map(|i| value(i).map_or(f32::NAN, |v| v as f32))
        .collect();
    ranges_of(b, &values)
}

/// The cell ranges of a brick of side `b` from its (b+4)³ stored values,
/// NaN for no data: a cell's [lo, hi] over the voxels interpolation inside
/// it reads, (+∞, −∞) where none has data. Separable: the extremes along x
/// of every row's cell spans, then along y of those, then along z, so each
/// stored value is read once (the cells' spans overlap by two voxels).
pub fn ranges_of(b: usize, values: &[f32]) -> Vec<[f32; 2]> {
    let (c, m) = layout(b);
    let s = b + 2 * OVERLAP;
    assert_eq!(values.len(), s * s * s, "a brick's stored values");
    // Interpolation at core coordinate u ∈ [k·M, (k+1)·M] (voxel centres at
    // i + ½) reads core voxels k·M − 1 … (k+1)·M, stored OVERLAP further on.
    let span = |k: usize| k * m + OVERLAP - 1..(k + 1) * m + OVERLAP + 1;
    // f32::min and max pass over NaN: voxels without data take no part.
    let none = [f32::INFINITY, f32::NEG_INFINITY];
    let widen = |e: &mut [f32; 2], o: [f32; 2]| {
        e[0] = e[0].min(o[0]);
        e[1] = e[1].max(o[1]);
    };
    // Along x: per row (z, y), per cell column cx.
    let mut rows = vec![none; s * s * c];
    for (row, out) in values.chunks_exact(s).zip(rows.chunks_exact_mut(c.max(1))) {
        for (cx, e) in out.iter_mut().enumerate().take(c) {
            for &v in &row[span(cx)] {
                widen(e, [v, v]);
            }
        }
    }
    // Along y: per slice z, per cell (cy, cx).
    let mut planes = vec![none; s * c * c];
    for z in 0..s {
        for cy in 0..c {
            let out = &mut planes[(z * c + cy) * c..(z * c + cy + 1) * c];
            for y in span(cy) {
                let r = &rows[(z * s + y) * c..(z * s + y + 1) * c];
                for (e, &o) in out.iter_mut().zip(r) {
                    widen(e, o);
                }
            }
        }
    }
    // Along z.
    let mut out = vec![none; c * c * c];
    for cz in 0..c {
        let cells = &mut out[cz * c * c..(cz + 1) * c * c];
        for z in span(cz) {
            for (e, &o) in cells.iter_mut().zip(&planes[z * c * c..(z + 1) * c * c]) {
                widen(e, o);
            }
        }
    }
    out
}

/// Codes of a range in the brick's [min, max]: 0..=255, rounded outwards;
/// (255, 0) for a cell without data.
pub fn encode(cells: &[[f32; 2]], min: f32, max: f32) -> Vec<u8> {
    let span = max as f64 - min as f64;
    let code = |v: f32, up: bool| -> u8 {
        if span <= 0.0 || !span.is_finite() {
            return 0;
        }
        let x = (v as f64 - min as f64) / span * 255.0;
        let r = if up { x.ceil() } else { x.floor() };
        r.clamp(0.0, 255.0) as u8
    };
    let mut out = Vec::with_capacity(2 * cells.len());
    for &[lo, hi] in cells {
        if lo > hi || lo.is_nan() || hi.is_nan() {
            out.extend_from_slice(&[255, 0]);
        } else {
            out.push(code(lo, false));
            out.push(code(hi, true));
        }
    }
    out
}

/// The ranges back in data values (each holding the range encoded).
pub fn decode(bytes: &[u8], min: f32, max: f32) -> Vec<[f32; 2]> {
    let span = max as f64 - min as f64;
    let value = |q: u8| (min as f64 + q as f64 / 255.0 * span) as f32;
    bytes
        .chunks_exact(2)
        .map(|p| {
            if p[0] > p[1] {
                [f32::INFINITY, f32::NEG_INFINITY]
            } else if p[1] == 255 {
                [value(p[0]), max]
            } else {
                [value(p[0]), value(p[1])]
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every cell's extremes read voxel by voxel over its span.
    fn brute(b: usize, values: &[f32]) -> Vec<[f32; 2]> {
        let (c, m) = layout(b);
        let s = b + 2 * OVERLAP;
        let span = |k: usize| k * m + OVERLAP - 1..=(k + 1) * m + OVERLAP;
        let mut out = Vec::new();
        for cz in 0..c {
            for cy in 0..c {
                for cx in 0..c {
                    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
                    for z in span(cz) {
                        for y in span(cy) {
                            for x in span(cx) {
                                let v = values[(z * s + y) * s + x];
                                if !v.is_nan() {
                                    lo = lo.min(v as f64);
                                    hi = hi.max(v as f64);
                                }
                            }
                        }
                    }
                    out.push([lo as f32, hi as f32]);
                }
            }
        }
        out
    }

    #[test]
    fn separable_ranges_equal_the_cell_by_cell_extremes() {
        for b in [4, 8, 16, 32, 64] {
            let s = b + 2 * OVERLAP;
            let hole = layout(b).1 + OVERLAP + 1;
            // Values with NaN (no data) scattered, and the first cell's
            // span all NaN.
            let values: Vec<f32> = (0..s * s * s)
                .map(|i| {
                    let (x, y, z) = (i % s, (i / s) % s, i / (s * s));
                    if (i * 2654435761usize).is_multiple_of(97)
                        || (x < hole && y < hole && z < hole)
                    {
                        f32::NAN
                    } else {
                        ((i * 7919) % 2003) as f32 * 0.37 - 300.0
                    }
                })
                .collect();
            let fast = ranges_of(b, &values);
            assert_eq!(fast, brute(b, &values), "b = {b}");
            assert!(fast[0][0] > fast[0][1], "b = {b}: the hole has no data");
        }
    }

    #[test]
    fn decoded_ranges_hold_the_values() {
        let b = 16;
        let s = b + 2 * OVERLAP;
        let values: Vec<f32> = (0..s * s * s)
            .map(|i| ((i * 7919) % 1000) as f32 * 0.37 - 50.0)
            .collect();
        let (min, max) = values
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &v| {
                (a.min(v), b.max(v))
            });
        let exact = ranges(b, |i| Some(values[i] as f64));
        assert_eq!(exact.len(), layout(b).0.pow(3));
        let stored = encode(&exact, min, max);
        assert_eq!(stored.len(), stored_len(b));
        let back = decode(&stored, min, max);
        let step = (max - min) / 255.0;
        for (e, d) in exact.iter().zip(&back) {
            assert!(d[0] <= e[0] && d[1] >= e[1], "{d:?} ⊉ {e:?}");
            assert!(e[0] - d[0] <= step * 1.001 && d[1] - e[1] <= step * 1.001);
        }
        // No data, a constant brick, and sides no cell size divides.
        let none = decode(
            &encode(&[[f32::INFINITY, f32::NEG_INFINITY]], 0.0, 1.0),
            0.0,
            1.0,
        );
        assert!(none[0][0] > none[0][1]);
        assert_eq!(
            decode(&encode(&[[3.0, 3.0]], 3.0, 3.0), 3.0, 3.0),
            [[3.0, 3.0]]
        );
        assert_eq!(layout(32), (8, 4));
        assert_eq!(layout(64), (8, 8));
        assert_eq!(layout(6), (0, 4));
        assert_eq!(stored_len(6), 0);
    }
}
