//! Cluster mode under a real `mpirun`: every projector image equals the same
//! projector rendered in the embedded mode; bad displays and a dead back end
//! end with a clear error instead of a hang.

use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::Duration;

fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_parallax")
}

fn mpirun(n: usize, args: &[&str], env: &[(&str, &str)]) -> Output {
    let args: Vec<&OsStr> = args.iter().map(OsStr::new).collect();
    mpirun_os(n, &args, env)
}

fn mpirun_os(n: usize, args: &[&OsStr], env: &[(&str, &str)]) -> Output {
    let mut c = Command::new("timeout");
    c.arg("120")
        .arg("mpirun")
        .arg("-n")
        .arg(n.to_string())
        .arg(bin())
        .args(args)
        .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
        .env("OMPI_MCA_rmaps_base_oversubscribe", "1");
    for (k, v) in env {
        c.env(k, v);
    }
    c.output()
        .expect("mpirun (install openmpi-bin: scripts/setup.sh)")
}

fn run(args: &[&str]) -> Output {
    Command::new(bin()).args(args).output().unwrap()
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

struct World {
    dir: tempfile::TempDir,
}

impl World {
    /// A small volume, a transfer function, a 4-projector wall and a scene.
    fn new() -> World {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let vol = d.join("v.nrrd");
        assert!(run(&["synth", "shells", "--size", "48", "-o", s(&vol)])
            .status
            .success());
        assert!(run(&[
            "import",
            s(&vol),
            "-o",
            s(&d.join("v.pxo")),
            "--brick",
            "16"
        ])
        .status
        .success());
        std::fs::write(
            d.join("tf.toml"),
            "[[point]]\nvalue = 0\ncolor = [0, 0, 0]\nextinction = 0\n[[point]]\nvalue = 100\ncolor = [0.2, 0.5, 1]\nextinction = 0.05\n[[point]]\nvalue = 255\ncolor = [1, 0.8, 0.4]\nextinction = 0.4\n",
        )
        .unwrap();
        let gen = run(&[
            "display-gen",
            "--projectors",
            "4",
            "--resolution",
            "48x27",
            "--pixel-size",
            "0.0333",
            "--angular-accuracy",
            "12.5",
            "-o",
            s(&d.join("wall")),
        ]);
        assert!(gen.status.success(), "{}", text(&gen));
        std::fs::write(
            d.join("scene.toml"),
            "volume = \"v.pxo\"\ntransfer_function = \"tf.toml\"\ndisplay = \"wall/display.toml\"\n[placement]\ncenter = [0, 0, 0.1]\nsize = 0.5\nrotation_deg = [15, 30, 0]\n[render]\neta = 1.0\nshading = \"phong\"\n",
        )
        .unwrap();
        World { dir }
    }

    fn path(&self, p: &str) -> PathBuf {
        self.dir.path().join(p)
    }

    fn render_args<'a>(&'a self, out: &'a Path, scene: &'a Path) -> Vec<&'a str> {
        vec![
            "render",
            "--scene",
            s(scene),
            "--frames",
            "4",
            "--sync",
            "--float",
            "--out",
            s(out),
        ]
    }
}

fn npy(dir: &Path, frame: u32, id: &str) -> Vec<[f32; 4]> {
    parallax_backend::output::read_npy(&dir.join(format!("frame_{frame:05}/{id}.npy")))
        .unwrap()
        .2
}

#[test]
fn cluster_images_equal_the_embedded_ones() {
    let w = World::new();
    let scene = w.path("scene.toml");
    for ranks in [2usize, 3, 5] {
        let backends = ranks - 1;
        let cluster = w.path(&format!("cluster{ranks}"));
        let o = mpirun(ranks, &w.render_args(&cluster, &scene), &[]);
        assert!(o.status.success(), "mpirun -n {ranks}: {}", text(&o));
        let embedded = w.path(&format!("embedded{ranks}"));
        let mut args = w.render_args(&embedded, &scene);
        let b = backends.to_string();
        args.extend(["--backends", &b]);
        let o = run(&args);
        assert!(o.status.success(), "{}", text(&o));
        for id in ["p00", "p01", "p02", "p03"] {
            for frame in [1, 3] {
                let (c, e) = (npy(&cluster, frame, id), npy(&embedded, frame, id));
                assert_eq!(c, e, "{ranks} ranks, projector {id}, frame {frame}");
            }
            assert!(
                npy(&cluster, 3, id).iter().any(|p| p[3] > 0.1),
                "{id} sees the volume"
            );
        }
        // one stats line per back end per frame
        let stats = std::fs::read_to_string(cluster.join("stats.jsonl")).unwrap();
        assert_eq!(stats.lines().count(), 4 * backends, "{ranks} ranks");
        eprintln!("{ranks} ranks: identical to the embedded mode");
    }
    // the parallax is real: neighbouring projectors see different images
    let c = w.path("cluster5");
    assert_ne!(npy(&c, 3, "p00"), npy(&c, 3, "p01"));
}

#[test]
fn bad_displays_and_rank_counts_are_refused() {
    let w = World::new();
    let scene = w.path("scene.toml");
    let out = w.path("o");
    // more back ends than projectors
    let o = mpirun(6, &w.render_args(&out, &scene), &[]);
    assert!(!o.status.success());
    assert!(
        text(&o).contains("5 back-end ranks but only 4 projectors"),
        "{}",
        text(&o)
    );
    // a projector pinned to a rank that does not exist
    let p = w.path("wall/projectors/p02.toml");
    let orig = std::fs::read_to_string(&p).unwrap();
    std::fs::write(&p, format!("{orig}rank = 7\n")).unwrap();
    let o = mpirun(3, &w.render_args(&out, &scene), &[]);
    assert!(!o.status.success());
    assert!(
        text(&o).contains("projector 'p02': rank 7 does not exist"),
        "{}",
        text(&o)
    );
    // duplicate ids
    std::fs::write(&p, orig.replace("\"p02\"", "\"p01\"")).unwrap();
    let o = run(&w.render_args(&out, &scene));
    assert!(!o.status.success());
    assert!(
        text(&o).contains("p02.toml") && text(&o).contains("'p01'"),
        "{}",
        text(&o)
    );
    std::fs::write(&p, &orig).unwrap();
    // a missing projector file in a list
    std::fs::write(
        w.path("list.toml"),
        "[screen]\nsize = [1.6, 0.9]\npixel_size = 0.03\n[observer]\nposition = [0, 0, 2]\nprojectors = [\"wall/projectors/p00.toml\", \"wall/projectors/nope.toml\"]\n",
    )
    .unwrap();
    let mut args = w.render_args(&out, &scene);
    let l = w.path("list.toml");
    args.extend(["--display", s(&l)]);
    let o = run(&args);
    assert!(!o.status.success());
    assert!(text(&o).contains("nope.toml"), "{}", text(&o));
}

#[test]
fn a_dead_back_end_ends_the_run_naming_it() {
    let w = World::new();
    let scene = w.path("scene.toml");
    let out = w.path("dead");
    let start = std::time::Instant::now();
    let o = mpirun(
        4,
        &w.render_args(&out, &scene),
        &[("PARALLAX_FAULT", "exit:2:2")],
    );
    assert!(!o.status.success(), "{}", text(&o));
    assert!(start.elapsed() < Duration::from_secs(100), "no hang");
    let t = text(&o);
    // the launcher names the process that died: rank 2 ("[[job,1],2]")
    assert!(t.contains(",2]") && t.contains("70"), "{t}");
    // frames before the failure were written
    assert!(out.join("frame_00001/p00.png").exists());
}

#[test]
fn the_72_projector_wall_runs_with_4_back_ends() {
    let w = World::new();
    let wall = w.path("wall72");
    let o = run(&[
        "display-gen",
        "--projectors",
        "72",
        "--resolution",
        "32x18",
        "--pixel-size",
        "0.05",
        "-o",
        s(&wall),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let scene = w.path("scene72.toml");
    std::fs::write(
        &scene,
        std::fs::read_to_string(w.path("scene.toml"))
            .unwrap()
            .replace("wall/display.toml", "wall72/display.toml"),
    )
    .unwrap();
    let out = w.path("out72");
    let o = mpirun(
        5,
        &[
            "render",
            "--scene",
            s(&scene),
            "--frames",
            "2",
            "--sync",
            "--out",
            s(&out),
        ],
        &[],
    );
    assert!(o.status.success(), "{}", text(&o));
    let n = std::fs::read_dir(out.join("frame_00001")).unwrap().count();
    assert_eq!(n, 72);
    let stats = std::fs::read_to_string(out.join("stats.jsonl")).unwrap();
    let frame1: Vec<serde_json::Value> = stats
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .filter(|v: &serde_json::Value| v["frame"] == 1)
        .collect();
    assert_eq!(frame1.len(), 4);
    assert!(frame1.iter().all(|v| v["views"] == 18));
}

// Failures tried as a user and an attacker would: each ends cleanly, names
// its cause, and stays inside its folder.

fn stats_lines(out: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(out.join("stats.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

#[test]
fn a_scene_in_a_folder_whose_name_is_not_utf8_renders() {
    use std::os::unix::ffi::OsStrExt;
    let w = World::new();
    let folder = w.dir.path().join(OsStr::from_bytes(b"sc\xe9ne"));
    std::fs::create_dir(&folder).unwrap();
    let scene = folder.join("scene.toml");
    std::fs::write(
        &scene,
        std::fs::read_to_string(w.path("scene.toml"))
            .unwrap()
            .replace("\"v.pxo\"", "\"../v.pxo\"")
            .replace("\"tf.toml\"", "\"../tf.toml\"")
            .replace("\"wall/", "\"../wall/"),
    )
    .unwrap();
    let out = folder.join("out");
    let args: Vec<&OsStr> = ["render", "--scene"]
        .iter()
        .map(OsStr::new)
        .chain([scene.as_os_str()])
        .chain(["--frames", "2", "--sync", "--out"].iter().map(OsStr::new))
        .chain([out.as_os_str()])
        .collect();
    let start = std::time::Instant::now();
    let o = mpirun_os(2, &args, &[]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(start.elapsed() < Duration::from_secs(60));
    assert!(out.join("frame_00001/p03.png").exists());
    // Embedded too.
    let o = Command::new(bin()).args(&args).output().unwrap();
    assert!(o.status.success(), "{}", text(&o));
}

#[test]
fn a_projector_id_that_is_a_path_is_refused_naming_the_file() {
    let w = World::new();
    let scene = w.path("scene.toml");
    let p = w.path("wall/projectors/p01.toml");
    let orig = std::fs::read_to_string(&p).unwrap();
    let out = w.path("deep/er/out");
    for id in ["../../../escaped", "a/b", ".."] {
        std::fs::write(&p, orig.replace("\"p01\"", &format!("{id:?}"))).unwrap();
        for o in [
            run(&w.render_args(&out, &scene)),
            mpirun(2, &w.render_args(&out, &scene), &[]),
        ] {
            assert!(!o.status.success(), "{id}: {}", text(&o));
            let t = text(&o);
            assert!(t.contains("p01.toml: id"), "{id}: {t}");
        }
    }
    // Nothing was written anywhere above (or inside) the output folder.
    let escaped: Vec<_> = walk(w.dir.path())
        .into_iter()
        .filter(|f| f.to_string_lossy().contains("escaped"))
        .collect();
    assert!(escaped.is_empty(), "{escaped:?}");
}

fn walk(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            out.extend(walk(&p));
        }
        out.push(p);
    }
    out
}

#[test]
fn an_upload_budget_of_4_converges_and_says_it_held_the_cut_back() {
    let w = World::new();
    let scene = w.path("scene4.toml");
    std::fs::write(
        &scene,
        std::fs::read_to_string(w.path("scene.toml"))
            .unwrap()
            .replace(
                "[render]\n",
                "[render]\nupload_budget = 4\naccuracy = 0.1\n",
            ),
    )
    .unwrap();
    let out = w.path("budget4");
    let o = mpirun(
        2,
        &[
            "render",
            "--scene",
            s(&scene),
            "--frames",
            "40",
            "--sync",
            "--out",
            s(&out),
        ],
        &[],
    );
    assert!(o.status.success(), "{}", text(&o));
    let stats = stats_lines(&out);
    assert!(stats.iter().all(|v| v["uploaded"].as_u64().unwrap() <= 4));
    let last = stats.last().unwrap();
    assert_eq!(last["adequate"], true, "{last}");
    assert!(last["cut_nodes"].as_u64().unwrap() > 9, "{last}");
    let t = text(&o);
    assert_eq!(t.matches("upload budget").count(), 1, "said once: {t}");
}

#[test]
fn a_corrupt_brick_is_named_and_the_run_goes_on() {
    use parallax_backend::store::{NodeKey, OctreeDb};
    let w = World::new();
    let bad = w.path("bad.pxo");
    std::fs::copy(w.path("v.pxo"), &bad).unwrap();
    let key = NodeKey::new(1, 1, 0, 1);
    let rec = *OctreeDb::open(&bad).unwrap().node(key).unwrap();
    assert!(rec.is_stored());
    let mut bytes = std::fs::read(&bad).unwrap();
    for b in &mut bytes[rec.offset as usize + 4..rec.offset as usize + 12] {
        *b ^= 0x5A;
    }
    std::fs::write(&bad, bytes).unwrap();
    let scene = w.path("scene-bad.toml");
    std::fs::write(
        &scene,
        std::fs::read_to_string(w.path("scene.toml"))
            .unwrap()
            .replace("\"v.pxo\"", "\"bad.pxo\""),
    )
    .unwrap();
    let out = w.path("corrupt");
    let o = mpirun(3, &w.render_args(&out, &scene), &[]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(out.join("frame_00003/p00.png").exists());
    let named: Vec<String> = stats_lines(&out)
        .iter()
        .flat_map(|v| v["bad_bricks"].as_array().unwrap().clone())
        .map(|b| b.as_str().unwrap().to_string())
        .collect();
    assert!(!named.is_empty());
    let want = format!("brick {key} (offset {})", rec.offset);
    assert!(named.iter().all(|b| b.contains(&want)), "{named:?}");
    assert!(text(&o).contains(&want), "{}", text(&o));
    // `info --verify` still reports it.
    let v = run(&["info", s(&bad), "--verify"]);
    assert!(!v.status.success());
    assert!(text(&v).contains(&want), "{}", text(&v));
}

#[test]
fn a_panicking_back_end_is_named() {
    let w = World::new();
    let out = w.path("panic");
    let start = std::time::Instant::now();
    let o = mpirun(
        3,
        &w.render_args(&out, &w.path("scene.toml")),
        &[("PARALLAX_FAULT", "panic:2:1")],
    );
    assert!(!o.status.success());
    assert!(start.elapsed() < Duration::from_secs(60), "no hang");
    let t = text(&o);
    assert!(
        t.contains("back end 2 failed") && t.contains("panic"),
        "{t}"
    );
    // Embedded: the same error, no hang.
    let scene = w.path("scene.toml");
    let mut args = w.render_args(&out, &scene);
    args.extend(["--backends", "2"]);
    let o = Command::new(bin())
        .args(&args)
        .env("PARALLAX_FAULT", "panic:2:1")
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(text(&o).contains("back end 2 failed"), "{}", text(&o));
}

#[test]
fn a_stopped_back_end_is_named_within_the_watchdog_timeout() {
    let w = World::new();
    let out = w.path("stopped");
    let scene = w.path("scene.toml");
    let mut args = w.render_args(&out, &scene);
    args.extend(["--watchdog", "5"]);
    let start = std::time::Instant::now();
    let o = mpirun(3, &args, &[("PARALLAX_FAULT", "stop:2:2")]);
    let took = start.elapsed();
    assert!(!o.status.success(), "{}", text(&o));
    // 5 s of watchdog, plus start-up and the launcher's clean-up.
    assert!(took < Duration::from_secs(60), "{took:?}");
    let t = text(&o);
    assert!(
        t.contains("back end rank 2 did not answer within 5 s"),
        "{t}"
    );
    // The frames before were written, and their figures flushed.
    let stats = stats_lines(&out);
    assert_eq!(stats.len(), 2 * 2, "frames 0 and 1 from two back ends");
}

/// Tools and MImDA in the cluster: a clip plane (moved by the script, so
/// the tool set is re-sent), a band picker and a context-preserving probe
/// chained, and γ > 0, with the tools' geometry and a cursor the script
/// moves drawn over every projector (G10 §5), render identically under
/// `mpirun -n 3` and embedded with two back ends.
#[test]
fn a_clip_plane_band_picker_probe_and_mimda_render_identically_in_the_cluster() {
    let w = World::new();
    std::fs::write(
        w.path("tf-importance.toml"),
        "[[point]]\nvalue = 0\ncolor = [0, 0, 0]\nextinction = 0\nimportance = 0.1\n\
         [[point]]\nvalue = 100\ncolor = [0.2, 0.5, 1]\nextinction = 0.05\nimportance = 0.2\n\
         [[point]]\nvalue = 255\ncolor = [1, 0.8, 0.4]\nextinction = 0.4\nimportance = 0.9\n",
    )
    .unwrap();
    let scene = w.path("scene-tools.toml");
    std::fs::write(
        &scene,
        std::fs::read_to_string(w.path("scene.toml"))
            .unwrap()
            .replace("\"tf.toml\"", "\"tf-importance.toml\"")
            .replace("[render]\n", "[render]\nmode = \"mimda\"\ngamma = 0.7\n")
            + "[render.overlay]\nshow = true\ncursor = [0.02, 0, 0.1]\nlabel_height = 0.03\n\
               [[tool]]\nkind = \"clip-plane\"\npoint = [0, 0, 0.12]\nnormal = [0, 0, 1]\nthickness = 0.02\n\
               [[tool]]\nkind = \"band-picker\"\nband = [80, 120, 200, 240]\naxis = [0.2, 0, 1]\n\
               [[tool]]\nkind = \"probe\"\ncenter = [0, 0, 0.04]\nradius = 0.05\n",
    )
    .unwrap();
    let script = w.path("move.toml");
    std::fs::write(
        &script,
        "frames = 4\n[[key]]\nframe = 0\ncursor = [0.02, 0, 0.1]\ntool = [{ index = 0, point = [0, 0, 0.12] }]\n\
         [[key]]\nframe = 3\ncursor = [-0.05, 0.03, 0.05]\ntool = [{ index = 0, point = [0, 0, 0.02] }]\n",
    )
    .unwrap();
    let cluster = w.path("tools-cluster");
    let mut args = w.render_args(&cluster, &scene);
    args.extend(["--script", s(&script)]);
    let o = mpirun(3, &args, &[]);
    assert!(o.status.success(), "{}", text(&o));
    let embedded = w.path("tools-embedded");
    let mut args = w.render_args(&embedded, &scene);
    args.extend(["--script", s(&script), "--backends", "2"]);
    let o = run(&args);
    assert!(o.status.success(), "{}", text(&o));
    let plain = w.path("plain");
    let o = run(&w.render_args(&plain, &w.path("scene.toml")));
    assert!(o.status.success(), "{}", text(&o));
    for id in ["p00", "p01", "p02", "p03"] {
        for frame in [1, 3] {
            assert_eq!(
                npy(&cluster, frame, id),
                npy(&embedded, frame, id),
                "projector {id}, frame {frame}"
            );
        }
        // The planes moved between frames 1 and 3, and they cut.
        assert_ne!(npy(&cluster, 1, id), npy(&cluster, 3, id), "{id}");
        assert_ne!(npy(&cluster, 3, id), npy(&plain, 3, id), "{id}");
    }
}

/// A scene with registered layers (`[[layer]]`, G10 §4: the volume again
/// through another transfer function, shown to one side of the wall, and
/// a label layer made of it by thresholds, with a 3D Slicer colour table,
/// on another grid (bricks of 8 against the volume's 16) and moved 1.5
/// voxels along x by its transform) renders under `mpirun -n 3` as
/// embedded, and the layers show.
#[test]
fn a_two_layer_scene_renders_identically_in_the_cluster() {
    let w = World::new();
    let o = run(&[
        "import",
        s(&w.path("v.nrrd")),
        "-o",
        s(&w.path("labels.pxo")),
        "--brick",
        "8",
        "--labels-from-thresholds",
        "120,220",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    std::fs::write(
        w.path("labels.ctbl"),
        "# Color table file\n0 none 0 0 0 0\n1 middle 40 200 90 60\n2 core 250 240 40 255\n",
    )
    .unwrap();
    std::fs::write(
        w.path("tf-layer.toml"),
        "[[point]]\nvalue = 150\ncolor = [1, 0.2, 0.1]\nextinction = 0\n\
         [[point]]\nvalue = 200\ncolor = [1, 0.2, 0.1]\nextinction = 0.3\n",
    )
    .unwrap();
    let scene = w.path("scene-layers.toml");
    std::fs::write(
        &scene,
        std::fs::read_to_string(w.path("scene.toml")).unwrap()
            + "[[layer]]\nvolume = \"v.pxo\"\ntransfer_function = \"tf-layer.toml\"\n\
               view_opacity = { axis = [1, 0, -1], angles_deg = [20, 60] }\n\
               [[layer]]\nvolume = \"labels.pxo\"\nlabels = \"labels.ctbl\"\nopacity = 0.5\n\
               transform = [[1, 0, 0, 1.5], [0, 1, 0, 0], [0, 0, 1, 0]]\n",
    )
    .unwrap();
    let cluster = w.path("layers-cluster");
    let o = mpirun(3, &w.render_args(&cluster, &scene), &[]);
    assert!(o.status.success(), "{}", text(&o));
    let embedded = w.path("layers-embedded");
    let mut args = w.render_args(&embedded, &scene);
    args.extend(["--backends", "2"]);
    let o = run(&args);
    assert!(o.status.success(), "{}", text(&o));
    let plain = w.path("layers-plain");
    let o = run(&w.render_args(&plain, &w.path("scene.toml")));
    assert!(o.status.success(), "{}", text(&o));
    let mut changed = 0;
    for id in ["p00", "p01", "p02", "p03"] {
        for frame in [1, 3] {
            assert_eq!(
                npy(&cluster, frame, id),
                npy(&embedded, frame, id),
                "projector {id}, frame {frame}"
            );
        }
        changed += (npy(&cluster, 3, id) != npy(&plain, 3, id)) as usize;
    }
    assert!(changed > 0, "the layer shows on some projector");
}

/// Frame reconstruction (G10 §5) per projector in the cluster: the same
/// images as embedded, and on a static view, once the cut has settled, the
/// full render bit for bit.
#[test]
fn frame_reconstruction_in_the_cluster() {
    let w = World::new();
    let scene = w.path("scene-recon.toml");
    std::fs::write(
        &scene,
        std::fs::read_to_string(w.path("scene.toml"))
            .unwrap()
            .replace("[render]\n", "[render]\nreconstruction = true\n"),
    )
    .unwrap();
    let args = |out: &Path, scene: &Path| -> Vec<String> {
        let mut a: Vec<String> = w
            .render_args(out, scene)
            .iter()
            .map(|s| s.to_string())
            .collect();
        a[4] = "16".into(); // --frames 16
        a
    };
    let cluster = w.path("recon-cluster");
    let a = args(&cluster, &scene);
    let o = mpirun(3, &a.iter().map(String::as_str).collect::<Vec<_>>(), &[]);
    assert!(o.status.success(), "{}", text(&o));
    let embedded = w.path("recon-embedded");
    let mut a = args(&embedded, &scene);
    a.extend(["--backends".into(), "2".into()]);
    let o = run(&a.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(o.status.success(), "{}", text(&o));
    let full = w.path("recon-full");
    let a = args(&full, &w.path("scene.toml"));
    let o = run(&a.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(o.status.success(), "{}", text(&o));
    for id in ["p00", "p01", "p02", "p03"] {
        for frame in [0, 1, 15] {
            assert_eq!(
                npy(&cluster, frame, id),
                npy(&embedded, frame, id),
                "projector {id}, frame {frame}"
            );
        }
        assert!(
            (1..8).any(|f| npy(&cluster, f, id) != npy(&full, f, id)),
            "{id}: while the cut refines, frames are reconstructed, not full"
        );
        assert!(
            npy(&cluster, 15, id) == npy(&full, 15, id),
            "{id}: frame 15 is the full render"
        );
    }
}

/// Ranks agree before the first frame: a back end that says it speaks
/// another protocol, or reads another database (`PARALLAX_FAULT`
/// `protocol:2:0`, `database:2:0`, as another build or another copy of the
/// file would), ends the run at set-up, named, with no frame rendered.
#[test]
fn ranks_that_disagree_stop_the_run_before_the_first_frame() {
    let w = World::new();
    let scene = w.path("scene.toml");
    // The fault makes back end 2 claim the next protocol version.
    let other_protocol = format!(
        "back end 2 runs protocol {} of parallax",
        parallax_common::protocol::PROTOCOL_VERSION + 1
    );
    for (fault, want) in [
        ("protocol:2:0", other_protocol.as_str()),
        (
            "database:2:0",
            "back end 2 reads another database than back end 1",
        ),
    ] {
        let out = w.path(&format!("out-{}", &fault[..8]));
        let t = std::time::Instant::now();
        let o = mpirun(
            3,
            &w.render_args(&out, &scene),
            &[("PARALLAX_FAULT", fault)],
        );
        assert!(!o.status.success(), "{fault}: {}", text(&o));
        assert!(
            text(&o).contains(want),
            "{fault}: wanted '{want}' in:\n{}",
            text(&o)
        );
        assert!(
            !out.join("frame_00000").exists(),
            "{fault}: a frame was rendered"
        );
        assert!(
            t.elapsed() < Duration::from_secs(60),
            "{fault}: took {:?}",
            t.elapsed()
        );
    }
}

/// The real case behind `database:2:0` above: each rank opens the scene's
/// volume path on its own machine, and one machine's copy differs. Here
/// back end 2 runs in a mount namespace of its own (`unshare -m`, root)
/// where that path holds another import of the same data (bricks of 8,
/// not 16): the run stops before the first frame, naming the rank.
#[test]
fn a_rank_reading_another_copy_of_the_volume_stops_the_run() {
    let permitted = Command::new("unshare")
        .args(["-m", "true"])
        .status()
        .is_ok_and(|s| s.success());
    if !permitted {
        println!("skipped: unshare -m is not permitted here (needs root)");
        return;
    }
    let w = World::new();
    let other = w.path("other.pxo");
    let imported = run(&[
        "import",
        s(&w.path("v.nrrd")),
        "-o",
        s(&other),
        "--brick",
        "8",
    ]);
    assert!(imported.status.success(), "{}", text(&imported));
    let scene = w.path("scene.toml");
    let out = w.path("out");
    let args = w.render_args(&out, &scene).join(" ");
    let t = std::time::Instant::now();
    let o = Command::new("timeout")
        .arg("120")
        .arg("mpirun")
        .args(["-n", "2", bin()])
        .args(w.render_args(&out, &scene))
        .args([":", "-n", "1", "unshare", "-m", "sh", "-c"])
        .arg(format!(
            "mount --bind '{}' '{}' && exec '{}' {args}",
            s(&other),
            s(&w.path("v.pxo")),
            bin()
        ))
        .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
        .env("OMPI_MCA_rmaps_base_oversubscribe", "1")
        .output()
        .unwrap();
    println!("{}", text(&o));
    assert!(!o.status.success());
    assert!(
        text(&o).contains("back end 2 reads another database than back end 1"),
        "{}",
        text(&o)
    );
    assert!(!out.join("frame_00000").exists(), "a frame was rendered");
    assert!(
        t.elapsed() < Duration::from_secs(60),
        "took {:?}",
        t.elapsed()
    );
}

/// A 20-step time series on the wall's grid: a 48³ u8 volume of a bright
/// blob over a faint background, the blob moving 1 voxel a step along x,
/// each step imported with bricks of 16 (`series/s00.pxo` …), and a scene
/// naming them; a script plays them at 2 frames a step.
fn series_world(steps: usize) -> (World, PathBuf, PathBuf) {
    let w = World::new();
    let n = 48usize;
    let mut series = Vec::new();
    for t in 0..steps {
        let c = [14.0 + t as f64, 24.0, 24.0];
        let mut v = Vec::with_capacity(n * n * n);
        for k in 0..n {
            for j in 0..n {
                for i in 0..n {
                    let r2 = (i as f64 - c[0]).powi(2)
                        + (j as f64 - c[1]).powi(2)
                        + (k as f64 - c[2]).powi(2);
                    v.push((40.0 + 210.0 * (-r2 / 72.0).exp()).round() as u8);
                }
            }
        }
        let raw = w.path(&format!("s{t:02}.raw"));
        std::fs::write(&raw, v).unwrap();
        let pxo = format!("s{t:02}.pxo");
        let o = run(&[
            "import",
            s(&raw),
            "--dims",
            "48,48,48",
            "--type",
            "u8",
            "--brick",
            "16",
            "-o",
            s(&w.path(&pxo)),
        ]);
        assert!(o.status.success(), "{}", text(&o));
        series.push(format!("\"{pxo}\""));
    }
    let scene = w.path("series.toml");
    std::fs::write(
        &scene,
        std::fs::read_to_string(w.path("scene.toml"))
            .unwrap()
            .replace(
                "volume = \"v.pxo\"",
                &format!("series = [{}]", series.join(", ")),
            ),
    )
    .unwrap();
    let script = w.path("play.toml");
    std::fs::write(
        &script,
        format!(
            "frames = {}\n[[key]]\nframe = 0\ntime = 0\n[[key]]\nframe = {}\ntime = {}\n",
            2 * steps,
            2 * (steps - 1),
            steps - 1
        ),
    )
    .unwrap();
    (w, scene, script)
}

fn play_args<'a>(out: &'a Path, scene: &'a Path, script: &'a Path, sync: bool) -> Vec<&'a str> {
    let mut a = vec![
        "render",
        "--scene",
        s(scene),
        "--script",
        s(script),
        "--float",
        "--out",
        s(out),
    ];
    if sync {
        a.push("--sync");
    }
    a
}

#[test]
fn a_time_series_plays_identically_in_the_cluster() {
    let steps = 20;
    let (w, scene, script) = series_world(steps);
    let cluster = w.path("series-cluster");
    let o = mpirun(3, &play_args(&cluster, &scene, &script, true), &[]);
    assert!(o.status.success(), "{}", text(&o));
    let embedded = w.path("series-embedded");
    let mut args = play_args(&embedded, &scene, &script, true);
    args.extend(["--backends", "2"]);
    let o = run(&args);
    assert!(o.status.success(), "{}", text(&o));
    for frame in 0..2 * steps as u32 {
        for id in ["p00", "p01", "p02", "p03"] {
            assert_eq!(
                npy(&cluster, frame, id),
                npy(&embedded, frame, id),
                "projector {id}, frame {frame}"
            );
        }
    }
    // The steps are drawn: the blob moves between steps 0, 10 and 19 and
    // stays within a step (frames 2k and 2k + 1 draw step k, the second
    // with a cut as fine or finer).
    let (a, b, c) = (
        npy(&cluster, 1, "p01"),
        npy(&cluster, 21, "p01"),
        npy(&cluster, 39, "p01"),
    );
    assert!(a != b && b != c && a != c);
    // The blob's brightness-weighted x on the image moves one way.
    let centroid = |img: &[[f32; 4]]| {
        let (mut sx, mut sw) = (0.0f64, 0.0f64);
        for (i, p) in img.iter().enumerate() {
            sx += (i % 48) as f64 * p[0] as f64;
            sw += p[0] as f64;
        }
        sx / sw
    };
    let xs = [centroid(&a), centroid(&b), centroid(&c)];
    assert!(
        (xs[0] < xs[1] && xs[1] < xs[2]) || (xs[0] > xs[1] && xs[1] > xs[2]),
        "{xs:?}"
    );
    // `parallax info` names the series and, with --verify, checks every
    // step.
    let o = run(&["info", s(&scene), "--verify"]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(
        text(&o).contains("series:        20 time steps"),
        "{}",
        text(&o)
    );
    assert!(text(&o).contains("series[19]:     ok"), "{}", text(&o));
    // A step past the series is refused naming the script.
    let bad = w.path("bad.toml");
    std::fs::write(&bad, "[[key]]\nframe = 0\ntime = 20\n").unwrap();
    let o = run(&play_args(&w.path("bad"), &scene, &bad, true));
    assert!(!o.status.success());
    assert!(
        text(&o).contains("bad.toml: time: step 20") && text(&o).contains("20 time steps"),
        "{}",
        text(&o)
    );
}

#[test]
fn a_time_series_with_a_budget_for_one_step_never_shows_a_hole() {
    // Caches that hold one step's bricks (36 of 48³ in bricks of 16: 1.2
    // MB in f32, 0.3 in 8 bits), playback without waiting for reads: the
    // frame after a step change shows the coarser levels it has (the
    // root at once), never nothing where the volume is.
    let steps = 20;
    let (w, scene, script) = series_world(steps);
    let small = w.path("series-small.toml");
    std::fs::write(
        &small,
        std::fs::read_to_string(&scene).unwrap().replace(
            "[render]\n",
            "[render]\ncpu_cache_mb = 1.5\ngpu_cache_mb = 0.6\n",
        ),
    )
    .unwrap();
    // Played in order (the next step read ahead), and jumping 5 steps
    // every 2 frames (what was read ahead is never the step drawn next).
    let jump = w.path("jump.toml");
    let keys: String = (0..4)
        .flat_map(|k| [(2 * k, 5 * k), (2 * k + 1, 5 * k)])
        .map(|(f, t)| format!("[[key]]\nframe = {f}\ntime = {t}\n"))
        .collect();
    std::fs::write(&jump, keys).unwrap();
    for (name, script, frames) in [("play", &script, 2 * steps as u32), ("jump", &jump, 8)] {
        let reference = w.path(&format!("{name}-sync"));
        let o = run(&play_args(&reference, &small, script, true));
        assert!(o.status.success(), "{}", text(&o));
        let played = w.path(&format!("{name}-async"));
        let o = run(&play_args(&played, &small, script, false));
        assert!(o.status.success(), "{}", text(&o));
        no_holes(&reference, &played, frames, name);
    }
}

/// Every frame of `played` draws the volume wherever the frame of
/// `reference` does (its coarser levels, if its bricks have not arrived),
/// and draws bricks.
fn no_holes(reference: &Path, played: &Path, frames: u32, name: &str) {
    let mut coarse_frames = 0;
    for frame in 0..frames {
        for id in ["p00", "p01", "p02", "p03"] {
            let (r, p) = (npy(reference, frame, id), npy(played, frame, id));
            // Of the pixels where the reference sees the volume, the
            // played frame sees it too.
            let seen = r.iter().filter(|q| q[3] > 0.05).count();
            let kept = r
                .iter()
                .zip(&p)
                .filter(|(q, x)| q[3] > 0.05 && x[3] > 0.01)
                .count();
            assert!(
                seen > 0,
                "{name}: frame {frame} {id}: the reference sees the volume"
            );
            assert!(
                kept * 100 >= seen * 97,
                "{name}: frame {frame} {id}: {kept} of the {seen} pixels the volume covers are drawn"
            );
            coarse_frames += (r != p) as usize;
        }
    }
    let stats = stats_lines(played);
    assert!(
        stats
            .iter()
            .all(|s| s["cut_leaves_with_data"].as_u64() > Some(0)),
        "{name}: every frame draws bricks"
    );
    let roots = stats
        .iter()
        .filter(|s| s["cut_nodes"].as_u64() == Some(1))
        .count();
    eprintln!(
        "{name}: {coarse_frames} of {} images differ from the reference; {roots} frames drew the root alone",
        4 * frames
    );
}
