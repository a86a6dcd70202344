//! Streaming import of a volume into the octree database (G10 §5 "Data
//! preprocessing", G08 §3, L12 §4.1).
//!
//! The volume is read front to back one z-slice at a time. Each octree level
//! keeps a rolling window of B + 2·OVERLAP slices of its own voxel grid; as
//! soon as the window holds every slice a row of bricks needs (overlap
//! included), the row is cut into bricks, encoded in parallel and written.
//! Every pair of slices a level receives is averaged 2×2×2 into one slice of
//! the next coarser level (only along the axes that level halves: over thick
//! slices the levels above the source halve x and y alone, and every slice
//! goes up on its own), so all levels advance together and memory is
//! bounded by the windows: Σ_l (B+5)·nx_l·ny_l values, whatever the depth of
//! the volume. Nothing else of the volume is held.

use crate::store::cells;
use crate::store::codec::{self, BrickEncoding, Codec};
use crate::store::writer::NodeStats;
use crate::store::{Header, NodeKey, OctreeLayout, OctreeWriter, Summary, OVERLAP};
use crate::volume::VolumeSource;
use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use rayon::prelude::*;
use std::collections::VecDeque;
use std::path::Path;
use std::time::Instant;

#[derive(Clone, Debug)]
pub struct ImportOptions {
    /// Brick side B (voxels, overlap excluded).
    pub brick: usize,
    pub encoding: BrickEncoding,
    /// How bricks are compressed ([`Codec::DEFAULT`] unless told).
    pub codec: Codec,
    /// Drop bricks whose values (overlap included) are all below this.
    pub empty_below: Option<f32>,
    /// Memory the import may use for its slice windows and brick buffers.
    pub memory_mb: usize,
    /// Show a progress bar (only drawn when stderr is a terminal).
    pub progress: bool,
    /// Halve all three axes at every level, whatever the voxel spacing
    /// (the octree of formats 1–4; otherwise levels over thick slices halve
    /// only the finer axes, `OctreeLayout::for_spacing`).
    pub isotropic_levels: bool,
    /// A label volume: every voxel a whole label (0 to 2³²−1, or NaN for no
    /// data) and each coarser voxel one of the labels it covers, never an
    /// average ([`label_of`]); bricks are stored exactly and the summary
    /// lists the labels.
    pub labels: bool,
    /// Take the coarser levels the source file holds itself (an OME-Zarr
    /// pyramid) where they halve the volume as the octree does, instead of
    /// averaging the finer level (`--recompute-levels` turns it off); the
    /// report gives each one's difference to the average. Not for a label
    /// volume, whose coarser voxels are always import's choice of a label
    /// (a file's pyramid may have averaged its labels).
    pub pyramid: bool,
}

impl Default for ImportOptions {
    fn default() -> Self {
        ImportOptions {
            brick: 32,
            encoding: BrickEncoding::U8Range,
            codec: Codec::DEFAULT,
            empty_below: None,
            memory_mb: 2048,
            progress: false,
            isotropic_levels: false,
            labels: false,
            pyramid: true,
        }
    }
}

#[derive(Clone, Debug)]
pub struct ImportReport {
    pub nodes: usize,
    pub stored: usize,
    pub empty: usize,
    pub file_bytes: u64,
    pub source_bytes: u64,
    /// Voxels without data (NaN, imported with `--nan empty`).
    pub no_data_voxels: u64,
    pub seconds: f64,
    pub summary: Summary,
    /// The octree's levels taken from the file's own pyramid, finest first.
    pub pyramid: Vec<PyramidReuse>,
    /// The file's levels that were not taken, and why.
    pub pyramid_unused: Vec<String>,
}

/// An octree level taken from the source file's pyramid.
#[derive(Clone, Debug)]
pub struct PyramidReuse {
    /// The octree level, and the file's level it holds.
    pub level: u32,
    pub file_level: usize,
    /// How far the file's voxels lie from what import would have stored
    /// there, the average of the finer level's (as that level was stored):
    /// root mean square and largest difference, over the voxels where both
    /// have data.
    pub rms: f64,
    pub max: f64,
    pub voxels: u64,
}

/// A file level feeding an octree level's slices in place of the average.
struct FileFeed {
    file_level: usize,
    src: Box<dyn VolumeSource + Send>,
    sum_sq: f64,
    max: f64,
    voxels: u64,
}

impl FileFeed {
    /// The file's next slice, in place of `averaged` (the same slice as
    /// import averaged it), the two compared.
    fn take(&mut self, averaged: &[f32], z: usize, source_name: &str) -> Result<Vec<f32>> {
        let mut slice = vec![0f32; averaged.len()];
        self.src.read_slices(&mut slice).with_context(|| {
            format!(
                "{source_name}: resolution level {}: reading slice {z} (--recompute-levels averages the levels instead of reading them)",
                self.file_level
            )
        })?;
        let (sq, max, n) = slice
            .par_chunks(1 << 14)
            .zip(averaged.par_chunks(1 << 14))
            .map(|(f, a)| {
                let (mut sq, mut max, mut n) = (0f64, 0f64, 0u64);
                for (&f, &a) in f.iter().zip(a) {
                    let d = (f as f64 - a as f64).abs();
                    if !d.is_nan() {
                        sq += d * d;
                        max = max.max(d);
                        n += 1;
                    }
                }
                (sq, max, n)
            })
            .reduce(
                || (0.0, 0.0, 0),
                |x, y| (x.0 + y.0, x.1.max(y.1), x.2 + y.2),
            );
        self.sum_sq += sq;
        self.max = self.max.max(max);
        self.voxels += n;
        Ok(slice)
    }
}

/// The file's coarser levels that halve the volume as the octree does, each
/// matched to its octree level (the same voxel counts, and spacing in the
/// ratio of the octree's voxels to the source's), opened; and a line for
/// each level not taken.
fn plan_pyramid(
    src: &dyn VolumeSource,
    layout: &OctreeLayout,
    spacing: [f64; 3],
) -> (Vec<Option<FileFeed>>, Vec<String>) {
    let leaf = layout.leaf_level();
    let mut feeds: Vec<Option<FileFeed>> = (0..layout.levels).map(|_| None).collect();
    let mut unused = Vec::new();
    let levels = match src.pyramid() {
        Ok(l) => l,
        Err(e) => {
            // The level chosen reads; its coarser ones are averaged.
            unused.push(format!(
                "the file's coarser resolution levels cannot be read ({e:#}): they are averaged from the finer ones"
            ));
            Vec::new()
        }
    };
    for fl in levels {
        let matching = (0..leaf).find(|&l| {
            let scale = layout.voxel_scale(l);
            layout.level_dims(l) == fl.dims
                && (0..3).all(|a| {
                    let want = spacing[a] * scale[a] as f64;
                    (fl.spacing[a] - want).abs() <= 1e-3 * want
                })
        });
        match matching {
            Some(l) if feeds[l as usize].is_none() => match src.open_level(fl.index) {
                Ok(src) => {
                    feeds[l as usize] = Some(FileFeed {
                        file_level: fl.index,
                        src,
                        sum_sq: 0.0,
                        max: 0.0,
                        voxels: 0,
                    })
                }
                Err(e) => unused.push(format!(
                    "resolution level {} cannot be opened ({e:#}): its octree level is averaged from the finer one",
                    fl.index
                )),
            },
            _ => unused.push(format!(
                "resolution level {} ({}×{}×{} voxels of {}×{}×{}) is none of the octree's levels: they are averaged from the finer ones",
                fl.index,
                fl.dims[0],
                fl.dims[1],
                fl.dims[2],
                fl.spacing[0],
                fl.spacing[1],
                fl.spacing[2]
            )),
        }
    }
    (feeds, unused)
}

/// Bricks encoded together in one parallel batch (bounds the memory of
/// encoded-but-unwritten bricks).
const BATCH: usize = 64;

/// Imports `src` into the database `out` (written under a temporary name and
/// renamed when complete).
pub fn import(
    src: &mut (dyn VolumeSource + Send),
    out: &Path,
    source_name: &str,
    opts: &ImportOptions,
) -> Result<ImportReport> {
    let start = Instant::now();
    let info = src.info().clone();
    let world = src.world();
    if !(4..=256).contains(&opts.brick) {
        bail!(
            "--brick {}: the brick size must be between 4 and 256",
            opts.brick
        );
    }
    if let Some(t) = opts.empty_below {
        if !t.is_finite() {
            bail!("--empty-below {t}: must be a finite value");
        }
    }
    let layout = if opts.isotropic_levels {
        OctreeLayout::new(info.dims, opts.brick)
    } else {
        OctreeLayout::for_spacing(info.dims, opts.brick, info.spacing)
    };
    let (feeds, pyramid_unused) = if opts.pyramid && !opts.labels {
        plan_pyramid(&*src, &layout, info.spacing)
    } else {
        ((0..layout.levels).map(|_| None).collect(), Vec::new())
    };
    let need = memory_needed(&layout)
        .saturating_add(src.buffer_bytes())
        .saturating_add(feeds.iter().flatten().map(|f| f.src.buffer_bytes()).sum());
    if need > opts.memory_mb as u64 * (1 << 20) {
        bail!(
            "{source_name}: --memory-mb {}: importing {}×{}×{} with {}³ bricks needs at least {} MiB \
             (slice windows of every level, and what the source and its reused levels buffer); raise --memory-mb",
            opts.memory_mb,
            info.dims[0],
            info.dims[1],
            info.dims[2],
            opts.brick,
            need.div_ceil(1 << 20)
        );
    }
    let header = Header {
        info: info.clone(),
        layout,
        encoding: opts.encoding,
        empty_below: opts.empty_below,
        source: source_name.to_string(),
    };
    let mut writer = OctreeWriter::create(out, &header)?;
    let mut levels: Vec<Level> = (0..layout.levels).map(|l| Level::new(&layout, l)).collect();
    let mut sink = Sink {
        source_name,
        feeds,
        writer: &mut writer,
        layout,
        opts,
        stored: 0,
        empty: 0,
        quant_sq: 0.0,
        quant_max: 0.0,
        quant_n: 0,
        inexact: None,
    };

    let bar = if opts.progress {
        ProgressBar::with_draw_target(Some(info.dims[2] as u64), ProgressDrawTarget::stderr())
    } else {
        ProgressBar::hidden()
    };
    bar.set_style(
        ProgressStyle::with_template("importing {bar:40} {pos}/{len} slices ({eta} left)").unwrap(),
    );

    let (mut vmin, mut vmax) = (f32::INFINITY, f32::NEG_INFINITY);
    let mut no_data = 0u64;
    let mut labels = std::collections::BTreeSet::new();
    let leaf = layout.leaf_level() as usize;
    // The source is read on a thread of its own, PREFETCH slices ahead, so
    // that reading and decoding the input overlap the levels' averaging
    // and the bricks' encoding (docs/performance.md "Import").
    let (nz, slice_len) = (info.dims[2], info.slice_len());
    std::thread::scope(|scope| -> Result<()> {
        let (tx, rx) = std::sync::mpsc::sync_channel::<Result<Vec<f32>>>(PREFETCH);
        scope.spawn(move || {
            for z in 0..nz {
                let mut slice = vec![0f32; slice_len];
                let read = src
                    .read_slices(&mut slice)
                    .map(|_| slice)
                    .with_context(|| format!("{source_name}: reading slice {z}"));
                let failed = read.is_err();
                // The importer stops taking slices when it fails.
                if tx.send(read).is_err() || failed {
                    break;
                }
            }
        });
        for z in 0..nz {
            let slice = rx
                .recv()
                .map_err(|_| anyhow::anyhow!("{source_name}: the reader stopped"))??;
            let (lo, hi, nan) = slice_stats(&slice);
            vmin = vmin.min(lo);
            vmax = vmax.max(hi);
            no_data += nan;
            if opts.labels {
                slice_labels(&slice, info.dims, z, &mut labels)
                    .with_context(|| format!("{source_name}: --labels"))?;
            }
            push_slice(&mut levels, leaf, slice, &mut sink)?;
            bar.inc(1);
        }
        Ok(())
    })?;
    // Flush from the finest level up: each level's last odd slice feeds its
    // parent before the parent emits its final rows.
    for l in (0..=leaf).rev() {
        while levels[l].next_row < levels[l].bricks[2] {
            emit_row(&mut levels[l], &mut sink)?;
        }
        if let Some(half) = levels[l].pending.take() {
            if l > 0 {
                push_slice(&mut levels, l - 1, half, &mut sink)?;
            }
        }
    }
    bar.finish_and_clear();
    if let Some(key) = sink.inexact {
        bail!(
            "{source_name}: --labels: brick {key} spans more labels than --quantize {} stores exactly; import with --quantize none",
            opts.encoding.name()
        );
    }

    let summary = Summary {
        value_min: vmin,
        value_max: vmax,
        quant_rms: if sink.quant_n > 0 {
            (sink.quant_sq / sink.quant_n as f64).sqrt()
        } else {
            0.0
        },
        quant_max: sink.quant_max,
        quant_samples: sink.quant_n,
        labels: opts.labels.then(|| labels.into_iter().collect()),
        world,
    };
    let (stored, empty) = (sink.stored, sink.empty);
    let pyramid = sink
        .feeds
        .iter()
        .enumerate()
        .rev()
        .filter_map(|(level, feed)| {
            feed.as_ref().map(|f| PyramidReuse {
                level: level as u32,
                file_level: f.file_level,
                rms: (f.sum_sq / f.voxels.max(1) as f64).sqrt(),
                max: f.max,
                voxels: f.voxels,
            })
        })
        .collect();
    let file_bytes = writer.finish(summary.clone())?;
    Ok(ImportReport {
        nodes: stored + empty,
        stored,
        empty,
        file_bytes,
        source_bytes: info.source_bytes(),
        no_data_voxels: no_data,
        seconds: start.elapsed().as_secs_f64(),
        summary,
        pyramid,
        pyramid_unused,
    })
}

/// Bytes the slice windows and brick batches take at most.
/// A slice's smallest and largest value (NaN aside) and its NaN count, in
/// eight lanes the compiler vectorises (`f32::min` per value, which must
/// pass over NaN, was an eighth of an import's time, all of it on the one
/// thread that feeds the others).
fn slice_stats(values: &[f32]) -> (f32, f32, u64) {
    // Blocks on every core; min, max and a count are the same in any order.
    values.par_chunks(1 << 16).map(block_stats).reduce(
        || (f32::INFINITY, f32::NEG_INFINITY, 0),
        |a, b| (a.0.min(b.0), a.1.max(b.1), a.2 + b.2),
    )
}

fn block_stats(values: &[f32]) -> (f32, f32, u64) {
    const L: usize = 8;
    let mut lo = [f32::INFINITY; L];
    let mut hi = [f32::NEG_INFINITY; L];
    let mut nan = [0u32; L];
    let chunks = values.chunks_exact(L);
    let rest = chunks.remainder();
    for c in chunks {
        for k in 0..L {
            let v = c[k];
            // A comparison with NaN is false: NaN never becomes an extreme.
            lo[k] = if v < lo[k] { v } else { lo[k] };
            hi[k] = if v > hi[k] { v } else { hi[k] };
            nan[k] += v.is_nan() as u32;
        }
    }
    let (mut l, mut h, mut n) = (f32::INFINITY, f32::NEG_INFINITY, 0u64);
    for k in 0..L {
        l = l.min(lo[k]);
        h = h.max(hi[k]);
        n += nan[k] as u64;
    }
    for &v in rest {
        l = l.min(v);
        h = h.max(v);
        n += v.is_nan() as u64;
    }
    (l, h, n)
}

/// Slices the reader thread may have read ahead of the import.
const PREFETCH: usize = 2;

pub fn memory_needed(layout: &OctreeLayout) -> u64 {
    // Saturating: a layout past every machine's memory says so, not wraps.
    let window = (layout.brick + 2 * OVERLAP + 1) as u64;
    let slices: u64 = (0..layout.levels)
        .map(|l| {
            let d = layout.level_dims(l);
            let slice = (d[0] as u64).saturating_mul(d[1] as u64);
            // window of full slices + one pending half-resolution slice
            window
                .saturating_mul(slice)
                .saturating_add(slice / 4)
                .saturating_mul(4)
        })
        .fold(0u64, u64::saturating_add);
    let batch = (BATCH as u64)
        .saturating_mul(layout.stored_len() as u64)
        .saturating_mul(8);
    // The slices read ahead, and the one being read.
    let d = layout.level_dims(layout.leaf_level());
    let ahead = (PREFETCH as u64 + 1)
        .saturating_mul(d[0] as u64)
        .saturating_mul(d[1] as u64)
        .saturating_mul(4);
    slices.saturating_add(batch).saturating_add(ahead)
}

/// One level's rolling window of slices.
struct Level {
    level: u32,
    dims: [usize; 3],
    bricks: [usize; 3],
    brick: usize,
    /// Consecutive slices; `slices[0]` has index `first`.
    slices: VecDeque<Vec<f32>>,
    first: usize,
    received: usize,
    next_row: usize,
    /// The x–y average of an unpaired slice, waiting for its z partner.
    pending: Option<Vec<f32>>,
    /// The axes the level above has half as many voxels along.
    halve: [bool; 3],
}

impl Level {
    fn new(layout: &OctreeLayout, level: u32) -> Self {
        Level {
            level,
            dims: layout.level_dims(level),
            bricks: layout.level_bricks(level),
            brick: layout.brick,
            slices: VecDeque::new(),
            first: 0,
            received: 0,
            next_row: 0,
            pending: None,
            halve: layout.split(level),
        }
    }

    /// The last slice index row `r` needs (its top overlap, clamped).
    fn last_needed(&self, r: usize) -> usize {
        ((r + 1) * self.brick + OVERLAP - 1).min(self.dims[2] - 1)
    }

    fn slice(&self, z: i64) -> &[f32] {
        let z = z.clamp(0, self.dims[2] as i64 - 1) as usize;
        &self.slices[z - self.first]
    }

    /// Gathers a brick's (B+4)³ values, clamping indices to the grid (the
    /// field is clamped to the edge voxels, docs/design.md).
    fn gather(&self, bx: usize, by: usize, r: usize, side: usize) -> Vec<f32> {
        let [nx, ny, _] = self.dims;
        let b = self.brick as i64;
        let o = OVERLAP as i64;
        let (x0, y0, z0) = (bx as i64 * b - o, by as i64 * b - o, r as i64 * b - o);
        let mut out = Vec::with_capacity(side * side * side);
        let inside_x = x0 >= 0 && x0 as usize + side <= nx;
        for zz in 0..side as i64 {
            let s = self.slice(z0 + zz);
            for yy in 0..side as i64 {
                let y = (y0 + yy).clamp(0, ny as i64 - 1) as usize;
                let row = &s[y * nx..(y + 1) * nx];
                if inside_x {
                    out.extend_from_slice(&row[x0 as usize..x0 as usize + side]);
                } else {
                    out.extend(
                        (0..side as i64).map(|xx| row[(x0 + xx).clamp(0, nx as i64 - 1) as usize]),
                    );
                }
            }
        }
        out
    }
}

/// Where finished bricks go, with the running figures of the import.
struct Sink<'a> {
    source_name: &'a str,
    /// Per level, the source file's own level that replaces the average.
    feeds: Vec<Option<FileFeed>>,
    writer: &'a mut OctreeWriter,
    layout: OctreeLayout,
    opts: &'a ImportOptions,
    stored: usize,
    empty: usize,
    quant_sq: f64,
    quant_max: f64,
    quant_n: u64,
    /// Label import: the first brick whose encoding changed a label.
    inexact: Option<NodeKey>,
}

/// Checks that a source slice (`z`) of a label volume holds whole labels,
/// and adds them to `labels`.
fn slice_labels(
    slice: &[f32],
    dims: [usize; 3],
    z: usize,
    labels: &mut std::collections::BTreeSet<u32>,
) -> Result<()> {
    let bad = slice
        .par_iter()
        .position_first(|&v| !v.is_nan() && !whole_label(v));
    if let Some(i) = bad {
        bail!(
            "voxel ({}, {}, {z}) holds {}, which is not a label (labels are whole numbers from 0 to {}; a fraction is an uncertain label)",
            i % dims[0],
            i / dims[0],
            slice[i],
            u32::MAX
        );
    }
    let found = slice
        .par_chunks(1 << 16)
        .map(|c| {
            let mut set = std::collections::BTreeSet::new();
            let mut last = f32::NAN;
            for &v in c {
                // Runs of one label are the rule: skip the set when unchanged.
                if v != last && !v.is_nan() {
                    set.insert(v as u32);
                    last = v;
                }
            }
            set
        })
        .reduce(std::collections::BTreeSet::new, |mut a, b| {
            a.extend(b);
            a
        });
    labels.extend(found);
    if labels.len() > crate::store::MAX_LABELS {
        bail!(
            "more than {} distinct labels by slice {z}: not a label volume",
            crate::store::MAX_LABELS
        );
    }
    Ok(())
}

/// A value that is a label: a whole number from 0 to 2³²−1.
fn whole_label(v: f32) -> bool {
    (0.0..=u32::MAX as f32).contains(&v) && v.fract() == 0.0
}

/// What a coarser voxel of a label volume holds, of the labels `taps` it
/// covers (NaN: no data): the most frequent label other than 0 (the
/// background) where there is one, the smallest on a tie; else 0 where a
/// tap is 0; else NaN. A label is never averaged into another, and a thin
/// structure stays visible in the coarser levels rather than vanishing
/// into the background.
pub fn label_of(taps: &[f32]) -> f32 {
    let mut best = f32::NAN;
    let mut best_n = 0;
    let mut background = false;
    for (i, &v) in taps.iter().enumerate() {
        if v.is_nan() {
            continue;
        }
        if v == 0.0 {
            background = true;
            continue;
        }
        let n = taps[i..].iter().filter(|&&w| w == v).count();
        let earlier = taps[..i].contains(&v);
        if !earlier && (n > best_n || (n == best_n && v < best)) {
            best = v;
            best_n = n;
        }
    }
    if best_n > 0 {
        best
    } else if background {
        0.0
    } else {
        f32::NAN
    }
}

fn push_slice(levels: &mut [Level], l: usize, slice: Vec<f32>, sink: &mut Sink) -> Result<()> {
    let slice = match sink.feeds[l].as_mut() {
        Some(f) => f.take(&slice, levels[l].received, sink.source_name)?,
        None => slice,
    };
    let parent_slice = {
        let lv = &mut levels[l];
        let [hx, hy, hz] = lv.halve;
        let labels = sink.opts.labels;
        let half = (l > 0).then(|| halve_xy(&slice, lv.dims[0], lv.dims[1], hx, hy, labels));
        lv.slices.push_back(slice);
        lv.received += 1;
        while lv.next_row < lv.bricks[2] && lv.received > lv.last_needed(lv.next_row) {
            emit_row(lv, sink)?;
        }
        match (half, lv.pending.take()) {
            (Some(h), _) if !hz => Some(h),
            (Some(h), Some(p)) => Some(
                p.par_iter()
                    .zip(h.par_iter())
                    .map(|(&a, &b)| {
                        if labels {
                            label_of(&[a, b])
                        } else {
                            mean2(a, b)
                        }
                    })
                    .collect(),
            ),
            (Some(h), None) => {
                lv.pending = Some(h);
                None
            }
            (None, _) => None,
        }
    };
    if let Some(ps) = parent_slice {
        push_slice(levels, l - 1, ps, sink)?;
    }
    Ok(())
}

/// The mean of two voxels, of the one that has data when the other is NaN
/// (no data), NaN when neither has.
fn mean2(a: f32, b: f32) -> f32 {
    match (a.is_nan(), b.is_nan()) {
        (false, false) => 0.5 * (a + b),
        (true, _) => b,
        (false, true) => a,
    }
}

/// 2×2 average of a slice in x and y (2×1, 1×2 or a copy where only one
/// or neither is halved); at an odd edge the average is over the voxels that
/// exist, and no-data (NaN) voxels are left out of it (NaN only where all
/// four are). Of a label volume (`labels`), [`label_of`] the voxels instead.
fn halve_xy(
    s: &[f32],
    nx: usize,
    ny: usize,
    halve_x: bool,
    halve_y: bool,
    labels: bool,
) -> Vec<f32> {
    let pair = |i: usize, n: usize, halve: bool| {
        if halve {
            (2 * i, (2 * i + 1).min(n - 1))
        } else {
            (i, i)
        }
    };
    let hx = if halve_x { nx.div_ceil(2) } else { nx };
    let hy = if halve_y { ny.div_ceil(2) } else { ny };
    let mut out = vec![0f32; hx * hy];
    // Rows in parallel (each output voxel is computed alone: the same
    // values in any order).
    out.par_chunks_mut(hx).enumerate().for_each(|(j, row)| {
        let (y0, y1) = pair(j, ny, halve_y);
        for (i, o) in row.iter_mut().enumerate() {
            let (x0, x1) = pair(i, nx, halve_x);
            let mut taps = [f32::NAN; 4];
            taps[0] = s[y0 * nx + x0];
            if x1 != x0 {
                taps[1] = s[y0 * nx + x1];
            }
            if y1 != y0 {
                taps[2] = s[y1 * nx + x0];
                if x1 != x0 {
                    taps[3] = s[y1 * nx + x1];
                }
            }
            if labels {
                *o = label_of(&taps);
                continue;
            }
            let (sum, n) = taps
                .iter()
                .filter(|v| !v.is_nan())
                .fold((0f32, 0f32), |(s, n), &v| (s + v, n + 1.0));
            *o = if n > 0.0 { sum / n } else { f32::NAN };
        }
    });
    out
}

struct Encoded {
    key: NodeKey,
    stats: NodeStats,
    bytes: Option<Vec<u8>>,
    quant_sq: f64,
    quant_max: f64,
    quant_n: u64,
    /// A label brick whose encoding changed a value.
    inexact: bool,
}

/// Cuts row `lv.next_row` into bricks, encodes and writes them, and drops the
/// slices no later row needs.
fn emit_row(lv: &mut Level, sink: &mut Sink) -> Result<()> {
    let r = lv.next_row;
    let side = sink.layout.stored_side();
    let leaf = lv.level == sink.layout.leaf_level();
    let columns: Vec<(usize, usize)> = (0..lv.bricks[1])
        .flat_map(|by| (0..lv.bricks[0]).map(move |bx| (bx, by)))
        .collect();
    for batch in columns.chunks(BATCH) {
        let lvr = &*lv;
        let opts = sink.opts;
        let encoded: Vec<Encoded> = batch
            .par_iter()
            .map(|&(bx, by)| encode_brick(lvr, bx, by, r, side, leaf, opts))
            .collect();
        for e in encoded {
            match &e.bytes {
                Some(b) => {
                    sink.stored += 1;
                    sink.writer.add(e.key, e.stats, Some(b))?;
                }
                None => {
                    sink.empty += 1;
                    sink.writer.add(e.key, e.stats, None)?;
                }
            }
            sink.quant_sq += e.quant_sq;
            sink.quant_max = sink.quant_max.max(e.quant_max);
            sink.quant_n += e.quant_n;
            if e.inexact && sink.inexact.is_none() {
                sink.inexact = Some(e.key);
            }
        }
    }
    lv.next_row += 1;
    let keep_from = (lv.next_row * lv.brick).saturating_sub(OVERLAP);
    while lv.first < keep_from && lv.slices.len() > 1 {
        lv.slices.pop_front();
        lv.first += 1;
    }
    Ok(())
}

fn encode_brick(
    lv: &Level,
    bx: usize,
    by: usize,
    r: usize,
    side: usize,
    leaf: bool,
    opts: &ImportOptions,
) -> Encoded {
    let key = NodeKey::new(lv.level as u8, bx as u32, by as u32, r as u32);
    let values = lv.gather(bx, by, r, side);
    let (min, max) = codec::value_range(&values);
    // Mean and variance over the node's own voxels inside the volume.
    let b = lv.brick;
    let own = |n: usize, o: usize| OVERLAP..OVERLAP + b.min(n - o * b);
    let (rx, ry, rz) = (own(lv.dims[0], bx), own(lv.dims[1], by), own(lv.dims[2], r));
    let (mut sum, mut sq, mut n) = (0f64, 0f64, 0u64);
    for z in rz.clone() {
        for y in ry.clone() {
            for &v in &values[(z * side + y) * side + rx.start..(z * side + y) * side + rx.end] {
                if !v.is_nan() {
                    sum += v as f64;
                    sq += v as f64 * v as f64;
                    n += 1;
                }
            }
        }
    }
    let mean = if n > 0 { sum / n as f64 } else { 0.0 };
    let variance = (sq / n as f64 - mean * mean).max(0.0);
    // No data at all: recorded as [0, 0] and not stored.
    let (min, max, no_data) = if min > max {
        (0.0, 0.0, true)
    } else {
        (min, max, false)
    };
    let stats = NodeStats {
        min,
        max,
        mean: mean as f32,
        variance: variance as f32,
    };
    // A brick with no data at all (every value NaN: min > max) is never
    // stored, so never loaded.
    let empty = no_data || opts.empty_below.is_some_and(|t| max < t);
    let mut e = Encoded {
        key,
        stats,
        bytes: None,
        quant_sq: 0.0,
        quant_max: 0.0,
        quant_n: 0,
        inexact: false,
    };
    if empty {
        return e;
    }
    // What the renderer will interpolate: the values as decoded.
    let (mut bytes, decoded) = codec::encode_decoded(&values, min, max, opts.encoding, opts.codec);
    // Its macrocell ranges follow the encoded values (format 4).
    let seen = decoded.as_deref().unwrap_or(&values);
    // A label stored as another would be drawn as another.
    e.inexact = opts.labels
        && seen
            .iter()
            .zip(&values)
            .any(|(d, v)| d.to_bits() != v.to_bits() && !(d.is_nan() && v.is_nan()));
    let cell_ranges = cells::ranges_of(b, seen);
    bytes.extend_from_slice(&cells::encode(&cell_ranges, min, max));
    if let (true, Some(decoded)) = (leaf, &decoded) {
        // Measure the quantisation error on the source voxels this brick owns,
        // through the same decoder the renderer uses.
        for z in rz {
            for y in ry.clone() {
                for x in rx.clone() {
                    let i = (z * side + y) * side + x;
                    let d = (values[i] as f64 - decoded[i] as f64).abs();
                    if d.is_nan() {
                        continue;
                    }
                    e.quant_sq += d * d;
                    e.quant_max = e.quant_max.max(d);
                    e.quant_n += 1;
                }
            }
        }
    } else if leaf {
        e.quant_n = n;
    }
    e.bytes = Some(bytes);
    e
}
