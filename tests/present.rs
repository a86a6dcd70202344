//! `--present` on a real X server (Xvfb) with the GPU that renders
//! (lavapipe without one): `mpirun -n 3 parallax render --present` of the
//! 16-projector wall shows each projector's image at its place on the
//! screen, equal to its PNG, with the swap lock's spread in the stats; a
//! rank that cannot open its window ends the run at once, naming itself.

mod support;

use std::io::{BufRead, BufReader, Read};
use std::path::Path;
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_parallax")
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// An X server of its own for the test, its screen kept as an XWD file.
struct Xvfb {
    child: Child,
    display: String,
    fb: tempfile::TempDir,
    _one: std::sync::MutexGuard<'static, ()>,
}

/// One X server at a time: the tests' servers, runs and captures share
/// two cores, and each test's timing assumes the machine to itself.
static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

impl Xvfb {
    fn start(w: u32, h: u32) -> Xvfb {
        let guard = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
        let fb = tempfile::tempdir().unwrap();
        let mut child = Command::new("Xvfb")
            .args(["-displayfd", "1", "-screen", "0"])
            .arg(format!("{w}x{h}x24"))
            .args(["-fbdir", s(fb.path()), "-nolisten", "tcp", "-br"])
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("Xvfb (Debian xvfb; scripts/test.sh installs it)");
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut line)
            .unwrap();
        let display = format!(":{}", line.trim());
        assert!(line.trim().parse::<u32>().is_ok(), "Xvfb said '{line}'");
        Xvfb {
            child,
            display,
            fb,
            _one: guard,
        }
    }

    /// The screen now: width, height and 8-bit RGB.
    fn screen(&self) -> (usize, usize, Vec<[u8; 3]>) {
        let d = std::fs::read(self.fb.path().join("Xvfb_screen0")).unwrap();
        read_xwd(&d)
    }
}

impl Drop for Xvfb {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// An XWD image (the X Window Dump format: a header of big-endian 32-bit
/// fields, a colour map, then the pixels), as RGB, through its masks.
fn read_xwd(d: &[u8]) -> (usize, usize, Vec<[u8; 3]>) {
    let f = |i: usize| u32::from_be_bytes(d[4 * i..4 * i + 4].try_into().unwrap());
    let (header, w, h, order, bpp, bpl) = (f(0), f(4), f(5), f(7), f(11), f(12));
    let (masks, ncolors) = ([f(14), f(15), f(16)], f(19));
    assert_eq!(bpp, 32, "24-bit screens are stored as 32-bit pixels");
    let start = (header + ncolors * 12) as usize;
    let mut px = Vec::with_capacity((w * h) as usize);
    for y in 0..h as usize {
        for x in 0..w as usize {
            let o = start + y * bpl as usize + 4 * x;
            let b: [u8; 4] = d[o..o + 4].try_into().unwrap();
            let v = if order == 0 {
                u32::from_le_bytes(b)
            } else {
                u32::from_be_bytes(b)
            };
            px.push(masks.map(|m| ((v & m) >> m.trailing_zeros()) as u8));
        }
    }
    (w as usize, h as usize, px)
}

fn read_png(p: &Path) -> (usize, usize, Vec<[u8; 3]>) {
    let dec = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(p).unwrap()));
    let mut r = dec.read_info().unwrap();
    let mut buf = vec![0; r.output_buffer_size()];
    let info = r.next_frame(&mut buf).unwrap();
    let ch = info.color_type.samples();
    let px = buf[..info.buffer_size()]
        .chunks_exact(ch)
        .map(|c| [c[0], c[1], c[2]])
        .collect();
    (info.width as usize, info.height as usize, px)
}

/// A shells volume, its transfer function and a scene on the committed
/// 16-projector wall (`configs/displays/wall16`), placed by `present`.
fn world(present: &str) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    support::volume(d, "shells", 48);
    let wall = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/displays/wall16");
    let display = std::fs::read_to_string(wall.join("display.toml")).unwrap();
    std::fs::write(d.join("display.toml"), format!("{display}\n{present}")).unwrap();
    std::fs::create_dir(d.join("projectors")).unwrap();
    for e in std::fs::read_dir(wall.join("projectors")).unwrap() {
        let e = e.unwrap();
        std::fs::copy(e.path(), d.join("projectors").join(e.file_name())).unwrap();
    }
    std::fs::write(
        d.join("scene.toml"),
        "volume = \"v.pxo\"\ntransfer_function = \"tf.toml\"\ndisplay = \"display.toml\"\n[placement]\ncenter = [0, 0, 0.1]\nsize = 0.5\nrotation_deg = [15, 30, 0]\n[render]\neta = 1.0\nshading = \"phong\"\n",
    )
    .unwrap();
    dir
}

/// `mpirun -n 3 parallax render --present` with these extra arguments, on
/// `display` (none: DISPLAY unset).
fn present(dir: &Path, out: &Path, display: Option<&str>, extra: &[&str]) -> Command {
    let mut c = Command::new("timeout");
    c.args(["120", "mpirun", "-n", "3"]);
    if display.is_some() {
        c.args(["-x", "DISPLAY"]);
    }
    c.arg(bin())
        .args(["render", "--scene", s(&dir.join("scene.toml")), "--sync"])
        .args(["--out", s(out), "--present"])
        .args(extra)
        .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
        .env("OMPI_MCA_rmaps_base_oversubscribe", "1")
        .env_remove("DISPLAY");
    if let Some(x) = display {
        c.env("DISPLAY", x);
    }
    c
}

/// Waits until `n` back-end stats of the run are in `out` (a frame's are
/// written after its present) and the X server has had a moment to show
/// it; panics with the run's output if the run ends or stalls first.
fn on_screen(out: &Path, n: usize, run: &mut Child) {
    let start = Instant::now();
    while stats(out).len() < n {
        if start.elapsed() > Duration::from_secs(90) || run.try_wait().unwrap().is_some() {
            let _ = run.kill();
            let mut said = String::new();
            for pipe in [
                run.stdout
                    .take()
                    .map(|p| Box::new(p) as Box<dyn std::io::Read>),
                run.stderr
                    .take()
                    .map(|p| Box::new(p) as Box<dyn std::io::Read>),
            ]
            .into_iter()
            .flatten()
            {
                let _ = BufReader::new(pipe).read_to_string(&mut said);
            }
            panic!("the run ended or stalled before its last frame: {said}");
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    std::thread::sleep(Duration::from_millis(500));
}

/// The largest channel difference between an image `w` wide and the
/// screen (`sw` wide) where the image's top left is at `at`.
fn region_diff(screen: &[[u8; 3]], sw: usize, img: &[[u8; 3]], w: usize, at: (usize, usize)) -> u8 {
    img.iter()
        .enumerate()
        .flat_map(|(i, b)| {
            let a = screen[(at.1 + i / w) * sw + at.0 + i % w];
            (0..3).map(move |c| a[c].abs_diff(b[c]))
        })
        .max()
        .unwrap_or(0)
}

/// The stats of every back end, one JSON object a line.
fn stats(out: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(out.join("stats.jsonl"))
        .unwrap_or_default()
        .lines()
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect()
}

#[test]
fn the_wall_on_one_x_screen_shows_every_projector_equal_to_its_png() {
    // The default layout: each projector's window on a grid of ⌈√16⌉ = 4
    // columns of 160×90 cells.
    let x = Xvfb::start(800, 400);
    let dir = world("");
    for frames in [3u64, 5] {
        let out = dir.path().join(format!("out{frames}"));
        let f = frames.to_string();
        let mut run = present(
            dir.path(),
            &out,
            Some(&x.display),
            &["--frames", &f, "--hold", "5"],
        )
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
        // The last frame is on the screen once both back ends' stats of
        // it are written (they are written after its present).
        on_screen(&out, 2 * frames as usize, &mut run);
        let (sw, _, screen) = x.screen();
        let last = out.join(format!("frame_{:05}", frames - 1));
        let mut worst = 0u8;
        let mut lit = 0;
        for p in 0..16usize {
            let (w, h, png) = read_png(&last.join(format!("p{p:02}.png")));
            assert_eq!((w, h), (160, 90));
            let at = ((p % 4) * 160, (p / 4) * 90);
            worst = worst.max(region_diff(&screen, sw, &png, w, at));
            lit += png.iter().filter(|b| **b != [0, 0, 0]).count();
        }
        eprintln!("frames {frames}: the screen and the PNGs differ by at most {worst}/255");
        assert!(lit > 1000, "the frame shows the volume ({lit} pixels)");
        assert!(
            worst <= 1,
            "frame {}: screen and PNGs differ by {worst}/255",
            frames - 1
        );
        // The swap lock: both back ends presented every frame, within a
        // frame's time of each other.
        let st = stats(&out);
        for f in 0..frames {
            let t: Vec<u64> = st
                .iter()
                .filter(|s| s["frame"] == f)
                .map(|s| s["present_us"].as_u64().unwrap())
                .collect();
            assert_eq!(t.len(), 2);
            assert!(t.iter().all(|&t| t > 0));
            // Drawn from the ray caster's image buffer, not read back.
            assert!(st
                .iter()
                .filter(|s| s["frame"] == f)
                .all(|s| s["present_direct"] == true));
            let spread_ms = (t[0].abs_diff(t[1])) as f64 / 1e3;
            eprintln!("frames {frames}: frame {f} present spread {spread_ms:.2} ms");
            assert!(spread_ms < 1000.0, "spread {spread_ms} ms");
        }
        let o = run.wait_with_output().unwrap();
        assert!(o.status.success(), "{}", text(&o));
        assert!(
            text(&o).contains("present spread across ranks"),
            "{}",
            text(&o)
        );
    }
}

#[test]
fn outputs_by_name_and_rect_place_projectors_side_by_side() {
    // One back end (embedded) with two outputs: Xvfb's one RandR output by
    // name (the whole screen) for p00–p07 side by side, and a window at a
    // rect for p08–p15 at their viewports, opened after it and so on top.
    let x = Xvfb::start(1400, 300);
    let ids = |r: std::ops::Range<usize>| {
        r.map(|p| format!("\"p{p:02}\""))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let viewports = (0..8)
        .map(|i| format!("[{}, 5]", i * 160 + 2))
        .collect::<Vec<_>>()
        .join(", ");
    let dir = world(&format!(
        "[present]\nmode = \"immediate\"\n[[present.output]]\nname = \"screen\"\nprojectors = [{}]\n[[present.output]]\nrect = [0, 120, 1300, 100]\nprojectors = [{}]\nviewports = [{viewports}]\n",
        ids(0..8),
        ids(8..16),
    ));
    // A calibrated projector (its image moved by 3 and 2 pixels): its back
    // end presents the images as written, read back and calibrated.
    let p03 = dir.path().join("projectors/p03.toml");
    let plain = std::fs::read_to_string(&p03).unwrap();
    std::fs::write(
        &p03,
        format!("{plain}[calibration]\nhomography = [[1, 0, 3], [0, 1, 2], [0, 0, 1]]\n"),
    )
    .unwrap();
    let out = dir.path().join("out");
    let mut run = Command::new(bin())
        .args([
            "render",
            "--scene",
            s(&dir.path().join("scene.toml")),
            "--sync",
        ])
        .args([
            "--out",
            s(&out),
            "--present",
            "--frames",
            "2",
            "--hold",
            "5",
        ])
        .args(["--backends", "1"])
        .env("DISPLAY", &x.display)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    on_screen(&out, 2, &mut run);
    let (sw, _, screen) = x.screen();
    let mut worst = 0u8;
    for p in 0..16usize {
        let (w, _, png) = read_png(&out.join(format!("frame_00001/p{p:02}.png")));
        // The named output starts at the screen's corner; the rect's
        // viewports are 2 pixels in and 5 down, at y = 120.
        let (x0, y0) = if p < 8 {
            (p * 160, 0)
        } else {
            ((p - 8) * 160 + 2, 125)
        };
        worst = worst.max(region_diff(&screen, sw, &png, w, (x0, y0)));
    }
    eprintln!("two outputs, read back: the screen and the PNGs differ by at most {worst}/255");
    assert!(worst <= 1, "screen and PNGs differ by {worst}/255");
    assert!(stats(&out).iter().all(|s| s["present_direct"] == false));
    let _ = run.kill();
    let _ = run.wait();
}

#[test]
fn a_rank_that_cannot_open_its_window_ends_the_run_naming_it() {
    let x = Xvfb::start(640, 400);
    let cases: [(&str, Option<&str>, &[&str]); 2] = [
        // No X display at all: every back end fails; the first is named.
        ("", None, &["back end 1 failed to set up: --present: no X display to present on (DISPLAY is not set)"]),
        // An output the X screen does not have (back end 2's).
        (
            "[present]\n[[present.output]]\nrect = [0, 0, 640, 90]\nprojectors = [\"p00\", \"p01\", \"p02\", \"p03\"]\n[[present.output]]\nname = \"DP-9\"\nprojectors = [\"p08\"]\n",
            Some(&x.display),
            &[
                "back end 2 failed to set up: --present: output 'DP-9'",
                "no output 'DP-9' (its outputs: screen)",
            ],
        ),
    ];
    for (present_section, display, want) in cases {
        let dir = world(present_section);
        let out = dir.path().join("out");
        let t = Instant::now();
        let o = present(dir.path(), &out, display, &["--frames", "3"])
            .output()
            .unwrap();
        let secs = t.elapsed().as_secs_f64();
        assert!(!o.status.success());
        let msg = text(&o);
        for w in want {
            assert!(msg.contains(w), "wanted '{w}' in:\n{msg}");
        }
        assert!(secs < 30.0, "took {secs:.1} s:\n{msg}");
    }
}

#[test]
fn a_looking_glass_display_writes_its_interleaved_panel() {
    // A Looking Glass Portrait's calibration (optical values of a real
    // unit), 4×3 views of 48×64: the display, then a frame of its panel.
    let dir = world("");
    let d = dir.path();
    std::fs::write(
        d.join("visual.json"),
        r#"{ "pitch": {"value": 52.59267044067383}, "slope": {"value": -7.083540916442871},
            "center": {"value": 0.8167931437492371}, "viewCone": {"value": 40.0},
            "invView": {"value": 1.0}, "DPI": {"value": 324.0},
            "screenW": {"value": 1536.0}, "screenH": {"value": 2048.0},
            "flipImageX": {"value": 0.0}, "flipImageY": {"value": 0.0}, "flipSubp": {"value": 0.0} }"#,
    )
    .unwrap();
    let gen = Command::new(bin())
        .args(["display-gen", "--looking-glass", s(&d.join("visual.json"))])
        .args([
            "--quilt",
            "4x3",
            "--view-size",
            "48x64",
            "-o",
            s(&d.join("lkg")),
        ])
        .output()
        .unwrap();
    assert!(gen.status.success(), "{}", text(&gen));
    let scene = std::fs::read_to_string(d.join("scene.toml"))
        .unwrap()
        .replace("display.toml", "lkg/display.toml")
        .replace("size = 0.5", "size = 0.1");
    std::fs::write(d.join("lkg.toml"), scene).unwrap();
    let out = d.join("out");
    let o = Command::new(bin())
        .args([
            "render",
            "--scene",
            s(&d.join("lkg.toml")),
            "--frames",
            "3",
            "--sync",
        ])
        .args(["--out", s(&out)])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let (w, h, panel) = read_png(&out.join("frame_00002/panel.png"));
    assert_eq!((w, h), (1536, 2048));
    // The views differ (the volume turns across the cone), and the panel
    // shows them: lit, and with sub-pixels from different views side by
    // side (colour fringes) where the volume's edge is.
    let views: Vec<Vec<[u8; 3]>> = (0..12)
        .map(|i| read_png(&out.join(format!("frame_00002/v{i:02}.png"))).2)
        .collect();
    assert_ne!(views[0], views[11]);
    let lit = panel.iter().filter(|p| **p != [0, 0, 0]).count();
    assert!(lit > 10_000, "{lit} lit panel pixels");
    // Presented: the panel fills one window at the screen's corner, the
    // same bytes as panel.png.
    let x = Xvfb::start(1536, 2048);
    let shown = d.join("shown");
    let mut run = Command::new(bin())
        .args([
            "render",
            "--scene",
            s(&d.join("lkg.toml")),
            "--frames",
            "3",
            "--sync",
        ])
        .args(["--out", s(&shown), "--present", "--hold", "5"])
        .env("DISPLAY", &x.display)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    on_screen(&shown, 3, &mut run);
    let (_, _, screen) = x.screen();
    let (_, _, panel) = read_png(&shown.join("frame_00002/panel.png"));
    let worst = screen
        .iter()
        .zip(&panel)
        .flat_map(|(a, b)| (0..3).map(move |c| a[c].abs_diff(b[c])))
        .max()
        .unwrap();
    assert!(worst <= 1, "the screen and panel.png differ by {worst}/255");
    assert!(stats(&shown).iter().all(|s| s["present_direct"] == false));
    let _ = run.kill();
    let _ = run.wait();
    // Two back ends cannot share the panel.
    let o = Command::new(bin())
        .args([
            "render",
            "--scene",
            s(&d.join("lkg.toml")),
            "--frames",
            "1",
            "--backends",
            "2",
        ])
        .args(["--out", s(&d.join("out2"))])
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(
        text(&o).contains("a Looking Glass's views are rendered by one back end"),
        "{}",
        text(&o)
    );
}
