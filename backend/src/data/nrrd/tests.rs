//! NRRD reader and writer tests.

use super::*;
use crate::volume::{Volume, VolumeInfo, VolumeSource, VoxelType};
use std::fs;
use std::io::Write;
use std::path::Path;

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
    for t in VoxelType::ALL {
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
        !std::fs::read_dir(dir.path()).unwrap().any(|e| e
            .unwrap()
            .file_name()
            .to_string_lossy()
            .ends_with(".tmp")),
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
            base("uchar", "3", "2 2 2", "zip", ""),
            vec![0; 8],
            "encoding 'zip' is not a NRRD encoding (raw, gzip, bzip2, ascii or hex)",
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
    // hex and bzip2 read; a bad digit or a damaged stream is named.
    for (enc, data) in [
        ("hex", b"01 02 0a 0B\n0c0d 0e ff\n".to_vec()),
        ("bzip2", {
            let mut e = bzip2::write::BzEncoder::new(Vec::new(), bzip2::Compression::default());
            e.write_all(&[1, 2, 10, 11, 12, 13, 14, 255]).unwrap();
            e.finish().unwrap()
        }),
    ] {
        let p = d.join(format!("{enc}.nrrd"));
        let mut bytes =
            format!("NRRD0004\n{}\n", base("uchar", "3", "2 2 2", enc, "")).into_bytes();
        bytes.extend_from_slice(&data);
        fs::write(&p, &bytes).unwrap();
        let mut src = open_nrrd(&p).unwrap();
        let v = Volume::read_all(&mut src).unwrap();
        assert_eq!(
            v.data,
            [1.0, 2.0, 10.0, 11.0, 12.0, 13.0, 14.0, 255.0],
            "{enc}"
        );
        bytes.truncate(bytes.len() - 3);
        fs::write(&p, &bytes).unwrap();
        let e = open_nrrd(&p).and_then(|mut s| Volume::read_all(&mut s).map(|_| ()));
        assert!(
            format!("{:#}", e.unwrap_err()).contains(&format!("{enc}.nrrd")),
            "{enc}"
        );
    }
    let p = d.join("badhex.nrrd");
    let mut bytes = format!("NRRD0004\n{}\n", base("uchar", "3", "2 2 2", "hex", "")).into_bytes();
    bytes.extend_from_slice(b"0102030405060g08");
    fs::write(&p, &bytes).unwrap();
    let e = open_nrrd(&p).and_then(|mut s| Volume::read_all(&mut s).map(|_| ()));
    let e = format!("{:#}", e.unwrap_err());
    assert!(
        e.contains("badhex.nrrd") && e.contains("'g' is not a hex digit"),
        "{e}"
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
        format!(
            "{}: voxel (2,0,1) is NaN{}",
            d.join("bad.nrrd").display(),
            " (if NaN means \"no data\" here, import with --nan empty)"
        )
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

mod wide_types {
    use super::*;
    use crate::volume::Volume;

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

mod ascii {
    use super::*;
    use crate::volume::Volume;

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

/// `space`, `space directions` and `space origin` give the scanner
/// geometry in LPS (a RAS space's x and y turned); a space that is not a
/// patient's, or no origin, gives none.
#[test]
fn the_space_fields_place_the_volume_in_lps() {
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, space: &str, origin: &str| {
        let p = dir.path().join(name);
        let mut bytes = format!(
            "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\n{space}\
             space directions: (0,0.5,0) (-0.5,0,0) (0,0,2)\n{origin}encoding: raw\n\n"
        )
        .into_bytes();
        bytes.extend([0u8; 8]);
        fs::write(&p, bytes).unwrap();
        open_nrrd(&p).unwrap().world()
    };
    let w = write(
        "ras.nrrd",
        "space: right-anterior-superior\n",
        "space origin: (10, 20, 30)\n",
    )
    .unwrap();
    // Voxel (1, 1, 1)'s centre: origin + each axis's direction, in RAS.
    let s = [0.5, 0.5, 2.0];
    let p: [f64; 3] = std::array::from_fn(|a| 1.5 * s[a]);
    let lps: [f64; 3] =
        std::array::from_fn(|r| w[r][0] * p[0] + w[r][1] * p[1] + w[r][2] * p[2] + w[r][3]);
    let ras = [10.0 - 0.5, 20.0 + 0.5, 30.0 + 2.0];
    assert!(
        (0..3).all(|k| (lps[k] - [-ras[0], -ras[1], ras[2]][k]).abs() < 1e-12),
        "{lps:?}"
    );
    assert_eq!(
        write(
            "none.nrrd",
            "space: scanner-xyz\n",
            "space origin: (1,2,3)\n"
        ),
        None
    );
    assert_eq!(write("noorigin.nrrd", "space: LPS\n", ""), None);
}
