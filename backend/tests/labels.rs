//! Label layers (a `[[layer]]` with `labels`: a segmentation drawn through
//! its colour table): the import that keeps labels at every level, the
//! colour of each label on Colin27 against the labels themselves, and the
//! errors for labels a table lacks, fractions and volumes of values. Every
//! test prints the figures it asserts on.

mod support;
use parallax_backend::data;
use parallax_backend::gpu::AdapterRequest;
use parallax_backend::reference;
use parallax_backend::render::Renderer;
use parallax_backend::store::{self, BrickEncoding, ImportOptions, NodeKey, OctreeDb};
use parallax_backend::volume::{MemorySource, Volume, VoxelType};
use parallax_common::camera::View;
use parallax_common::config::{Layer, RenderConfig};
use parallax_common::tf::{ControlPoint, TransferFunction};
use std::path::Path;

fn label_layer(volume: &Path, table: &Path) -> Layer {
    Layer {
        volume: volume.to_path_buf(),
        transfer_function: None,
        labels: Some(table.to_path_buf()),
        opacity: 1.0,
        visible: true,
        view_opacity: None,
        transform: None,
    }
}

fn import_labels(vol: &Volume, out: &Path, encoding: BrickEncoding) -> anyhow::Result<()> {
    store::import(
        &mut MemorySource::new(vol),
        out,
        "test labels",
        &ImportOptions {
            brick: 8,
            encoding,
            labels: true,
            ..Default::default()
        },
    )
    .map(|_| ())
}

/// Labels 0, 1, 2 and 7 in blocks and thin sheets, 40³.
fn blocks() -> Volume {
    Volume::from_fn([40, 40, 40], [1.0; 3], VoxelType::U8, |i, j, k| {
        if i == 20 {
            7.0 // a sheet one voxel thick
        } else if i < 12 && j < 30 {
            1.0
        } else if k > 25 {
            2.0
        } else {
            0.0
        }
    })
}

/// Every stored voxel of every level of `db`.
fn every_value(db: &OctreeDb) -> Vec<f32> {
    let mut out = Vec::new();
    for n in db.nodes.iter().filter(|n| n.is_stored()) {
        out.extend(db.read_brick(n.key).unwrap().unwrap());
    }
    out
}

/// A label volume's coarser levels hold labels, never averages: every
/// stored value at every level is one of the source's labels, the summary
/// lists them, and a one-voxel sheet of label 7 survives into the coarsest
/// level (a label wins over the background).
#[test]
fn label_import_keeps_labels_at_every_level() {
    let dir = tempfile::tempdir().unwrap();
    let vol = blocks();
    let db_path = dir.path().join("labels.pxo");
    import_labels(&vol, &db_path, BrickEncoding::U8Range).unwrap();
    let db = OctreeDb::open(&db_path).unwrap();
    assert_eq!(db.summary.labels.as_deref(), Some(&[0, 1, 2, 7][..]));
    let values = every_value(&db);
    let strays = values
        .iter()
        .filter(|v| ![0.0, 1.0, 2.0, 7.0].contains(*v))
        .count();
    let root = db.read_brick(NodeKey::new(0, 0, 0, 0)).unwrap().unwrap();
    let sheet_at_root = root.iter().filter(|&&v| v == 7.0).count();
    println!(
        "label import: {} levels, {} stored values, {strays} not a label; {sheet_at_root} root voxels of the one-voxel sheet",
        db.layout().levels,
        values.len()
    );
    assert!(db.layout().levels >= 3);
    assert_eq!(strays, 0);
    assert!(sheet_at_root > 0);
    // The same volume imported as values averages: 3.5 between 0 and 7.
    let plain = dir.path().join("plain.pxo");
    support::import_volume(&vol, &plain, 8, BrickEncoding::F32);
    let plain = OctreeDb::open(&plain).unwrap();
    assert_eq!(plain.summary.labels, None);
    assert!(every_value(&plain)
        .iter()
        .any(|v| ![0.0, 1.0, 2.0, 7.0].contains(v)));
}

/// A fraction is an uncertain label and a brick of more labels than 8 bits
/// hold is refused by the import, naming the voxel or the brick, within a
/// second; full precision stores it.
#[test]
fn label_import_refuses_fractions_and_lossy_bricks() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("l.pxo");
    let frac = Volume::from_fn([16, 16, 16], [1.0; 3], VoxelType::F32, |i, j, k| {
        if (i, j, k) == (3, 4, 5) {
            2.5
        } else {
            1.0
        }
    });
    let t = std::time::Instant::now();
    let e = format!(
        "{:#}",
        import_labels(&frac, &out, BrickEncoding::U8Range).unwrap_err()
    );
    println!("refused in {:?}: {e}", t.elapsed());
    assert!(
        e.contains("(3, 4, 5)") && e.contains("2.5") && e.contains("uncertain"),
        "{e}"
    );
    assert!(t.elapsed().as_secs_f64() < 1.0);
    assert!(!out.exists(), "nothing written under the name");
    let wide = Volume::from_fn([16, 16, 16], [1.0; 3], VoxelType::U16, |i, _, _| {
        (i * 100) as f32
    });
    let e = format!(
        "{:#}",
        import_labels(&wide, &out, BrickEncoding::U8Range).unwrap_err()
    );
    println!("refused: {e}");
    assert!(e.contains("--quantize none"), "{e}");
    import_labels(&wide, &out, BrickEncoding::F32).unwrap();
    let db = OctreeDb::open(&out).unwrap();
    assert_eq!(db.summary.labels.as_ref().map(Vec::len), Some(16));
    assert!(every_value(&db).iter().all(|v| v % 100.0 == 0.0));
}

/// What a pixel's ray meets in a label volume, marched at the nearest
/// voxel every 0.05 mm: its path length through each label, the first
/// label other than 0 and the length of that first run.
struct Marched {
    lengths: Vec<f64>,
    first: usize,
    run: f64,
}

fn march(
    vol: &Volume,
    placement: &parallax_common::camera::Placement,
    view: &View,
) -> Vec<Marched> {
    let ext = vol.info.extent();
    let step = 0.05;
    let [w, h] = view.resolution;
    (0..w * h)
        .map(|p| {
            let (o, d) = view.ray(p % w, p / w);
            let (vo, vd) = placement.ray_to_volume(ext, o, d);
            let mut m = Marched {
                lengths: vec![0.0; 8],
                first: 0,
                run: 0.0,
            };
            let mut open = true;
            if let Some((t0, t1)) = reference::clip_to_box(vo, vd, glam::DVec3::from(ext)) {
                let mut t = t0 + 0.5 * step;
                while t < t1 {
                    let q = vo + vd * t;
                    let i: [usize; 3] = std::array::from_fn(|a| {
                        ((q[a] / vol.info.spacing[a]).floor().max(0.0) as usize)
                            .min(vol.info.dims[a] - 1)
                    });
                    let l = vol.voxel(i[0], i[1], i[2]) as usize;
                    m.lengths[l] += step;
                    if m.first == 0 && l != 0 {
                        m.first = l;
                    }
                    if m.first != 0 && open {
                        if l == m.first {
                            m.run += step;
                        } else {
                            open = false;
                        }
                    }
                    t += step;
                }
            }
            m
        })
        .collect()
}

/// Colin27 with tissue labels made of it by thresholds (60, 95, 120: grey
/// matter, white matter, scalp fat): for each label, a colour table that
/// shows only that label, opaque (α = 1 a millimetre), in its own colour,
/// over a volume whose function shows nothing, so the label is the only
/// medium. Against the labels themselves, marched at the nearest voxel
/// every 0.05 mm along each pixel's ray: where a ray crosses at least
/// 1.5 mm of the label the pixel is opaque, where it crosses none it is
/// clear, and every pixel drawn has the label's colour.
#[test]
fn colin27_label_layer_draws_each_label_in_its_colour() {
    let dir = tempfile::tempdir().unwrap();
    let Some(colin) = support::colin27(dir.path(), BrickEncoding::U8Range) else {
        return;
    };
    let labelled = || {
        data::Thresholded::new(
            data::open(Path::new(support::COLIN27), None).unwrap(),
            vec![60.0, 95.0, 120.0],
        )
        .unwrap()
    };
    let labels_db = dir.path().join("labels.pxo");
    store::import(
        &mut labelled(),
        &labels_db,
        "Colin27 labels",
        &ImportOptions {
            labels: true,
            ..Default::default()
        },
    )
    .unwrap();
    let vol = Volume::read_all(&mut labelled()).unwrap();
    let nothing =
        TransferFunction::from_points(vec![ControlPoint::new(0.0, [0.0; 3], 0.0)]).unwrap();
    let placement = support::colin_placement();
    let (w, h) = (80u32, 80u32);
    let view = View::window([w, h], [0.3, 0.3], [0.0, 0.0, 0.8]);
    let cfg = support::exact_config();
    let colours = [[1.0, 0.1, 0.0], [0.0, 0.8, 0.2], [0.1, 0.2, 1.0]];
    let marched = march(&vol, &placement, &view);
    // The converged image of the label layer with a table of labels 0, 1,
    // … in `table`'s colours and opacities (α of 1 mm).
    let render = |name: &str, table: &[([f64; 3], f64)]| {
        let text: String = table
            .iter()
            .enumerate()
            .map(|(l, (c, a))| format!("[[label]]\nvalue = {l}\ncolor = {c:?}\nopacity = {a}\n\n"))
            .collect();
        let path = dir.path().join(format!("{name}.toml"));
        std::fs::write(&path, text).unwrap();
        let layers = [label_layer(&labels_db, &path)];
        let mut r =
            Renderer::with_layers(&colin, &layers, &cfg, &AdapterRequest::from_env(None, 0))
                .unwrap();
        r.set_transfer_function(1, &nothing).unwrap();
        r.converge(&placement, &[view], &cfg, 64)
            .unwrap()
            .images
            .swap_remove(0)
    };
    let lengths: Vec<Vec<f64>> = marched.iter().map(|m| m.lengths.clone()).collect();
    for k in 1..=3usize {
        let c = colours[k - 1];
        let only: Vec<([f64; 3], f64)> = (0..=3)
            .map(|l| if l == k { (c, 1.0) } else { ([0.0; 3], 0.0) })
            .collect();
        let img = &render(&format!("only{k}"), &only);
        support::assert_valid("label layer", img);
        let (mut inside, mut inside_opaque, mut outside, mut outside_clear) = (0, 0, 0, 0);
        let mut colour_err = 0f64;
        let mut drawn = 0;
        for (px, len) in img.iter().zip(&lengths) {
            let a = px[3] as f64;
            if len[k] >= 1.5 {
                inside += 1;
                inside_opaque += (a >= 0.95) as usize;
            } else if len[k] == 0.0 {
                outside += 1;
                outside_clear += (a <= 0.05) as usize;
            }
            if a > 0.05 {
                drawn += 1;
                for ch in 0..3 {
                    colour_err = colour_err.max((px[ch] as f64 / a - c[ch]).abs());
                }
            }
        }
        let frac = |n: usize, of: usize| n as f64 / of.max(1) as f64;
        println!(
            "Colin27 label {k}: {inside} pixels cross ≥ 1.5 mm of it, {:.1} % of them opaque; {outside} cross none, {:.1} % of them clear; {drawn} drawn, colour within {colour_err:.1e} of the label's",
            100.0 * frac(inside_opaque, inside),
            100.0 * frac(outside_clear, outside)
        );
        assert!(inside > 200 && outside > 200, "{inside}, {outside}");
        assert!(frac(inside_opaque, inside) >= 0.99);
        assert!(frac(outside_clear, outside) >= 0.99);
        assert!(colour_err < 1e-3, "{colour_err}");
    }
    // Every label at once, each opaque in its colour: a pixel whose ray
    // first meets a label for at least 1.5 mm has that label's colour.
    let all: Vec<([f64; 3], f64)> = std::iter::once(([0.0; 3], 0.0))
        .chain(colours.iter().map(|&c| (c, 1.0)))
        .collect();
    let img = render("all", &all);
    let (mut thick, mut right) = (0, 0);
    let mut per_label = [0usize; 4];
    for (px, m) in img.iter().zip(&marched) {
        let (first, run) = (m.first, m.run);
        if first == 0 || run < 1.5 {
            continue;
        }
        thick += 1;
        let a = px[3] as f64;
        let c = colours[first - 1];
        let err = (0..3)
            .map(|ch| (px[ch] as f64 / a.max(1e-9) - c[ch]).abs())
            .fold(0.0, f64::max);
        if a >= 0.95 && err < 0.05 {
            right += 1;
            per_label[first] += 1;
        }
    }
    println!(
        "Colin27, every label at once: {thick} pixels first meet a label for ≥ 1.5 mm; {right} ({:.1} %) have its colour within 0.05 (labels 1, 2, 3: {:?})",
        100.0 * right as f64 / thick.max(1) as f64,
        &per_label[1..]
    );
    assert!(thick > 2000, "{thick}");
    assert!(right as f64 >= 0.97 * thick as f64, "{right} of {thick}");
}

/// Labels are read at the nearest voxel, never interpolated: where label 1
/// meets label 3 there is no label 2 between them. A table that shows only
/// label 2 over a volume of labels 1 and 3 (with a sheet of label 2 far
/// from their boundary) draws the sheet and nothing at the boundary; an
/// interpolated label would draw the boundary as a sheet of 2 too.
#[test]
fn no_label_appears_between_two_others() {
    let dir = tempfile::tempdir().unwrap();
    let vol = Volume::from_fn([32, 32, 32], [1.0; 3], VoxelType::U8, |i, _, _| match i {
        4 => 2.0,
        i if i < 16 => 1.0,
        _ => 3.0,
    });
    let db = dir.path().join("labels.pxo");
    import_labels(&vol, &db, BrickEncoding::U8Range).unwrap();
    let table = dir.path().join("two.toml");
    std::fs::write(
        &table,
        "[[label]]\nvalue = 1\ncolor = [1, 0, 0]\nextinction = 0\n\n\
         [[label]]\nvalue = 2\ncolor = [0, 1, 0]\nopacity = 1\n\n\
         [[label]]\nvalue = 3\ncolor = [0, 0, 1]\nextinction = 0\n",
    )
    .unwrap();
    let nothing =
        TransferFunction::from_points(vec![ControlPoint::new(0.0, [0.0; 3], 0.0)]).unwrap();
    // The cube turned 40° about y, so that rays cross the boundary
    // obliquely.
    let placement = parallax_common::camera::Placement {
        center: [0.0, 0.0, 0.0],
        rotation_deg: [0.0, 40.0, 0.0],
        size: 0.1,
    };
    let cfg = support::exact_config();
    // The label volume itself is the scene's volume (its function shows
    // nothing).
    let mut r = Renderer::with_layers(
        &db,
        &[label_layer(&db, &table)],
        &cfg,
        &AdapterRequest::from_env(None, 0),
    )
    .unwrap();
    r.set_transfer_function(1, &nothing).unwrap();
    let view = View::window([64, 64], [0.12, 0.12], [0.0, 0.0, 0.4]);
    let f = r.converge(&placement, &[view], &cfg, 64).unwrap();
    let img = &f.images[0];
    support::assert_valid("labels 1 | 3", img);
    // Pixels whose rays cross from label 1 into label 3 without meeting a
    // voxel of 2, against those that cross at least 1.5 mm of the sheet.
    let (mut boundary, mut boundary_max, mut sheet, mut sheet_min) = (0, 0f32, 0, 1f32);
    for (px, m) in img.iter().zip(march(&vol, &placement, &view)) {
        let l = &m.lengths;
        if l[1] > 0.0 && l[3] > 0.0 && l[2] == 0.0 {
            boundary += 1;
            boundary_max = boundary_max.max(px[3]);
        } else if l[2] >= 1.5 {
            sheet += 1;
            sheet_min = sheet_min.min(px[3]);
        }
    }
    println!(
        "labels 1 | 3 with only 2 shown: {boundary} pixels cross the boundary (and no 2), opacity at most {boundary_max:.2e}; {sheet} cross ≥ 1.5 mm of the sheet of 2, opacity at least {sheet_min:.3}"
    );
    assert!(boundary > 100 && sheet > 20, "{boundary}, {sheet}");
    assert_eq!(boundary_max, 0.0);
    assert!(sheet_min > 0.99);
}

/// A label the colour table lacks, a layer of labels over a volume of
/// values, and a bad table line are refused before anything is drawn,
/// naming the field, the file and the label, within a second.
#[test]
fn unknown_labels_and_volumes_of_values_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let vol = blocks();
    let labels = dir.path().join("labels.pxo");
    import_labels(&vol, &labels, BrickEncoding::U8Range).unwrap();
    let values = dir.path().join("values.pxo");
    support::import_volume(&vol, &values, 8, BrickEncoding::U8Range);
    let write = |name: &str, text: &str| {
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        p
    };
    // Slicer: value name R G B A; label 7 missing.
    let slicer = write(
        "no7.ctbl",
        "# Color table file\n0 background 0 0 0 0\n1 one 255 0 0 255\n2 two 0 255 0 255\n",
    );
    let full = write(
        "all.ctbl",
        "0 background 0 0 0 0\n1 one 255 0 0 255\n2 two 0 255 0 255\n7 seven 0 0 255 128\n",
    );
    let bad = write("bad.ctbl", "0 background 0 0 0 0\n1 one 255 0 300 255\n");
    let cfg = RenderConfig::default();
    let open = |l: Layer| {
        let t = std::time::Instant::now();
        let r = Renderer::with_layers(&values, &[l], &cfg, &AdapterRequest::from_env(None, 0));
        (r.err().map(|e| format!("{e:#}")), t.elapsed())
    };
    for (l, want) in [
        (
            label_layer(&labels, &slicer),
            ["layer[0].labels", "no7.ctbl", "label 7"],
        ),
        (
            label_layer(&values, &full),
            ["layer[0].labels", "values.pxo", "--labels"],
        ),
        (
            label_layer(&labels, &bad),
            ["layer[0].labels", "bad.ctbl: line 2", "300"],
        ),
    ] {
        let (e, took) = open(l);
        let e = e.expect("refused");
        println!("refused in {took:?}: {e}");
        for w in want {
            assert!(e.contains(w), "{w:?} in {e}");
        }
        assert!(took.as_secs_f64() < 1.0);
    }
    let (e, _) = open(label_layer(&labels, &full));
    assert_eq!(e, None, "a table that lists every label is taken");
}
