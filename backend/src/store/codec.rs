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

/// Quantises (if the encoding says so) and compresses a brick whose values
/// span [min, max]. The result is what is stored on disk.
pub fn encode(values: &[f32], min: f32, max: f32, encoding: BrickEncoding) -> Vec<u8> {
    let raw: Vec<u8> = match encoding {
        BrickEncoding::F32 => bytemuck::cast_slice::<f32, u8>(values).to_vec(),
        BrickEncoding::U8Range => {
            let q = Quantiser::new(min, max, encoding);
            values.iter().map(|&v| q.quantise(v) as u8).collect()
        }
        BrickEncoding::U16Range => {
            let q = Quantiser::new(min, max, encoding);
            values
                .iter()
                .flat_map(|&v| (q.quantise(v) as u16).to_le_bytes())
                .collect()
        }
    };
    lz4_flex::compress_prepend_size(&raw)
}

fn bytes_per_value(encoding: BrickEncoding) -> usize {
    match encoding {
        BrickEncoding::U8Range => 1,
        BrickEncoding::U16Range => 2,
        BrickEncoding::F32 => 4,
    }
}

/// The most bytes a brick of `len` values can take on disk (LZ4's worst case
/// plus its 4-byte size prefix): a longer record is corrupt.
pub fn max_encoded_len(len: usize, encoding: BrickEncoding) -> usize {
    4 + lz4_flex::block::get_maximum_output_size(len * bytes_per_value(encoding))
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
) -> Result<Vec<f32>, DecodeError> {
    let computed = crc32fast::hash(stored);
    if computed != crc {
        return Err(DecodeError::Checksum {
            stored: crc,
            computed,
        });
    }
    let bytes_per = bytes_per_value(encoding);
    // The size prefix is checked before anything is allocated for it.
    let declared = stored
        .get(..4)
        .map(|b| u32::from_le_bytes(b.try_into().unwrap()) as usize)
        .ok_or_else(|| DecodeError::Decompress("shorter than its size prefix".into()))?;
    if declared != len * bytes_per {
        return Err(DecodeError::Size {
            got: declared,
            expected: len * bytes_per,
        });
    }
    let raw = lz4_flex::decompress_size_prepended(stored)
        .map_err(|e| DecodeError::Decompress(e.to_string()))?;
    if raw.len() != len * bytes_per {
        return Err(DecodeError::Size {
            got: raw.len(),
            expected: len * bytes_per,
        });
    }
    let q = Quantiser::new(min, max, encoding);
    Ok(match encoding {
        BrickEncoding::F32 => raw
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect(),
        BrickEncoding::U8Range => raw.iter().map(|&b| q.value(b as u32)).collect(),
        BrickEncoding::U16Range => raw
            .chunks_exact(2)
            .map(|b| q.value(u16::from_le_bytes([b[0], b[1]]) as u32))
            .collect(),
    })
}

/// The linear map between a brick's [min, max] and the integer codes
/// 0..=steps. Computed in f64 so the only error is the rounding to a code.
struct Quantiser {
    min: f64,
    step: f64,
    steps: f64,
}

impl Quantiser {
    fn new(min: f32, max: f32, encoding: BrickEncoding) -> Self {
        let steps = encoding.steps();
        let span = max as f64 - min as f64;
        Quantiser {
            min: min as f64,
            step: if steps > 0.0 { span / steps } else { 0.0 },
            steps,
        }
    }

    fn quantise(&self, v: f32) -> u32 {
        if self.step <= 0.0 {
            return 0;
        }
        ((v as f64 - self.min) / self.step)
            .round()
            .clamp(0.0, self.steps) as u32
    }

    fn value(&self, code: u32) -> f32 {
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

    fn ramp() -> Vec<f32> {
        (0..1000).map(|i| -1024.0 + (i as f32) * 3.7).collect()
    }

    #[test]
    fn round_trips_within_the_quantisation_bound() {
        let v = ramp();
        let (lo, hi) = value_range(&v);
        for enc in [
            BrickEncoding::U8Range,
            BrickEncoding::U16Range,
            BrickEncoding::F32,
        ] {
            let s = encode(&v, lo, hi, enc);
            let d = decode(&s, crc32fast::hash(&s), lo, hi, enc, v.len()).unwrap();
            let bound = enc.error_bound(lo, hi);
            let worst = v
                .iter()
                .zip(&d)
                .map(|(a, b)| (*a as f64 - *b as f64).abs())
                .fold(0.0, f64::max);
            // f32 rounding of the decoded value adds at most half an ulp of
            // the largest magnitude (2^-24 · 4096 here).
            assert!(worst <= bound + 1e-3, "{enc:?}: {worst} > {bound}");
            if enc == BrickEncoding::F32 {
                assert_eq!(worst, 0.0);
            }
        }
    }

    #[test]
    fn constant_brick_decodes_exactly() {
        let v = vec![42.5f32; 64];
        let s = encode(&v, 42.5, 42.5, BrickEncoding::U8Range);
        let d = decode(
            &s,
            crc32fast::hash(&s),
            42.5,
            42.5,
            BrickEncoding::U8Range,
            64,
        )
        .unwrap();
        assert!(d.iter().all(|&x| x == 42.5));
    }

    #[test]
    fn corruption_is_detected() {
        let v = ramp();
        let (lo, hi) = value_range(&v);
        let mut s = encode(&v, lo, hi, BrickEncoding::U8Range);
        let crc = crc32fast::hash(&s);
        s[5] ^= 0x10;
        assert!(matches!(
            decode(&s, crc, lo, hi, BrickEncoding::U8Range, v.len()),
            Err(DecodeError::Checksum { .. })
        ));
        // a wrong expected length is caught even with a valid checksum
        let s = encode(&v, lo, hi, BrickEncoding::U8Range);
        assert!(matches!(
            decode(&s, crc32fast::hash(&s), lo, hi, BrickEncoding::U8Range, 999),
            Err(DecodeError::Size { .. })
        ));
    }
}
