//! The display simulation (what an eye sees on the G10 §3 light field
//! display): with full horizontal parallax (η = 1) it tends to the eye's own
//! perspective view as the projectors get denser; with η = 0 every projector
//! shows the same image; the screen's tent blend of width Φ has the weights
//! it should; degenerate eyes and displays give black, never NaN; frames load
//! from `.npy` or sRGB `.png`. Every test prints the figures it asserts on.

mod support;
use parallax_backend::output::{write_npy, write_png};
use parallax_backend::render::Renderer;
use parallax_backend::simulate::{
    default_resolution, load_frame, parse_eye, sample, simulate, simulate_detailed, strip, sweep,
};
use parallax_backend::store::BrickEncoding;
use parallax_common::camera::{Placement, View};
use parallax_common::config::{
    Display, Interpolation, Observer, Projector, RenderConfig, Screen, Shading,
};
use parallax_common::tf::{ControlPoint, TransferFunction};
use support::{assert_valid, import_volume, marschner_lobb, mean_alpha};

use parallax_common::wall::{Layout, WallSpec};
use std::path::Path;

const SCREEN: [f64; 2] = [1.6, 0.9];
const RES: [u32; 2] = [192, 108];
const FOV: f64 = 40.0;

/// An arc of `n` projectors 2 m behind a 1.6 × 0.9 m screen over a 40° field
/// of view, the screen diffusing over exactly the projector spacing
/// (Φ = fov/n), observer at 2 m; s0 = one projector pixel.
fn wall(dir: &Path, n: usize) -> Display {
    let spec = WallSpec {
        projectors: n,
        resolution: RES,
        screen: SCREEN,
        pixel_size: SCREEN[0] / RES[0] as f64,
        angular_accuracy_deg: FOV / n as f64,
        fov_deg: FOV,
        distance: 2.0,
        observer: [0.0, 0.0, 2.0],
        layout: Layout::Arc,
    };
    let d = dir.join(format!("wall{n}"));
    spec.write(&d).unwrap();
    Display::load(&d.join("display.toml")).unwrap()
}

fn translucent() -> TransferFunction {
    TransferFunction::from_points(vec![
        ControlPoint::new(0.0, [0.0, 0.0, 0.0], 0.0),
        ControlPoint::new(80.0, [0.9, 0.5, 0.2], 0.0),
        ControlPoint::new(140.0, [0.9, 0.6, 0.3], 0.25),
        ControlPoint::new(200.0, [0.3, 0.6, 1.0], 0.06),
        ControlPoint::new(255.0, [1.0, 1.0, 1.0], 0.9),
    ])
    .unwrap()
}

/// Plain DVR, every leaf at full resolution, exact brick interpolation, step
/// 1/4 (a quarter of `step_factor` at sub-pixel accuracy 0.01).
fn config() -> RenderConfig {
    RenderConfig {
        shading: Shading::None,
        step_factor: 1.0,
        early_termination: 1.0,
        accuracy: 0.01,
        visibility_feedback: false,
        interpolation: Interpolation::Exact,
        ..RenderConfig::default()
    }
}

/// A 48³ Marschner–Lobb volume in bricks of 16, and a renderer for it.
fn setup(dir: &Path) -> Renderer {
    let vol = marschner_lobb(48);
    let db = dir.join("ml48.pxo");
    import_volume(&vol, &db, 16, BrickEncoding::U8Range);
    let mut r = Renderer::new(&db, &config()).unwrap();
    r.set_transfer_function(1, &translucent()).unwrap();
    r
}

/// 0.25 m wide, floating 15 cm in front of the screen, turned to show
/// depth.
fn placement() -> Placement {
    Placement {
        center: [0.0, 0.0, 0.15],
        rotation_deg: [20.0, 35.0, 0.0],
        size: 0.25,
    }
}

fn whole_screen() -> [f64; 4] {
    [-SCREEN[0] / 2.0, -SCREEN[1] / 2.0, SCREEN[0], SCREEN[1]]
}

/// PSNR (dB, peak 1) of the colour channels over the pixels in `mask`.
fn psnr(a: &[[f32; 4]], b: &[[f32; 4]], mask: &[bool]) -> f64 {
    let (mut sq, mut n) = (0.0, 0usize);
    for ((x, y), &m) in a.iter().zip(b).zip(mask) {
        if m {
            for c in 0..3 {
                let d = x[c] as f64 - y[c] as f64;
                sq += d * d;
            }
            n += 3;
        }
    }
    if sq == 0.0 {
        return f64::INFINITY;
    }
    10.0 * (n as f64 / sq).log10()
}

// ---------------------------------------------------------------------------

#[test]
fn full_parallax_tends_to_the_eyes_perspective_view() {
    let dir = tempfile::tempdir().unwrap();
    let mut r = setup(dir.path());
    let cfg = config();
    let pl = placement();
    // Between projector directions for every N below (2.86° from the screen
    // centre; the nearest directions are 2.5°/7.5°, 1.25°/3.75°,
    // 1.875°/3.125°, 2.5°/3.06°).
    let eye = [0.1, 0.0, 2.0];
    let direct_view = View {
        resolution: RES,
        region: whole_screen(),
        eye,
        observer: eye,
        eta: 0.0,
    };
    // What a display without parallax would show this eye: the observer's
    // own view.
    let centre_view = View {
        eye: [0.0, 0.0, 2.0],
        observer: [0.0, 0.0, 2.0],
        ..direct_view
    };
    let f = r
        .converge(&pl, &[direct_view, centre_view], &cfg, 20)
        .unwrap();
    assert!(f.stats.adequate);
    let direct = f.images[0].clone();
    let centre = f.images[1].clone();
    assert_valid("direct", &direct);
    assert!(mean_alpha(&direct) > 0.01, "{}", mean_alpha(&direct));

    let ns = [8usize, 16, 32, 72];
    let mut sims = Vec::new();
    let mut mirrored = None;
    for &n in &ns {
        let display = wall(dir.path(), n);
        let views = display.views(1.0);
        let t = std::time::Instant::now();
        let f = r.converge(&pl, &views, &cfg, 20).unwrap();
        assert!(f.stats.adequate);
        for im in &f.images {
            assert_valid("projector", im);
        }
        let s = simulate_detailed(&display, &f.images, eye, RES).unwrap();
        assert_valid("simulated", &s.image);
        if n == 72 {
            // A control: the eye mirrored to x = −0.1 sees another view.
            let m = simulate(&display, &f.images, [-0.1, 0.0, 2.0], RES).unwrap();
            mirrored = Some(m);
        }
        eprintln!(
            "N = {n}: {} views rendered in {:.1} s, {} of {} simulated pixels lit",
            views.len(),
            t.elapsed().as_secs_f64(),
            s.lit.iter().filter(|&&l| l).count(),
            s.lit.len()
        );
        sims.push(s);
    }
    // Compare where every display lights the eye (with projectors and eye
    // both 2 m from the screen, the eye sees the middle of the screen lit),
    // after checking the volume's image lies there.
    let mask: Vec<bool> = (0..direct.len())
        .map(|i| sims.iter().all(|s| s.lit[i]))
        .collect();
    let total: f64 = direct.iter().map(|p| p[3] as f64).sum();
    let inside: f64 = direct
        .iter()
        .zip(&mask)
        .filter(|(_, &m)| m)
        .map(|(p, _)| p[3] as f64)
        .sum();
    let coverage = inside / total;
    // The pixels the volume covers (in either image), for a second figure
    // not diluted by the empty background.
    let footprint = |s: &[[f32; 4]]| -> Vec<bool> {
        (0..direct.len())
            .map(|i| mask[i] && (direct[i][3] > 1e-3 || s[i][3] > 1e-3))
            .collect()
    };
    let base = psnr(&centre, &direct, &mask);
    let base_fp = psnr(&centre, &direct, &footprint(&centre));
    eprintln!(
        "eye {eye:?}: {} pixels lit for every N, holding {:.4} of the direct image's alpha; \
         no-parallax baseline (the observer's view): PSNR {base:.2} dB (footprint {base_fp:.2} dB)",
        mask.iter().filter(|&&m| m).count(),
        coverage
    );
    assert!(
        coverage >= 0.999,
        "the volume leaves the lit area: {coverage}"
    );
    let mut figures = Vec::new();
    for (n, s) in ns.iter().zip(&sims) {
        let p = psnr(&s.image, &direct, &mask);
        let pf = psnr(&s.image, &direct, &footprint(&s.image));
        eprintln!(
            "N = {n:2} (Φ = {:.3}°): PSNR vs the eye's perspective view {p:.2} dB (footprint \
             {pf:.2} dB)",
            FOV / *n as f64
        );
        figures.push((p, pf));
    }
    for w in figures.windows(2) {
        assert!(w[1].0 >= w[0].0 && w[1].1 >= w[0].1, "{figures:?}");
    }
    let (first, last) = (figures[0], figures[figures.len() - 1]);
    assert!(
        last.0 > first.0 + 3.0 && last.1 > first.1 + 3.0,
        "{figures:?}"
    );
    // Every display beats showing this eye the observer's view.
    assert!(
        figures.iter().all(|f| f.1 > base_fp),
        "{figures:?} vs {base_fp}"
    );
    // Measured 56.3 dB (footprint) on lavapipe.
    assert!(last.1 >= 50.0, "72 projectors: {:.2} dB", last.1);
    // The simulation follows the eye: the same display seen from the
    // mirrored eye (x = −0.1) is far from this eye's view.
    let m = mirrored.unwrap();
    let pm = psnr(&m, &direct, &footprint(&m));
    eprintln!("control: 72 projectors seen from x = −0.1 vs the view from x = 0.1: {pm:.2} dB");
    assert!(pm < base_fp, "{pm} vs {base_fp}");
}

#[test]
fn without_parallax_every_projector_shows_the_same_image() {
    let dir = tempfile::tempdir().unwrap();
    let mut r = setup(dir.path());
    let cfg = config();
    let display = wall(dir.path(), 8);
    let views = display.views(0.0);
    let f = r.converge(&placement(), &views, &cfg, 20).unwrap();
    assert!(f.stats.adequate);
    let first = &f.images[0];
    assert!(mean_alpha(first) > 0.01);
    let mut worst = 0f32;
    for im in &f.images[1..] {
        for (a, b) in im.iter().zip(first) {
            for c in 0..4 {
                worst = worst.max((a[c] - b[c]).abs());
            }
        }
    }
    eprintln!(
        "η = 0, 8 projectors: largest difference between projector images {worst:.1e} \
         (mean alpha {:.3})",
        mean_alpha(first)
    );
    assert!(worst < 1e-6);

    let half = [RES[0] / 2, RES[1] / 2];
    for eye in [[0.1, 0.0, 2.0], [-0.3, 0.1, 1.5], [0.5, -0.2, 3.0]] {
        // On the projectors' own grid: the image itself where lit.
        let s = simulate_detailed(&display, &f.images, eye, RES).unwrap();
        let mut worst = 0f32;
        let mut lit = 0;
        for (i, (p, &l)) in s.image.iter().zip(&s.lit).enumerate() {
            if l {
                lit += 1;
                for c in 0..4 {
                    worst = worst.max((p[c] - first[i][c]).abs());
                }
            } else {
                assert_eq!(*p, [0.0; 4]);
            }
        }
        // On a coarser grid: the image resampled (bilinear at each point).
        let s2 = simulate_detailed(&display, &f.images, eye, half).unwrap();
        let mut worst2 = 0f32;
        for j in 0..half[1] {
            for i in 0..half[0] {
                let k = (j * half[0] + i) as usize;
                if !s2.lit[k] {
                    assert_eq!(s2.image[k], [0.0; 4]);
                    continue;
                }
                // Output pixel (i, j) of the half grid is the corner shared
                // by projector pixels (2i, 2j) … (2i+1, 2j+1).
                let at = |x: u32, y: u32| first[(y * RES[0] + x) as usize];
                let want: [f32; 4] = std::array::from_fn(|c| {
                    (at(2 * i, 2 * j)[c]
                        + at(2 * i + 1, 2 * j)[c]
                        + at(2 * i, 2 * j + 1)[c]
                        + at(2 * i + 1, 2 * j + 1)[c])
                        / 4.0
                });
                for (got, w) in s2.image[k].iter().zip(want) {
                    worst2 = worst2.max((got - w).abs());
                }
            }
        }
        eprintln!(
            "η = 0, eye {eye:?}: {lit} pixels lit; largest difference from the projector image \
             {worst:.1e}, on the half grid from the image resampled {worst2:.1e}"
        );
        assert!(lit > 0);
        assert!(worst < 1e-6 && worst2 < 1e-6);
    }
}

// ---------------------------------------------------------------------------
// CPU only: small hand-made displays with constant-colour projector images.

fn projector(k: usize, position: [f64; 3], region: Option<[f64; 4]>) -> Projector {
    Projector {
        id: format!("p{k}"),
        position,
        resolution: [8, 6],
        region,
        rank: None,
        adapter: None,
        calibration: None,
    }
}

fn hand_display(projectors: Vec<Projector>, phi_deg: f64) -> Display {
    Display {
        screen: Screen {
            size: [0.4, 0.3],
            pixel_size: 0.01,
            angular_accuracy_deg: phi_deg,
        },
        observer: Observer {
            position: [0.0, 0.0, 1.0],
        },
        projectors,
        present: Default::default(),
        looking_glass: None,
    }
}

const RED: [f32; 4] = [1.0, 0.0, 0.0, 1.0];
const BLUE: [f32; 4] = [0.0, 0.0, 1.0, 1.0];

#[test]
fn the_screen_blends_neighbouring_beams_with_a_tent_of_width_phi() {
    // Two projectors 1 m behind the screen at x = ∓0.2: through the screen
    // centre their beams leave at ±atan(0.2) = ±11.31°, 2·11.31° apart; Φ is
    // that spacing.
    let spacing = 2.0 * 0.2f64.atan();
    let d = hand_display(
        vec![
            projector(0, [-0.2, 0.0, -1.0], None),
            projector(1, [0.2, 0.0, -1.0], None),
        ],
        spacing.to_degrees(),
    );
    let images = vec![vec![RED; 48], vec![BLUE; 48]];
    // 9 columns: column 4 is x = 0.
    let res = [9, 3];
    let centre = |img: &[[f32; 4]]| img[9 + 4];
    for wx in [0.0, 0.2, 0.1, -0.05, 0.3] {
        let img = simulate(&d, &images, [wx, 0.0, 1.0], res).unwrap();
        let to_eye = wx.atan(); // angle of Q→W at Q = 0
        let w0 = (1.0 - (to_eye - spacing / 2.0).abs() / spacing).max(0.0);
        let w1 = (1.0 - (to_eye + spacing / 2.0).abs() / spacing).max(0.0);
        let want_red = w0 / (w0 + w1);
        let got = centre(&img);
        eprintln!(
            "eye x = {wx}: weights {w0:.4} (beam of p0) / {w1:.4} (p1) → red {want_red:.4}, \
             simulated {got:?}"
        );
        assert!((got[0] as f64 - want_red).abs() < 1e-6);
        assert!((got[2] as f64 - (1.0 - want_red)).abs() < 1e-6);
        assert!((got[3] - 1.0).abs() < 1e-6);
        // the screen diffuses vertically: every row the same
        assert_eq!(img[4], img[9 + 4]);
        assert_eq!(img[18 + 4], img[9 + 4]);
    }
    // Beyond both beams by more than Φ: black.
    let far = simulate(&d, &images, [2.0, 0.0, 1.0], res).unwrap();
    assert_eq!(centre(&far), [0.0; 4]);

    // Φ = 0: the nearest beam alone, so every pixel is one projector's colour.
    let d0 = hand_display(d.projectors.clone(), 0.0);
    for wx in [0.1, -0.1, 0.03, 3.0] {
        let img = simulate(&d0, &images, [wx, 0.0, 1.0], res).unwrap();
        assert!(img.iter().all(|p| *p == RED || *p == BLUE), "{img:?}");
        assert_eq!(centre(&img), if wx > 0.0 { RED } else { BLUE });
    }

    // A projector lights only its region: p1 covers the left half only.
    let half = hand_display(
        vec![
            projector(0, [-0.2, 0.0, -1.0], None),
            projector(1, [0.2, 0.0, -1.0], Some([-0.2, -0.15, 0.2, 0.3])),
        ],
        spacing.to_degrees(),
    );
    let alone = hand_display(
        vec![projector(0, [-0.2, 0.0, -1.0], None)],
        spacing.to_degrees(),
    );
    for wx in [-0.2, -0.05, 0.1] {
        let eye = [wx, 0.0, 1.0];
        let got = simulate(&half, &images, eye, [8, 2]).unwrap();
        let both = simulate(&d, &images, eye, [8, 2]).unwrap();
        let red = simulate(&alone, &images[..1], eye, [8, 2]).unwrap();
        for k in 0..16 {
            // columns 0..3 are left of the centre, 4..7 right of it
            let want = if k % 8 < 4 { both[k] } else { red[k] };
            assert_eq!(got[k], want, "eye x {wx}, pixel {k}");
        }
        assert!(got.iter().any(|p| p[2] > 0.0) || wx > 0.0);
    }
}

#[test]
fn degenerate_eyes_and_displays_give_black_not_nan() {
    let spacing = 2.0 * 0.2f64.atan();
    let ps = vec![
        projector(0, [-0.2, 0.0, -1.0], None),
        projector(1, [0.2, 0.0, -1.0], None),
    ];
    let images = vec![vec![RED; 48], vec![BLUE; 48]];
    for phi in [spacing.to_degrees(), 0.0, 89.9] {
        let d = hand_display(ps.clone(), phi);
        for eye in [
            [0.0, 0.0, 0.0],   // at the screen centre
            [0.1, 0.05, 0.0],  // on the screen plane
            [1.0, 0.0, 0.0],   // on the plane, beside the screen
            [0.0, 0.0, -1.0],  // behind the screen, among the projectors
            [-0.2, 0.0, -1.0], // at a projector
            [0.0, 0.0, 1e-300],
            [0.0, 0.0, 1e9],
            [1e6, 0.0, 1e-3],
            [0.0, 1e6, 1.0],
        ] {
            let s = simulate_detailed(&d, &images, eye, [9, 5]).unwrap();
            assert_valid("degenerate", &s.image);
            if eye[2] <= 0.0 {
                assert!(s.image.iter().all(|p| *p == [0.0; 4]), "eye {eye:?}");
                assert!(s.lit.iter().all(|l| !l));
            }
        }
    }
    // A projector in front of the screen: its beams go away from an eye in
    // front, so only the one behind lights it.
    let d = hand_display(
        vec![
            projector(0, [-0.2, 0.0, -1.0], None),
            projector(1, [0.2, 0.0, 1.0], None),
        ],
        30.0,
    );
    let img = simulate(&d, &images, [0.0, 0.0, 1.0], [9, 3]).unwrap();
    assert!(img.iter().all(|p| *p == RED || *p == [0.0; 4]));
    assert!(img.contains(&RED));
    // Bad input is an error, not a panic.
    let d = hand_display(ps.clone(), 5.0);
    assert!(simulate(&d, &images, [f64::NAN, 0.0, 1.0], [4, 4]).is_err());
    assert!(simulate(&d, &images[..1], [0.0, 0.0, 1.0], [4, 4]).is_err());
    let e = simulate(&d, &[vec![RED; 48], vec![RED; 47]], [0.0, 0.0, 1.0], [4, 4]).unwrap_err();
    assert!(format!("{e:#}").contains("p1"), "{e:#}");
    assert!(simulate(&d, &images, [0.0, 0.0, 1.0], [0, 0])
        .unwrap()
        .is_empty());
    // Sampling far outside the image clamps to its edge.
    let q = sample(&images[0], [8, 6], [-0.2, -0.15, 0.4, 0.3], 1e300, -1e300);
    assert_eq!(q, RED);
    eprintln!("degenerate eyes (on the screen plane, behind it, at a projector, at 1e9 m): finite, black where no beam reaches");
}

#[test]
fn frames_load_from_npy_or_srgb_png() {
    let dir = tempfile::tempdir().unwrap();
    let d = hand_display(
        vec![
            projector(0, [-0.2, 0.0, -1.0], None),
            projector(1, [0.2, 0.0, -1.0], None),
        ],
        10.0,
    );
    // p0 as .npy only, p1 as .png and a different .npy: the .npy wins.
    let grad: Vec<[f32; 4]> = (0..48)
        .map(|i| {
            let v = i as f32 / 47.0;
            [v * 0.5, v, 1.0 - v, 1.0]
        })
        .collect();
    write_npy(&dir.path().join("p0.npy"), 8, 6, &grad).unwrap();
    write_png(&dir.path().join("p1.png"), 8, 6, &grad).unwrap();
    let frame = load_frame(&d, dir.path()).unwrap();
    assert_eq!(frame[0], grad);
    let mut worst = 0f32;
    for (a, b) in frame[1].iter().zip(&grad) {
        for c in 0..3 {
            worst = worst.max((a[c] - b[c]).abs());
        }
        assert_eq!(a[3], 1.0);
    }
    eprintln!("PNG (8-bit sRGB) round trip: largest linear error {worst:.2e}");
    assert!(worst < 5e-3);
    write_npy(&dir.path().join("p1.npy"), 8, 6, &vec![BLUE; 48]).unwrap();
    assert_eq!(load_frame(&d, dir.path()).unwrap()[1], vec![BLUE; 48]);
    // Missing and mis-sized images name the file.
    std::fs::remove_file(dir.path().join("p0.npy")).unwrap();
    let e = format!("{:#}", load_frame(&d, dir.path()).unwrap_err());
    assert!(
        e.contains("p0.npy") && e.contains("p0.png") && e.contains("'p0'"),
        "{e}"
    );
    write_npy(&dir.path().join("p0.npy"), 6, 8, &grad).unwrap();
    let e = format!("{:#}", load_frame(&d, dir.path()).unwrap_err());
    assert!(e.contains("p0.npy") && e.contains("8×6"), "{e}");
    // A render output folder instead of one of its frames.
    let out = tempfile::tempdir().unwrap();
    std::fs::create_dir(out.path().join("frame_00000")).unwrap();
    let e = format!("{:#}", load_frame(&d, out.path()).unwrap_err());
    assert!(e.contains("frame_NNNNN"), "{e}");
    eprintln!("errors: {e}");
}

#[test]
fn strips_sweeps_and_defaults() {
    let d = hand_display(
        vec![
            projector(0, [-0.2, 0.0, -1.0], None),
            projector(1, [0.2, 0.0, -1.0], None),
        ],
        2.0 * 0.2f64.atan().to_degrees(),
    );
    let images = vec![vec![RED; 48], vec![BLUE; 48]];
    let eyes = sweep([-0.2, 0.0, 1.0], [0.2, 0.0, 1.0], 5);
    assert_eq!(eyes.len(), 5);
    assert_eq!(eyes[2], [0.0, 0.0, 1.0]);
    let res = [7, 4];
    let (w, h, img) = strip(&d, &images, &eyes, res).unwrap();
    assert_eq!((w, h), (35, 4));
    for (k, &eye) in eyes.iter().enumerate() {
        let one = simulate(&d, &images, eye, res).unwrap();
        for j in 0..4 {
            for i in 0..7 {
                assert_eq!(img[j * 35 + k * 7 + i], one[j * 7 + i]);
            }
        }
    }
    // The leftmost eye sees the beam of the right projector more.
    assert!(img[35 + 3][2] > img[35 + 4 * 7 + 3][2]);
    assert_eq!(parse_eye("0.1, -0.2,2").unwrap(), [0.1, -0.2, 2.0]);
    assert!(parse_eye("1,2").is_err() && parse_eye("a,b,c").is_err());
    assert!(parse_eye("1,nan,2").is_err());
    // One pixel per s0, capped.
    assert_eq!(default_resolution(&d, 2048), [40, 30]);
    assert_eq!(default_resolution(&d, 20), [20, 15]);
    let g10 = hand_display(vec![], 0.8);
    let g10 = Display {
        screen: Screen {
            size: [1.6, 0.9],
            pixel_size: 0.0015,
            angular_accuracy_deg: 0.8,
        },
        ..g10
    };
    assert_eq!(default_resolution(&g10, 2048), [1067, 600]);
}
