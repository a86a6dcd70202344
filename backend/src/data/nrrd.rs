//! NRRD input and output (<http://teem.sourceforge.net/nrrd/format.html>).
//!
//! NRRD is the format Parallax writes for procedural volumes and the one most
//! volume tools can exchange with it (DESIGN.md "Data"). The reader handles
//! what such tools write for a 3-D scalar volume: attached (`.nrrd`) and
//! detached (`.nhdr` + `data file`) headers, `raw`, `gzip` and `ascii` encodings,
//! either byte order, `spacings` or `space directions`. The writer streams
//! slice by slice so that a volume larger than RAM can be produced.

use std::fs::{self, File};
use std::io::{BufRead, BufReader, BufWriter, Read, Write};
use std::path::{Path, PathBuf};

use anyhow::{bail, ensure, Context, Result};
use flate2::bufread::MultiGzDecoder;
use parallax_common::volume::{VolumeInfo, VoxelType};

use super::raw::{check_file_size, skip_bytes, RawSource, READ_BUFFER};
use super::{check_finite, check_info, encode_samples};

/// Longest header accepted: protects against reading a large binary file
/// line by line when it is not a NRRD at all.
const MAX_HEADER_BYTES: u64 = 1 << 20;

/// Data encodings the reader can stream.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NrrdEncoding {
    Raw,
    Gzip,
    /// Values written as text, separated by white space.
    Ascii,
}

/// What a NRRD header says about a 3-D scalar volume.
#[derive(Clone, Debug, PartialEq)]
pub struct NrrdHeader {
    /// Dimensions and spacing (a size-1 axis of a 4-D header is dropped).
    pub info: VolumeInfo,
    pub encoding: NrrdEncoding,
    pub big_endian: bool,
    /// Detached data file, resolved relative to the header's folder; `None`
    /// when the data follows the header in the same file.
    pub data_file: Option<PathBuf>,
    /// Lines of the data file to skip before `byte_skip`.
    pub line_skip: u64,
    /// Bytes to skip before the data (of the decompressed stream for gzip);
    /// −1 (raw only) means the data is the last bytes of the file.
    pub byte_skip: i64,
}

/// NRRD `type` names of the supported sample types (every spelling teem
/// accepts), and the known ones that are not supported.
fn parse_type(label: &str, value: &str) -> Result<VoxelType> {
    Ok(match value {
        "uchar" | "unsigned char" | "uint8" | "uint8_t" => VoxelType::U8,
        "ushort" | "unsigned short" | "unsigned short int" | "uint16" | "uint16_t" => {
            VoxelType::U16
        }
        "short" | "short int" | "signed short" | "signed short int" | "int16" | "int16_t" => {
            VoxelType::I16
        }
        "float" => VoxelType::F32,
        "signed char" | "int8" | "int8_t" => VoxelType::I8,
        "int" | "signed int" | "int32" | "int32_t" => VoxelType::I32,
        "uint" | "unsigned int" | "uint32" | "uint32_t" => VoxelType::U32,
        "double" => VoxelType::F64,
        "longlong"
        | "long long"
        | "long long int"
        | "signed long long"
        | "signed long long int"
        | "int64"
        | "int64_t"
        | "ulonglong"
        | "unsigned long long"
        | "unsigned long long int"
        | "uint64"
        | "uint64_t"
        | "block" => {
            bail!("{label}: type '{value}' is not supported (use int8, uint8, int16, uint16, int32, uint32, float or double)")
        }
        _ => bail!("{label}: type '{value}' is not a NRRD type"),
    })
}

fn parse_encoding(label: &str, value: &str) -> Result<NrrdEncoding> {
    Ok(match value {
        "raw" => NrrdEncoding::Raw,
        "gzip" | "gz" => NrrdEncoding::Gzip,
        "ascii" | "text" | "txt" => NrrdEncoding::Ascii,
        "hex" | "bzip2" | "bz2" => {
            bail!("{label}: encoding '{value}' is not supported (use raw, gzip or ascii)")
        }
        _ => bail!("{label}: encoding '{value}' is not a NRRD encoding (use raw, gzip or ascii)"),
    })
}

/// Parses `space directions`: one `(x,y,z)` vector or `none` per axis.
/// Returns the vector norms (`None` for `none`).
fn parse_space_directions(label: &str, value: &str) -> Result<Vec<Option<f64>>> {
    let mut out = Vec::new();
    let mut rest = value.trim();
    while !rest.is_empty() {
        if let Some(after) = rest.strip_prefix('(') {
            let Some(end) = after.find(')') else {
                bail!("{label}: space directions: missing ')' in '{value}'");
            };
            let mut sq = 0.0f64;
            for c in after[..end].split(',') {
                let x: f64 = c.trim().parse().map_err(|_| {
                    anyhow::anyhow!("{label}: space directions: '{}' is not a number", c.trim())
                })?;
                sq += x * x;
            }
            out.push(Some(sq.sqrt()));
            rest = after[end + 1..].trim_start();
        } else {
            let end = rest.find(char::is_whitespace).unwrap_or(rest.len());
            let word = &rest[..end];
            if word != "none" {
                bail!("{label}: space directions: expected '(x,y,z)' or 'none', found '{word}'");
            }
            out.push(None);
            rest = rest[end..].trim_start();
        }
    }
    Ok(out)
}

/// Reads one header line (without its line ending) into `line`; returns
/// false at the end of the file.
fn read_line(
    r: &mut impl BufRead,
    line: &mut Vec<u8>,
    consumed: &mut u64,
    label: &str,
) -> Result<bool> {
    line.clear();
    let n = r
        .by_ref()
        .take(MAX_HEADER_BYTES)
        .read_until(b'\n', line)
        .with_context(|| format!("{label}: reading the header"))?;
    *consumed += n as u64;
    ensure!(
        *consumed < MAX_HEADER_BYTES,
        "{label}: header longer than {MAX_HEADER_BYTES} bytes (is this a NRRD file?)"
    );
    if n == 0 {
        return Ok(false);
    }
    while matches!(line.last(), Some(b'\n' | b'\r')) {
        line.pop();
    }
    Ok(true)
}

/// Parses the header of `path` and returns it with the file positioned just
/// after the header (where attached data begins) and the header's length.
pub fn read_header(path: &Path) -> Result<(NrrdHeader, BufReader<File>, u64)> {
    let label = path.display().to_string();
    let file = File::open(path).with_context(|| format!("{label}: cannot open"))?;
    let mut r = BufReader::with_capacity(READ_BUFFER, file);
    let mut consumed = 0u64;
    let mut line = Vec::new();

    read_line(&mut r, &mut line, &mut consumed, &label)?;
    let magic_ok = line.len() == 8 && line.starts_with(b"NRRD000") && line[7].is_ascii_digit();
    ensure!(
        magic_ok,
        "{label}: not a NRRD file (the first line must be NRRD000X)"
    );

    let mut dimension = None;
    let mut sizes = None;
    let mut type_ = None;
    let mut encoding = None;
    let mut endian = None;
    let mut spacings = None;
    let mut directions = None;
    let mut data_file = None;
    let mut byte_skip = None;
    let mut line_skip = None;
    let mut ended_by_blank_line = false;
    while read_line(&mut r, &mut line, &mut consumed, &label)? {
        if line.is_empty() {
            ended_by_blank_line = true;
            break;
        }
        let text = String::from_utf8_lossy(&line);
        if text.starts_with('#') {
            continue;
        }
        // "field: value", or "key:=value" (free-form metadata, ignored).
        let field_sep = text.find(": ").or_else(|| text.find(':'));
        let Some(f) = field_sep else {
            bail!("{label}: header line '{text}' is not 'field: value'");
        };
        if text[f..].starts_with(":=") || text.find(":=").is_some_and(|kv| kv < f) {
            continue;
        }
        let (field, value) = (&text[..f], text[f + 1..].trim());
        let value = value.to_string();
        match field.trim().to_ascii_lowercase().as_str() {
            "dimension" => dimension = Some(value),
            "sizes" => sizes = Some(value),
            "type" => type_ = Some(value),
            "encoding" => encoding = Some(value),
            "endian" => endian = Some(value),
            "spacings" => spacings = Some(value),
            "space directions" => directions = Some(value),
            "data file" | "datafile" => data_file = Some(value),
            "byte skip" | "byteskip" => byte_skip = Some(value),
            "line skip" | "lineskip" => line_skip = Some(value),
            _ => {} // content, kinds, space, space origin, units, …: not needed here
        }
    }

    let missing = |f: &str| anyhow::anyhow!("{label}: missing field '{f}'");
    let dimension = dimension.ok_or_else(|| missing("dimension"))?;
    let dimension: usize = dimension
        .parse()
        .map_err(|_| anyhow::anyhow!("{label}: dimension: '{dimension}' is not a number"))?;
    let sizes_text = sizes.ok_or_else(|| missing("sizes"))?;
    let mut sizes = Vec::new();
    for s in sizes_text.split_whitespace() {
        sizes.push(
            s.parse::<usize>()
                .map_err(|_| anyhow::anyhow!("{label}: sizes: '{s}' is not a size"))?,
        );
    }
    ensure!(
        sizes.len() == dimension,
        "{label}: sizes: {} sizes for dimension {dimension}",
        sizes.len()
    );
    // Axes to keep: a 4-D header with a size-1 axis is a 3-D volume (the
    // dropped axis does not change the memory layout).
    let keep: Vec<usize> = match dimension {
        3 => vec![0, 1, 2],
        4 => match sizes.iter().position(|&s| s == 1) {
            Some(drop) => (0..4).filter(|&a| a != drop).collect(),
            None => bail!(
                "{label}: dimension: 4 with sizes {sizes_text} is not a scalar volume \
                 (need 3 dimensions, or 4 with an axis of size 1)"
            ),
        },
        d => bail!("{label}: dimension: {d} is not supported (need a 3-dimensional volume)"),
    };
    let dims = [sizes[keep[0]], sizes[keep[1]], sizes[keep[2]]];

    let voxel_type = parse_type(&label, &type_.ok_or_else(|| missing("type"))?)?;
    let encoding = parse_encoding(&label, &encoding.ok_or_else(|| missing("encoding"))?)?;
    let big_endian = match endian.as_deref() {
        Some("little") => false,
        Some("big") => true,
        Some(e) => bail!("{label}: endian: '{e}' is not 'little' or 'big'"),
        None if voxel_type.bytes() == 1 || encoding == NrrdEncoding::Ascii => false,
        None => bail!(
            "{label}: missing field 'endian' (required for type {})",
            voxel_type.name()
        ),
    };

    let (spacing, spacing_field) = if let Some(d) = directions {
        let norms = parse_space_directions(&label, &d)?;
        ensure!(
            norms.len() == dimension,
            "{label}: space directions: {} entries for dimension {dimension}",
            norms.len()
        );
        let mut s = [0.0; 3];
        for (a, &axis) in keep.iter().enumerate() {
            s[a] = norms[axis].ok_or_else(|| {
                anyhow::anyhow!("{label}: space directions: axis {axis} is 'none' but holds voxels")
            })?;
        }
        (s, "space directions")
    } else if let Some(sp) = spacings {
        let mut values = Vec::new();
        for t in sp.split_whitespace() {
            values.push(
                t.parse::<f64>()
                    .map_err(|_| anyhow::anyhow!("{label}: spacings: '{t}' is not a number"))?,
            );
        }
        ensure!(
            values.len() == dimension,
            "{label}: spacings: {} values for dimension {dimension}",
            values.len()
        );
        (
            [values[keep[0]], values[keep[1]], values[keep[2]]],
            "spacings",
        )
    } else {
        ([1.0; 3], "spacings") // no spacing given: unit voxels
    };

    let info = VolumeInfo {
        dims,
        spacing,
        voxel_type,
    };
    check_info(&label, &info, "sizes", spacing_field)?;

    let byte_skip = match byte_skip {
        None => 0,
        Some(b) => {
            let v: i64 = b
                .parse()
                .map_err(|_| anyhow::anyhow!("{label}: byte skip: '{b}' is not a number"))?;
            ensure!(v >= -1, "{label}: byte skip: {v} is negative");
            ensure!(
                v != -1 || encoding == NrrdEncoding::Raw,
                "{label}: byte skip: -1 is only allowed with raw encoding"
            );
            v
        }
    };
    let line_skip = match line_skip {
        None => 0,
        Some(l) => l
            .parse::<u64>()
            .map_err(|_| anyhow::anyhow!("{label}: line skip: '{l}' is not a number"))?,
    };

    let data_file = match data_file {
        None => {
            ensure!(
                ended_by_blank_line,
                "{label}: no data after the header (attached data must follow a blank line)"
            );
            None
        }
        Some(f) => {
            let multi =
                f.starts_with("LIST") || (f.contains('%') && f.split_whitespace().count() > 1);
            ensure!(
                !multi,
                "{label}: data file: '{f}' names several files, which is not supported"
            );
            let p = Path::new(&f);
            Some(if p.is_absolute() {
                p.to_path_buf()
            } else {
                path.parent().unwrap_or(Path::new("")).join(p)
            })
        }
    };

    Ok((
        NrrdHeader {
            info,
            encoding,
            big_endian,
            data_file,
            line_skip,
            byte_skip,
        },
        r,
        consumed,
    ))
}

/// Opens a NRRD volume (attached or detached header) for streaming.
pub fn open_nrrd(path: &Path) -> Result<RawSource> {
    let (header, attached, header_len) = read_header(path)?;
    let info = header.info.clone();
    let (label, mut reader, mut pos) = match &header.data_file {
        None => (path.display().to_string(), attached, header_len),
        Some(data) => {
            let label = format!("{} (data file of {})", data.display(), path.display());
            let file = File::open(data).with_context(|| format!("{label}: cannot open"))?;
            (label, BufReader::with_capacity(READ_BUFFER, file), 0)
        }
    };
    let mut line = Vec::new();
    for n in 0..header.line_skip {
        line.clear();
        let got = reader
            .read_until(b'\n', &mut line)
            .with_context(|| format!("{label}: line skip"))?;
        ensure!(got > 0, "{label}: line skip: the file ends after {n} lines");
        pos += got as u64;
    }
    match header.encoding {
        NrrdEncoding::Raw => {
            let len = reader
                .get_ref()
                .metadata()
                .with_context(|| format!("{label}: cannot stat"))?
                .len();
            let skip = if header.byte_skip == -1 {
                // The data is the last bytes of the file.
                check_file_size(&label, &info, pos, len, false)?;
                len - pos - info.source_bytes()
            } else {
                let skip = header.byte_skip as u64;
                check_file_size(&label, &info, pos + skip, len, true)?;
                skip
            };
            skip_bytes(&mut reader, skip).with_context(|| format!("{label}: byte skip"))?;
            Ok(RawSource::from_reader(
                label,
                info,
                header.big_endian,
                false,
                Box::new(reader),
            ))
        }
        NrrdEncoding::Ascii => {
            skip_bytes(&mut reader, header.byte_skip.max(0) as u64)
                .with_context(|| format!("{label}: byte skip {}", header.byte_skip))?;
            Ok(RawSource::from_reader(label, info, false, false, Box::new(reader)).as_text())
        }
        NrrdEncoding::Gzip => {
            let mut dec = MultiGzDecoder::new(reader);
            skip_bytes(&mut dec, header.byte_skip as u64)
                .with_context(|| format!("{label}: byte skip {}", header.byte_skip))?;
            Ok(RawSource::from_reader(
                label,
                info,
                header.big_endian,
                true,
                Box::new(dec),
            ))
        }
    }
}

/// NRRD `type` name written for each voxel type.
fn type_name(t: VoxelType) -> &'static str {
    match t {
        VoxelType::U8 => "uint8",
        VoxelType::U16 => "uint16",
        VoxelType::I16 => "int16",
        VoxelType::F32 => "float",
        VoxelType::I8 => "int8",
        VoxelType::I32 => "int32",
        VoxelType::U32 => "uint32",
        VoxelType::F64 => "double",
    }
}

/// Streams a volume into an attached-header, raw, little-endian NRRD.
///
/// The file is written to `path + ".tmp"` and renamed on [`finish`], so a
/// crash or an error never leaves a half-written volume under the final name
/// (the same rule as the database, DESIGN.md "Data"). Dropping an unfinished
/// writer removes the temporary file.
///
/// [`finish`]: NrrdWriter::finish
pub struct NrrdWriter {
    path: PathBuf,
    tmp: PathBuf,
    out: Option<BufWriter<File>>,
    info: VolumeInfo,
    header_len: u64,
    written: u64,
    buf: Vec<u8>,
}

impl NrrdWriter {
    /// Creates the temporary file and writes the header.
    pub fn create(
        path: &Path,
        dims: [usize; 3],
        voxel_type: VoxelType,
        spacing: [f64; 3],
    ) -> Result<Self> {
        let label = path.display().to_string();
        let info = VolumeInfo {
            dims,
            spacing,
            voxel_type,
        };
        check_info(&label, &info, "dims", "spacing")?;
        let mut tmp = path.as_os_str().to_owned();
        tmp.push(".tmp");
        let tmp = PathBuf::from(tmp);
        let file =
            File::create(&tmp).with_context(|| format!("{}: cannot create", tmp.display()))?;
        let header = format!(
            "NRRD0004\n\
             # Complete NRRD file format specification at:\n\
             # http://teem.sourceforge.net/nrrd/format.html\n\
             type: {}\n\
             dimension: 3\n\
             sizes: {} {} {}\n\
             spacings: {} {} {}\n\
             endian: little\n\
             encoding: raw\n\n",
            type_name(voxel_type),
            dims[0],
            dims[1],
            dims[2],
            spacing[0],
            spacing[1],
            spacing[2]
        );
        let mut writer = NrrdWriter {
            path: path.to_path_buf(),
            tmp,
            out: Some(BufWriter::with_capacity(READ_BUFFER, file)),
            info,
            header_len: header.len() as u64,
            written: 0,
            buf: Vec::new(),
        };
        writer
            .stream()?
            .write_all(header.as_bytes())
            .with_context(|| format!("{label}: writing the header"))?;
        Ok(writer)
    }

    pub fn info(&self) -> &VolumeInfo {
        &self.info
    }

    /// Bytes of the header: the data starts at this offset.
    pub fn header_len(&self) -> u64 {
        self.header_len
    }

    fn stream(&mut self) -> Result<&mut BufWriter<File>> {
        self.out
            .as_mut()
            .ok_or_else(|| anyhow::anyhow!("{}: writer already finished", self.path.display()))
    }

    /// Appends whole z-slices (x fastest) of data values. Integer types get
    /// the value rounded to the nearest integer and clamped to the type's
    /// limits; NaN and infinities are refused (no reader would accept them).
    pub fn write_slices(&mut self, values: &[f32]) -> Result<()> {
        let label = self.path.display().to_string();
        let slice_len = self.info.slice_len() as u64;
        let n = values.len() as u64;
        ensure!(
            n / slice_len * slice_len == n,
            "{label}: write_slices needs whole slices of {slice_len} values, got {n}"
        );
        ensure!(
            self.written + n <= self.info.voxel_count(),
            "{label}: writing past the end of the volume ({} of {} voxels)",
            self.written + n,
            self.info.voxel_count()
        );
        check_finite(
            &format!("{label}: cannot write"),
            self.info.dims,
            self.written,
            values,
        )?;
        let mut buf = std::mem::take(&mut self.buf);
        buf.clear();
        encode_samples(values, self.info.voxel_type, false, &mut buf);
        let res = self.stream()?.write_all(&buf);
        self.buf = buf;
        res.with_context(|| format!("{}: writing", self.tmp.display()))?;
        self.written += n;
        Ok(())
    }

    /// Flushes, syncs and renames the file to its final name. Every voxel
    /// must have been written.
    pub fn finish(mut self) -> Result<()> {
        let label = self.path.display().to_string();
        ensure!(
            self.written == self.info.voxel_count(),
            "{label}: only {} of {} voxels were written",
            self.written,
            self.info.voxel_count()
        );
        let out = self.out.take().expect("finish runs once");
        let file = out
            .into_inner()
            .map_err(|e| e.into_error())
            .with_context(|| format!("{}: writing", self.tmp.display()))?;
        file.sync_all()
            .with_context(|| format!("{}: syncing", self.tmp.display()))?;
        drop(file);
        fs::rename(&self.tmp, &self.path)
            .with_context(|| format!("{}: renaming {}", label, self.tmp.display()))?;
        // Make the rename durable; not every platform can sync a directory.
        if let Some(dir) = self.path.parent().filter(|d| !d.as_os_str().is_empty()) {
            if let Ok(d) = File::open(dir) {
                let _ = d.sync_all();
            }
        }
        Ok(())
    }
}

impl Drop for NrrdWriter {
    fn drop(&mut self) {
        if self.out.take().is_some() {
            let _ = fs::remove_file(&self.tmp);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use parallax_common::volume::{Volume, VolumeSource};

    fn gzip(bytes: &[u8]) -> Vec<u8> {
        let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
        enc.write_all(bytes).unwrap();
        enc.finish().unwrap()
    }

    /// Values exactly representable in `t`, covering its extremes.
    fn test_values(t: VoxelType, n: usize) -> Vec<f32> {
        (0..n)
            .map(|x| match t {
                VoxelType::U8 => ((x * 37) % 256) as f32,
                VoxelType::U16 => ((x * 4099) % 65536) as f32,
                VoxelType::I16 => ((x * 4099) % 65536) as f32 - 32768.0,
                VoxelType::F32 => (x as f32 - 17.0) * 0.123_456_7 + 1e-30,
                VoxelType::I8 => ((x * 37) % 256) as f32 - 128.0,
                // Integers an f32 holds exactly, with the sign and range of
                // the type (|x| ≤ 2²⁴).
                VoxelType::I32 => ((x * 279_841) % (1 << 24)) as f32 - 8_388_608.0,
                VoxelType::U32 => ((x * 279_841) % (1 << 24)) as f32,
                VoxelType::F64 => (x as f32 - 17.0) * 0.123_456_7 + 1e-30,
            })
            .collect()
    }

    #[test]
    fn write_read_round_trip_each_type() {
        let dir = tempfile::tempdir().unwrap();
        let dims = [5, 4, 3];
        for t in [
            VoxelType::U8,
            VoxelType::U16,
            VoxelType::I16,
            VoxelType::F32,
            VoxelType::I8,
            VoxelType::I32,
            VoxelType::U32,
            VoxelType::F64,
        ] {
            let path = dir.path().join(format!("rt-{}.nrrd", t.name()));
            let values = test_values(t, 60);
            let mut w = NrrdWriter::create(&path, dims, t, [0.5, 1.25, 3.0]).unwrap();
            w.write_slices(&values[..20]).unwrap();
            w.write_slices(&values[20..]).unwrap();
            let header_len = w.header_len();
            assert!(!path.exists(), "the final name appears only on finish");
            w.finish().unwrap();
            assert_eq!(
                fs::metadata(&path).unwrap().len(),
                header_len + 60 * t.bytes() as u64
            );
            let mut src = crate::data::open(&path, None).unwrap();
            assert_eq!(
                src.info(),
                &VolumeInfo {
                    dims,
                    spacing: [0.5, 1.25, 3.0],
                    voxel_type: t
                }
            );
            let v = Volume::read_all(&mut *src).unwrap();
            assert_eq!(v.data, values, "{t:?}");
        }
    }

    #[test]
    fn writer_rounds_clamps_and_refuses_nan() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("clamp.nrrd");
        let mut w = NrrdWriter::create(&path, [4, 1, 1], VoxelType::U8, [1.0; 3]).unwrap();
        let err = w.write_slices(&[0.0, f32::NAN, 0.0, 0.0]).unwrap_err();
        assert!(
            format!("{err:#}").contains("voxel (1,0,0) is NaN"),
            "{err:#}"
        );
        w.write_slices(&[-5.0, 3.4, 3.6, 300.0]).unwrap();
        w.finish().unwrap();
        let v = Volume::read_all(&mut open_nrrd(&path).unwrap()).unwrap();
        assert_eq!(v.data, vec![0.0, 3.0, 4.0, 255.0]);

        let path = dir.path().join("short.nrrd");
        let mut w = NrrdWriter::create(&path, [2, 2, 2], VoxelType::I16, [1.0; 3]).unwrap();
        w.write_slices(&[40000.0, -40000.0, 1.5, -2.5]).unwrap();
        assert!(w.write_slices(&[1.0; 3]).is_err());
        let err = w.finish().unwrap_err().to_string();
        assert!(
            err.contains("short.nrrd") && err.contains("only 4 of 8"),
            "{err}"
        );
        assert!(!path.exists());
        assert!(
            !dir.path().join("short.nrrd.tmp").exists(),
            "an unfinished file is removed"
        );
    }

    #[test]
    fn reads_attached_gzip() {
        let dir = tempfile::tempdir().unwrap();
        let values: Vec<u16> = (0..4 * 3 * 2).map(|x| x * 1000 + 7).collect();
        let raw: Vec<u8> = values.iter().flat_map(|v| v.to_be_bytes()).collect();
        for enc in ["gzip", "gz"] {
            let path = dir.path().join(format!("g-{enc}.nrrd"));
            let mut bytes = format!(
                "NRRD0004\n# a comment\ntype: unsigned short\ndimension: 3\nsizes: 4 3 2\n\
                 spacings: 0.7 0.8 0.9\nendian: big\nencoding: {enc}\nmodality:=CT\n\n"
            )
            .into_bytes();
            bytes.extend(gzip(&raw));
            fs::write(&path, bytes).unwrap();
            let mut src = open_nrrd(&path).unwrap();
            assert_eq!(src.info().spacing, [0.7, 0.8, 0.9]);
            assert_eq!(src.info().voxel_type, VoxelType::U16);
            let v = Volume::read_all(&mut src).unwrap();
            assert_eq!(v.data, values.iter().map(|&x| x as f32).collect::<Vec<_>>());
        }
    }

    #[test]
    fn reads_detached_header() {
        let dir = tempfile::tempdir().unwrap();
        fs::create_dir(dir.path().join("data")).unwrap();
        let values: Vec<i16> = vec![-5, 4, 300, -32768, 32767, 0, 1, 2];
        // Two text lines and 3 bytes of junk before the samples.
        let mut raw = b"junk line\nmore junk\nabc".to_vec();
        raw.extend(values.iter().flat_map(|v| v.to_le_bytes()));
        fs::write(dir.path().join("data/vol.raw"), &raw).unwrap();
        let nhdr = dir.path().join("vol.nhdr");
        fs::write(
            &nhdr,
            "NRRD0005\ntype: short\ndimension: 4\nsizes: 1 2 2 2\nencoding: raw\nendian: little\n\
             space dimension: 3\nspace directions: none (0,0.5,0) (0, 0, -2) (3,4,0)\n\
             line skip: 2\nbyte skip: 3\ndata file: data/vol.raw\n",
        )
        .unwrap();
        let mut src = crate::data::open(&nhdr, None).unwrap();
        assert_eq!(src.info().dims, [2, 2, 2]);
        assert_eq!(src.info().spacing, [0.5, 2.0, 5.0]);
        let v = Volume::read_all(&mut *src).unwrap();
        assert_eq!(v.data, values.iter().map(|&x| x as f32).collect::<Vec<_>>());

        // byte skip −1: the data is the end of the file.
        fs::write(
            &nhdr,
            "NRRD0004\ntype: int16\ndimension: 3\nsizes: 2 2 2\nencoding: raw\nendian: little\n\
             byte skip: -1\ndatafile: data/vol.raw\n",
        )
        .unwrap();
        let v = Volume::read_all(&mut open_nrrd(&nhdr).unwrap()).unwrap();
        assert_eq!(v.data, values.iter().map(|&x| x as f32).collect::<Vec<_>>());

        // A detached gzip file; errors name the data file and its header.
        let gz = dir.path().join("data/vol.raw.gz");
        let packed: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        let full = gzip(&packed);
        fs::write(&gz, &full[..full.len() - 12]).unwrap();
        fs::write(
            &nhdr,
            "NRRD0004\ntype: int16\ndimension: 3\nsizes: 2 2 2\nencoding: gzip\nendian: little\n\
             data file: data/vol.raw.gz\n",
        )
        .unwrap();
        let err = Volume::read_all(&mut open_nrrd(&nhdr).unwrap()).unwrap_err();
        let err = format!("{err:#}");
        assert!(
            err.contains("vol.raw.gz (data file of") && err.contains("vol.nhdr"),
            "{err}"
        );
        fs::write(&gz, &full).unwrap();
        let v = Volume::read_all(&mut open_nrrd(&nhdr).unwrap()).unwrap();
        assert_eq!(v.data[3], -32768.0);
    }

    /// Writes an attached NRRD with `header` (fields after the magic) and
    /// `data`, opens it and returns the error message.
    fn open_error(dir: &Path, header: &str, data: &[u8]) -> String {
        let path = dir.join("bad.nrrd");
        let mut bytes = format!("NRRD0004\n{header}\n").into_bytes();
        bytes.extend_from_slice(data);
        fs::write(&path, bytes).unwrap();
        match open_nrrd(&path) {
            Ok(mut src) => format!("{:#}", Volume::read_all(&mut src).expect_err("must fail")),
            Err(e) => format!("{e:#}"),
        }
    }

    #[test]
    fn bad_headers_name_file_and_field() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let base = |t: &str, dim: &str, sizes: &str, enc: &str, extra: &str| {
            format!("type: {t}\ndimension: {dim}\nsizes: {sizes}\nencoding: {enc}\n{extra}")
        };
        let cases: Vec<(String, Vec<u8>, &str)> = vec![
            (
                base("int64", "3", "2 2 2", "raw", "endian: little\n"),
                vec![0; 64],
                "type 'int64' is not supported",
            ),
            (
                base("quux", "3", "2 2 2", "raw", ""),
                vec![0; 8],
                "type 'quux' is not a NRRD type",
            ),
            (
                base("uchar", "3", "2 2 2", "bzip2", ""),
                vec![0; 8],
                "encoding 'bzip2' is not supported (use raw, gzip or ascii)",
            ),
            (
                base("uchar", "3", "2 2 2", "hex", ""),
                vec![0; 8],
                "encoding 'hex' is not supported",
            ),
            (
                base("uchar", "2", "2 2", "raw", ""),
                vec![0; 4],
                "dimension: 2 is not supported",
            ),
            (
                base("uchar", "4", "2 2 2 2", "raw", ""),
                vec![0; 16],
                "dimension: 4 with sizes 2 2 2 2",
            ),
            (
                "type: uchar\ndimension: 3\nencoding: raw\n".into(),
                vec![0; 8],
                "missing field 'sizes'",
            ),
            (
                base("uchar", "3", "2 2", "raw", ""),
                vec![0; 8],
                "sizes: 2 sizes for dimension 3",
            ),
            (
                base("uchar", "3", "2 0 2", "raw", ""),
                vec![],
                "sizes: axis 1 has size 0",
            ),
            (
                base("uchar", "3", "2 2 2", "raw", "spacings: 1 0 1\n"),
                vec![0; 8],
                "spacings: spacing of axis 1 is 0",
            ),
            (
                base("uchar", "3", "2 2 2", "raw", "spacings: 1 1 -2\n"),
                vec![0; 8],
                "spacings: spacing of axis 2 is -2",
            ),
            (
                base("uchar", "3", "2 2 2", "raw", "spacings: nan 1 1\n"),
                vec![0; 8],
                "spacings: spacing of axis 0 is NaN",
            ),
            (
                base(
                    "uchar",
                    "3",
                    "2 2 2",
                    "raw",
                    "space directions: (0,0,0) (1,0,0) (0,1,0)\n",
                ),
                vec![0; 8],
                "space directions: spacing of axis 0 is 0",
            ),
            (
                base("ushort", "3", "2 2 2", "raw", ""),
                vec![0; 16],
                "missing field 'endian' (required for type u16)",
            ),
            (
                base("uchar", "3", "181 217 181", "raw", ""),
                vec![0; 1000],
                "expected 7109205 bytes (68-byte header + 7109137 for 181×217×181 u8) but the file has 1068",
            ),
            (
                base("uchar", "3", "2 2 2", "raw", ""),
                vec![0; 9],
                "but the file has",
            ),
        ];
        for (header, data, want) in cases {
            let err = open_error(d, &header, &data);
            assert!(
                err.contains("bad.nrrd") && err.contains(want),
                "{header:?}: got {err:?}, want {want:?}"
            );
        }
        let err = open_error(
            d,
            &base("uchar", "3", "2 2 2", "hex", ""),
            b"0102030405060708",
        );
        assert_eq!(
            err,
            format!(
                "{}: encoding 'hex' is not supported (use raw, gzip or ascii)",
                d.join("bad.nrrd").display()
            )
        );

        let path = d.join("nomagic.nrrd");
        fs::write(&path, "NRRX0004\ntype: uchar\n\n").unwrap();
        let err = open_nrrd(&path).err().unwrap().to_string();
        assert!(
            err.contains("nomagic.nrrd") && err.contains("NRRD000X"),
            "{err}"
        );
    }

    #[test]
    fn truncated_gzip_and_nan_are_errors() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let data: Vec<u8> = (0..32 * 32 * 8u32)
            .map(|x| (x.wrapping_mul(2654435761) >> 24) as u8)
            .collect();
        let gz = gzip(&data);
        let header = "type: uint8\ndimension: 3\nsizes: 32 32 8\nencoding: gzip\n";
        let err = open_error(d, header, &gz[..gz.len() / 2]);
        assert!(err.contains("bad.nrrd") && err.contains("slice"), "{err}");
        // Only the CRC / length trailer missing: caught after the last slice.
        let err = open_error(d, header, &gz[..gz.len() - 4]);
        assert!(err.contains("bad.nrrd") && err.contains("gzip"), "{err}");

        let mut floats = [1.0f32; 3 * 2 * 2];
        floats[3 * 2 + 2] = f32::NAN; // (2,0,1)
        let bytes: Vec<u8> = floats.iter().flat_map(|v| v.to_le_bytes()).collect();
        let err = open_error(
            d,
            "type: float\ndimension: 3\nsizes: 3 2 2\nendian: little\nencoding: raw\n",
            &bytes,
        );
        assert_eq!(
            err,
            format!("{}: voxel (2,0,1) is NaN", d.join("bad.nrrd").display())
        );
    }

    #[test]
    fn four_d_with_leading_unit_axis() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("4d.nrrd");
        let mut bytes = b"NRRD0004\ntype: uint8\ndimension: 4\nsizes: 1 2 1 2\nspacings: nan 2 3 4\nencoding: raw\n\n".to_vec();
        bytes.extend_from_slice(&[1, 2, 3, 4]);
        fs::write(&path, bytes).unwrap();
        let mut src = open_nrrd(&path).unwrap();
        assert_eq!(src.info().dims, [2, 1, 2]);
        assert_eq!(src.info().spacing, [2.0, 3.0, 4.0]);
        let v = Volume::read_all(&mut src).unwrap();
        assert_eq!(v.data, vec![1.0, 2.0, 3.0, 4.0]);
    }
}

#[cfg(test)]
mod wide_types {
    use super::*;
    use parallax_common::volume::Volume;

    /// numpy's default float64, and 32-bit integers beyond what an f32
    /// holds: they import, rounded to the nearest f32, and the reader says
    /// how many values changed and by how much.
    #[test]
    fn doubles_and_wide_integers_import_and_say_what_rounding_changed() {
        let dir = tempfile::tempdir().unwrap();
        let cases: [(&str, Vec<u8>, f64); 3] = [
            (
                "double",
                [0.1f64, 1.0, 2.5, 1e10 + 0.5, -3.0, 0.0, 7.0, 1.0 / 3.0]
                    .iter()
                    .flat_map(|x| x.to_le_bytes())
                    .collect(),
                0.0,
            ),
            (
                "int32",
                [16_777_217i32, -5, 0, 7, i32::MAX, i32::MIN, 3, 4]
                    .iter()
                    .flat_map(|x| x.to_le_bytes())
                    .collect(),
                1.0,
            ),
            (
                "uint32",
                [16_777_217u32, 5, 0, 7, u32::MAX, 1, 3, 4]
                    .iter()
                    .flat_map(|x| x.to_le_bytes())
                    .collect(),
                1.0,
            ),
        ];
        for (t, data, _) in &cases {
            let p = dir.path().join(format!("{t}.nrrd"));
            let mut bytes = format!(
                "NRRD0004\ntype: {t}\ndimension: 3\nsizes: 2 2 2\nencoding: raw\nendian: little\n\n"
            )
            .into_bytes();
            bytes.extend_from_slice(data);
            fs::write(&p, bytes).unwrap();
            let mut src = crate::data::open(&p, None).unwrap();
            let v = Volume::read_all(&mut *src).unwrap();
            assert_eq!(v.data.len(), 8);
            let note = src
                .conversion_note()
                .unwrap_or_else(|| panic!("{t}: no note"));
            assert!(
                note.contains(&format!("{t}.nrrd")) && note.contains("rounded"),
                "{note}"
            );
            match *t {
                "double" => {
                    assert_eq!(v.data[2], 2.5);
                    assert_eq!(v.data[0], 0.1f32);
                    assert!(note.contains("3 f64 values"), "{note}");
                }
                "int32" => {
                    assert_eq!(v.data[1], -5.0);
                    assert_eq!(v.data[5], i32::MIN as f32);
                    assert!(note.contains("2 i32 values"), "{note}");
                }
                _ => {
                    assert_eq!(v.data[1], 5.0);
                    assert!(note.contains("2 u32 values"), "{note}");
                }
            }
        }
        // int8 is exact: no note.
        let p = dir.path().join("i8.nrrd");
        let mut bytes =
            b"NRRD0004\ntype: int8\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n\n".to_vec();
        bytes.extend_from_slice(&[0x80, 0xff, 0, 1, 2, 3, 0x7f, 5]);
        fs::write(&p, bytes).unwrap();
        let mut src = crate::data::open(&p, None).unwrap();
        let v = Volume::read_all(&mut *src).unwrap();
        assert_eq!(&v.data[..3], &[-128.0, -1.0, 0.0]);
        assert_eq!(v.data[6], 127.0);
        assert!(src.conversion_note().is_none());
        // A double too large for f32 is refused, naming the voxel.
        let p = dir.path().join("huge.nrrd");
        let mut bytes = b"NRRD0004\ntype: double\ndimension: 3\nsizes: 2 1 1\nencoding: raw\nendian: little\n\n".to_vec();
        bytes.extend(1e300f64.to_le_bytes());
        bytes.extend(1.0f64.to_le_bytes());
        fs::write(&p, bytes).unwrap();
        let mut src = crate::data::open(&p, None).unwrap();
        let e = format!("{:#}", Volume::read_all(&mut *src).unwrap_err());
        assert!(e.contains("huge.nrrd"), "{e}");
    }
}

#[cfg(test)]
mod ascii {
    use super::*;
    use parallax_common::volume::Volume;

    fn read(dir: &Path, t: &str, text: &str) -> Result<Volume> {
        let p = dir.join("a.nrrd");
        fs::write(
            &p,
            format!("NRRD0004\ntype: {t}\ndimension: 3\nsizes: 2 2 2\nencoding: ascii\n\n{text}"),
        )
        .unwrap();
        let mut src = crate::data::open(&p, None)?;
        Volume::read_all(&mut *src)
    }

    /// `encoding: ascii` (also `text`, `txt`): white-space separated values,
    /// across lines, as integers or floats; short data, junk and values out
    /// of the type's range are refused naming the value.
    #[test]
    fn ascii_values_import_and_bad_ones_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let v = read(d, "short", "1 -2 3\n4\t5   6\n7 8\n").unwrap();
        assert_eq!(v.data, vec![1.0, -2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0]);
        assert_eq!(v.info.voxel_type, VoxelType::I16);
        let v = read(d, "double", "0.5 1e-3 2 3 4 5 6 7.25").unwrap();
        assert_eq!(v.data[1], 1e-3f32);
        assert_eq!(v.data[7], 7.25);
        for (t, text, want) in [
            ("uchar", "1 2 3 4 5 6 7", "truncated"),
            ("uchar", "1 2 x 4 5 6 7 8", "value 2 ('x') is not a number"),
            (
                "uchar",
                "1 2 3 4 5 6 7 300",
                "value 7 (300) is outside the range of u8",
            ),
            ("float", "1 2 3 nan 5 6 7 8", "NaN"),
        ] {
            let e = format!("{:#}", read(d, t, text).unwrap_err());
            assert!(
                e.contains("a.nrrd") && e.contains(want),
                "{t} {text:?}: {e}"
            );
        }
    }
}
