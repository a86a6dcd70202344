//! Import → .pxo → read back: every brick against the source, overlaps against
//! neighbours, inner nodes against their children, corruption detection.

use parallax_backend::store::{self, info, ImportOptions};
use parallax_backend::store::{BrickEncoding, NodeKey, OctreeDb};
use parallax_backend::volume::{MemorySource, Volume, VoxelType};
use std::path::Path;

/// A signed, anisotropic test volume with structure at every scale and a
/// region of low values (for empty-brick tests).
fn test_volume(dims: [usize; 3]) -> Volume {
    Volume::from_fn(dims, [0.5, 0.7, 1.3], VoxelType::I16, |i, j, k| {
        if i < dims[0] / 3 {
            -1000.0
        } else {
            ((i * 37 + j * 11 + k * 5) % 97) as f32 * 13.0 - 300.0 + (i as f32 * 0.37).sin() * 200.0
        }
        .round()
    })
}

fn import(vol: &Volume, out: &Path, opts: &ImportOptions) -> store::ImportReport {
    store::import(&mut MemorySource::new(vol), out, "test volume", opts).unwrap()
}

/// Reassembles a level's full voxel grid from its decoded bricks (interior
/// voxels only), checking on the way that every overlap voxel equals the
/// owning neighbour's voxel (or the clamped edge voxel).
fn level_grid(db: &OctreeDb, level: u32) -> Vec<f32> {
    let l = db.layout();
    let d = l.level_dims(level);
    let nb = l.level_bricks(level);
    let side = l.stored_side();
    let grid = db.read_level(level).unwrap();
    let mut bricks = Vec::new();
    for z in 0..nb[2] {
        for y in 0..nb[1] {
            for x in 0..nb[0] {
                let key = NodeKey::new(level as u8, x as u32, y as u32, z as u32);
                bricks.push((key, db.read_brick(key).unwrap().expect("stored")));
            }
        }
    }
    assert!(
        grid.iter().all(|v| !v.is_nan()),
        "level {level} fully covered"
    );
    for (key, v) in bricks {
        let o = l.brick_origin(key);
        for k in 0..side {
            for j in 0..side {
                for i in 0..side {
                    let c = |p: i64, n: usize| p.clamp(0, n as i64 - 1) as usize;
                    let (gx, gy, gz) = (
                        c(o[0] + i as i64, d[0]),
                        c(o[1] + j as i64, d[1]),
                        c(o[2] + k as i64, d[2]),
                    );
                    assert_eq!(
                        v[(k * side + j) * side + i],
                        grid[(gz * d[1] + gy) * d[0] + gx],
                        "brick {key} voxel ({i},{j},{k}) vs its neighbour"
                    );
                }
            }
        }
    }
    grid
}

#[test]
fn full_precision_round_trip_overlaps_and_averages() {
    let dims = [70, 45, 37];
    let vol = test_volume(dims);
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("t.pxo");
    let opts = ImportOptions {
        brick: 8,
        encoding: BrickEncoding::F32,
        ..Default::default()
    };
    let r = import(&vol, &out, &opts);
    let db = OctreeDb::open(&out).unwrap();
    let l = *db.layout();
    assert_eq!(l.levels, 5); // 8·2^4 = 128 ≥ 70
                             // 0.5 × 0.7 × 1.3: the level above the source halves x and y only
                             // (1 × 1.4 × 1.3), every level above it all three.
    assert_eq!(l.split(4), [true, true, false]);
    assert_eq!(l.split(3), [true; 3]);
    assert_eq!(l.level_dims(3), [35, 23, 37]);
    assert_eq!(r.nodes, l.node_count());
    assert_eq!(db.header.info.spacing, [0.5, 0.7, 1.3]);
    assert_eq!(db.header.info.voxel_type, VoxelType::I16);
    assert_eq!(db.summary.value_min, vol.range().0);
    assert_eq!(db.summary.value_max, vol.range().1);

    // Source level: exact.
    let leaf = level_grid(&db, l.leaf_level());
    assert_eq!(leaf, vol.data);

    // Every inner level is the 2×2×2 average of the level below along the
    // axes it halves (over the voxels that exist at odd edges).
    let mut fine = leaf;
    for level in (0..l.leaf_level()).rev() {
        let coarse = level_grid(&db, level);
        let (fd, cd) = (l.level_dims(level + 1), l.level_dims(level));
        let f = l.split(level + 1).map(|s| 1 + s as usize);
        for k in 0..cd[2] {
            for j in 0..cd[1] {
                for i in 0..cd[0] {
                    let (mut sum, mut n) = (0f64, 0);
                    for dk in 0..f[2] {
                        for dj in 0..f[1] {
                            for di in 0..f[0] {
                                let (x, y, z) = (f[0] * i + di, f[1] * j + dj, f[2] * k + dk);
                                if x < fd[0] && y < fd[1] && z < fd[2] {
                                    sum += fine[(z * fd[1] + y) * fd[0] + x] as f64;
                                    n += 1;
                                }
                            }
                        }
                    }
                    let want = sum / n as f64;
                    let got = coarse[(k * cd[1] + j) * cd[0] + i] as f64;
                    assert!(
                        (got - want).abs() <= 1e-5 * want.abs().max(1.0),
                        "level {level} voxel ({i},{j},{k}): {got} vs average {want}"
                    );
                }
            }
        }
        fine = coarse;
    }
    info::verify(&db).unwrap();
}

#[test]
fn quantised_bricks_stay_within_their_bound() {
    let vol = test_volume([40, 33, 29]);
    let dir = tempfile::tempdir().unwrap();
    for enc in [BrickEncoding::U8Range, BrickEncoding::U16Range] {
        let out = dir.path().join(format!("{}.pxo", enc.name()));
        import(
            &vol,
            &out,
            &ImportOptions {
                brick: 16,
                encoding: enc,
                ..Default::default()
            },
        );
        let db = OctreeDb::open(&out).unwrap();
        let l = *db.layout();
        let side = l.stored_side();
        let mut worst_ratio = 0f64;
        let mut max_err = 0f64;
        for n in db
            .nodes
            .iter()
            .filter(|n| n.key.level as u32 == l.leaf_level())
        {
            let v = db.read_brick(n.key).unwrap().unwrap();
            let bound = enc.error_bound(n.min, n.max) + 1e-4;
            let o = l.brick_origin(n.key);
            for k in 0..side {
                for j in 0..side {
                    for i in 0..side {
                        let c = |p: i64, d: usize| p.clamp(0, d as i64 - 1) as usize;
                        let src = vol.voxel(
                            c(o[0] + i as i64, 40),
                            c(o[1] + j as i64, 33),
                            c(o[2] + k as i64, 29),
                        ) as f64;
                        let err = (v[(k * side + j) * side + i] as f64 - src).abs();
                        assert!(
                            err <= bound,
                            "{}: brick {} error {err} > {bound}",
                            enc.name(),
                            n.key
                        );
                        worst_ratio = worst_ratio.max(err / bound);
                        max_err = max_err.max(err);
                    }
                }
            }
        }
        // the import's own figures agree with what we measure
        assert!(db.summary.quant_max <= max_err + 1e-9);
        if enc == BrickEncoding::U16Range {
            // Integer data spanning less than 65536 values: every brick on
            // the unit grid, lossless.
            assert_eq!(max_err, 0.0, "u16 bricks of 16-bit data are lossless");
            assert_eq!(db.summary.quant_rms, 0.0);
            continue;
        }
        assert!(db.summary.quant_rms > 0.0 && db.summary.quant_rms <= db.summary.quant_max);
        assert!(worst_ratio > 0.3, "the bound is tight ({worst_ratio})");
    }
}

#[test]
fn empty_bricks_are_dropped_and_counted() {
    let dims = [64, 16, 16];
    let vol = test_volume(dims); // x < 21 is −1000
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("e.pxo");
    let r = import(
        &vol,
        &out,
        &ImportOptions {
            brick: 8,
            empty_below: Some(-999.0),
            ..Default::default()
        },
    );
    let db = OctreeDb::open(&out).unwrap();
    // Leaf bricks x = 0, 1 cover voxels 0..18 (overlap included): all −1000.
    // Brick x = 2 reaches voxel 21 through its overlap: stored.
    let per = info::bricks_per_level(&db);
    let leaf = per[db.layout().leaf_level() as usize];
    assert_eq!(leaf, (6 * 2 * 2, 2 * 2 * 2));
    assert_eq!(r.empty, per.iter().map(|p| p.1).sum::<usize>());
    for n in &db.nodes {
        let expect_empty = n.max < -999.0;
        assert_eq!(!n.is_stored(), expect_empty, "{}", n.key);
        if !n.is_stored() {
            assert!(db.read_brick(n.key).unwrap().is_none());
        }
    }
}

#[test]
fn corruption_and_truncation_are_reported_with_the_brick() {
    let vol = test_volume([32, 32, 32]);
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("c.pxo");
    import(
        &vol,
        &out,
        &ImportOptions {
            brick: 16,
            ..Default::default()
        },
    );
    let db = OctreeDb::open(&out).unwrap();
    let victim = *db.nodes.iter().filter(|n| n.is_stored()).nth(3).unwrap();
    drop(db);
    let mut bytes = std::fs::read(&out).unwrap();
    bytes[(victim.offset + victim.len as u64 / 2) as usize] ^= 0x40;
    let bad = dir.path().join("bad.pxo");
    std::fs::write(&bad, &bytes).unwrap();
    let db = OctreeDb::open(&bad).unwrap();
    let e = format!("{:#}", db.read_brick(victim.key).unwrap_err());
    assert!(
        e.contains("bad.pxo") && e.contains(&victim.key.to_string()) && e.contains("checksum"),
        "{e}"
    );
    let e = format!("{:#}", info::verify(&db).unwrap_err());
    assert!(e.contains(&victim.key.to_string()), "{e}");
    // other bricks still read
    let other = *db
        .nodes
        .iter()
        .find(|n| n.is_stored() && n.key != victim.key)
        .unwrap();
    assert!(db.read_brick(other.key).unwrap().is_some());

    // truncated file: no footer
    std::fs::write(&bad, &bytes[..bytes.len() - 100]).unwrap();
    let e = format!("{:#}", OctreeDb::open(&bad).err().unwrap());
    assert!(e.contains("bad.pxo") && e.contains("truncated"), "{e}");
    // corrupt node table
    let mut b2 = std::fs::read(&out).unwrap();
    let n = b2.len();
    b2[n - 40] ^= 1;
    std::fs::write(&bad, &b2).unwrap();
    let e = format!("{:#}", OctreeDb::open(&bad).err().unwrap());
    assert!(e.contains("node table"), "{e}");
    // not a database at all
    std::fs::write(&bad, b"hello world, this is not an octree database at all").unwrap();
    let e = format!("{:#}", OctreeDb::open(&bad).err().unwrap());
    assert!(e.contains("bad magic"), "{e}");
}

#[test]
fn a_failed_import_keeps_the_existing_file_and_leaves_no_temporary() {
    let vol = test_volume([64, 64, 64]);
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("keep.pxo");
    std::fs::write(&out, b"precious").unwrap();
    let e = store::import(
        &mut MemorySource::new(&vol),
        &out,
        "v",
        &ImportOptions {
            memory_mb: 0,
            ..Default::default()
        },
    )
    .unwrap_err();
    assert!(format!("{e:#}").contains("--memory-mb"), "{e:#}");
    // a source that fails halfway through
    struct Failing<'a>(MemorySource<'a>, usize);
    impl parallax_backend::volume::VolumeSource for Failing<'_> {
        fn info(&self) -> &parallax_backend::volume::VolumeInfo {
            self.0.info()
        }
        fn read_slices(&mut self, out: &mut [f32]) -> anyhow::Result<()> {
            self.1 += 1;
            anyhow::ensure!(self.1 < 40, "disk on fire");
            self.0.read_slices(out)
        }
    }
    let e = store::import(
        &mut Failing(MemorySource::new(&vol), 0),
        &out,
        "v",
        &ImportOptions::default(),
    )
    .unwrap_err();
    assert!(format!("{e:#}").contains("disk on fire"));
    assert_eq!(std::fs::read(&out).unwrap(), b"precious");
    let names: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names.len(), 1, "{names:?}");
}

#[test]
fn single_voxel_and_thin_volumes_import() {
    let dir = tempfile::tempdir().unwrap();
    for dims in [[1, 1, 1], [1, 50, 3], [100, 1, 1]] {
        let vol = Volume::from_fn(dims, [1.0; 3], VoxelType::U8, |i, j, k| {
            (i + 2 * j + 3 * k) as f32
        });
        let out = dir.path().join("s.pxo");
        import(
            &vol,
            &out,
            &ImportOptions {
                brick: 16,
                encoding: BrickEncoding::F32,
                ..Default::default()
            },
        );
        let db = OctreeDb::open(&out).unwrap();
        assert_eq!(
            level_grid(&db, db.layout().leaf_level()),
            vol.data,
            "{dims:?}"
        );
        level_grid(&db, 0);
    }
}

/// Format 5 records which axes each level halves. A file of format 4 (no
/// such record: every level halves all three axes) still opens as that
/// octree: made here by rewriting a fresh import with levels halving all
/// axes into format 4's header (same length, so every brick stays where it
/// is), it reads brick for brick like the file it came from, while a
/// default import of the same thick slices halves the finer axes first.
#[test]
fn format_four_files_open_as_octrees_halving_every_axis() {
    use parallax_backend::store::format::{bincode_config, HeaderV4, LayoutV4, PREAMBLE_LEN};
    use parallax_backend::store::OctreeLayout;
    let dims = [40, 36, 6];
    let vol = Volume::from_fn(dims, [0.5, 0.5, 3.0], VoxelType::U16, |i, j, k| {
        ((i * 7 + j * 13 + k * 101) % 300) as f32
    });
    let dir = tempfile::tempdir().unwrap();
    let (iso_path, fitted_path, v4_path) = (
        dir.path().join("iso.pxo"),
        dir.path().join("fitted.pxo"),
        dir.path().join("v4.pxo"),
    );
    let opts = ImportOptions {
        brick: 8,
        ..Default::default()
    };
    import(
        &vol,
        &iso_path,
        &ImportOptions {
            isotropic_levels: true,
            ..opts.clone()
        },
    );
    import(&vol, &fitted_path, &opts);
    let iso = OctreeDb::open(&iso_path).unwrap();
    let fitted = OctreeDb::open(&fitted_path).unwrap();
    assert_eq!(*iso.layout(), OctreeLayout::new(dims, 8));
    assert_eq!(
        *fitted.layout(),
        OctreeLayout::for_spacing(dims, 8, [0.5, 0.5, 3.0])
    );
    assert_ne!(iso.layout(), fitted.layout());
    // 0.5 × 0.5 × 3: x and y are halved twice (2 × 2 × 3 mm) before z.
    assert_eq!(
        fitted.layout().split(fitted.layout().leaf_level()),
        [true, true, false]
    );
    assert_eq!(fitted.layout().level_dims(1), [10, 9, 6]);
    info::verify(&fitted).unwrap();

    // Format 4's header: the layout without its split record, padded to the
    // same length.
    let mut b = std::fs::read(&iso_path).unwrap();
    let len = u32::from_le_bytes(b[12..16].try_into().unwrap()) as usize;
    let h = iso.header.clone();
    let old = HeaderV4 {
        info: h.info,
        layout: LayoutV4 {
            dims: h.layout.dims,
            brick: h.layout.brick,
            levels: h.layout.levels,
        },
        encoding: h.encoding,
        empty_below: h.empty_below,
        source: h.source,
    };
    let mut enc = bincode::serde::encode_to_vec(&old, bincode_config()).unwrap();
    assert!(enc.len() < len);
    enc.resize(len, 0);
    b[8..12].copy_from_slice(&4u32.to_le_bytes());
    b[16..20].copy_from_slice(&crc32fast::hash(&enc).to_le_bytes());
    b[PREAMBLE_LEN..PREAMBLE_LEN + len].copy_from_slice(&enc);
    std::fs::write(&v4_path, b).unwrap();
    assert_eq!(format_version(&v4_path), 4);

    let v4 = OctreeDb::open(&v4_path).unwrap();
    assert_eq!(v4.layout(), iso.layout());
    assert_eq!(v4.nodes.len(), iso.nodes.len());
    for n in &iso.nodes {
        assert_eq!(
            v4.read_brick(n.key).unwrap(),
            iso.read_brick(n.key).unwrap(),
            "brick {}",
            n.key
        );
    }
    info::verify(&v4).unwrap();
}

/// The format version in a `.pxo` file's preamble.
fn format_version(path: &Path) -> u32 {
    let bytes = std::fs::read(path).unwrap();
    u32::from_le_bytes(bytes[8..12].try_into().unwrap())
}

/// A database kept in `tests/fixtures` by an earlier release, and a fresh
/// import (this build's format, the default codec) of the fixture volume it
/// was made from, with bricks of `brick`.
fn old_and_fresh(old: &str, source: &str, brick: usize) -> (OctreeDb, OctreeDb, tempfile::TempDir) {
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures");
    let old = OctreeDb::open(&fixtures.join(old)).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("new.pxo");
    let mut src = parallax_backend::data::open(&fixtures.join(source), None).unwrap();
    let opts = ImportOptions {
        brick,
        ..Default::default()
    };
    store::import(src.as_mut(), &out, source, &opts).unwrap();
    assert_eq!(format_version(&out), store::format::VERSION);
    let new = OctreeDb::open(&out).unwrap();
    (old, new, dir)
}

/// A `.pxo` written by the first release (format 1: untagged LZ4 bricks)
/// still opens, and every brick decodes to what a fresh import of the same
/// NRRD holds (none of this 16-bit volume's bricks fits the unit grid).
#[test]
fn format_one_files_still_read() {
    let (old, new, _dir) = old_and_fresh("v1-shells40.pxo", "shells40-u16.nrrd", 16);
    assert_eq!(old.framing(), store::codec::Framing::Untagged);
    assert_eq!(new.framing(), store::codec::Framing::Tagged);
    assert_eq!(old.nodes.len(), new.nodes.len());
    let mut compared = 0;
    for n in &old.nodes {
        let a = old.read_brick(n.key).unwrap();
        let b = new.read_brick(n.key).unwrap();
        assert_eq!(a, b, "brick {}", n.key);
        compared += a.is_some() as usize;
    }
    assert!(compared > 8, "{compared} bricks compared");
    assert!(
        new.file_len() < old.file_len(),
        "{} ≥ {}",
        new.file_len(),
        old.file_len()
    );
}

/// A `.pxo` of format 2 (tagged bricks, every 8-bit brick quantised in 255
/// range steps; `v2-ml24.pxo`, the previous release's import of the 24³
/// u8 Marschner–Lobb `ml24-u8.nrrd` with bricks of 8) still opens in this
/// build, which writes format 3 (integer bricks on the unit grid): every
/// brick decodes to within its quantisation bound of a fresh import, which
/// itself is exact wherever the unit grid fits.
#[test]
fn format_two_files_still_read() {
    let (old, new, _dir) = old_and_fresh("v2-ml24.pxo", "ml24-u8.nrrd", 8);
    assert_eq!(old.framing(), store::codec::Framing::Tagged);
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures");
    assert_eq!(format_version(&fixtures.join("v2-ml24.pxo")), 2);
    assert_eq!(old.nodes.len(), new.nodes.len());
    let (mut compared, mut moved) = (0, 0);
    for n in &old.nodes {
        let (Some(a), Some(b)) = (
            old.read_brick(n.key).unwrap(),
            new.read_brick(n.key).unwrap(),
        ) else {
            assert_eq!(n.is_stored(), new.node(n.key).unwrap().is_stored());
            continue;
        };
        let bound = old.encoding().error_bound(n.min, n.max) + 1e-3;
        for (x, y) in a.iter().zip(&b) {
            assert!((x - y).abs() as f64 <= bound, "brick {}: {x} vs {y}", n.key);
        }
        compared += 1;
        moved += (a != b) as usize;
    }
    eprintln!("{compared} bricks compared, {moved} decode differently (now on the unit grid)");
    assert!(compared > 8, "{compared} bricks compared");
    assert!(moved > 0, "the unit grid changed some bricks");
    assert!(new.summary.quant_max <= old.summary.quant_max);
}

/// Format 4: every stored brick carries its macrocell ranges (L12 §4.1),
/// computed by the importer from the values the renderer interpolates;
/// each stored range holds every value interpolation inside its cell can
/// read, and is at most one code (1/255 of the brick's range) wider on each
/// side. Files of formats 1–3 carry none (the pool computes them).
#[test]
fn stored_macrocell_ranges_hold_what_interpolation_reads() {
    use store::cells;
    let dir = tempfile::tempdir().unwrap();
    let dims = [48, 40, 36];
    let src = test_volume(dims);
    // A float volume with a few no-data voxels (NaN, `--nan empty`).
    let vol = Volume::from_fn(dims, src.info.spacing, VoxelType::F32, |i, j, k| {
        let at = (k * dims[1] + j) * dims[0] + i;
        if [5000, 5001, 20_000].contains(&at) {
            f32::NAN
        } else {
            src.data[at]
        }
    });
    for encoding in [
        BrickEncoding::U8Range,
        BrickEncoding::U16Range,
        BrickEncoding::F32,
    ] {
        let out = dir.path().join(format!("{encoding:?}.pxo"));
        import(
            &vol,
            &out,
            &ImportOptions {
                brick: 16,
                encoding,
                ..Default::default()
            },
        );
        let db = OctreeDb::open(&out).unwrap();
        assert!(db.stores_cells());
        let (c, _) = cells::layout(16);
        let mut checked = 0;
        for n in db.nodes.iter().filter(|n| n.is_stored()) {
            let brick = db.read_brick_cells(n.key).unwrap().unwrap();
            let stored = brick.cells.expect("format 4 stores cells");
            assert_eq!(stored.len(), c * c * c);
            let exact = cells::ranges(16, |i| {
                let v = brick.values[i];
                (!v.is_nan()).then_some(v as f64)
            });
            let step = (n.max - n.min) / 255.0 * 1.0001 + 1e-6;
            for (s, e) in stored.iter().zip(&exact) {
                if e[0] > e[1] {
                    assert!(s[0] > s[1], "{encoding:?} {}: a cell without data", n.key);
                    continue;
                }
                assert!(
                    s[0] <= e[0] && s[1] >= e[1],
                    "{encoding:?} {}: {s:?} ⊉ {e:?}",
                    n.key
                );
                assert!(e[0] - s[0] <= step && s[1] - e[1] <= step, "{s:?} vs {e:?}");
                checked += 1;
            }
        }
        eprintln!("{encoding:?}: {checked} cells checked");
        assert!(checked > 500);
    }
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures");
    let old = OctreeDb::open(&fixtures.join("v2-ml24.pxo")).unwrap();
    assert!(!old.stores_cells());
    let root = old.read_brick_cells(NodeKey::root()).unwrap().unwrap();
    assert!(root.cells.is_none());
}
