use super::*;

/// Checks a stored brick against its checksum, decompresses it and maps it
/// back to data values (`len` values expected).
pub(crate) fn decode(
    bytes: &[u8],
    crc: u32,
    lo: f32,
    hi: f32,
    enc: BrickEncoding,
    n: usize,
    fr: Framing,
) -> Result<Vec<f32>, DecodeError> {
    let computed = crc32fast::hash(bytes);
    if computed != crc {
        return Err(DecodeError::Checksum {
            stored: crc,
            computed,
        });
    }
    decode_checked(bytes, lo, hi, enc, n, fr)
}

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

#[test]
fn the_codes_round_as_f64_round_does_and_the_integer_test_is_fract() {
    // Quantiser::quantise rounds by truncating x + ½ (no library call):
    // the same codes as round-half-away-from-zero, clamped, for every x,
    // ties, negative, NaN, infinite and huge ones included.
    for encoding in [BrickEncoding::U8Range, BrickEncoding::U16Range] {
        let q = Quantiser::new(0.0, 1.0, encoding, false, true);
        let steps = encoding.steps();
        let mut xs: Vec<f64> = (-2000..200_000).map(|i| i as f64 * 0.5).collect();
        xs.extend((0..100_000).map(|i| (i as f64 * 0.7310585786300049).fract() * 70000.0 - 10.0));
        for k in 0..200 {
            let t = k as f64 + 0.5;
            xs.extend([
                t,
                f64::from_bits(t.to_bits() - 1),
                f64::from_bits(t.to_bits() + 1),
            ]);
        }
        xs.extend([
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            3e9,
            -3e9,
            1e300,
            -0.0,
        ]);
        for x in xs {
            // With min 0 and the unit step, quantise(v) sees x = v.
            let v = x as f32;
            let want = if (v as f64).is_nan() {
                0
            } else {
                (v as f64).round().clamp(0.0, steps) as u32
            };
            assert_eq!(q.quantise(v), want, "{encoding:?}: {v}");
        }
    }
    for v in [
        0.0f32, -0.0, 1.0, -1.5, 2.5, 8388607.5, 8388608.0, 1e30, -1e30, 0.1, 123456.0,
    ] {
        assert_eq!(is_integer(v), v.fract() == 0.0, "{v}");
    }
    assert!(!is_integer(f32::INFINITY) && !is_integer(f32::NAN));
}
