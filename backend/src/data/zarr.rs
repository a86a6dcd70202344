//! OME-Zarr (NGFF 0.4 on Zarr v2, NGFF 0.5 on Zarr v3) and plain Zarr
//! arrays, read with the `zarrs` crate: the codecs microscopy writers use
//! (blosc, zstd, gzip, sharding, transpose), chunks decoded in parallel.
//!
//! An OME-Zarr image is a group whose `multiscales` metadata (`.zattrs` in
//! v2, `attributes.ome` of `zarr.json` in v3) lists its axes (`t`, `c`, then
//! the space axes `z`, `y`, `x`), their units, and its resolution levels,
//! each an array with a `scale` transform. One 3-D volume is chosen from it:
//! level 0 unless `--level`, channel and time point 0 unless `--channel` /
//! `--time` (what was chosen out of how many is said). Its spacing is the
//! level's scale on the space axes (times the image's own scale, where the
//! metadata has one), in the axes' unit, which the import names: a transfer
//! function's extinction is per that unit. The translation does not place
//! the volume (the scene does, docs/design.md "Volume space").
//!
//! Reading streams along z, one row of chunks at a time (every chunk whose
//! z range holds the next slices, decoded on all cores), so memory holds one
//! slab of the chunks' depth, not the volume. A chunk that fails to decode
//! is an error naming the file, the array, the chunk and its key; a missing
//! chunk takes the array's fill value (Zarr's rule) and the import says how
//! many there were, once.

use std::path::Path;
use std::sync::Arc;

use anyhow::{anyhow, bail, ensure, Context, Result};
use rayon::prelude::*;
use serde_json::Value;
use zarrs::array::Array;
use zarrs::filesystem::FilesystemStore;

use super::{check_finite, check_info, Rounding};
use crate::volume::{FileLevel, VolumeInfo, VolumeSource, VoxelType};

/// Which volume of an OME-Zarr image to read (`--level`, `--channel`,
/// `--time`); `None` is the first.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ZarrSelect {
    pub level: Option<usize>,
    pub channel: Option<usize>,
    pub time: Option<usize>,
}

/// Whether `path` is a Zarr hierarchy or array (a folder with Zarr v3's
/// `zarr.json` or v2's `.zgroup`, `.zattrs` or `.zarray`).
pub fn is_zarr(path: &Path) -> bool {
    path.is_dir()
        && ["zarr.json", ".zgroup", ".zattrs", ".zarray"]
            .iter()
            .any(|f| path.join(f).is_file())
}

/// One axis of the array, outermost first.
#[derive(Clone, Debug)]
struct Axis {
    name: String,
    /// "space", "time", "channel", or another type (or none).
    kind: Option<String>,
    unit: Option<String>,
}

/// What the metadata says about the chosen array.
struct Chosen {
    /// The array's path in the hierarchy ("" for a plain array at the root).
    path: String,
    axes: Vec<Axis>,
    /// Scale per axis (1 where the metadata gives none).
    scale: Vec<f64>,
    /// "OME-Zarr (NGFF 0.4, Zarr v2), level 0 of 3" and the like.
    what: String,
    /// The image's resolution levels (1 for a plain array).
    levels: usize,
}

/// A Zarr array's volume, read slab by slab along z.
pub struct ZarrSource {
    label: String,
    /// Where it was opened, what was chosen, and the image's levels: for
    /// the coarser levels import reuses (`VolumeSource::pyramid`).
    path: std::path::PathBuf,
    sel: ZarrSelect,
    levels: usize,
    /// The spacing the metadata gives this level (before `--spacing`).
    meta_spacing: [f64; 3],
    /// The length of the image's time axis (1 without one).
    time_points: usize,
    array_label: String,
    info: VolumeInfo,
    array: Array<FilesystemStore>,
    /// The fixed index of each non-space axis (time, channel), in array
    /// order; the last three axes are z, y, x.
    fixed: Vec<u64>,
    /// Chunk shape (a regular grid).
    chunk: Vec<u64>,
    /// The decoded slab: slices `slab_z0 ..` of the volume, x fastest, in
    /// the samples' own type (u64 words: aligned for every type).
    slab: Vec<u64>,
    slab_z0: usize,
    slab_len: usize,
    next: usize,
    missing: u64,
    chunks_read: u64,
    rounding: Rounding,
    nan_empty: bool,
    note: String,
}

fn read_json(path: &Path) -> Result<Value> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("{}: cannot read", path.display()))?;
    serde_json::from_str(&text).with_context(|| format!("{}: not valid JSON", path.display()))
}

/// `v[key]` as an array, or an error naming the field.
fn field_array<'a>(v: &'a Value, key: &str, at: &str) -> Result<&'a Vec<Value>> {
    v.get(key)
        .ok_or_else(|| anyhow!("{at}.{key} is missing"))?
        .as_array()
        .ok_or_else(|| anyhow!("{at}.{key} is not a list"))
}

fn parse_axes(ms: &Value, at: &str) -> Result<Vec<Axis>> {
    let list = field_array(ms, "axes", at)?;
    list.iter()
        .enumerate()
        .map(|(i, a)| match a {
            // NGFF 0.3 listed axes by name.
            Value::String(s) => Ok(Axis {
                name: s.clone(),
                kind: None,
                unit: None,
            }),
            Value::Object(o) => Ok(Axis {
                name: o
                    .get("name")
                    .and_then(Value::as_str)
                    .ok_or_else(|| anyhow!("{at}.axes[{i}].name is missing"))?
                    .to_string(),
                kind: o.get("type").and_then(Value::as_str).map(str::to_string),
                unit: o.get("unit").and_then(Value::as_str).map(str::to_string),
            }),
            _ => bail!("{at}.axes[{i}] is neither a name nor an object"),
        })
        .collect()
}

/// The `scale` of a list of coordinate transformations (NGFF: at most one
/// scale, then at most one translation), checked against `n` axes; `None`
/// where the list has none.
fn parse_scale(transforms: Option<&Value>, n: usize, at: &str) -> Result<Option<Vec<f64>>> {
    let Some(list) = transforms else {
        return Ok(None);
    };
    let list = list
        .as_array()
        .ok_or_else(|| anyhow!("{at}.coordinateTransformations is not a list"))?;
    let mut scale = None;
    for (i, t) in list.iter().enumerate() {
        let here = format!("{at}.coordinateTransformations[{i}]");
        match t.get("type").and_then(Value::as_str) {
            Some("scale") => {
                if t.get("path").is_some() {
                    bail!("{here}: a scale stored in a separate array (\"path\") is not supported");
                }
                let v = field_array(t, "scale", &here)?;
                ensure!(
                    v.len() == n,
                    "{here}.scale has {} values for {n} axes (inconsistent metadata)",
                    v.len()
                );
                let s: Vec<f64> = v
                    .iter()
                    .enumerate()
                    .map(|(a, x)| {
                        x.as_f64()
                            .ok_or_else(|| anyhow!("{here}.scale[{a}] is not a number"))
                    })
                    .collect::<Result<_>>()?;
                scale = Some(s);
            }
            Some("translation") | Some("identity") => {}
            Some(other) => bail!("{here}: transformation type \"{other}\" is not supported"),
            None => bail!("{here}.type is missing"),
        }
    }
    Ok(scale)
}

/// Reads the hierarchy's metadata and chooses the array `sel` names.
fn choose(root: &Path, label: &str, sel: &ZarrSelect) -> Result<Chosen> {
    let (attrs, format, node_is_array) = if root.join("zarr.json").is_file() {
        let meta = read_json(&root.join("zarr.json"))?;
        let node = meta.get("node_type").and_then(Value::as_str).unwrap_or("");
        let attrs = meta.get("attributes").cloned().unwrap_or(Value::Null);
        (attrs, "Zarr v3", node == "array")
    } else {
        let attrs = if root.join(".zattrs").is_file() {
            read_json(&root.join(".zattrs"))?
        } else {
            Value::Null
        };
        (attrs, "Zarr v2", root.join(".zarray").is_file())
    };
    // NGFF 0.5 keeps its metadata under "ome"; 0.4 at the top.
    let (ngff, version) = match attrs.get("ome") {
        Some(ome) => (
            ome.clone(),
            ome.get("version")
                .and_then(Value::as_str)
                .map(str::to_string),
        ),
        None => (attrs.clone(), None),
    };
    let Some(multiscales) = ngff.get("multiscales") else {
        if node_is_array {
            // A plain array: its last three axes are z, y, x.
            for (i, s) in [sel.level, sel.channel, sel.time].iter().enumerate() {
                if s.is_some_and(|v| v > 0) {
                    let flag = ["--level", "--channel", "--time"][i];
                    bail!("{label}: a plain Zarr array without OME-Zarr multiscales metadata has no {flag} to choose");
                }
            }
            return Ok(Chosen {
                path: String::new(),
                axes: Vec::new(),
                scale: Vec::new(),
                what: format!("a plain {format} array (no OME-Zarr metadata: spacing 1, 1, 1 unless --spacing)"),
                levels: 1,
            });
        }
        bail!("{label}: a Zarr group without OME-Zarr \"multiscales\" metadata (and not an array): nothing to import");
    };
    let multiscales = multiscales
        .as_array()
        .filter(|m| !m.is_empty())
        .ok_or_else(|| anyhow!("{label}: multiscales is not a non-empty list"))?;
    let at = "multiscales[0]";
    let ms = &multiscales[0];
    let version = version.or_else(|| {
        ms.get("version")
            .and_then(Value::as_str)
            .map(str::to_string)
    });
    let axes = parse_axes(ms, at).with_context(|| label.to_string())?;
    let n = axes.len();
    ensure!(
        (3..=5).contains(&n),
        "{label}: {at}.axes has {n} axes; a volume needs 3 space axes (and at most a time and a channel axis)"
    );
    let datasets = field_array(ms, "datasets", at).with_context(|| label.to_string())?;
    ensure!(!datasets.is_empty(), "{label}: {at}.datasets is empty");
    let level = sel.level.unwrap_or(0);
    ensure!(
        level < datasets.len(),
        "{label}: --level {level}: the image has {} resolution levels (0 to {})",
        datasets.len(),
        datasets.len() - 1
    );
    let ds_at = format!("{at}.datasets[{level}]");
    let ds = &datasets[level];
    let path = ds
        .get("path")
        .and_then(Value::as_str)
        .ok_or_else(|| anyhow!("{label}: {ds_at}.path is missing"))?
        .to_string();
    let mut scale = parse_scale(ds.get("coordinateTransformations"), n, &ds_at)
        .with_context(|| label.to_string())?
        .unwrap_or_else(|| vec![1.0; n]);
    if let Some(global) = parse_scale(ms.get("coordinateTransformations"), n, at)
        .with_context(|| label.to_string())?
    {
        for (s, g) in scale.iter_mut().zip(global) {
            *s *= g;
        }
    }
    let what = format!(
        "OME-Zarr (NGFF {}, {format}), level {level} of {} (array \"{path}\")",
        version.as_deref().unwrap_or("?"),
        datasets.len()
    );
    Ok(Chosen {
        path,
        axes,
        scale,
        what,
        levels: datasets.len(),
    })
}

/// The sample type of a Zarr data type name (v3's, or v2's as zarrs reads
/// it).
fn voxel_type(name: &str) -> Option<VoxelType> {
    Some(match name {
        "uint8" => VoxelType::U8,
        "int8" => VoxelType::I8,
        "uint16" => VoxelType::U16,
        "int16" => VoxelType::I16,
        "uint32" => VoxelType::U32,
        "int32" => VoxelType::I32,
        "float32" => VoxelType::F32,
        "float64" => VoxelType::F64,
        _ => return None,
    })
}

/// Opens the volume `sel` chooses in the Zarr hierarchy or array at `path`.
/// `spacing` overrides the metadata's.
pub fn open_zarr(path: &Path, sel: &ZarrSelect, spacing: Option<[f64; 3]>) -> Result<ZarrSource> {
    let label = path.display().to_string();
    let chosen = choose(path, &label, sel)?;
    let store = Arc::new(
        FilesystemStore::new(path)
            .with_context(|| format!("{label}: cannot open as a Zarr store"))?,
    );
    let array_path = format!("/{}", chosen.path.trim_matches('/'));
    let array_label = if chosen.path.is_empty() {
        format!("{label}: the array")
    } else {
        format!("{label}: array \"{}\"", chosen.path)
    };
    let array = Array::open(store, &array_path).map_err(|e| anyhow!("{array_label}: {e}"))?;
    let shape = array.shape().to_vec();
    let n = shape.len();
    ensure!(
        (3..=5).contains(&n),
        "{array_label}: {n} dimensions; a volume needs 3 space dimensions (and at most a time and a channel dimension)"
    );
    // The axes: from the multiscales metadata, else the last three are
    // z, y, x (a plain array).
    let axes = if chosen.axes.is_empty() {
        let names = ["t", "c", "z", "y", "x"];
        names[5 - n..]
            .iter()
            .map(|s| Axis {
                name: s.to_string(),
                kind: None,
                unit: None,
            })
            .collect()
    } else {
        ensure!(
            chosen.axes.len() == n,
            "{array_label}: {n} dimensions, but multiscales[0].axes lists {} (inconsistent metadata)",
            chosen.axes.len()
        );
        chosen.axes.clone()
    };
    let scale = if chosen.scale.is_empty() {
        vec![1.0; n]
    } else {
        chosen.scale.clone()
    };
    let space: Vec<usize> = (0..n)
        .filter(|&i| match &axes[i].kind {
            Some(k) => k == "space",
            None => matches!(axes[i].name.as_str(), "x" | "y" | "z"),
        })
        .collect();
    ensure!(
        space == [n - 3, n - 2, n - 1],
        "{label}: multiscales[0].axes {:?}: the last three axes must be the space axes z, y, x (found {} space axes)",
        axes.iter().map(|a| a.name.as_str()).collect::<Vec<_>>(),
        space.len()
    );
    let units: Vec<Option<&str>> = space.iter().map(|&i| axes[i].unit.as_deref()).collect();
    ensure!(
        units.iter().all(|u| *u == units[0]),
        "{label}: multiscales[0].axes: the space axes have different units ({units:?}); convert them to one"
    );
    // The other axes: time and channel, fixed at the chosen index.
    let mut fixed = Vec::with_capacity(n - 3);
    let mut chosen_text = Vec::new();
    let (mut used_channel, mut used_time) = (false, false);
    let mut time_points = 1;
    for i in 0..n - 3 {
        let a = &axes[i];
        let is_time = a.kind.as_deref() == Some("time") || a.name == "t";
        let (flag, pick) = if is_time {
            used_time = true;
            time_points = shape[i] as usize;
            ("--time", sel.time)
        } else {
            used_channel = true;
            ("--channel", sel.channel)
        };
        let k = pick.unwrap_or(0) as u64;
        ensure!(
            k < shape[i],
            "{label}: {flag} {k}: axis \"{}\" has {} (0 to {})",
            a.name,
            shape[i],
            shape[i] - 1
        );
        if shape[i] > 1 {
            chosen_text.push(format!("{} {k} of {} ({flag})", a.name, shape[i]));
        }
        fixed.push(k);
    }
    if sel.time.is_some() && !used_time {
        bail!("{label}: --time: the image has no time axis");
    }
    if sel.channel.is_some() && !used_channel {
        bail!("{label}: --channel: the image has no channel axis");
    }
    let type_name = array.data_type().to_string();
    let type_name = type_name.split(" / ").next().unwrap_or("").to_string();
    let voxel_type = voxel_type(&type_name).ok_or_else(|| {
        anyhow!("{array_label}: data type {type_name} is not supported (u8, i8, u16, i16, u32, i32, f32, f64)")
    })?;
    let dims = [
        shape[n - 1] as usize,
        shape[n - 2] as usize,
        shape[n - 3] as usize,
    ];
    let meta_spacing = [scale[n - 1], scale[n - 2], scale[n - 3]];
    let spacing = spacing.unwrap_or(meta_spacing);
    let info = VolumeInfo {
        dims,
        spacing,
        voxel_type,
    };
    check_info(
        &label,
        &info,
        &format!(
            "{} shape",
            array_label.trim_start_matches(&format!("{label}: "))
        ),
        "multiscales[0].datasets[…].coordinateTransformations scale",
    )?;
    let chunk: Vec<u64> = array
        .chunk_shape(&vec![0; n])
        .map_err(|e| anyhow!("{array_label}: chunk grid: {e}"))?
        .iter()
        .map(|c| c.get())
        .collect();
    // A chunk is decoded whole: its size is checked before any is read
    // (a chunk may exceed a small array, not the memory of a machine).
    let chunk_elems = chunk.iter().try_fold(1u64, |a, &c| a.checked_mul(c));
    let array_elems = info.voxel_count();
    let limit = (8 * array_elems)
        .max(1 << 24)
        .min((4u64 << 30) / voxel_type.bytes() as u64);
    ensure!(
        chunk_elems.is_some_and(|e| e <= limit),
        "{array_label}: chunk shape {chunk:?} is too large ({} values; at most {limit} are read at once)",
        chunk_elems.map_or("more than 2^64".to_string(), |e| e.to_string())
    );
    // The chunk grid must be regular (the slab reads whole rows of
    // chunks of one depth).
    let grid = array.chunk_grid_shape().to_vec();
    for (a, (&c, &g)) in chunk.iter().zip(&grid).enumerate() {
        ensure!(
            c.checked_mul(g).is_some_and(|t| t >= shape[a]),
            "{array_label}: the chunk grid is not regular along axis {a}"
        );
    }
    let mut note = chosen.what;
    if !chosen_text.is_empty() {
        note += &format!(", {}", chosen_text.join(", "));
    }
    note += &format!(", {type_name}");
    if let Some(u) = units[0] {
        note += &format!("; spacing in {u}");
    }
    Ok(ZarrSource {
        label,
        path: path.to_path_buf(),
        sel: sel.clone(),
        levels: chosen.levels,
        meta_spacing,
        time_points,
        array_label,
        info,
        array,
        fixed,
        chunk,
        slab: Vec::new(),
        slab_z0: 0,
        slab_len: 0,
        next: 0,
        missing: 0,
        chunks_read: 0,
        rounding: Rounding::default(),
        nan_empty: false,
        note,
    })
}

/// Samples a chunk holds, as `f64` for conversion (exact for every type).
trait Sample: bytemuck::Pod + Send + Sync + zarrs::array::ElementOwned + 'static {
    fn value(self) -> f64;
}
macro_rules! sample {
    ($($t:ty),*) => {$(impl Sample for $t {
        fn value(self) -> f64 {
            self as f64
        }
    })*};
}
sample!(u8, i8, u16, i16, u32, i32, f32, f64);

/// Calls the method `Self::$f::<T>` with the Rust type of a sample type.
macro_rules! with_type {
    ($t:expr, $f:ident ( $($arg:expr),* )) => {
        match $t {
            VoxelType::U8 => Self::$f::<u8>($($arg),*),
            VoxelType::I8 => Self::$f::<i8>($($arg),*),
            VoxelType::U16 => Self::$f::<u16>($($arg),*),
            VoxelType::I16 => Self::$f::<i16>($($arg),*),
            VoxelType::U32 => Self::$f::<u32>($($arg),*),
            VoxelType::I32 => Self::$f::<i32>($($arg),*),
            VoxelType::F32 => Self::$f::<f32>($($arg),*),
            VoxelType::F64 => Self::$f::<f64>($($arg),*),
        }
    };
}

/// Chunks decoded at once per core: decoded chunks wait in memory only
/// until they are copied into the slab.
const CHUNKS_PER_CORE: usize = 4;

impl ZarrSource {
    /// Decodes the row of chunks at chunk row `zc` along z into the slab,
    /// in the samples' own type (half the memory of f32 for 16-bit data).
    fn load_slab_as<T: Sample>(&mut self, zc: u64) -> Result<()> {
        let n = self.chunk.len();
        let [nx, ny, nz] = self.info.dims;
        let (cz, cy, cx) = (self.chunk[n - 3], self.chunk[n - 2], self.chunk[n - 1]);
        let z0 = zc * cz;
        let z1 = (z0 + cz).min(nz as u64);
        // The chunks of this row: the fixed axes' chunk, every y and x.
        let mut lead: Vec<u64> = self
            .fixed
            .iter()
            .zip(&self.chunk)
            .map(|(&k, &c)| k / c)
            .collect();
        lead.push(zc);
        let gy = (ny as u64).div_ceil(cy);
        let gx = (nx as u64).div_ceil(cx);
        let indices: Vec<Vec<u64>> = (0..gy)
            .flat_map(|yc| (0..gx).map(move |xc| (yc, xc)))
            .map(|(yc, xc)| {
                let mut idx = lead.clone();
                idx.push(yc);
                idx.push(xc);
                idx
            })
            .collect();
        let depth = (z1 - z0) as usize;
        let slice = nx * ny;
        // Every voxel of the slab is written below (the chunks cover every
        // y and x): the buffer is kept between slabs, not zeroed. It is
        // held as u64 words, aligned for every sample type.
        let words = (slice * depth * std::mem::size_of::<T>()).div_ceil(8);
        self.slab.resize(words, 0);
        let slab: &mut [T] =
            &mut bytemuck::cast_slice_mut::<u64, T>(&mut self.slab)[..slice * depth];
        // Offsets of the fixed axes inside a chunk (C order).
        let chunk_len: u64 = self.chunk.iter().product();
        let mut lead_off = 0u64;
        for (a, &k) in self.fixed.iter().enumerate() {
            let stride: u64 = self.chunk[a + 1..].iter().product();
            lead_off += (k % self.chunk[a]) * stride;
        }
        let array = &self.array;
        let array_label = &self.array_label;
        let at_once = rayon::current_num_threads() * CHUNKS_PER_CORE;
        for batch in indices.chunks(at_once) {
            let decoded: Vec<Result<(Vec<T>, bool)>> = batch
                .par_iter()
                .map(|idx| {
                    let name = || {
                        format!(
                            "{array_label}: chunk {idx:?} (key \"{}\")",
                            array.chunk_key(idx)
                        )
                    };
                    match array.retrieve_chunk_if_exists::<Vec<T>>(idx) {
                        Ok(Some(v)) => Ok((v, false)),
                        Ok(None) => array
                            .retrieve_chunk::<Vec<T>>(idx)
                            .map(|v| (v, true))
                            .map_err(|e| anyhow!("{}: cannot decode: {e}", name())),
                        Err(e) => Err(anyhow!("{}: cannot decode: {e}", name())),
                    }
                })
                .collect();
            for (idx, res) in batch.iter().zip(decoded) {
                let (values, missing) = res?;
                ensure!(
                    values.len() as u64 == chunk_len,
                    "{array_label}: chunk {idx:?} decoded to {} values, expected {chunk_len}",
                    values.len()
                );
                self.missing += missing as u64;
                self.chunks_read += 1;
                let (y0, x0) = (idx[n - 2] * cy, idx[n - 1] * cx);
                let y1 = (y0 + cy).min(ny as u64);
                let w = ((x0 + cx).min(nx as u64) - x0) as usize;
                for z in 0..depth as u64 {
                    for y in y0..y1 {
                        let src = (lead_off + z * cy * cx + (y - y0) * cx) as usize;
                        let dst = z as usize * slice + y as usize * nx + x0 as usize;
                        slab[dst..dst + w].copy_from_slice(&values[src..src + w]);
                    }
                }
            }
        }
        self.slab_z0 = z0 as usize;
        self.slab_len = depth;
        Ok(())
    }

    /// Slice `k` of the slab as data values.
    fn slice_as<T: Sample>(&mut self, k: usize, out: &mut [f32]) -> Result<()> {
        let slice = self.info.slice_len();
        let slab: &[T] = &bytemuck::cast_slice::<u64, T>(&self.slab)[k * slice..(k + 1) * slice];
        let exact = self.info.voxel_type.may_round();
        for (o, &s) in out.iter_mut().zip(slab) {
            let v = s.value();
            *o = v as f32;
            if exact {
                self.rounding.add_value(v, *o);
            }
        }
        if !self.info.voxel_type.is_float() {
            return Ok(()); // integers are finite
        }
        check_finite(
            &self.label,
            self.info.dims,
            ((self.slab_z0 + k) * slice) as u64,
            out,
            self.nan_empty,
        )
    }
}

impl VolumeSource for ZarrSource {
    fn info(&self) -> &VolumeInfo {
        &self.info
    }

    fn read_slices(&mut self, out: &mut [f32]) -> Result<()> {
        let slice = self.info.slice_len();
        ensure!(
            out.len().is_multiple_of(slice),
            "{}: read_slices needs whole slices",
            self.label
        );
        let cz = self.chunk[self.chunk.len() - 3] as usize;
        let t = self.info.voxel_type;
        for dst in out.chunks_mut(slice) {
            ensure!(
                self.next < self.info.dims[2],
                "{}: reading past the last slice",
                self.label
            );
            if !(self.slab_z0..self.slab_z0 + self.slab_len).contains(&self.next) {
                let zc = (self.next / cz) as u64;
                with_type!(t, load_slab_as(self, zc))?;
            }
            let k = self.next - self.slab_z0;
            with_type!(t, slice_as(self, k, dst))?;
            self.next += 1;
        }
        if self.next == self.info.dims[2] {
            self.slab = Vec::new();
            self.slab_len = 0;
        }
        Ok(())
    }

    /// Bytes the source holds while reading: the slab of one chunk row in
    /// the samples' own type, and the chunks decoded at once.
    fn buffer_bytes(&self) -> u64 {
        let n = self.chunk.len();
        let bytes = self.info.voxel_type.bytes() as u64;
        let chunk: u64 = self.chunk.iter().product();
        let at_once = (rayon::current_num_threads() * CHUNKS_PER_CORE) as u64;
        (self.info.slice_len() as u64 * self.chunk[n - 3] + at_once * chunk) * bytes
    }

    fn conversion_note(&self) -> Option<String> {
        let mut notes = Vec::new();
        if self.missing > 0 {
            notes.push(format!(
                "{}: {} of the {} chunks read are missing; their voxels take the array's fill value {}",
                self.array_label,
                self.missing,
                self.chunks_read,
                fill_text(&self.array)
            ));
        }
        if let Some(r) = self.rounding.note_for(&self.label, self.info.voxel_type) {
            notes.push(r);
        }
        (!notes.is_empty()).then(|| notes.join("\n"))
    }

    fn describe(&self) -> Option<String> {
        Some(self.note.clone())
    }

    fn time_points(&self) -> usize {
        self.time_points
    }

    fn pyramid(&self) -> Result<Vec<FileLevel>> {
        let level = self.sel.level.unwrap_or(0);
        (level + 1..self.levels)
            .map(|index| {
                let s = self.level_source(index)?;
                Ok(FileLevel {
                    index,
                    dims: s.info.dims,
                    spacing: s.info.spacing,
                })
            })
            .collect()
    }

    fn open_level(&self, index: usize) -> Result<Box<dyn VolumeSource + Send>> {
        Ok(Box::new(self.level_source(index)?))
    }

    fn set_nan_empty(&mut self) {
        self.nan_empty = true;
    }
}

/// The array's fill value as its metadata writes it.
impl ZarrSource {
    /// Another resolution level of the same image, channel and time point,
    /// its spacing in this level's terms (this level's spacing, `--spacing`
    /// included, times the ratio of the two levels' scales).
    fn level_source(&self, index: usize) -> Result<ZarrSource> {
        let sel = ZarrSelect {
            level: Some(index),
            ..self.sel.clone()
        };
        let mut s = open_zarr(&self.path, &sel, None)?;
        s.info.spacing = std::array::from_fn(|a| {
            self.info.spacing[a] * s.meta_spacing[a] / self.meta_spacing[a]
        });
        s.nan_empty = self.nan_empty;
        Ok(s)
    }
}

fn fill_text(array: &Array<FilesystemStore>) -> String {
    serde_json::to_value(array.metadata())
        .ok()
        .and_then(|m| m.get("fill_value").cloned())
        .map_or_else(|| "?".to_string(), |v| v.to_string())
}

/// Writes a volume as an OME-Zarr image (NGFF 0.5 on Zarr v3: one
/// resolution level, array `s0`, chunks of 64³, zstd), z-slices in
/// increasing order as [`super::NrrdWriter`] does: `parallax synth … -o
/// x.ome.zarr`, for the demo and the import benches. Rows of chunks are
/// written as they fill; the image is written into a folder beside `path`
/// and renamed over it when finished, so an interrupted write never leaves
/// a half image under the final name.
pub struct ZarrWriter {
    path: std::path::PathBuf,
    tmp: std::path::PathBuf,
    info: VolumeInfo,
    array: Array<FilesystemStore>,
    rows: Vec<f32>,
    z0: usize,
    next: usize,
}

/// The chunk side of [`ZarrWriter`].
pub const WRITE_CHUNK: usize = 64;

impl ZarrWriter {
    /// Starts an image of `dims` voxels of `voxel_type` and `spacing` (in
    /// `unit`, an NGFF unit name such as "millimeter").
    pub fn create(
        path: &Path,
        dims: [usize; 3],
        voxel_type: VoxelType,
        spacing: [f64; 3],
        unit: &str,
    ) -> Result<Self> {
        let label = path.display();
        let name = path
            .file_name()
            .ok_or_else(|| anyhow!("{label}: not a file name"))?
            .to_string_lossy()
            .to_string();
        let tmp = path.with_file_name(format!(".{name}.partial-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&tmp);
        std::fs::create_dir_all(&tmp)
            .with_context(|| format!("{}: cannot create", tmp.display()))?;
        let info = VolumeInfo {
            dims,
            spacing,
            voxel_type,
        };
        let made = Self::start(path, &tmp, &name, info, unit);
        if made.is_err() {
            let _ = std::fs::remove_dir_all(&tmp);
        }
        made
    }

    fn start(path: &Path, tmp: &Path, name: &str, info: VolumeInfo, unit: &str) -> Result<Self> {
        let label = path.display();
        let VolumeInfo {
            dims,
            spacing,
            voxel_type,
        } = info;
        let axes: Vec<Value> = ["z", "y", "x"]
            .iter()
            .map(|a| serde_json::json!({"name": a, "type": "space", "unit": unit}))
            .collect();
        let group = serde_json::json!({
            "zarr_format": 3,
            "node_type": "group",
            "attributes": {"ome": {"version": "0.5", "multiscales": [{
                "name": name,
                "axes": axes,
                "datasets": [{"path": "s0", "coordinateTransformations": [
                    {"type": "scale", "scale": [spacing[2], spacing[1], spacing[0]]}
                ]}]
            }]}}
        });
        std::fs::write(tmp.join("zarr.json"), serde_json::to_vec_pretty(&group)?)
            .with_context(|| format!("{}: cannot write", tmp.display()))?;
        let store = Arc::new(
            FilesystemStore::new(tmp).with_context(|| format!("{}: cannot open", tmp.display()))?,
        );
        let shape = vec![dims[2] as u64, dims[1] as u64, dims[0] as u64];
        let chunk = vec![WRITE_CHUNK as u64; 3];
        let array = zarrs::array::ArrayBuilder::new(
            shape,
            chunk,
            zarr_type(voxel_type),
            zarrs::array::FillValue::new(vec![0u8; voxel_type.bytes()]),
        )
        .bytes_to_bytes_codecs(vec![Arc::new(zarrs::array::codec::ZstdCodec::new(
            1, false,
        ))])
        .dimension_names(Some(["z", "y", "x"]))
        .build(store, "/s0")
        .map_err(|e| anyhow!("{label}: array s0: {e}"))?;
        array
            .store_metadata()
            .map_err(|e| anyhow!("{label}: array s0: {e}"))?;
        Ok(ZarrWriter {
            path: path.to_path_buf(),
            tmp: tmp.to_path_buf(),
            info,
            array,
            rows: Vec::new(),
            z0: 0,
            next: 0,
        })
    }

    /// Appends whole z-slices (data values, x fastest).
    pub fn write_slices(&mut self, values: &[f32]) -> Result<()> {
        let slice = self.info.slice_len();
        ensure!(
            values.len().is_multiple_of(slice),
            "{}: write_slices needs whole slices",
            self.path.display()
        );
        for s in values.chunks(slice) {
            ensure!(
                self.next < self.info.dims[2],
                "{}: more slices than the volume has",
                self.path.display()
            );
            self.rows.extend_from_slice(s);
            self.next += 1;
            if self.next - self.z0 == WRITE_CHUNK || self.next == self.info.dims[2] {
                self.flush()?;
            }
        }
        Ok(())
    }

    fn flush(&mut self) -> Result<()> {
        let [nx, ny, _] = self.info.dims;
        let subset = [self.z0 as u64..self.next as u64, 0..ny as u64, 0..nx as u64];
        let label = self.path.display().to_string();
        let rows = std::mem::take(&mut self.rows);
        check_finite(
            &format!("{label}: cannot write"),
            self.info.dims,
            (self.z0 * nx * ny) as u64,
            &rows,
            false,
        )?;
        // Integers: the nearest, clamped to the type (as the NRRD writer).
        let (lo, hi) = self.info.voxel_type.limits();
        let float = self.info.voxel_type.is_float();
        macro_rules! store {
            ($t:ty) => {{
                let v: Vec<$t> = rows
                    .iter()
                    .map(|&x| {
                        if float {
                            x as $t
                        } else {
                            (x as f64).round().clamp(lo, hi) as $t
                        }
                    })
                    .collect();
                self.array.store_array_subset(&subset, v)
            }};
        }
        match self.info.voxel_type {
            VoxelType::U8 => store!(u8),
            VoxelType::I8 => store!(i8),
            VoxelType::U16 => store!(u16),
            VoxelType::I16 => store!(i16),
            VoxelType::U32 => store!(u32),
            VoxelType::I32 => store!(i32),
            VoxelType::F32 => store!(f32),
            VoxelType::F64 => store!(f64),
        }
        .map_err(|e| anyhow!("{label}: array s0: {e}"))?;
        self.z0 = self.next;
        Ok(())
    }

    /// Checks that every slice was written and puts the image in place.
    pub fn finish(self) -> Result<()> {
        ensure!(
            self.next == self.info.dims[2],
            "{}: {} of {} slices written",
            self.path.display(),
            self.next,
            self.info.dims[2]
        );
        if self.path.exists() {
            ensure!(
                is_zarr(&self.path),
                "{}: exists and is not a Zarr image: not replaced",
                self.path.display()
            );
            std::fs::remove_dir_all(&self.path)
                .with_context(|| format!("{}: cannot replace", self.path.display()))?;
        }
        std::fs::rename(&self.tmp, &self.path)
            .with_context(|| format!("{}: cannot rename into place", self.path.display()))
    }
}

impl Drop for ZarrWriter {
    /// An image not finished leaves nothing behind.
    fn drop(&mut self) {
        if self.tmp.exists() {
            let _ = std::fs::remove_dir_all(&self.tmp);
        }
    }
}

/// The Zarr v3 data type name of a sample type.
fn zarr_type(t: VoxelType) -> &'static str {
    match t {
        VoxelType::U8 => "uint8",
        VoxelType::I8 => "int8",
        VoxelType::U16 => "uint16",
        VoxelType::I16 => "int16",
        VoxelType::U32 => "uint32",
        VoxelType::I32 => "int32",
        VoxelType::F32 => "float32",
        VoxelType::F64 => "float64",
    }
}
