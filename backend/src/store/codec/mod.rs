//! Brick encoding: quantisation against the brick's own value range (G10 §5:
//! "an 8bit value obtained by linearly mapping each voxel value to the range
//! of values contained in the brick"), LZ4 compression, CRC-32 checksums.

use serde::{Deserialize, Serialize};

/// How brick values are stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum BrickEncoding {
    /// 8 bit, linearly mapped to the brick's [min, max] (G10 §5). Error at
    /// most (max − min)/510 per voxel.
    U8Range,
    /// 16 bit, linearly mapped to the brick's [min, max]. Error at most
    /// (max − min)/131070 per voxel.
    U16Range,
    /// Full precision: the data values as f32 (exact for 8/16-bit sources).
    F32,
}

impl BrickEncoding {
    pub fn parse(s: &str) -> Option<Self> {
        Some(match s {
            "u8" => BrickEncoding::U8Range,
            "u16" => BrickEncoding::U16Range,
            "none" | "f32" => BrickEncoding::F32,
            _ => return None,
        })
    }

    pub fn name(self) -> &'static str {
        match self {
            BrickEncoding::U8Range => "u8",
            BrickEncoding::U16Range => "u16",
            BrickEncoding::F32 => "none",
        }
    }

    /// Quantisation levels (0 for full precision).
    fn steps(self) -> f64 {
        match self {
            BrickEncoding::U8Range => 255.0,
            BrickEncoding::U16Range => 65535.0,
            BrickEncoding::F32 => 0.0,
        }
    }

    /// Worst-case absolute error of a decoded value in a brick whose values
    /// span [min, max] (half a quantisation step).
    pub fn error_bound(self, min: f32, max: f32) -> f64 {
        match self {
            BrickEncoding::F32 => 0.0,
            e => (max as f64 - min as f64) / (2.0 * e.steps()),
        }
    }
}

/// Smallest and largest of a brick's values.
pub fn value_range(values: &[f32]) -> (f32, f32) {
    values
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        })
}

/// The compressor of a stored brick.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Compressor {
    Lz4,
    /// zstd at the given level (only the encoder needs the level).
    Zstd(i32),
}

/// The pre-filter before compression.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Filter {
    None,
    /// Each value minus the one before it along x (wrapping), then the bytes
    /// of 2- and 4-byte values split into byte planes: the slow ramps of
    /// smooth data become runs of small numbers.
    Delta,
    /// Per brick, whichever of the two stores smaller (the brick's tag says
    /// which). Costs a second compression at import, nothing at decode.
    Auto,
}

/// How a brick's quantised bytes are compressed: a compressor after a
/// pre-filter.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Codec {
    pub compressor: Compressor,
    pub filter: Filter,
}

/// How the stored bricks of a file are framed. Format 1 (the first release)
/// stored every brick as LZ4 with a 4-byte size prefix; format 2 begins every
/// brick with a one-byte codec tag, so each brick names its own codec and
/// files that mix codecs read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Framing {
    /// Format 1: LZ4, 4-byte size prefix, no tag.
    Untagged,
    /// Format 2: tag, 4-byte size, payload.
    Tagged,
}

impl Codec {
    pub const LZ4: Codec = Codec {
        compressor: Compressor::Lz4,
        filter: Filter::None,
    };
    /// What import writes unless told otherwise: chosen by ratio and decode
    /// speed on Colin27, a CT and a smooth field (docs/performance.md,
    /// "Brick compression").
    pub const DEFAULT: Codec = Codec {
        compressor: Compressor::Zstd(1),
        filter: Filter::Auto,
    };

    /// `lz4`, `zstd` (level 1) or `zstdN` (level N, 1–19), each optionally
    /// followed by `+delta` or `+auto`.
    pub fn parse(s: &str) -> Option<Self> {
        let (base, filter) = if let Some(b) = s.strip_suffix("+delta") {
            (b, Filter::Delta)
        } else if let Some(b) = s.strip_suffix("+auto") {
            (b, Filter::Auto)
        } else {
            (s, Filter::None)
        };
        let compressor = match base {
            "lz4" => Compressor::Lz4,
            "zstd" => Compressor::Zstd(1),
            _ => {
                let level: i32 = base.strip_prefix("zstd")?.parse().ok()?;
                if !(1..=19).contains(&level) {
                    return None;
                }
                Compressor::Zstd(level)
            }
        };
        Some(Codec { compressor, filter })
    }

    pub fn name(self) -> String {
        let base = match self.compressor {
            Compressor::Lz4 => "lz4".to_string(),
            Compressor::Zstd(l) => format!("zstd{l}"),
        };
        match self.filter {
            Filter::None => base,
            Filter::Delta => base + "+delta",
            Filter::Auto => base + "+auto",
        }
    }

    /// The tag byte of format 2: bits 0–3 the compressor, bit 4 the filter
    /// (a resolved one: never [`Filter::Auto`]).
    fn tag(self) -> u8 {
        let c = match self.compressor {
            Compressor::Lz4 => 0,
            Compressor::Zstd(_) => 1,
        };
        c | if self.filter == Filter::Delta {
            0x10
        } else {
            0
        }
    }

    /// The codec a tag names (the zstd level is not recorded: decoding does
    /// not need it).
    pub fn from_tag(tag: u8) -> Option<Codec> {
        let compressor = match tag & 0x0f {
            0 => Compressor::Lz4,
            1 => Compressor::Zstd(0),
            _ => return None,
        };
        if tag & !(0x1f | NO_DATA_BIT | UNIT_STEP_BIT) != 0 {
            return None;
        }
        Some(Codec {
            compressor,
            filter: if tag & 0x10 != 0 {
                Filter::Delta
            } else {
                Filter::None
            },
        })
    }
}

/// Tag bit of a quantised brick that holds no-data voxels (NaN in the
/// source, imported with `--nan empty`): its top code (255, 65535) means "no
/// data" and the values use the codes below it. Full-precision bricks keep
/// NaN as it is.
const NO_DATA_BIT: u8 = 0x20;

/// Tag bit of a quantised brick stored on the unit grid (format 3): its
/// codes are value − min, step 1, not [min, max] cut into 255 (65535)
/// steps. Chosen whenever every value is an integer and the brick spans at
/// most the code range — the bricks of 8- and 16-bit sources at full
/// detail mostly — which are then stored without any loss. (A range step
/// of span/255 moves integer data by up to half a step: a quarter of a
/// data value for a span of 128, enough to smear a transfer function peak
/// one value wide.)
const UNIT_STEP_BIT: u8 = 0x40;

/// Whether a brick can be quantised on the unit grid: integer min and
/// values, span within the codes (the top one kept for no data).
pub fn unit_step_fits(
    values: &[f32],
    min: f32,
    max: f32,
    encoding: BrickEncoding,
    no_data: bool,
) -> bool {
    let codes = encoding.steps() - if no_data { 1.0 } else { 0.0 };
    encoding != BrickEncoding::F32
        && min.fract() == 0.0
        && (max as f64 - min as f64) <= codes
        && values
            .iter()
            .fold(true, |a, &v| a & (v.is_nan() | is_integer(v)))
}

/// `v.fract() == 0.0` without a library call per value: every finite f32
/// of magnitude 2²³ or more is an integer; below, the cast truncates
/// exactly.
fn is_integer(v: f32) -> bool {
    v.is_finite() && (v.abs() >= 8_388_608.0 || v as i32 as f32 == v)
}

/// Quantises (if the encoding says so) and compresses a brick whose values
/// span [min, max] (NaN, "no data", aside). The result is what is stored on
/// disk (format 2).
pub fn encode(
    values: &[f32],
    min: f32,
    max: f32,
    encoding: BrickEncoding,
    codec: Codec,
) -> Vec<u8> {
    encode_decoded(values, min, max, encoding, codec).0
}

/// [`encode`], and for quantised encodings the values as a reader decodes
/// them (dequantised from the codes just made, not decompressed again).
pub fn encode_decoded(
    values: &[f32],
    min: f32,
    max: f32,
    encoding: BrickEncoding,
    codec: Codec,
) -> (Vec<u8>, Option<Vec<f32>>) {
    // Without an early exit, so that the loop is vectorised.
    let no_data =
        encoding != BrickEncoding::F32 && values.iter().fold(false, |a, v| a | v.is_nan());
    let unit = unit_step_fits(values, min, max, encoding, no_data);
    let codes = quantise(values, min, max, encoding, no_data, unit);
    let mut out = compress(&codes, encoding, codec);
    if no_data {
        out[0] |= NO_DATA_BIT;
    }
    if unit {
        out[0] |= UNIT_STEP_BIT;
    }
    let decoded = (encoding != BrickEncoding::F32)
        .then(|| dequantise(&codes, min, max, encoding, no_data, unit));
    debug_assert_eq!(
        decoded
            .as_ref()
            .map(|d| d.iter().map(|v| v.to_bits()).collect::<Vec<_>>()),
        (encoding != BrickEncoding::F32).then(|| {
            decode_checked(&out, min, max, encoding, values.len(), Framing::Tagged)
                .expect("a brick just encoded decodes")
                .iter()
                .map(|v| v.to_bits())
                .collect::<Vec<_>>()
        }),
        "the codes decode to what the reader decodes"
    );
    (out, decoded)
}

/// A brick's values as the bytes the encoding stores (little endian). With
/// `no_data`, NaN takes the top code and values the codes below it; with
/// `unit` the codes are value − min (see [`unit_step_fits`]).
pub fn quantise(
    values: &[f32],
    min: f32,
    max: f32,
    encoding: BrickEncoding,
    no_data: bool,
    unit: bool,
) -> Vec<u8> {
    match encoding {
        BrickEncoding::F32 => bytemuck::cast_slice::<f32, u8>(values).to_vec(),
        BrickEncoding::U8Range => {
            let q = Quantiser::new(min, max, encoding, no_data, unit);
            values.iter().map(|&v| q.quantise(v) as u8).collect()
        }
        BrickEncoding::U16Range => {
            let q = Quantiser::new(min, max, encoding, no_data, unit);
            values
                .iter()
                .flat_map(|&v| (q.quantise(v) as u16).to_le_bytes())
                .collect()
        }
    }
}

/// Compresses quantised bytes into a format-2 record: tag, size, payload.
pub fn compress(raw: &[u8], encoding: BrickEncoding, codec: Codec) -> Vec<u8> {
    if codec.filter == Filter::Auto {
        let plain = compress(
            raw,
            encoding,
            Codec {
                filter: Filter::None,
                ..codec
            },
        );
        let delta = compress(
            raw,
            encoding,
            Codec {
                filter: Filter::Delta,
                ..codec
            },
        );
        return if delta.len() < plain.len() {
            delta
        } else {
            plain
        };
    }
    let filtered;
    let data = if codec.filter == Filter::Delta {
        filtered = delta_forward(raw, bytes_per_value(encoding));
        &filtered[..]
    } else {
        raw
    };
    let mut out = Vec::with_capacity(raw.len() / 2 + 16);
    out.push(codec.tag());
    out.extend_from_slice(&(raw.len() as u32).to_le_bytes());
    match codec.compressor {
        Compressor::Lz4 => out.extend_from_slice(&lz4_flex::block::compress(data)),
        Compressor::Zstd(level) => out.extend_from_slice(&zstd_compress(data, level)),
    }
    out
}

/// zstd at `level` through one compression context per thread and level (a
/// fresh context per brick cost 3 % of an import); the output is the same.
fn zstd_compress(data: &[u8], level: i32) -> Vec<u8> {
    use std::cell::RefCell;
    thread_local! {
        static CONTEXTS: RefCell<Vec<(i32, zstd::bulk::Compressor<'static>)>> =
            const { RefCell::new(Vec::new()) };
    }
    CONTEXTS.with(|c| {
        let mut c = c.borrow_mut();
        let i = match c.iter().position(|(l, _)| *l == level) {
            Some(i) => i,
            None => {
                let made = zstd::bulk::Compressor::new(level)
                    .expect("a zstd compression context for a valid level");
                c.push((level, made));
                c.len() - 1
            }
        };
        c[i].1
            .compress(data)
            .expect("zstd compresses any input in memory")
    })
}

/// zstd decompression of at most `capacity` bytes through one context per
/// thread (the loader's I/O threads and the import decode every brick).
fn zstd_decompress(data: &[u8], capacity: usize) -> std::io::Result<Vec<u8>> {
    use std::cell::RefCell;
    thread_local! {
        static CONTEXT: RefCell<Option<zstd::bulk::Decompressor<'static>>> =
            const { RefCell::new(None) };
    }
    CONTEXT.with(|c| {
        let mut c = c.borrow_mut();
        if c.is_none() {
            *c = Some(zstd::bulk::Decompressor::new()?);
        }
        c.as_mut().unwrap().decompress(data, capacity)
    })
}

/// Wrapping differences of consecutive `width`-byte values, then the bytes
/// split into planes (all first bytes, all second bytes, …).
fn delta_forward(raw: &[u8], width: usize) -> Vec<u8> {
    let n = raw.len() / width;
    let mut out = vec![0u8; raw.len()];
    match width {
        1 => {
            out.iter_mut().zip(raw).fold(0u8, |prev, (o, &v)| {
                *o = v.wrapping_sub(prev);
                v
            });
        }
        2 => {
            let (lo, hi) = out.split_at_mut(n);
            let mut prev = 0u16;
            for ((c, l), h) in raw.chunks_exact(2).zip(lo).zip(hi) {
                let v = u16::from_le_bytes([c[0], c[1]]);
                let [a, b] = v.wrapping_sub(prev).to_le_bytes();
                (*l, *h) = (a, b);
                prev = v;
            }
        }
        _ => {
            let mut prev = 0u32;
            for (i, c) in raw.chunks_exact(4).enumerate() {
                let v = u32::from_le_bytes([c[0], c[1], c[2], c[3]]);
                let d = v.wrapping_sub(prev).to_le_bytes();
                for (b, byte) in d.into_iter().enumerate() {
                    out[b * n + i] = byte;
                }
                prev = v;
            }
        }
    }
    out
}

fn delta_inverse(planes: &[u8], width: usize) -> Vec<u8> {
    // Running sums of the differences, the planes gathered back into
    // little-endian values.
    if width == 1 {
        return planes
            .iter()
            .scan(0u8, |acc, &d| {
                *acc = acc.wrapping_add(d);
                Some(*acc)
            })
            .collect();
    }
    let n = planes.len() / width;
    let mut out = vec![0u8; planes.len()];
    if width == 2 {
        let (lo, hi) = planes.split_at(n);
        let mut acc = 0u16;
        for ((o, &l), &h) in out.chunks_exact_mut(2).zip(lo).zip(hi) {
            acc = acc.wrapping_add(u16::from_le_bytes([l, h]));
            o.copy_from_slice(&acc.to_le_bytes());
        }
        return out;
    }
    let (p0, rest) = planes.split_at(n);
    let (p1, rest) = rest.split_at(n);
    let (p2, p3) = rest.split_at(n);
    let mut acc = 0u32;
    for (i, o) in out.chunks_exact_mut(4).enumerate() {
        acc = acc.wrapping_add(u32::from_le_bytes([p0[i], p1[i], p2[i], p3[i]]));
        o.copy_from_slice(&acc.to_le_bytes());
    }
    out
}

fn bytes_per_value(encoding: BrickEncoding) -> usize {
    match encoding {
        BrickEncoding::U8Range => 1,
        BrickEncoding::U16Range => 2,
        BrickEncoding::F32 => 4,
    }
}

/// The most bytes a brick of `len` values can take on disk (the larger of
/// LZ4's and zstd's worst cases plus tag and size prefix): a longer record is
/// corrupt.
pub fn max_encoded_len(len: usize, encoding: BrickEncoding) -> usize {
    let n = len * bytes_per_value(encoding);
    5 + lz4_flex::block::get_maximum_output_size(n).max(zstd::zstd_safe::compress_bound(n))
}

/// Why a stored brick could not be decoded.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum DecodeError {
    #[error("checksum mismatch (stored {stored:08x}, computed {computed:08x})")]
    Checksum { stored: u32, computed: u32 },
    #[error("corrupt compressed data: {0}")]
    Decompress(String),
    #[error("decoded to {got} bytes, expected {expected}")]
    Size { got: usize, expected: usize },
    #[error("unknown codec tag {0:#04x} (written by a newer Parallax?)")]
    Codec(u8),
}

/// The codec a stored brick names (format 1 is always LZ4).
pub fn stored_codec(stored: &[u8], framing: Framing) -> Result<Codec, DecodeError> {
    match framing {
        Framing::Untagged => Ok(Codec::LZ4),
        Framing::Tagged => {
            let tag = *stored
                .first()
                .ok_or_else(|| DecodeError::Decompress("empty record".into()))?;
            Codec::from_tag(tag).ok_or(DecodeError::Codec(tag))
        }
    }
}

/// Checks a stored brick's framing and size, and decompresses it to the
/// quantised bytes (`expected` of them).
pub fn decompress(
    stored: &[u8],
    encoding: BrickEncoding,
    expected: usize,
    framing: Framing,
) -> Result<Vec<u8>, DecodeError> {
    let codec = stored_codec(stored, framing)?;
    let body = match framing {
        Framing::Untagged => stored,
        Framing::Tagged => &stored[1..],
    };
    // The size prefix is checked before anything is allocated for it.
    let declared = body
        .get(..4)
        .map(|b| u32::from_le_bytes(b.try_into().unwrap()) as usize)
        .ok_or_else(|| DecodeError::Decompress("shorter than its size prefix".into()))?;
    if declared != expected {
        return Err(DecodeError::Size {
            got: declared,
            expected,
        });
    }
    let payload = &body[4..];
    let raw = match codec.compressor {
        Compressor::Lz4 => lz4_flex::block::decompress(payload, expected)
            .map_err(|e| DecodeError::Decompress(e.to_string()))?,
        Compressor::Zstd(_) => zstd_decompress(payload, expected)
            .map_err(|e| DecodeError::Decompress(e.to_string()))?,
    };
    if raw.len() != expected {
        return Err(DecodeError::Size {
            got: raw.len(),
            expected,
        });
    }
    Ok(if codec.filter == Filter::Delta {
        delta_inverse(&raw, bytes_per_value(encoding))
    } else {
        raw
    })
}

/// Decompresses a stored brick whose checksum was already checked and maps
/// it back to data values (`len` values expected).
pub fn decode_checked(
    stored: &[u8],
    min: f32,
    max: f32,
    encoding: BrickEncoding,
    len: usize,
    framing: Framing,
) -> Result<Vec<f32>, DecodeError> {
    let raw = decompress(stored, encoding, len * bytes_per_value(encoding), framing)?;
    let no_data = framing == Framing::Tagged && stored[0] & NO_DATA_BIT != 0;
    let unit = framing == Framing::Tagged && stored[0] & UNIT_STEP_BIT != 0;
    Ok(dequantise(&raw, min, max, encoding, no_data, unit))
}

/// Quantised bytes back to data values (NaN for the no-data code).
pub fn dequantise(
    raw: &[u8],
    min: f32,
    max: f32,
    encoding: BrickEncoding,
    no_data: bool,
    unit: bool,
) -> Vec<f32> {
    let q = Quantiser::new(min, max, encoding, no_data, unit);
    match encoding {
        BrickEncoding::F32 => raw
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect(),
        BrickEncoding::U8Range => raw.iter().map(|&b| q.value(b as u32)).collect(),
        BrickEncoding::U16Range => raw
            .chunks_exact(2)
            .map(|b| q.value(u16::from_le_bytes([b[0], b[1]]) as u32))
            .collect(),
    }
}

/// The linear map between a brick's [min, max] and the integer codes
/// 0..=steps. Computed in f64 so the only error is the rounding to a code.
struct Quantiser {
    min: f64,
    step: f64,
    steps: f64,
    /// The no-data code (the top one), when the brick has no-data voxels.
    no_data: Option<u32>,
}

impl Quantiser {
    fn new(min: f32, max: f32, encoding: BrickEncoding, no_data: bool, unit: bool) -> Self {
        let full = encoding.steps();
        let (steps, no_data) = if no_data && full > 0.0 {
            (full - 1.0, Some(full as u32))
        } else {
            (full, None)
        };
        let span = max as f64 - min as f64;
        Quantiser {
            min: min as f64,
            step: if unit {
                1.0
            } else if steps > 0.0 && span.is_finite() {
                span / steps
            } else {
                0.0
            },
            steps,
            no_data,
        }
    }

    fn quantise(&self, v: f32) -> u32 {
        if let (Some(code), true) = (self.no_data, v.is_nan()) {
            return code;
        }
        if self.step <= 0.0 {
            return 0;
        }
        // Round half away from zero, clamped to the codes: for x ≥ 0,
        // truncating x + ½ is the rounding (x + ½ rounds to a multiple of
        // x's ulp, never across an integer); the saturating cast takes
        // what lies below 0 (NaN included, which casts to 0) and above
        // 2³¹ to the clamp's ends. Without SSE4.1 `f64::round` is a
        // library call per voxel, a tenth of an import's time.
        let x = (v as f64 - self.min) / self.step;
        ((x + 0.5) as i32).clamp(0, self.steps as i32) as u32
    }

    fn value(&self, code: u32) -> f32 {
        if Some(code) == self.no_data {
            return f32::NAN;
        }
        (self.min + code as f64 * self.step) as f32
    }
}

/// The checksum stored with every brick (CRC-32 of its stored bytes).
pub fn checksum(bytes: &[u8]) -> u32 {
    crc32fast::hash(bytes)
}

#[cfg(test)]
pub(crate) mod tests;
