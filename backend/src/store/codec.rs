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
    /// speed on Colin27, a CT and a smooth field (docs/figures.md
    /// "Compression").
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
        && values.iter().all(|v| v.is_nan() || v.fract() == 0.0)
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
    let no_data = encoding != BrickEncoding::F32 && values.iter().any(|v| v.is_nan());
    let unit = unit_step_fits(values, min, max, encoding, no_data);
    let mut out = compress(
        &quantise(values, min, max, encoding, no_data, unit),
        encoding,
        codec,
    );
    if no_data {
        out[0] |= NO_DATA_BIT;
    }
    if unit {
        out[0] |= UNIT_STEP_BIT;
    }
    out
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
        Compressor::Zstd(level) => out.extend_from_slice(
            &zstd::bulk::compress(data, level).expect("zstd compresses any input in memory"),
        ),
    }
    out
}

/// Wrapping differences of consecutive `width`-byte values, then the bytes
/// split into planes (all first bytes, all second bytes, …).
fn delta_forward(raw: &[u8], width: usize) -> Vec<u8> {
    let n = raw.len() / width;
    let mut out = vec![0u8; raw.len()];
    match width {
        1 => {
            let mut prev = 0u8;
            for (o, &v) in out.iter_mut().zip(raw) {
                *o = v.wrapping_sub(prev);
                prev = v;
            }
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
    let n = planes.len() / width;
    let mut out = vec![0u8; planes.len()];
    match width {
        1 => {
            let mut acc = 0u8;
            for (o, &d) in out.iter_mut().zip(planes) {
                acc = acc.wrapping_add(d);
                *o = acc;
            }
        }
        2 => {
            let (lo, hi) = planes.split_at(n);
            let mut acc = 0u16;
            for ((o, &l), &h) in out.chunks_exact_mut(2).zip(lo).zip(hi) {
                acc = acc.wrapping_add(u16::from_le_bytes([l, h]));
                o.copy_from_slice(&acc.to_le_bytes());
            }
        }
        _ => {
            let (p0, rest) = planes.split_at(n);
            let (p1, rest) = rest.split_at(n);
            let (p2, p3) = rest.split_at(n);
            let mut acc = 0u32;
            for (i, o) in out.chunks_exact_mut(4).enumerate() {
                acc = acc.wrapping_add(u32::from_le_bytes([p0[i], p1[i], p2[i], p3[i]]));
                o.copy_from_slice(&acc.to_le_bytes());
            }
        }
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
        Compressor::Zstd(_) => zstd::bulk::decompress(payload, expected)
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

/// Checks a stored brick against its checksum, decompresses it and maps it
/// back to data values (`len` values expected).
pub fn decode(
    stored: &[u8],
    crc: u32,
    min: f32,
    max: f32,
    encoding: BrickEncoding,
    len: usize,
    framing: Framing,
) -> Result<Vec<f32>, DecodeError> {
    let computed = crc32fast::hash(stored);
    if computed != crc {
        return Err(DecodeError::Checksum {
            stored: crc,
            computed,
        });
    }
    decode_checked(stored, min, max, encoding, len, framing)
}

/// [`decode`] of bytes whose checksum was already checked.
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
        ((v as f64 - self.min) / self.step)
            .round()
            .clamp(0.0, self.steps) as u32
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
mod tests {
    use super::*;

    const CODECS: [Codec; 5] = [
        Codec::LZ4,
        Codec {
            compressor: Compressor::Lz4,
            filter: Filter::Delta,
        },
        Codec {
            compressor: Compressor::Zstd(3),
            filter: Filter::None,
        },
        Codec {
            compressor: Compressor::Zstd(1),
            filter: Filter::Delta,
        },
        Codec::DEFAULT,
    ];
    const ENCODINGS: [BrickEncoding; 3] = [
        BrickEncoding::U8Range,
        BrickEncoding::U16Range,
        BrickEncoding::F32,
    ];

    fn ramp() -> Vec<f32> {
        (0..1000).map(|i| -1024.0 + (i as f32) * 3.7).collect()
    }

    #[test]
    fn round_trips_within_the_quantisation_bound_with_every_codec() {
        let v = ramp();
        let (lo, hi) = value_range(&v);
        for enc in ENCODINGS {
            let exact = quantise(
                &v,
                lo,
                hi,
                enc,
                false,
                unit_step_fits(&v, lo, hi, enc, false),
            );
            for codec in CODECS {
                let s = encode(&v, lo, hi, enc, codec);
                if codec.filter != Filter::Auto {
                    assert_eq!(
                        stored_codec(&s, Framing::Tagged).unwrap().tag(),
                        codec.tag()
                    );
                }
                let raw = decompress(&s, enc, exact.len(), Framing::Tagged).unwrap();
                assert_eq!(raw, exact, "{enc:?} {}: lossless", codec.name());
                let d = decode(&s, checksum(&s), lo, hi, enc, v.len(), Framing::Tagged).unwrap();
                let bound = enc.error_bound(lo, hi);
                let worst = v
                    .iter()
                    .zip(&d)
                    .map(|(a, b)| (*a as f64 - *b as f64).abs())
                    .fold(0.0, f64::max);
                // f32 rounding of the decoded value adds at most half an ulp
                // of the largest magnitude (2^-24 · 4096 here).
                assert!(worst <= bound + 1e-3, "{enc:?}: {worst} > {bound}");
                if enc == BrickEncoding::F32 {
                    assert_eq!(worst, 0.0);
                }
            }
        }
    }

    #[test]
    fn delta_filter_inverts_on_extremes_and_helps_ramps() {
        for width in [1usize, 2, 4] {
            let raw: Vec<u8> = (0..width * 300).map(|i| (i * 7919 % 256) as u8).collect();
            assert_eq!(delta_inverse(&delta_forward(&raw, width), width), raw);
            let ramp: Vec<u8> = (0..3000u32)
                .flat_map(|i| (i * 13).to_le_bytes()[..width].to_vec())
                .collect();
            let d = delta_forward(&ramp, width);
            assert_eq!(delta_inverse(&d, width), ramp);
            let plain = compress(&ramp, enc_of(width), CODECS[2]).len();
            let filtered = compress(&ramp, enc_of(width), CODECS[3]).len();
            assert!(filtered < plain, "width {width}: {filtered} ≥ {plain}");
            // Auto keeps the smaller of the two, brick by brick.
            let auto = compress(&ramp, enc_of(width), Codec::DEFAULT);
            assert_eq!(auto.len(), filtered);
            assert_eq!(
                stored_codec(&auto, Framing::Tagged).unwrap().filter,
                Filter::Delta
            );
            let noise: Vec<u8> = (0..3000u64)
                .map(|i| (i.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 56) as u8 & 0x0f)
                .collect();
            let auto = compress(&noise, BrickEncoding::U8Range, Codec::DEFAULT);
            let plain = compress(&noise, BrickEncoding::U8Range, CODECS[2]).len();
            assert!(auto.len() <= plain + 1, "{} > {plain}", auto.len());
        }
    }

    fn enc_of(width: usize) -> BrickEncoding {
        match width {
            1 => BrickEncoding::U8Range,
            2 => BrickEncoding::U16Range,
            _ => BrickEncoding::F32,
        }
    }

    #[test]
    fn format_one_bricks_still_decode() {
        // What the first release wrote: LZ4 with lz4_flex's size prefix.
        let v = ramp();
        let (lo, hi) = value_range(&v);
        let old = lz4_flex::compress_prepend_size(&quantise(
            &v,
            lo,
            hi,
            BrickEncoding::U8Range,
            false,
            false,
        ));
        let d = decode(
            &old,
            checksum(&old),
            lo,
            hi,
            BrickEncoding::U8Range,
            v.len(),
            Framing::Untagged,
        )
        .unwrap();
        let new = encode(&v, lo, hi, BrickEncoding::U8Range, Codec::DEFAULT);
        let d2 = decode(
            &new,
            checksum(&new),
            lo,
            hi,
            BrickEncoding::U8Range,
            v.len(),
            Framing::Tagged,
        )
        .unwrap();
        assert_eq!(d, d2);
    }

    #[test]
    fn codec_names_parse_back_and_bad_ones_are_refused() {
        for c in CODECS {
            assert_eq!(Codec::parse(&c.name()), Some(c));
        }
        assert_eq!(Codec::parse("zstd"), Some(Codec::parse("zstd1").unwrap()));
        for bad in ["", "zstd0", "zstd20", "gzip", "lz4+", "+delta", "zstd-1"] {
            assert_eq!(Codec::parse(bad), None, "{bad}");
        }
        assert!(Codec::from_tag(0x02).is_none() && Codec::from_tag(0x80).is_none());
        assert!(Codec::from_tag(0x31).is_some(), "zstd, delta, no data");
    }

    #[test]
    fn no_data_voxels_survive_every_encoding_and_codec() {
        let mut v = ramp();
        for i in (0..v.len()).step_by(7) {
            v[i] = f32::NAN;
        }
        let (lo, hi) = value_range(&v);
        assert!(lo.is_finite() && hi.is_finite());
        for enc in ENCODINGS {
            for codec in CODECS {
                let s = encode(&v, lo, hi, enc, codec);
                let d = decode(&s, checksum(&s), lo, hi, enc, v.len(), Framing::Tagged).unwrap();
                // The top code is no data: the bound is that of one code fewer.
                let bound = match enc {
                    BrickEncoding::U8Range => (hi - lo) as f64 / (2.0 * 254.0),
                    BrickEncoding::U16Range => (hi - lo) as f64 / (2.0 * 65534.0),
                    BrickEncoding::F32 => 0.0,
                };
                for (a, b) in v.iter().zip(&d) {
                    assert_eq!(a.is_nan(), b.is_nan(), "{enc:?} {}", codec.name());
                    if !a.is_nan() {
                        assert!((*a as f64 - *b as f64).abs() <= bound + 1e-3, "{a} {b}");
                    }
                }
            }
        }
        // A brick without NaN keeps every code for values.
        let s = encode(&ramp(), lo, hi, BrickEncoding::U8Range, Codec::DEFAULT);
        assert_eq!(s[0] & NO_DATA_BIT, 0);
    }

    #[test]
    fn integer_bricks_within_the_codes_are_lossless() {
        // A CT brick of soft tissue: integers spanning 200 (8 bit) and
        // 3000 (16 bit) values, with a no-data voxel.
        for (enc, span) in [
            (BrickEncoding::U8Range, 200.0),
            (BrickEncoding::U16Range, 3000.0),
        ] {
            let mut v: Vec<f32> = (0..729)
                .map(|i| -50.0 + ((i * 37) % 200) as f32 * span / 200.0)
                .collect();
            v[5] = f32::NAN;
            let (lo, hi) = value_range(&v);
            assert!(unit_step_fits(&v, lo, hi, enc, true));
            let s = encode(&v, lo, hi, enc, Codec::DEFAULT);
            assert_ne!(s[0] & UNIT_STEP_BIT, 0);
            let d = decode(&s, checksum(&s), lo, hi, enc, v.len(), Framing::Tagged).unwrap();
            for (a, b) in v.iter().zip(&d) {
                assert!(a == b || (a.is_nan() && b.is_nan()), "{enc:?}: {a} → {b}");
            }
        }
        // Not integers, or wider than the codes: the range step, no bit.
        let half: Vec<f32> = (0..64).map(|i| i as f32 * 0.5).collect();
        let wide: Vec<f32> = (0..64).map(|i| i as f32 * 5.0).collect();
        for v in [half, wide] {
            let (lo, hi) = value_range(&v);
            let s = encode(&v, lo, hi, BrickEncoding::U8Range, Codec::DEFAULT);
            assert_eq!(s[0] & UNIT_STEP_BIT, 0);
        }
    }

    #[test]
    fn constant_brick_decodes_exactly() {
        let v = vec![42.5f32; 64];
        for codec in CODECS {
            let s = encode(&v, 42.5, 42.5, BrickEncoding::U8Range, codec);
            let d = decode(
                &s,
                checksum(&s),
                42.5,
                42.5,
                BrickEncoding::U8Range,
                64,
                Framing::Tagged,
            )
            .unwrap();
            assert!(d.iter().all(|&x| x == 42.5));
        }
    }

    #[test]
    fn corruption_is_detected() {
        let v = ramp();
        let (lo, hi) = value_range(&v);
        let enc = BrickEncoding::U8Range;
        for codec in CODECS {
            let mut s = encode(&v, lo, hi, enc, codec);
            let crc = checksum(&s);
            s[6] ^= 0x10;
            assert!(matches!(
                decode(&s, crc, lo, hi, enc, v.len(), Framing::Tagged),
                Err(DecodeError::Checksum { .. })
            ));
            // With a matching checksum, damage is still an error, never a panic.
            let d = decode(&s, checksum(&s), lo, hi, enc, v.len(), Framing::Tagged);
            if let Ok(d) = d {
                assert_eq!(d.len(), v.len());
            }
            // a wrong expected length is caught even with a valid checksum
            let s = encode(&v, lo, hi, enc, codec);
            assert!(matches!(
                decode(&s, checksum(&s), lo, hi, enc, 999, Framing::Tagged),
                Err(DecodeError::Size { .. })
            ));
            let mut t = s.clone();
            t[0] = 0x0f;
            assert_eq!(
                decode(&t, checksum(&t), lo, hi, enc, v.len(), Framing::Tagged),
                Err(DecodeError::Codec(0x0f))
            );
        }
    }
}
