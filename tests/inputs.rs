//! The data people bring, written by independent tools: DICOM series
//! (pydicom) and TIFF stacks (tifffile), against the same volume written as
//! NRRD. `tests/data/make_inputs.py` writes them; the test command installs
//! python3-pydicom, python3-tifffile and python3-numpy.

use parallax_backend::data::{self, InputOptions};
use parallax_backend::volume::{Volume, VoxelType};
use std::path::{Path, PathBuf};
use std::process::Command;

mod support;

/// The inputs, written once per test run.
fn inputs() -> PathBuf {
    support::inputs("inputs")
}

fn read(path: &Path, opts: &InputOptions) -> Volume {
    let mut src = data::open_with(path, opts).unwrap();
    Volume::read_all(src.as_mut()).unwrap()
}

fn reference() -> Volume {
    read(&inputs().join("ct.nrrd"), &InputOptions::default())
}

fn open_err(path: &Path, opts: &InputOptions) -> String {
    match data::open_with(path, opts) {
        Ok(_) => panic!("{} opened", path.display()),
        Err(e) => format!("{e:#}"),
    }
}

#[test]
fn a_dicom_series_imports_to_the_voxels_spacing_and_hounsfield_units_of_the_nrrd() {
    let nrrd = reference();
    assert_eq!(nrrd.info.dims, [24, 20, 16]);
    for folder in ["dicom", "dicom-rle"] {
        let dcm = read(&inputs().join(folder), &InputOptions::default());
        assert_eq!(dcm.info.dims, nrrd.info.dims, "{folder}");
        for a in 0..3 {
            assert!(
                (dcm.info.spacing[a] - nrrd.info.spacing[a]).abs() < 1e-9,
                "{folder}: spacing {:?} vs {:?}",
                dcm.info.spacing,
                nrrd.info.spacing
            );
        }
        assert_eq!(dcm.info.voxel_type, VoxelType::I16, "{folder}: HU fit i16");
        assert_eq!(dcm.data, nrrd.data, "{folder}: every voxel, in HU");
    }
    // Hounsfield units, not stored values: the extremes written are −1024 and 3071.
    let (lo, hi) = nrrd.range();
    assert_eq!((lo, hi), (-1024.0, 3071.0));
}

#[test]
fn a_folder_of_several_series_lists_them_and_series_chooses() {
    let two = inputs().join("dicom-two");
    let e = open_err(&two, &InputOptions::default());
    assert!(
        e.contains("2 series")
            && e.contains("--series")
            && e.contains("1.2.826.0.1.3680043.8.498.10")
            && e.contains("\"scout\"  4 slices"),
        "{e}"
    );
    let list = data::dicom::list_series(&two).unwrap();
    assert_eq!(list.len(), 2);
    assert_eq!(list[1].slices, 4);
    let by_uid = read(
        &two,
        &InputOptions {
            series: Some("1.2.826.0.1.3680043.8.498.10".into()),
            ..Default::default()
        },
    );
    assert_eq!(by_uid.data, reference().data);
    let by_number = read(
        &two,
        &InputOptions {
            series: Some("2".into()),
            ..Default::default()
        },
    );
    assert_eq!(by_number.info.dims, [24, 20, 4]);
    let e = open_err(
        &two,
        &InputOptions {
            series: Some("9.9.9".into()),
            ..Default::default()
        },
    );
    assert!(e.contains("--series 9.9.9: no such series"), "{e}");
}

#[test]
fn broken_series_get_errors_naming_the_file_and_the_tag() {
    let d = InputOptions::default();
    let e = open_err(&inputs().join("dicom-missing"), &d);
    assert!(
        e.contains("missing slice")
            && e.contains("ImagePositionPatient (0020,0032)")
            && e.contains("2×"),
        "{e}"
    );
    let e = open_err(&inputs().join("dicom-uneven"), &d);
    assert!(
        e.contains("uneven slice spacing")
            && e.contains("(0020,0032)")
            && e.contains("1.9000 mm")
            && e.contains("IM00"),
        "{e}"
    );
    let e = open_err(&inputs().join("dicom-tilt"), &d);
    assert!(e.contains("GantryDetectorTilt (0018,1120) is 2°"), "{e}");
    let e = open_err(&inputs().join("dicom-j2k"), &d);
    assert!(
        e.contains("TransferSyntaxUID (0002,0010) 1.2.840.10008.1.2.4.90")
            && e.contains("JPEG 2000"),
        "{e}"
    );
    let empty = tempfile::tempdir().unwrap();
    std::fs::write(empty.path().join("notes.txt"), "x").unwrap();
    let e = open_err(empty.path(), &d);
    assert!(
        e.contains("no DICOM files") && e.contains("1 other files"),
        "{e}"
    );
}

#[test]
fn tiff_stacks_import_to_the_voxels_of_the_nrrd() {
    let nrrd = reference();
    // A folder of 2-D TIFFs named slice0 … slice15: natural order.
    let folder = read(
        &inputs().join("tiff"),
        &InputOptions {
            spacing: Some([0.7, 0.6, 1.5]),
            ..Default::default()
        },
    );
    assert_eq!(folder.info.dims, nrrd.info.dims);
    assert_eq!(folder.info.voxel_type, VoxelType::I16);
    assert_eq!(folder.info.spacing, [0.7, 0.6, 1.5]);
    assert_eq!(folder.data, nrrd.data);
    // One multi-page uint16 TIFF with ImageJ metadata: spacing from it.
    let stack = read(&inputs().join("stack.tif"), &InputOptions::default());
    assert_eq!(stack.info.voxel_type, VoxelType::U16);
    for a in 0..3 {
        assert!(
            (stack.info.spacing[a] - nrrd.info.spacing[a]).abs() < 1e-6,
            "{:?}",
            stack.info.spacing
        );
    }
    let shifted: Vec<f32> = nrrd.data.iter().map(|v| v + 1024.0).collect();
    assert_eq!(stack.data, shifted);
    // Float pages.
    let f = read(&inputs().join("stack-f32.tif"), &InputOptions::default());
    assert_eq!(f.info.voxel_type, VoxelType::F32);
    let expect: Vec<f32> = nrrd.data.iter().map(|v| v / 7.0).collect();
    assert_eq!(f.data, expect);
}

#[test]
fn natural_order_puts_slice2_before_slice10() {
    use parallax_backend::data::tiff::natural_cmp;
    let mut v = vec!["s10.tif", "s2.tif", "s1.tif", "s002b.tif", "a.tif"];
    v.sort_by(|a, b| natural_cmp(a, b));
    assert_eq!(v, ["a.tif", "s1.tif", "s2.tif", "s002b.tif", "s10.tif"]);
}

/// The DICOM series and the NRRD render the same image through the real
/// binary (import, then render).
#[test]
fn a_dicom_series_renders_the_same_image_as_the_nrrd() {
    let d = tempfile::tempdir().unwrap();
    let nrrd = inputs().join("ct.nrrd");
    let dicom = inputs().join("dicom");
    let a = d.path().join("a.pxo");
    run(&["import", s(&nrrd), "-o", s(&a), "--brick", "8"]);
    let b = d.path().join("b.pxo");
    let said = run(&["import", s(&dicom), "-o", s(&b), "--brick", "8"]);
    assert!(said.contains("patient (LPS) directions"), "{said}");
    let info = run(&["info", s(&b)]);
    assert!(
        info.contains("DICOM series 1.2.826.0.1.3680043.8.498.10"),
        "{info}"
    );
    write_display(d.path());
    std::fs::write(
        d.path().join("tf.toml"),
        "[[point]]\nvalue = -1000\ncolor = [0, 0, 0]\nextinction = 0\n[[point]]\nvalue = 0\ncolor = [0.9, 0.5, 0.4]\nextinction = 0.3\n[[point]]\nvalue = 1000\ncolor = [1, 1, 1]\nextinction = 2\n",
    )
    .unwrap();
    let mut images = Vec::new();
    for db in ["a", "b"] {
        let scene = d.path().join(format!("{db}.toml"));
        std::fs::write(
            &scene,
            format!("volume = \"{db}.pxo\"\ntransfer_function = \"tf.toml\"\n{SCENE_VIEW}"),
        )
        .unwrap();
        let px = render_last(&scene, &d.path().join(format!("out-{db}")));
        assert!(
            px.iter().any(|p| p[3] > 0.05),
            "{db}: the volume is visible"
        );
        images.push(px);
    }
    assert_eq!(images[0], images[1], "bit for bit");
}

/// Runs the binary; its stdout and stderr, or a panic naming the call.
fn run(args: &[&str]) -> String {
    let o = Command::new(env!("CARGO_BIN_EXE_parallax"))
        .args(args)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "parallax {args:?}:\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned() + &String::from_utf8_lossy(&o.stderr)
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// The scenes' display (one 40×30 view) and placement.
const SCENE_VIEW: &str = "display = \"display.toml\"\n[placement]\ncenter = [0, 0, 0]\nsize = 0.2\nrotation_deg = [20, 30, 0]\n";

fn write_display(dir: &Path) {
    std::fs::write(
        dir.join("display.toml"),
        "[screen]\nsize = [0.4, 0.3]\npixel_size = 0.01\n[observer]\nposition = [0, 0, 0.8]\nprojectors = \"p/\"\n",
    )
    .unwrap();
    std::fs::create_dir_all(dir.join("p")).unwrap();
    std::fs::write(
        dir.join("p/v.toml"),
        "id = \"v\"\nposition = [0, 0, 0.8]\nresolution = [40, 30]\n",
    )
    .unwrap();
}

/// `parallax render --float` of `scene` into `out`: its last frame's view.
fn render_last(scene: &Path, out: &Path) -> Vec<[f32; 4]> {
    run(&["render", "--scene", s(scene), "--out", s(out), "--float"]);
    let frames: Vec<_> = std::fs::read_dir(out)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with("frame_"))
        .map(|e| e.path())
        .collect();
    let last = frames.iter().max().unwrap();
    parallax_backend::output::read_npy(&last.join("v.npy"))
        .unwrap()
        .2
}

/// A DICOM segmentation lands on its CT by the scanner geometry both
/// series carry (`[[layer]] transform = "scanner"`): the label series of
/// `make_inputs.py` is on another grid (cropped, its rows running to −x,
/// its slice normal −z), and drawn over the CT it gives the image of the
/// same labels made on the CT's own grid (`--labels-from-thresholds`). A
/// layer whose database has no scanner geometry (a NRRD without a space)
/// is refused naming the field.
#[test]
fn a_dicom_segmentation_lands_on_its_ct_by_the_scanner_geometry() {
    let d = tempfile::tempdir().unwrap();
    let dicom = inputs().join("dicom");
    let ct = d.path().join("ct.pxo");
    run(&["import", s(&dicom), "-o", s(&ct), "--brick", "8"]);
    let aligned = d.path().join("aligned.pxo");
    let thresholds = ["--labels-from-thresholds", "-500,500", "--brick", "8"];
    run(&[
        &["import", s(&dicom), "-o", s(&aligned)][..],
        &thresholds[..],
    ]
    .concat());
    let seg = d.path().join("seg.pxo");
    let seg_dir = inputs().join("dicom-seg");
    run(&[
        "import",
        s(&seg_dir),
        "-o",
        s(&seg),
        "--labels",
        "--brick",
        "8",
    ]);
    let info = run(&["info", s(&seg)]);
    assert!(
        info.contains("23 × 20 × 14") && info.contains("scanner:"),
        "{info}"
    );
    let nogeo = d.path().join("nogeo.pxo");
    let nrrd = inputs().join("ct.nrrd");
    run(&[&["import", s(&nrrd), "-o", s(&nogeo)][..], &thresholds[..]].concat());
    write_display(d.path());
    std::fs::write(
        d.path().join("none.toml"),
        "[[point]]\nvalue = -1000\ncolor = [0, 0, 0]\nextinction = 0\n[[point]]\nvalue = 3000\ncolor = [0, 0, 0]\nextinction = 0\n",
    )
    .unwrap();
    std::fs::write(
        d.path().join("labels.txt"),
        "0 0 0 0 0 0 0 \"air\"\n1 200 120 90 0.3 1 1 \"soft\"\n2 255 250 240 0.9 1 1 \"bone\"\n",
    )
    .unwrap();
    // At the finest level (the two label databases' coarser levels are
    // made on their own grids).
    let scene = |name: &str, layer: &str| {
        let p = d.path().join(name);
        std::fs::write(
            &p,
            format!("volume = \"ct.pxo\"\ntransfer_function = \"none.toml\"\n{SCENE_VIEW}[render]\naccuracy = 0.05\n[[layer]]\nlabels = \"labels.txt\"\n{layer}"),
        )
        .unwrap();
        p
    };
    let on_grid = render_last(
        &scene("aligned.toml", "volume = \"aligned.pxo\"\n"),
        &d.path().join("out-aligned"),
    );
    let placed_scene = scene(
        "placed.toml",
        "volume = \"seg.pxo\"\ntransform = \"scanner\"\n",
    );
    let info = run(&["info", s(&placed_scene)]);
    assert!(info.contains("transform:     scanner"), "{info}");
    let placed = render_last(&placed_scene, &d.path().join("out-placed"));
    let lit = on_grid.iter().filter(|p| p[3] > 0.05).count();
    let (mut sq, mut max) = (0.0f64, 0.0f64);
    for (a, b) in placed.iter().zip(&on_grid) {
        for c in 0..4 {
            let e = (a[c] - b[c]) as f64;
            sq += e * e;
            max = max.max(e.abs());
        }
    }
    let rmse = (sq / (4 * placed.len()) as f64).sqrt();
    println!(
        "a DICOM label series on another grid placed by the scanner geometry, against the same labels on the CT's grid: RMSE {rmse:.2e}, max {max:.2e}; {lit} of {} pixels lit",
        placed.len()
    );
    assert!(lit > 50, "the labels are in view: {lit}");
    assert!(rmse < 1e-5 && max < 1e-4, "RMSE {rmse:.2e}, max {max:.2e}");
    // Without scanner geometry: refused, naming the field and the file.
    let bad = scene(
        "nogeo.toml",
        "volume = \"nogeo.pxo\"\ntransform = \"scanner\"\n",
    );
    let o = Command::new(env!("CARGO_BIN_EXE_parallax"))
        .args([
            "render",
            "--scene",
            s(&bad),
            "--out",
            s(&d.path().join("x")),
        ])
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        e.contains("nogeo.toml")
            && e.contains("layer[0].transform")
            && e.contains("no scanner geometry"),
        "{e}"
    );
}

/// Hostile headers (issue 38), written by `make_inputs.py` into `crafted/`:
/// each is refused by `parallax import` within a second, naming the file
/// and the field, and nothing is written.
#[test]
fn crafted_headers_are_refused_at_once_naming_the_field() {
    let dir = inputs().join("crafted");
    let out = tempfile::tempdir().unwrap();
    for (name, field) in [
        (
            "huge.nii",
            "huge.nii: dim, datatype, vox_offset: expected at least",
        ),
        ("huge.nii.gz", "huge.nii.gz: --memory-mb"),
        ("negative.nii", "negative.nii: dim: dim[1] is -5"),
        ("offset.nii", "offset.nii: dim, datatype, vox_offset"),
        (
            "huge.tif",
            "huge.tif: ImageWidth/ImageLength: axis 0 has 4294967295 voxels",
        ),
        ("loop.tif", "loop.tif: not a TIFF file"),
        ("dicom-huge", "NumberOfFrames (0028,0008) is 2147483647"),
    ] {
        let pxo = out.path().join(format!("{name}.pxo"));
        let t = std::time::Instant::now();
        let o = Command::new("timeout")
            .arg("10")
            .arg(env!("CARGO_BIN_EXE_parallax"))
            .arg("import")
            .arg(dir.join(name))
            .arg("-o")
            .arg(&pxo)
            .output()
            .unwrap();
        let secs = t.elapsed().as_secs_f64();
        let err = String::from_utf8_lossy(&o.stderr);
        println!("{name}: {secs:.3} s: {}", err.trim());
        assert_eq!(o.status.code(), Some(1), "{name}: {err}");
        assert!(err.contains(field), "{name}: {err}");
        assert!(secs < 1.0, "{name}: took {secs:.2} s");
        assert!(!pxo.exists(), "{name}: wrote {}", pxo.display());
    }
}
