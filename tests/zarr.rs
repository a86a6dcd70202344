//! OME-Zarr written by the ome-zarr and zarr Python packages
//! (`tests/data/make_zarr.py`): Zarr v2 (NGFF 0.4) and v3 (NGFF 0.5),
//! blosc, zstd, gzip and sharding, a 3-level pyramid, channel and time
//! axes, imported to the arrays' own voxels and spacing; and the damaged
//! files, each refused (or, for a missing chunk, filled and said) naming
//! the file and the array. The test command installs the writers in
//! `target/py-zarr` (scripts/test.sh). Also time series: a 4-D NIfTI
//! written by nibabel and an OME-Zarr image's `t` axis imported as a
//! scene's series (`--all-times`).

use parallax_backend::data::zarr::ZarrSelect;
use parallax_backend::data::{self, InputOptions};
use parallax_backend::volume::{Volume, VoxelType};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

/// The writers' Python: `PARALLAX_ZARR_PYTHON`, else the test command's
/// virtual environment.
fn python() -> PathBuf {
    std::env::var_os("PARALLAX_ZARR_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("target/py-zarr/bin/python"))
}

/// The images, written once per test run.
fn inputs() -> PathBuf {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("zarr-inputs");
        let _ = std::fs::remove_dir_all(&dir);
        let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/make_zarr.py");
        let py = python();
        let o = Command::new(&py)
            .arg(&script)
            .arg(&dir)
            .output()
            .unwrap_or_else(|e| {
                panic!(
                    "run {} ({e}): scripts/test.sh installs zarr and ome-zarr there",
                    py.display()
                )
            });
        assert!(
            o.status.success(),
            "{} failed:\n{}",
            script.display(),
            String::from_utf8_lossy(&o.stderr)
        );
        dir
    })
    .clone()
}

fn select(level: usize, channel: Option<usize>, time: Option<usize>) -> InputOptions {
    InputOptions {
        zarr: ZarrSelect {
            level: Some(level),
            channel,
            time,
        },
        ..Default::default()
    }
}

fn read(path: &Path, opts: &InputOptions) -> (Volume, Option<String>, Option<String>) {
    let mut src = data::open_with(path, opts).unwrap_or_else(|e| panic!("{e:#}"));
    let vol = Volume::read_all(src.as_mut()).unwrap_or_else(|e| panic!("{e:#}"));
    (vol, src.describe(), src.conversion_note())
}

fn open_err(path: &Path, opts: &InputOptions) -> String {
    match data::open_with(path, opts) {
        Ok(mut src) => match Volume::read_all(src.as_mut()) {
            Ok(_) => panic!("{} read without an error", path.display()),
            Err(e) => format!("{e:#}"),
        },
        Err(e) => format!("{e:#}"),
    }
}

/// The array's own samples as `make_zarr.py` wrote them: (dims x, y, z,
/// values as f32, numpy dtype).
fn expected(name: &str) -> ([usize; 3], Vec<f32>, String) {
    let dir = inputs();
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join(format!("{name}.json"))).unwrap())
            .unwrap();
    let shape: Vec<usize> = meta["shape"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap() as usize)
        .collect();
    let dtype = meta["dtype"].as_str().unwrap().to_string();
    let bytes = std::fs::read(dir.join(format!("{name}.raw"))).unwrap();
    let values: Vec<f32> = match dtype.as_str() {
        "int16" => bytes
            .chunks_exact(2)
            .map(|b| i16::from_le_bytes([b[0], b[1]]) as f32)
            .collect(),
        "uint16" => bytes
            .chunks_exact(2)
            .map(|b| u16::from_le_bytes([b[0], b[1]]) as f32)
            .collect(),
        "float32" => bytes
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect(),
        other => panic!("{name}: dtype {other}"),
    };
    ([shape[2], shape[1], shape[0]], values, dtype)
}

#[test]
fn every_writer_codec_level_channel_and_time_point_imports_to_the_arrays_voxels_and_spacing() {
    let dir = inputs();
    // (file, its channels, its time points, the sample type)
    let images = [
        ("v2-blosc.ome.zarr", 2, 0, VoxelType::I16),
        ("v2-zstd.ome.zarr", 2, 0, VoxelType::I16),
        ("v3-zstd.ome.zarr", 2, 0, VoxelType::I16),
        ("v3-sharded.ome.zarr", 2, 2, VoxelType::U16),
        ("v3-gzip-f32.ome.zarr", 1, 0, VoxelType::F32),
    ];
    let mut checked = 0;
    for (file, channels, times, voxel_type) in images {
        for level in 0..3usize {
            for c in 0..channels {
                for t in 0..times.max(1) {
                    let time = (times > 0).then_some(t);
                    let tag = match time {
                        Some(t) => format!("s{level}.t{t}.c{c}"),
                        None => format!("s{level}.c{c}"),
                    };
                    let (dims, values, dtype) = expected(&format!("{file}.{tag}"));
                    let (vol, described, note) =
                        read(&dir.join(file), &select(level, Some(c), time));
                    assert_eq!(vol.info.dims, dims, "{file} {tag}");
                    assert_eq!(vol.info.voxel_type, voxel_type, "{file} {tag} ({dtype})");
                    // Bit for bit: every voxel of the array itself.
                    let same = vol
                        .data
                        .iter()
                        .zip(&values)
                        .filter(|(a, b)| a.to_bits() == b.to_bits())
                        .count();
                    assert_eq!(
                        (same, vol.data.len()),
                        (values.len(), values.len()),
                        "{file} {tag}: voxels equal to the array's"
                    );
                    // The level's scale: 0.75 × 0.5 × 2.5 µm, doubled per level.
                    let f = (1 << level) as f64;
                    assert_eq!(
                        vol.info.spacing,
                        [0.75 * f, 0.5 * f, 2.5 * f],
                        "{file} {tag}"
                    );
                    let d = described.unwrap();
                    assert!(d.contains(&format!("level {level} of 3")), "{d}");
                    assert!(d.contains("spacing in micrometer"), "{d}");
                    assert!(note.is_none(), "{file} {tag}: {note:?}");
                    checked += 1;
                }
            }
        }
    }
    assert_eq!(checked, 3 * (2 + 2 + 2 + 4 + 1));
    // The defaults are level 0, channel 0, time 0, and say what they chose.
    let (vol, described, _) = read(&dir.join("v3-sharded.ome.zarr"), &InputOptions::default());
    assert_eq!(vol.data, expected("v3-sharded.ome.zarr.s0.t0.c0").1);
    let d = described.unwrap();
    assert!(
        d.contains("NGFF 0.5, Zarr v3")
            && d.contains("t 0 of 2 (--time)")
            && d.contains("c 0 of 2 (--channel)"),
        "{d}"
    );
    let (_, described, _) = read(&dir.join("v2-blosc.ome.zarr"), &InputOptions::default());
    assert!(described.unwrap().contains("NGFF 0.4, Zarr v2"));
}

#[test]
fn a_missing_chunk_takes_the_fill_value_and_is_said_once() {
    let dir = inputs();
    let (vol, _, note) = read(
        &dir.join("missing-chunk.ome.zarr"),
        &InputOptions::default(),
    );
    let (dims, values, _) = expected("v3-zstd.ome.zarr.s0.c0");
    assert_eq!(vol.info.dims, dims);
    // Chunk (c 0, z 1, y 1, x 0) of 8 × 10 × 12: z 8..16, y 10..20, x 0..12.
    let mut filled = 0;
    for k in 0..16 {
        for j in 0..20 {
            for i in 0..24 {
                let at = (k * 20 + j) * 24 + i;
                if (8..16).contains(&k) && (10..20).contains(&j) && i < 12 {
                    assert_eq!(vol.data[at], 0.0, "({i}, {j}, {k}): the fill value");
                    filled += 1;
                } else {
                    assert_eq!(vol.data[at], values[at], "({i}, {j}, {k})");
                }
            }
        }
    }
    assert_eq!(filled, 8 * 10 * 12);
    let note = note.expect("the missing chunk is said");
    assert_eq!(note.lines().count(), 1, "{note}");
    assert!(
        note.contains("missing-chunk.ome.zarr: array \"s0\": 1 of the 8 chunks read are missing")
            && note.contains("fill value 0"),
        "{note}"
    );
}

#[test]
fn damaged_files_and_bad_choices_are_refused_naming_the_file_and_the_array() {
    let dir = inputs();
    let none = InputOptions::default();
    let cases: [(&str, InputOptions, &[&str]); 8] = [
        (
            "corrupt-chunk.ome.zarr",
            InputOptions::default(),
            &[
                "corrupt-chunk.ome.zarr: array \"s0\": chunk [0, 1, 1, 0]",
                "key \"s0/c/0/1/1/0\"",
                "cannot decode",
            ],
        ),
        (
            "inconsistent.ome.zarr",
            InputOptions::default(),
            &[
                "inconsistent.ome.zarr",
                "multiscales[0].datasets[0].coordinateTransformations[0].scale has 3 values for 4 axes",
            ],
        ),
        (
            "axes-mismatch.ome.zarr",
            InputOptions::default(),
            &[
                "axes-mismatch.ome.zarr: array \"s0\": 4 dimensions",
                "multiscales[0].axes lists 3",
            ],
        ),
        (
            "lzma.ome.zarr",
            InputOptions::default(),
            &["lzma.ome.zarr: array \"s0\"", "lzma is not supported"],
        ),
        (
            "v2-blosc.ome.zarr",
            select(3, None, None),
            &["v2-blosc.ome.zarr: --level 3: the image has 3 resolution levels"],
        ),
        (
            "v3-zstd.ome.zarr",
            select(0, Some(2), None),
            &["v3-zstd.ome.zarr: --channel 2: axis \"c\" has 2"],
        ),
        (
            "v3-zstd.ome.zarr",
            select(0, None, Some(0)),
            &["v3-zstd.ome.zarr: --time: the image has no time axis"],
        ),
        (
            "v3-sharded.ome.zarr",
            select(0, None, Some(5)),
            &["v3-sharded.ome.zarr: --time 5: axis \"t\" has 2"],
        ),
    ];
    for (file, opts, wants) in cases {
        let t = std::time::Instant::now();
        let e = open_err(&dir.join(file), &opts);
        assert!(t.elapsed().as_secs_f64() < 1.0, "{file}: {:?}", t.elapsed());
        for w in wants {
            assert!(e.contains(w), "{file}: {w:?} not in: {e}");
        }
    }
    // A .zarr folder without metadata, and a choice given for another format.
    let empty = dir.join("empty.zarr");
    std::fs::create_dir_all(&empty).unwrap();
    let e = open_err(&empty, &none);
    assert!(
        e.contains("empty.zarr: a .zarr folder without Zarr metadata"),
        "{e}"
    );
    let nrrd = dir.join("v.nrrd");
    std::fs::write(&nrrd, "NRRD0004\n").unwrap();
    let e = open_err(&nrrd, &select(1, None, None));
    assert!(
        e.contains("v.nrrd: --level, --channel and --time choose within an OME-Zarr image"),
        "{e}"
    );
}

#[test]
fn parallax_import_reads_an_ome_zarr_channel_into_an_octree() {
    let dir = inputs();
    let out = dir.join("imported.pxo");
    let o = Command::new(env!("CARGO_BIN_EXE_parallax"))
        .args(["import"])
        .arg(dir.join("v2-blosc.ome.zarr"))
        .args(["--channel", "1", "--quantize", "none", "--brick", "8", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("c 1 of 2 (--channel)"), "{err}");
    // Its pyramid halves z with y and x, where the octree over 0.75 × 0.5
    // × 2.5 voxels halves y first: none of its levels is reused, and the
    // import says so.
    assert!(
        err.contains(
            "resolution level 1 (12×10×8 voxels of 1.5×1×5) is none of the octree's levels"
        ),
        "{err}"
    );
    let db = parallax_backend::store::OctreeDb::open(&out).unwrap();
    assert_eq!(db.header.info.dims, [24, 20, 16]);
    assert_eq!(db.header.info.spacing, [0.75, 0.5, 2.5]);
    // The stored range is the channel's.
    let (_, values, _) = expected("v2-blosc.ome.zarr.s0.c1");
    let lo = values.iter().cloned().fold(f32::INFINITY, f32::min);
    let hi = values.iter().cloned().fold(f32::NEG_INFINITY, f32::max);
    assert_eq!((db.summary.value_min, db.summary.value_max), (lo, hi));
    assert_eq!(db.summary.quant_max, 0.0, "full precision");
}

#[test]
fn parallax_synth_writes_an_ome_zarr_that_reads_back_as_its_nrrd() {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("zarr-synth");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    // 70 × 70 × 30: two rows of 64³ chunks along y and x, a partial one.
    let mut vols = Vec::new();
    for name in ["ct.nrrd", "ct.ome.zarr"] {
        let out = dir.join(name);
        let o = Command::new(env!("CARGO_BIN_EXE_parallax"))
            .args([
                "synth", "ct", "--size", "70", "--slices", "30", "--type", "i16", "-o",
            ])
            .arg(&out)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        vols.push(read(&out, &InputOptions::default()));
    }
    let (nrrd, zarr) = (&vols[0].0, &vols[1].0);
    assert_eq!(zarr.info, nrrd.info);
    let differ = zarr
        .data
        .iter()
        .zip(&nrrd.data)
        .filter(|(a, b)| a != b)
        .count();
    assert_eq!(differ, 0, "voxels that differ from the NRRD's");
    let d = vols[1].1.as_deref().unwrap();
    assert!(
        d.contains("NGFF 0.5, Zarr v3") && d.contains("spacing in millimeter"),
        "{d}"
    );
    // No partial image is left beside it.
    let left: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().contains("partial"))
        .collect();
    assert!(left.is_empty(), "{left:?}");
}

/// The 2×2 average in x and y of a grid of `d` voxels (z kept), as f64.
fn mean_xy(g: &[f32], d: [usize; 3]) -> Vec<f64> {
    let mut out = Vec::new();
    for k in 0..d[2] {
        for j in 0..d[1] / 2 {
            for i in 0..d[0] / 2 {
                let at =
                    |di: usize, dj: usize| g[(k * d[1] + 2 * j + dj) * d[0] + 2 * i + di] as f64;
                out.push((at(0, 0) + at(1, 0) + at(0, 1) + at(1, 1)) / 4.0);
            }
        }
    }
    out
}

fn import_pyramid(extra: &[&str]) -> (parallax_backend::store::OctreeDb, String, String) {
    let dir = inputs();
    let out = dir.join(format!("pyramid{}.pxo", extra.len()));
    let o = Command::new(env!("CARGO_BIN_EXE_parallax"))
        .arg("import")
        .arg(dir.join("pyramid.ome.zarr"))
        .args(["--quantize", "none", "--brick", "8", "-o"])
        .arg(&out)
        .args(extra)
        .output()
        .unwrap();
    let (stdout, stderr) = (
        String::from_utf8_lossy(&o.stdout).to_string(),
        String::from_utf8_lossy(&o.stderr).to_string(),
    );
    assert!(o.status.success(), "{stderr}");
    (
        parallax_backend::store::OctreeDb::open(&out).unwrap(),
        stdout,
        stderr,
    )
}

#[test]
fn the_files_pyramid_becomes_the_octrees_coarser_levels_and_its_difference_is_reported() {
    // 64 × 64 × 16 voxels of 1 × 1 × 4 µm, a pyramid halving y and x: the
    // octree (bricks of 8) halves the same axes, so its levels 2 and 1 are
    // the file's levels 1 and 2; the root (8³) is averaged from level 1.
    let (db, stdout, _) = import_pyramid(&[]);
    let l = db.layout();
    assert_eq!(l.levels, 4);
    assert_eq!(l.level_dims(2), [32, 32, 16]);
    assert_eq!(l.level_dims(1), [16, 16, 16]);
    let (d0, s0, _) = expected("pyramid.ome.zarr.s0");
    let (d1, s1, _) = expected("pyramid.ome.zarr.s1");
    let (d2, s2, _) = expected("pyramid.ome.zarr.s2");
    assert_eq!((d0, d1, d2), ([64, 64, 16], [32, 32, 16], [16, 16, 16]));
    // The source level and the two reused levels hold the file's voxels,
    // bit for bit.
    assert_eq!(db.read_level(3).unwrap(), s0);
    assert_eq!(db.read_level(2).unwrap(), s1);
    assert_eq!(db.read_level(1).unwrap(), s2);
    // The writer's levels are not averages (it interpolates), and the
    // report says by how much: against the average of s0 for level 2, of
    // s1 (as stored) for level 1.
    for (level, file_level, fine, fine_d, coarse) in [(2, 1, &s0, d0, &s1), (1, 2, &s1, d1, &s2)] {
        let avg = mean_xy(fine, fine_d);
        let d: Vec<f64> = coarse
            .iter()
            .zip(&avg)
            .map(|(&c, &a)| c as f64 - a)
            .collect();
        let rms = (d.iter().map(|x| x * x).sum::<f64>() / d.len() as f64).sqrt();
        let max = d.iter().fold(0f64, |m, x| m.max(x.abs()));
        assert!(
            rms > 1.0,
            "the writer's level {file_level} is not an average"
        );
        let line = stdout
            .lines()
            .find(|s| {
                s.starts_with(&format!(
                    "level {level} from the file's resolution level {file_level}:"
                ))
            })
            .unwrap_or_else(|| panic!("no report of level {level}:\n{stdout}"));
        let nums: Vec<f64> = line
            .split(|c: char| !(c.is_ascii_digit() || c == '.'))
            .filter_map(|t| t.parse().ok())
            .collect();
        // level, file level, RMS, max, voxels
        assert!((nums[2] - rms).abs() <= 1e-3 * rms, "{line}: RMS {rms}");
        assert!((nums[3] - max).abs() <= 1e-3 * max, "{line}: max {max}");
        assert_eq!(nums[4] as usize, coarse.len(), "{line}");
    }
    // The root: the 2×2×2 average of the file's level 2.
    let root = db.read_level(0).unwrap();
    for k in 0..8 {
        for j in 0..8 {
            for i in 0..8 {
                let mut sum = 0.0;
                for (di, dj, dk) in (0..8).map(|n| (n & 1, (n >> 1) & 1, n >> 2)) {
                    sum += s2[((2 * k + dk) * 16 + 2 * j + dj) * 16 + 2 * i + di] as f64;
                }
                let got = root[(k * 8 + j) * 8 + i] as f64;
                assert!(
                    (got - sum / 8.0).abs() < 1e-2,
                    "root ({i}, {j}, {k}): {got} against {}",
                    sum / 8.0
                );
            }
        }
    }

    // A coarser level that cannot be read does not stop the import: it is
    // named, and the octree's levels are averaged.
    let o = Command::new(env!("CARGO_BIN_EXE_parallax"))
        .arg("import")
        .arg(inputs().join("pyramid-broken.ome.zarr"))
        .args(["--quantize", "none", "--brick", "8", "-o"])
        .arg(inputs().join("pyramid-broken.pxo"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains("coarser resolution levels cannot be read") && err.contains("s2"),
        "{err}"
    );
    assert!(!String::from_utf8_lossy(&o.stdout).contains("from the file's resolution level"));

    // --recompute-levels: level 2 is the average of the source again.
    let (db, stdout, _) = import_pyramid(&["--recompute-levels"]);
    assert!(
        !stdout.contains("from the file's resolution level"),
        "{stdout}"
    );
    let avg = mean_xy(&s0, d0);
    let level2 = db.read_level(2).unwrap();
    assert!(level2
        .iter()
        .zip(&avg)
        .all(|(&s, &a)| (s as f64 - a).abs() < 1e-2));
}

/// `parallax import … --all-times -o DIR`: every time point into
/// DIR/tNNNN.pxo; returns the run's stdout.
fn import_all_times(input: &Path, out: &Path, extra: &[&str]) -> String {
    let _ = std::fs::remove_dir_all(out);
    let o = Command::new(env!("CARGO_BIN_EXE_parallax"))
        .arg("import")
        .arg(input)
        .args(["--all-times", "--quantize", "none", "--brick", "8", "-o"])
        .arg(out)
        .args(extra)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).to_string()
}

fn leaf_values(pxo: &Path) -> Vec<f32> {
    let db = parallax_backend::store::OctreeDb::open(pxo).unwrap();
    db.read_level(db.layout().leaf_level()).unwrap()
}

#[test]
fn every_time_point_of_a_4d_nifti_and_of_an_ome_zarr_t_axis_imports_as_a_series() {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("series-4d");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    // nibabel writes a gzip 4-D NIfTI: 6 × 5 × 4 voxels of 0.5 × 0.75 × 2
    // mm, 3 time points, each its own values; beside it each time point
    // as raw f32, x fastest.
    let script = r#"
import sys, numpy as np, nibabel as nib
d = sys.argv[1]
x, y, z = np.meshgrid(np.arange(6), np.arange(5), np.arange(4), indexing="ij")
vol = np.stack([(x * 3 + y * 17 + z * 101) * (t + 1) - 700 * t for t in range(3)], axis=-1).astype(np.int16)
img = nib.Nifti1Image(vol, np.diag([0.5, 0.75, 2.0, 1.0]))
img.header.set_xyzt_units("mm", "sec")
nib.save(img, d + "/scan4d.nii.gz")
for t in range(3):
    vol[..., t].astype("<f4").flatten(order="F").tofile(d + f"/t{t}.raw")
"#;
    let o = Command::new(python())
        .args(["-c", script])
        .arg(&dir)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stdout = import_all_times(&dir.join("scan4d.nii.gz"), &dir.join("nii"), &[]);
    assert!(stdout.contains("3 time points in"), "{stdout}");
    assert!(stdout.contains("series = ["), "{stdout}");
    for t in 0..3 {
        let want: Vec<f32> = std::fs::read(dir.join(format!("t{t}.raw")))
            .unwrap()
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        let pxo = dir.join(format!("nii/t{t:04}.pxo"));
        assert_eq!(leaf_values(&pxo), want, "time point {t}");
        let db = parallax_backend::store::OctreeDb::open(&pxo).unwrap();
        assert_eq!(db.header.info.spacing, [0.5, 0.75, 2.0]);
    }
    // One time point by --time, and one past the end refused.
    let one = dir.join("t2.pxo");
    let o = Command::new(env!("CARGO_BIN_EXE_parallax"))
        .arg("import")
        .arg(dir.join("scan4d.nii.gz"))
        .args(["--time", "2", "--quantize", "none", "--brick", "8", "-o"])
        .arg(&one)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("time point 2 of 3"), "{err}");
    assert_eq!(leaf_values(&one), leaf_values(&dir.join("nii/t0002.pxo")));
    let o = Command::new(env!("CARGO_BIN_EXE_parallax"))
        .arg("import")
        .arg(dir.join("scan4d.nii.gz"))
        .args(["--time", "3", "-o"])
        .arg(dir.join("t3.pxo"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("scan4d.nii.gz") && err.contains("--time 3: dim[4] holds 3 time point(s)"),
        "{err}"
    );

    // The OME-Zarr image with a t axis (2 points) and a channel axis.
    let stdout = import_all_times(
        &inputs().join("v3-sharded.ome.zarr"),
        &dir.join("zarr"),
        &["--channel", "1"],
    );
    assert!(stdout.contains("2 time points in"), "{stdout}");
    for t in 0..2 {
        let (_, want, _) = expected(&format!("v3-sharded.ome.zarr.s0.t{t}.c1"));
        assert_eq!(
            leaf_values(&dir.join(format!("zarr/t{t:04}.pxo"))),
            want,
            "time point {t}"
        );
    }
}
