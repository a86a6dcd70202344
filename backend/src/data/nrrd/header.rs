//! The NRRD header: fields, their checks, attached and detached files.

use std::fs::File;
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};

use anyhow::{bail, ensure, Context, Result};

use crate::data::check_info;
use crate::data::raw::READ_BUFFER;
use crate::volume::{VolumeInfo, VoxelType};

/// Longest header accepted: protects against reading a large binary file
/// line by line when it is not a NRRD at all.
const MAX_HEADER_BYTES: u64 = 1 << 20;

/// Data encodings the reader can stream.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NrrdEncoding {
    Raw,
    Gzip,
    Bzip2,
    /// Two hexadecimal digits a byte, white space ignored.
    Hex,
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
    /// Volume space → LPS mm, from `space`, `space directions` and `space
    /// origin` where the header has all three in a patient space (LPS, RAS
    /// or LAS); `None` otherwise (`VolumeSource::world`).
    pub world: Option<[[f64; 4]; 3]>,
}

/// The scanner geometry of a header's `space`, `space directions` (of the
/// kept axes) and `space origin` (the first voxel's centre), in LPS.
/// `None` where one is missing, the space is not a patient space or not
/// three-dimensional, or a value is malformed (the spacing's own checks
/// name those).
fn world_of(label: &str, f: &Fields, keep: &[usize], spacing: [f64; 3]) -> Option<[[f64; 4]; 3]> {
    // Which LPS axes the space's axes run against.
    let flip = match f.space.as_deref()?.trim().to_ascii_lowercase().as_str() {
        "left-posterior-superior" | "lps" => [1.0, 1.0, 1.0],
        "right-anterior-superior" | "ras" => [-1.0, -1.0, 1.0],
        "left-anterior-superior" | "las" => [1.0, -1.0, 1.0],
        _ => return None,
    };
    let vectors = space_vectors(label, f.directions.as_deref()?).ok()?;
    let origin: Vec<f64> = f
        .origin
        .as_deref()?
        .trim()
        .trim_start_matches('(')
        .trim_end_matches(')')
        .split(',')
        .map(|c| c.trim().parse::<f64>())
        .collect::<std::result::Result<_, _>>()
        .ok()?;
    if origin.len() != 3 {
        return None;
    }
    let lps = |v: &[f64]| -> Option<[f64; 3]> {
        (v.len() == 3).then(|| std::array::from_fn(|k| flip[k] * v[k]))
    };
    let mut steps = [[0.0; 3]; 3];
    for (a, &axis) in keep.iter().enumerate() {
        steps[a] = lps(vectors.get(axis)?.as_deref()?)?;
    }
    super::super::world_from(lps(&origin)?, steps, spacing)
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
        "bzip2" | "bz2" => NrrdEncoding::Bzip2,
        "hex" => NrrdEncoding::Hex,
        _ => bail!(
            "{label}: encoding '{value}' is not a NRRD encoding (raw, gzip, bzip2, ascii or hex)"
        ),
    })
}

/// Parses `space directions`: one `(x,y,z)` vector or `none` per axis.
/// Returns the vector norms (`None` for `none`).
fn parse_space_directions(label: &str, value: &str) -> Result<Vec<Option<f64>>> {
    Ok(space_vectors(label, value)?
        .into_iter()
        .map(|v| v.map(|v| v.iter().map(|x| x * x).sum::<f64>().sqrt()))
        .collect())
}

/// The vectors of `space directions` (`None` for `none`).
fn space_vectors(label: &str, value: &str) -> Result<Vec<Option<Vec<f64>>>> {
    let mut out = Vec::new();
    let mut rest = value.trim();
    while !rest.is_empty() {
        if let Some(after) = rest.strip_prefix('(') {
            let Some(end) = after.find(')') else {
                bail!("{label}: space directions: missing ')' in '{value}'");
            };
            let mut v = Vec::new();
            for c in after[..end].split(',') {
                let x: f64 = c.trim().parse().map_err(|_| {
                    anyhow::anyhow!("{label}: space directions: '{}' is not a number", c.trim())
                })?;
                v.push(x);
            }
            out.push(Some(v));
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

/// The header's fields as written, before they are checked.
#[derive(Default)]
struct Fields {
    dimension: Option<String>,
    sizes: Option<String>,
    type_: Option<String>,
    encoding: Option<String>,
    endian: Option<String>,
    spacings: Option<String>,
    directions: Option<String>,
    space: Option<String>,
    origin: Option<String>,
    data_file: Option<String>,
    byte_skip: Option<String>,
    line_skip: Option<String>,
    ended_by_blank_line: bool,
}

/// Reads the field lines after the magic line, up to the blank line that
/// ends an attached header (or the end of a detached one).
fn read_fields(r: &mut BufReader<File>, consumed: &mut u64, label: &str) -> Result<Fields> {
    let mut f = Fields::default();
    let mut line = Vec::new();
    while read_line(r, &mut line, consumed, label)? {
        if line.is_empty() {
            f.ended_by_blank_line = true;
            break;
        }
        let text = String::from_utf8_lossy(&line);
        if text.starts_with('#') {
            continue;
        }
        // "field: value", or "key:=value" (free-form metadata, ignored).
        let field_sep = text.find(": ").or_else(|| text.find(':'));
        let Some(at) = field_sep else {
            bail!("{label}: header line '{text}' is not 'field: value'");
        };
        if text[at..].starts_with(":=") || text.find(":=").is_some_and(|kv| kv < at) {
            continue;
        }
        let (field, value) = (&text[..at], text[at + 1..].trim());
        let value = Some(value.to_string());
        match field.trim().to_ascii_lowercase().as_str() {
            "dimension" => f.dimension = value,
            "sizes" => f.sizes = value,
            "type" => f.type_ = value,
            "encoding" => f.encoding = value,
            "endian" => f.endian = value,
            "spacings" => f.spacings = value,
            "space directions" => f.directions = value,
            "space" => f.space = value,
            "space origin" => f.origin = value,
            "data file" | "datafile" => f.data_file = value,
            "byte skip" | "byteskip" => f.byte_skip = value,
            "line skip" | "lineskip" => f.line_skip = value,
            _ => {} // content, kinds, units, …: not needed here
        }
    }
    Ok(f)
}

fn missing(label: &str, f: &str) -> anyhow::Error {
    anyhow::anyhow!("{label}: missing field '{f}'")
}

/// The dimension, the sizes of all axes, and the three axes kept: a 4-D
/// header with a size-1 axis is a 3-D volume (the dropped axis does not
/// change the memory layout).
fn axes(label: &str, f: &Fields) -> Result<(usize, Vec<usize>, Vec<usize>)> {
    let dimension = f
        .dimension
        .as_ref()
        .ok_or_else(|| missing(label, "dimension"))?;
    let dimension: usize = dimension
        .parse()
        .map_err(|_| anyhow::anyhow!("{label}: dimension: '{dimension}' is not a number"))?;
    let sizes_text = f.sizes.as_ref().ok_or_else(|| missing(label, "sizes"))?;
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
    Ok((dimension, sizes, keep))
}

/// The kept axes' spacing, from the space directions' lengths or the
/// spacings (unit voxels without either), and the field it came from.
fn spacing_of(
    label: &str,
    f: &Fields,
    dimension: usize,
    keep: &[usize],
) -> Result<([f64; 3], &'static str)> {
    if let Some(d) = &f.directions {
        let norms = parse_space_directions(label, d)?;
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
        Ok((s, "space directions"))
    } else if let Some(sp) = &f.spacings {
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
        Ok((
            [values[keep[0]], values[keep[1]], values[keep[2]]],
            "spacings",
        ))
    } else {
        Ok(([1.0; 3], "spacings")) // no spacing given: unit voxels
    }
}

/// The byte skip (−1: the data are the file's last bytes, raw only) and
/// the line skip.
fn skips(label: &str, f: &Fields, encoding: NrrdEncoding) -> Result<(i64, u64)> {
    let byte_skip = match &f.byte_skip {
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
    let line_skip = match &f.line_skip {
        None => 0,
        Some(l) => l
            .parse::<u64>()
            .map_err(|_| anyhow::anyhow!("{label}: line skip: '{l}' is not a number"))?,
    };
    Ok((byte_skip, line_skip))
}

/// The detached data file, relative to the header's folder, or none where
/// the data follow the header's blank line.
fn data_file_of(label: &str, path: &Path, f: &Fields) -> Result<Option<PathBuf>> {
    match &f.data_file {
        None => {
            ensure!(
                f.ended_by_blank_line,
                "{label}: no data after the header (attached data must follow a blank line)"
            );
            Ok(None)
        }
        Some(file) => {
            let multi = file.starts_with("LIST")
                || (file.contains('%') && file.split_whitespace().count() > 1);
            ensure!(
                !multi,
                "{label}: data file: '{file}' names several files, which is not supported"
            );
            let p = Path::new(file);
            Ok(Some(if p.is_absolute() {
                p.to_path_buf()
            } else {
                path.parent().unwrap_or(Path::new("")).join(p)
            }))
        }
    }
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
    let f = read_fields(&mut r, &mut consumed, &label)?;
    let (dimension, sizes, keep) = axes(&label, &f)?;
    let dims = [sizes[keep[0]], sizes[keep[1]], sizes[keep[2]]];

    let voxel_type = parse_type(
        &label,
        f.type_.as_ref().ok_or_else(|| missing(&label, "type"))?,
    )?;
    let encoding = parse_encoding(
        &label,
        f.encoding
            .as_ref()
            .ok_or_else(|| missing(&label, "encoding"))?,
    )?;
    let big_endian = match f.endian.as_deref() {
        Some("little") => false,
        Some("big") => true,
        Some(e) => bail!("{label}: endian: '{e}' is not 'little' or 'big'"),
        None if voxel_type.bytes() == 1 || encoding == NrrdEncoding::Ascii => false,
        None => bail!(
            "{label}: missing field 'endian' (required for type {})",
            voxel_type.name()
        ),
    };
    let (spacing, spacing_field) = spacing_of(&label, &f, dimension, &keep)?;
    let info = VolumeInfo {
        dims,
        spacing,
        voxel_type,
    };
    check_info(&label, &info, "sizes", spacing_field)?;
    let (byte_skip, line_skip) = skips(&label, &f, encoding)?;
    let data_file = data_file_of(&label, path, &f)?;
    let world = world_of(&label, &f, &keep, spacing);
    Ok((
        NrrdHeader {
            info,
            encoding,
            big_endian,
            data_file,
            line_skip,
            byte_skip,
            world,
        },
        r,
        consumed,
    ))
}
