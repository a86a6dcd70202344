//! The real `parallax` binary, end to end: synth → import → info --verify →
//! render, and the errors a user sees for bad input.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn parallax(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_parallax"))
        .args(args)
        .output()
        .expect("run parallax")
}

fn ok(args: &[&str]) -> String {
    let o = parallax(args);
    let out = String::from_utf8_lossy(&o.stdout).to_string();
    assert!(
        o.status.success(),
        "parallax {args:?} failed:\n{out}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    out
}

fn fails(args: &[&str]) -> String {
    let o = parallax(args);
    assert!(!o.status.success(), "parallax {args:?} should fail");
    String::from_utf8_lossy(&o.stderr).to_string()
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// `synth ct --slices`: a thick-slice scan of the CT phantom imports with
/// its slice thickness, in levels that halve the in-plane axes first.
#[test]
fn a_thick_slice_ct_is_synthesised_and_imported() {
    let d = tempfile::tempdir().unwrap();
    let vol = d.path().join("thick.nrrd");
    let out = ok(&[
        "synth",
        "ct",
        "--size",
        "64",
        "--slices",
        "8",
        "--type",
        "i16",
        "-o",
        s(&vol),
    ]);
    assert!(out.contains("64 × 64 × 8 i16, slices 8.000 thick"), "{out}");
    let db = d.path().join("thick.pxo");
    ok(&["import", s(&vol), "-o", s(&db), "--brick", "16"]);
    let info = ok(&["info", s(&db)]);
    assert!(info.contains("64 × 64 × 8 i16"), "{info}");
    assert!(info.contains("spacing:       1 × 1 × 8"), "{info}");
    assert!(info.contains("voxels of 2 × 2 × 8"), "{info}");
    let e = fails(&[
        "synth",
        "shells",
        "--size",
        "16",
        "--slices",
        "4",
        "-o",
        s(&vol),
    ]);
    assert!(e.contains("--slices"), "{e}");
    let e = fails(&[
        "synth",
        "ct",
        "--size",
        "16",
        "--slices",
        "32",
        "-o",
        s(&vol),
    ]);
    assert!(e.contains("--slices must be in 1..=--size"), "{e}");
}

#[test]
fn synth_import_info_verify() {
    let d = tempfile::tempdir().unwrap();
    let vol = d.path().join("sl.nrrd");
    ok(&[
        "synth",
        "shepp-logan",
        "--size",
        "48",
        "--type",
        "u16",
        "-o",
        s(&vol),
    ]);
    let db = d.path().join("sl.pxo");
    let out = ok(&[
        "import",
        s(&vol),
        "-o",
        s(&db),
        "--brick",
        "16",
        "--empty-below",
        "1",
    ]);
    assert!(out.contains("MB/s"), "{out}");
    let info = ok(&["info", s(&db), "--verify"]);
    assert!(info.contains("48 × 48 × 48 u16"), "{info}");
    assert!(info.contains("levels:        3"), "{info}");
    assert!(info.contains("verify:        ok"), "{info}");
    assert!(info.contains("quantisation:  RMS"), "{info}");

    // one flipped byte in the middle of the brick area: named, refused
    let mut bytes = std::fs::read(&db).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0x5a;
    let bad = d.path().join("bad.pxo");
    std::fs::write(&bad, &bytes).unwrap();
    let e = fails(&["info", s(&bad), "--verify"]);
    assert!(
        e.contains("bad.pxo") && e.contains("brick level") && e.contains("checksum"),
        "{e}"
    );
}

#[test]
fn bad_input_gets_a_clear_error_and_keeps_existing_output() {
    let d = tempfile::tempdir().unwrap();
    let raw = d.path().join("v.raw");
    std::fs::write(&raw, vec![7u8; 1000]).unwrap();
    let out = d.path().join("keep.pxo");
    std::fs::write(&out, b"earlier result").unwrap();
    let e = fails(&[
        "import",
        s(&raw),
        "-o",
        s(&out),
        "--dims",
        "10,10,11",
        "--type",
        "u8",
    ]);
    assert!(e.contains("v.raw") && e.contains("1100"), "{e}");
    assert_eq!(std::fs::read(&out).unwrap(), b"earlier result");
    let e = fails(&[
        "import",
        s(&raw),
        "-o",
        s(&out),
        "--dims",
        "10,10",
        "--type",
        "u8",
    ]);
    assert!(e.contains("--dims"), "{e}");
    let nrrd = d.path().join("a.nrrd");
    std::fs::write(
        &nrrd,
        "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: hex\n\n00010203040506\n",
    )
    .unwrap();
    let e = fails(&["import", s(&nrrd), "-o", s(&out)]);
    assert!(e.contains("a.nrrd") && e.contains("truncated"), "{e}");
    let e = fails(&[
        "import",
        s(&raw),
        "-o",
        s(&out),
        "--dims",
        "10,10,10",
        "--type",
        "u8",
        "--quantize",
        "u12",
    ]);
    assert!(e.contains("--quantize"), "{e}");
    let e = fails(&["info", s(&d.path().join("missing.pxo"))]);
    assert!(e.contains("missing.pxo"), "{e}");
    assert_eq!(std::fs::read(&out).unwrap(), b"earlier result");
}

/// Writes each (path under `dir`, text).
fn write_all(dir: &Path, files: &[(&str, &str)]) {
    for (name, text) in files {
        write(dir.join(name), text);
    }
}

fn write(p: PathBuf, text: &str) -> PathBuf {
    std::fs::create_dir_all(p.parent().unwrap()).unwrap();
    std::fs::write(&p, text).unwrap();
    p
}

/// `dir/ml.pxo`: a Marschner–Lobb volume of `size`³ in bricks of 16.
fn marschner_lobb_database(dir: &Path, size: u32) {
    let vol = dir.join("ml.nrrd");
    let size = size.to_string();
    ok(&["synth", "marschner-lobb", "--size", &size, "-o", s(&vol)]);
    ok(&[
        "import",
        s(&vol),
        "-o",
        s(&dir.join("ml.pxo")),
        "--brick",
        "16",
    ]);
}

#[test]
fn render_writes_images_floats_and_stats() {
    let d = tempfile::tempdir().unwrap();
    marschner_lobb_database(d.path(), 40);
    write_all(
        d.path(),
        &[
            (
                "tf.toml",
                "[[point]]\nvalue = 0\ncolor = [0, 0, 0]\nextinction = 0\n[[point]]\nvalue = 128\ncolor = [1, 0.5, 0.2]\nextinction = 0.05\n[[point]]\nvalue = 255\ncolor = [1, 1, 1]\nextinction = 0.2\n",
            ),
            (
                "display.toml",
                "[screen]\nsize = [0.4, 0.3]\npixel_size = 0.005\n[observer]\nposition = [0, 0, 0.8]\nprojectors = \"p/\"\n",
            ),
            (
                "p/left.toml",
                "id = \"left\"\nposition = [-0.05, 0, 0.8]\nresolution = [32, 24]\n",
            ),
            (
                "p/right.toml",
                "id = \"right\"\nposition = [0.05, 0, 0.8]\nresolution = [40, 30]\n",
            ),
            (
                "scene.toml",
                "volume = \"ml.pxo\"\ntransfer_function = \"tf.toml\"\ndisplay = \"display.toml\"\n[placement]\ncenter = [0, 0, 0]\nsize = 0.2\nrotation_deg = [10, 20, 0]\n[render]\nshading = \"phong\"\n",
            ),
        ],
    );
    let scene = d.path().join("scene.toml");
    let out = d.path().join("out");
    let text = ok(&[
        "render",
        "--scene",
        s(&scene),
        "--frames",
        "6",
        "--out",
        s(&out),
        "--float",
        "--sync",
    ]);
    assert!(text.contains("converged"), "{text}");
    for id in ["left", "right"] {
        let png = out.join(format!("frame_00005/{id}.png"));
        assert!(
            std::fs::metadata(&png).unwrap().len() > 100,
            "{}",
            png.display()
        );
        let (w, h, px) =
            parallax_backend::output::read_npy(&out.join(format!("frame_00005/{id}.npy"))).unwrap();
        assert_eq!((w, h), if id == "left" { (32, 24) } else { (40, 30) });
        assert!(px
            .iter()
            .flatten()
            .all(|v| v.is_finite() && *v >= 0.0 && *v <= 1.0));
        assert!(px.iter().any(|p| p[3] > 0.1), "{id} sees the volume");
    }
    let stats = std::fs::read_to_string(out.join("stats.jsonl")).unwrap();
    let lines: Vec<serde_json::Value> = stats
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), 6, "one line per rank per frame");
    let last = &lines[5];
    for key in [
        "refine_ms",
        "render_ms",
        "cut_nodes",
        "resident",
        "uploaded",
        "visible",
        "cache_hits",
        "bytes_read",
    ] {
        assert!(last.get(key).is_some(), "stats has {key}");
    }
    assert!(last["bytes_read"].as_u64().unwrap() > 0);
    assert_eq!(last["views"].as_u64().unwrap(), 2);

    // a malformed scene names the file and the field
    let bad = write(d.path().join("bad.toml"), "volume = \"ml.pxo\"\ntransfer_function = \"tf.toml\"\n[placement]\ncenter = [0, 0]\nsize = 0.2\n");
    let e = fails(&[
        "render",
        "--scene",
        s(&bad),
        "--display",
        s(&d.path().join("display.toml")),
    ]);
    assert!(e.contains("bad.toml") && e.contains("center"), "{e}");
}

/// Run directly, with no per-user runtime folder in the environment (a
/// headless shell, a batch job), a render prints no error line: the binary
/// gives the Vulkan stack what it needs itself. `RUST_LOG=info` shows the
/// adapter it chose.
#[test]
fn a_clean_run_prints_no_error_lines() {
    let d = tempfile::tempdir().unwrap();
    let vol = d.path().join("c.nrrd");
    ok(&["synth", "shells", "--size", "16", "-o", s(&vol)]);
    let db = d.path().join("c.pxo");
    ok(&["import", s(&vol), "-o", s(&db), "--brick", "8"]);
    write(
        d.path().join("tf.toml"),
        "[[point]]\nvalue = 0\ncolor = [1, 1, 1]\nextinction = 0.1\n",
    );
    write(
        d.path().join("display.toml"),
        "[screen]\nsize = [0.4, 0.3]\npixel_size = 0.005\n[observer]\nposition = [0, 0, 0.8]\nprojectors = \"p/\"\n",
    );
    write(
        d.path().join("p/w.toml"),
        "id = \"w\"\nposition = [0, 0, 0.8]\nresolution = [16, 12]\n",
    );
    let scene = write(
        d.path().join("scene.toml"),
        "volume = \"c.pxo\"\ntransfer_function = \"tf.toml\"\ndisplay = \"display.toml\"\n[placement]\ncenter = [0, 0, 0]\nsize = 0.2\n",
    );
    for log in [None, Some("info")] {
        let mut c = Command::new(env!("CARGO_BIN_EXE_parallax"));
        c.args(["render", "--scene", s(&scene)])
            .current_dir(d.path())
            .env_remove("XDG_RUNTIME_DIR")
            .env_remove("RUST_LOG");
        if let Some(l) = log {
            c.env("RUST_LOG", l);
        }
        let o = c.output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(o.status.success(), "{err}");
        assert!(!err.to_lowercase().contains("error"), "{err}");
        if log.is_some() {
            assert!(err.contains("GPU adapter chosen"), "{err}");
        } else {
            assert!(err.trim().is_empty(), "{err}");
        }
        // Without --frames it renders until the cut has converged; without
        // --out it writes to out/<scene name> and says where.
        let text = String::from_utf8_lossy(&o.stdout);
        assert!(text.contains("converged"), "{text}");
        assert!(text.contains("out/scene"), "{text}");
        let stats = std::fs::read_to_string(d.path().join("out/scene/stats.jsonl")).unwrap();
        let last: serde_json::Value = serde_json::from_str(stats.lines().last().unwrap()).unwrap();
        assert_eq!(last["adequate"], true);
        assert!(stats.lines().count() > 1);
    }
}

/// A wall whose projector files name back-end ranks renders embedded with
/// that many back ends, no flag needed; `display-gen` sets Φ to the
/// projectors' spacing.
#[test]
fn embedded_back_ends_follow_the_display() {
    let d = tempfile::tempdir().unwrap();
    let vol = d.path().join("c.nrrd");
    ok(&["synth", "shells", "--size", "16", "-o", s(&vol)]);
    ok(&[
        "import",
        s(&vol),
        "-o",
        s(&d.path().join("c.pxo")),
        "--brick",
        "8",
    ]);
    let wall = d.path().join("wall");
    ok(&[
        "display-gen",
        "--projectors",
        "4",
        "--resolution",
        "16x9",
        "-o",
        s(&wall),
    ]);
    let disp = std::fs::read_to_string(wall.join("display.toml")).unwrap();
    assert!(disp.contains("angular_accuracy_deg = 12.5"), "{disp}");
    for (i, r) in [1, 1, 2, 3].iter().enumerate() {
        let p = wall.join(format!("projectors/p{i:02}.toml"));
        let text = std::fs::read_to_string(&p).unwrap();
        std::fs::write(&p, format!("{text}rank = {r}\n")).unwrap();
    }
    write(
        d.path().join("tf.toml"),
        "[[point]]\nvalue = 0\ncolor = [1, 1, 1]\nextinction = 0.1\n",
    );
    let scene = write(
        d.path().join("scene.toml"),
        "volume = \"c.pxo\"\ntransfer_function = \"tf.toml\"\ndisplay = \"wall/display.toml\"\n[placement]\ncenter = [0, 0, 0]\nsize = 0.3\n[render]\neta = 1\n",
    );
    let out = d.path().join("out");
    ok(&[
        "render",
        "--scene",
        s(&scene),
        "--frames",
        "2",
        "--out",
        s(&out),
    ]);
    let stats = std::fs::read_to_string(out.join("stats.jsonl")).unwrap();
    let ranks: std::collections::BTreeSet<u64> = stats
        .lines()
        .map(|l| {
            serde_json::from_str::<serde_json::Value>(l).unwrap()["rank"]
                .as_u64()
                .unwrap()
        })
        .collect();
    assert_eq!(ranks.into_iter().collect::<Vec<_>>(), vec![1, 2, 3]);
}

/// numpy's default float64, written as NRRD, imports (rounded to 32-bit
/// floats, and the import says how many values changed).
#[test]
fn a_float64_volume_imports_and_says_what_rounding_changed() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("f64.nrrd");
    let mut bytes = b"NRRD0004\ntype: double\ndimension: 3\nsizes: 4 4 4\nencoding: raw\nendian: little\nspacings: 1 1 1\n\n".to_vec();
    for i in 0..64 {
        bytes.extend((i as f64 / 3.0).to_le_bytes());
    }
    std::fs::write(&p, bytes).unwrap();
    let o = parallax(&["import", s(&p), "-o", s(&d.path().join("f64.pxo"))]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains("f64.nrrd") && err.contains("f64 values were rounded"),
        "{err}"
    );
    let info = ok(&["info", s(&d.path().join("f64.pxo")), "--verify"]);
    assert!(info.contains("f64"), "{info}");
}

/// `parallax tf import`: a 3D Slicer presets.xml excerpt with two presets is
/// listed, one is converted, and the result renders as a transfer function.
#[test]
fn tf_import_converts_a_slicer_preset() {
    let d = tempfile::tempdir().unwrap();
    let xml = write(
        d.path().join("presets.xml"),
        "<MRML>\n<VolumeProperty name=\"CT-Test\" scalarOpacity=\"8 -1000 0 0 0 300 0.5 1000 1\" \
         colorTransfer=\"8 -1000 0 0 0 1000 1 1 1\"/>\n<VolumeProperty name=\"MR-Test\" \
         scalarOpacity=\"4 0 0 100 1\" colorTransfer=\"8 0 0 0 0 100 1 0.5 0\"/>\n</MRML>\n",
    );
    let out = ok(&["tf", "import", s(&xml), "--list"]);
    assert_eq!(out.lines().collect::<Vec<_>>(), ["CT-Test", "MR-Test"]);
    let e = fails(&["tf", "import", s(&xml), "-o", s(&d.path().join("x.toml"))]);
    assert!(e.contains("presets.xml") && e.contains("CT-Test"), "{e}");
    let toml = d.path().join("ct.toml");
    let out = ok(&["tf", "import", s(&xml), "--name", "ct-test", "-o", s(&toml)]);
    assert!(out.contains("CT-Test"), "{out}");
    let tf = parallax_common::tf::TransferFunction::load(&toml).unwrap();
    // α = 0.5 per 1 mm at 300 HU: τ = ln 2.
    let t = tf.eval(300.0).tau;
    assert!((t - std::f64::consts::LN_2).abs() < 1e-9, "{t}");
    assert!(tf.eval(1000.0).tau.is_finite());
    assert!(!d.path().join("x.toml").exists());
}

/// NaN in float input: refused naming the voxel (with the hint), imported
/// as "no data" with `--nan empty`.
#[test]
fn nan_is_refused_or_no_data() {
    let d = tempfile::tempdir().unwrap();
    let mut bytes =
        b"NRRD0004\ntype: float\ndimension: 3\nsizes: 4 4 4\nendian: little\nencoding: raw\n\n"
            .to_vec();
    for i in 0..64 {
        let v = if i == 21 { f32::NAN } else { i as f32 };
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    let vol = d.path().join("nan.nrrd");
    std::fs::write(&vol, &bytes).unwrap();
    let db = d.path().join("nan.pxo");
    let e = fails(&["import", s(&vol), "-o", s(&db)]);
    assert!(
        e.contains("nan.nrrd") && e.contains("voxel (1,1,1) is NaN") && e.contains("--nan empty"),
        "{e}"
    );
    assert!(!db.exists());
    let o = parallax(&["import", s(&vol), "-o", s(&db), "--nan", "empty"]);
    assert!(o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("1 voxels are NaN: no data"), "{err}");
    ok(&["info", s(&db), "--verify"]);
}

/// A projector file can name its back end's GPU adapter (by name or #N); an
/// adapter that is not there is an error naming the projector and listing
/// the adapters.
#[test]
fn a_projector_names_its_adapter() {
    let d = tempfile::tempdir().unwrap();
    let vol = d.path().join("ml.nrrd");
    ok(&["synth", "marschner-lobb", "--size", "16", "-o", s(&vol)]);
    ok(&[
        "import",
        s(&vol),
        "-o",
        s(&d.path().join("ml.pxo")),
        "--brick",
        "8",
    ]);
    write(
        d.path().join("tf.toml"),
        "[[point]]\nvalue = 0\ncolor = [1, 1, 1]\nextinction = 0.1\n[[point]]\nvalue = 255\ncolor = [1, 1, 1]\nextinction = 0.1\n",
    );
    write(
        d.path().join("display.toml"),
        "[screen]\nsize = [0.4, 0.3]\npixel_size = 0.01\n[observer]\nposition = [0, 0, 0.8]\nprojectors = \"p/\"\n",
    );
    let scene = write(
        d.path().join("scene.toml"),
        "volume = \"ml.pxo\"\ntransfer_function = \"tf.toml\"\ndisplay = \"display.toml\"\n[placement]\ncenter = [0, 0, 0]\nsize = 0.2\n",
    );
    let projector = |adapter: &str| {
        write(
            d.path().join("p/a.toml"),
            &format!("id = \"a\"\nposition = [0, 0, 0.8]\nresolution = [8, 6]\nadapter = \"{adapter}\"\n"),
        )
    };
    projector("no-such-gpu");
    let e = fails(&[
        "render",
        "--scene",
        s(&scene),
        "--frames",
        "1",
        "--out",
        s(&d.path().join("o1")),
    ]);
    assert!(
        e.contains("projector a: adapter = \"no-such-gpu\": no such adapter") && e.contains("#0 "),
        "{e}"
    );
    projector("#0");
    ok(&[
        "render",
        "--scene",
        s(&scene),
        "--frames",
        "1",
        "--out",
        s(&d.path().join("o2")),
    ]);
}

/// `PARALLAX_KERNEL_DUMP` (backend/src/raycast/shader.rs) writes the
/// composed kernel the render uses, and changes nothing in its images; a
/// dump that cannot be written is an error naming the variable and the
/// file.
#[test]
fn kernel_dump_writes_the_kernel_and_changes_no_pixel() {
    let d = tempfile::tempdir().unwrap();
    marschner_lobb_database(d.path(), 24);
    write_all(
        d.path(),
        &[
            (
                "tf.toml",
                "[[point]]\nvalue = 0\ncolor = [1, 1, 1]\nextinction = 0.1\n[[point]]\nvalue = 255\ncolor = [1, 1, 1]\nextinction = 0.1\n",
            ),
            (
                "display.toml",
                "[screen]\nsize = [0.3, 0.2]\npixel_size = 0.005\n[observer]\nposition = [0, 0, 0.8]\nprojectors = \"p/\"\n",
            ),
            (
                "p/window.toml",
                "id = \"window\"\nposition = [0, 0, 0.8]\nresolution = [24, 16]\n",
            ),
            (
                "scene.toml",
                "volume = \"ml.pxo\"\ntransfer_function = \"tf.toml\"\ndisplay = \"display.toml\"\n[placement]\ncenter = [0, 0, 0]\nsize = 0.2\nrotation_deg = [0, 0, 0]\n",
            ),
        ],
    );
    let scene = d.path().join("scene.toml");
    let render = |name: &str, env: &[(&str, &Path)]| {
        let out = d.path().join(name);
        let o = Command::new(env!("CARGO_BIN_EXE_parallax"))
            .args(["render", "--scene", s(&scene), "--frames", "3", "--float"])
            .args(["--sync", "--out", s(&out)])
            .envs(env.iter().map(|(k, v)| (k, v.as_os_str())))
            .output()
            .unwrap();
        (o, out.join("frame_00002/window.npy"))
    };
    let dumped = d.path().join("kernel.wgsl");
    let (o, npy) = render("dumped", &[("PARALLAX_KERNEL_DUMP", &dumped)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let src = std::fs::read_to_string(&dumped).unwrap();
    let write_pixel = "image[out] = vec4<f32>(acc.color, acc.alpha);";
    assert_eq!(
        src.matches(write_pixel).count(),
        1,
        "the dump is the kernel"
    );
    let (_, _, with_dump) = parallax_backend::output::read_npy(&npy).unwrap();
    let (o, npy) = render("plain", &[]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (_, _, plain) = parallax_backend::output::read_npy(&npy).unwrap();
    assert!(plain.iter().any(|p| p[3] > 0.0));
    assert_eq!(plain, with_dump);

    let unwritable = d.path().join("no-such-folder/kernel.wgsl");
    let (o, _) = render("unwritable", &[("PARALLAX_KERNEL_DUMP", &unwritable)]);
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains("PARALLAX_KERNEL_DUMP") && e.contains("no-such-folder"),
        "{e}"
    );
}

/// A 100-byte NRRD whose size along x (2^63 + 1, gzip) once wrapped the
/// octree layout's loop and hung the import: refused within a second,
/// naming the field, with nothing written.
#[test]
fn a_crafted_nrrd_size_is_refused_at_once() {
    use std::io::Write;
    let d = tempfile::tempdir().unwrap();
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    gz.write_all(&[0u8; 16]).unwrap();
    let mut file =
        b"NRRD0004\ntype: uint8\ndimension: 3\nsizes: 9223372036854775809 1 1\nencoding: gzip\n\n"
            .to_vec();
    file.extend(gz.finish().unwrap());
    let nrrd = d.path().join("crafted.nrrd");
    std::fs::write(&nrrd, &file).unwrap();
    let pxo = d.path().join("out.pxo");
    let t = std::time::Instant::now();
    let o = std::process::Command::new("timeout")
        .arg("10")
        .arg(env!("CARGO_BIN_EXE_parallax"))
        .args([
            "import",
            nrrd.to_str().unwrap(),
            "-o",
            pxo.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    let secs = t.elapsed().as_secs_f64();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("crafted.nrrd: sizes: axis 0 has 9223372036854775809 voxels"),
        "{err}"
    );
    assert!(secs < 1.0, "took {secs:.2} s");
    assert!(!pxo.exists());
}

/// A scene's registered layers through the real binary: `info` lists them,
/// `render` draws them, and a layer that is missing, corrupt or on another
/// grid, or a layer count the kernel cannot take, is refused naming the
/// scene file and the layer's field, within a second.
#[test]
fn layers_are_listed_rendered_and_bad_ones_refused_naming_the_scene() {
    let d = tempfile::tempdir().unwrap();
    marschner_lobb_database(d.path(), 40);
    let vol = d.path().join("small.nrrd");
    ok(&["synth", "shells", "--size", "24", "-o", s(&vol)]);
    ok(&["import", s(&vol), "-o", s(&d.path().join("small.pxo"))]);
    std::fs::write(d.path().join("corrupt.pxo"), b"PXO not really").unwrap();
    let head = "volume = \"ml.pxo\"\ntransfer_function = \"tf.toml\"\ndisplay = \"display.toml\"\n[placement]\ncenter = [0, 0, 0]\nsize = 0.2\n";
    write_all(
        d.path(),
        &[
            (
                "tf.toml",
                "[[point]]\nvalue = 0\ncolor = [0, 0, 0]\nextinction = 0\n[[point]]\nvalue = 255\ncolor = [1, 1, 1]\nextinction = 0.1\n",
            ),
            (
                "red.toml",
                "[[point]]\nvalue = 150\ncolor = [1, 0, 0]\nextinction = 0\n[[point]]\nvalue = 255\ncolor = [1, 0, 0]\nextinction = 0.3\n",
            ),
            (
                "display.toml",
                "[screen]\nsize = [0.3, 0.3]\npixel_size = 0.005\n[observer]\nposition = [0, 0, 0.8]\nprojectors = \"p/\"\n",
            ),
            (
                "p/w.toml",
                "id = \"w\"\nposition = [0, 0, 0.8]\nresolution = [32, 32]\n",
            ),
        ],
    );
    let layer = |volume: &str| {
        format!(
            "[[layer]]\nvolume = \"{volume}\"\ntransfer_function = \"red.toml\"\nopacity = 0.5\n"
        )
    };
    let scene = write(
        d.path().join("layers.toml"),
        &format!("{head}{}", layer("ml.pxo")),
    );
    let info = ok(&["info", s(&scene)]);
    assert!(
        info.contains("layer[0]") && info.contains("red.toml") && info.contains("opacity 0.5"),
        "{info}"
    );
    let out = d.path().join("out");
    let text = ok(&[
        "render",
        "--scene",
        s(&scene),
        "--frames",
        "3",
        "--sync",
        "--out",
        s(&out),
    ]);
    assert!(out.join("frame_00002/w.png").exists(), "{text}");
    // A script switches the layer's function to one that shows nothing:
    // the image is the volume's alone, bit for bit.
    write_all(
        d.path(),
        &[
            (
                "clear.toml",
                "[[point]]\nvalue = 0\ncolor = [0, 0, 0]\nextinction = 0\n",
            ),
            (
                "switch.toml",
                "[[key]]\nframe = 0\nlayer_functions = [{ index = 0, file = \"clear.toml\" }]\n",
            ),
        ],
    );
    let alone = write(d.path().join("alone.toml"), head);
    let (out_alone, out_switched) = (d.path().join("alone"), d.path().join("switched"));
    let frames = ["--frames", "3", "--sync", "--out"];
    ok(&[
        &["render", "--scene", s(&alone)][..],
        &frames,
        &[s(&out_alone)],
    ]
    .concat());
    let script = d.path().join("switch.toml");
    let switched = [
        &["render", "--scene", s(&scene), "--script", s(&script)][..],
        &frames,
        &[s(&out_switched)],
    ]
    .concat();
    ok(&switched);
    let png = |o: &Path| std::fs::read(o.join("frame_00002/w.png")).unwrap();
    let with_layer = png(&out);
    assert_eq!(
        png(&out_switched),
        png(&out_alone),
        "the layer's function switched to nothing"
    );
    assert_ne!(
        with_layer,
        png(&out_alone),
        "the layer shows before the switch"
    );
    // A label layer: labels made of the volume by thresholds, drawn through
    // an ITK-SNAP label description file.
    let imported = ok(&[
        "import",
        s(&d.path().join("ml.nrrd")),
        "-o",
        s(&d.path().join("labels.pxo")),
        "--brick",
        "16",
        "--labels-from-thresholds",
        "100,200",
    ]);
    assert!(imported.contains("labels: 0–2 (3 labels)"), "{imported}");
    write_all(
        d.path(),
        &[
            (
                "labels.txt",
                "# ITK-SnAP Label Description File\n0 0 0 0 0 0 0 \"Clear Label\"\n1 255 0 0 0.2 1 1 \"low\"\n2 0 0 255 0.5 1 1 \"high\"\n",
            ),
            ("no2.txt", "0 0 0 0 0 0 0 \"Clear Label\"\n1 255 0 0 0.2 1 1 \"low\"\n"),
        ],
    );
    let labels =
        |table: &str| format!("[[layer]]\nvolume = \"labels.pxo\"\nlabels = \"{table}\"\n");
    let scene = write(
        d.path().join("labels.toml"),
        &format!("{head}{}", labels("labels.txt")),
    );
    let info = ok(&["info", s(&scene)]);
    assert!(
        info.contains("layer[0]:      labels") && info.contains("labels:        0–2 (3 labels)"),
        "{info}"
    );
    ok(&[
        "render",
        "--scene",
        s(&scene),
        "--frames",
        "2",
        "--sync",
        "--out",
        s(&out),
    ]);
    for (text, field) in [
        (layer("none.pxo"), "layer[0].volume"),
        (layer("corrupt.pxo"), "layer[0].volume"),
        (layer("small.pxo"), "layer[0].volume"),
        (layer("ml.pxo").repeat(4), "layer: 4 layers"),
        (labels("no2.txt"), "label 2"),
        (
            layer("labels.pxo").replace("red.toml", "labels.txt"),
            "layer[0].transfer_function",
        ),
    ] {
        let bad = write(d.path().join("bad.toml"), &format!("{head}{text}"));
        let t = std::time::Instant::now();
        let e = fails(&[
            "render",
            "--scene",
            s(&bad),
            "--frames",
            "1",
            "--out",
            s(&out),
        ]);
        let took = t.elapsed();
        println!("refused in {took:?}: {e}");
        assert!(e.contains("bad.toml") && e.contains(field), "{field}: {e}");
        assert!(took.as_secs_f64() < 1.0, "{took:?}");
    }
}

/// Mean of one channel (0 red … 2 blue) over columns [x0, x1) of an 8-bit
/// RGB or RGBA PNG.
fn png_mean(path: &Path, channel: usize, x0: u32, x1: u32) -> f64 {
    let mut r = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()))
        .read_info()
        .unwrap();
    let mut buf = vec![0u8; r.output_buffer_size()];
    let info = r.next_frame(&mut buf).unwrap();
    let c = info.color_type.samples();
    let (w, h) = (info.width as usize, info.height as usize);
    let mut sum = 0.0;
    for y in 0..h {
        for x in x0 as usize..x1 as usize {
            sum += buf[(y * w + x) * c + channel] as f64;
        }
    }
    sum / (h * (x1 - x0) as usize) as f64
}

/// View-dependent layer opacity on a light field wall, in `parallax
/// simulate`'s images (G10 §4): two eyes on either side of the viewing
/// line see the red layer's share the smoothstep gives their direction to
/// the volume — each eye's red over the volume alone, as a fraction of the
/// layer at full opacity's, against the layer at that fixed opacity.
#[test]
fn a_layers_share_in_the_simulated_eyes_follows_the_smoothstep() {
    let d = tempfile::tempdir().unwrap();
    let vol = d.path().join("v.nrrd");
    ok(&["synth", "shells", "--size", "48", "-o", s(&vol)]);
    ok(&[
        "import",
        s(&vol),
        "-o",
        s(&d.path().join("v.pxo")),
        "--brick",
        "16",
    ]);
    ok(&[
        "display-gen",
        "--projectors",
        "12",
        "--resolution",
        "64x36",
        "--pixel-size",
        "0.0333",
        "-o",
        s(&d.path().join("wall")),
    ]);
    write_all(
        d.path(),
        &[
            (
                "tf.toml",
                "[[point]]\nvalue = 0\ncolor = [0.3, 0.6, 1]\nextinction = 0\n[[point]]\nvalue = 255\ncolor = [0.3, 0.6, 1]\nextinction = 0.05\n",
            ),
            (
                "red.toml",
                "[[point]]\nvalue = 0\ncolor = [1, 0, 0]\nextinction = 0\n[[point]]\nvalue = 255\ncolor = [1, 0, 0]\nextinction = 0.15\n",
            ),
        ],
    );
    let head = "volume = \"v.pxo\"\ntransfer_function = \"tf.toml\"\ndisplay = \"wall/display.toml\"\n[placement]\ncenter = [0, 0, 0]\nsize = 0.4\nrotation_deg = [15, 30, 0]\n[render]\neta = 1.0\n";
    let (axis, angles) = ([-1.0f64, 0.0, 0.0], [70.0f64, 110.0]);
    let eyes = [-0.3f64, 0.3];
    // The smoothstep of each eye's direction to the volume's centre.
    let factor = |ex: f64| {
        let n = (ex * ex + 4.0).sqrt();
        let cos = (-ex * axis[0] + -2.0 * axis[2]) / n;
        let t = ((cos.acos().to_degrees() - angles[0]) / (angles[1] - angles[0])).clamp(0.0, 1.0);
        t * t * (3.0 - 2.0 * t)
    };
    // Renders a scene and simulates both eyes: each eye's mean red.
    let red = |name: &str, layer: &str| -> [f64; 2] {
        let scene = write(
            d.path().join(format!("{name}.toml")),
            &format!("{head}{layer}"),
        );
        let out = d.path().join(name);
        ok(&[
            "render",
            "--scene",
            s(&scene),
            "--frames",
            "4",
            "--sync",
            "--out",
            s(&out),
        ]);
        let png = d.path().join(format!("{name}-eyes.png"));
        ok(&[
            "simulate",
            "--display",
            s(&d.path().join("wall/display.toml")),
            "--frames",
            s(&out.join("frame_00003")),
            "--eye=-0.3,0,2",
            "--eye=0.3,0,2",
            "--resolution",
            "160x90",
            "-o",
            s(&png),
        ]);
        [png_mean(&png, 0, 0, 160), png_mean(&png, 0, 160, 320)]
    };
    let layer = |extra: &str| {
        format!("[[layer]]\nvolume = \"v.pxo\"\ntransfer_function = \"red.toml\"\n{extra}")
    };
    let base = red("base", "");
    let full = red("full", &layer(""));
    let seen = red(
        "seen",
        &layer(&format!(
            "view_opacity = {{ axis = {axis:?}, angles_deg = {angles:?} }}\n"
        )),
    );
    let mut shares = Vec::new();
    for (e, &ex) in eyes.iter().enumerate() {
        let f = factor(ex);
        let fixed = red(&format!("fixed{e}"), &layer(&format!("opacity = {f}\n")));
        let share = |v: [f64; 2]| (v[e] - base[e]) / (full[e] - base[e]);
        println!(
            "simulated eye at x = {ex}: smoothstep {f:.3}; the layer's share {:.3}, at that fixed opacity {:.3} (mean red {:.1} without the layer, {:.1} at full)",
            share(seen),
            share(fixed),
            base[e],
            full[e]
        );
        assert!(full[e] - base[e] > 3.0, "the layer shows to eye {e}");
        assert!(
            (share(seen) - share(fixed)).abs() < 0.1,
            "eye {e}: {:.3} against {:.3}",
            share(seen),
            share(fixed)
        );
        shares.push(share(seen));
    }
    assert!(shares[0] > shares[1] + 0.4, "{shares:?}");
}
