//! Adaptive frame reconstruction (G10 §5) on the GPU: a static view becomes
//! the full render bit for bit; during a rotation the reconstructed frames
//! stay close to the full renders; the filter run on the GPU gives the
//! images the CPU's gives.

mod support;

use parallax_backend::metric::{as_reference, image_error};
use parallax_backend::render::Renderer;
use parallax_backend::store::BrickEncoding;
use parallax_common::camera::{Placement, View};
use parallax_common::config::{RenderConfig, Shading};
use support::{import_volume, marschner_lobb, translucent};

fn config(reconstruction: bool) -> RenderConfig {
    RenderConfig {
        shading: Shading::Phong,
        reconstruction,
        ..RenderConfig::default()
    }
}

fn placement(turn: f64) -> Placement {
    Placement {
        center: [0.0, 0.0, 0.0],
        rotation_deg: [20.0, 30.0 + turn, 0.0],
        size: 0.2,
    }
}

fn psnr(img: &[[f32; 4]], reference: &[[f32; 4]]) -> f64 {
    image_error(img, &as_reference(reference)).psnr_db
}

#[test]
fn a_static_view_becomes_the_full_render_and_a_rotation_stays_close() {
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("ml.pxo");
    import_volume(&marschner_lobb(48), &db, 16, BrickEncoding::U8Range);
    let views = [View::window([96, 72], [0.4, 0.3], [0.0, 0.0, 0.8])];

    // Full renders, the cut converged first.
    let full_cfg = config(false);
    let mut full = Renderer::new(&db, &full_cfg).unwrap();
    full.set_transfer_function(1, &translucent()).unwrap();
    let reference = full
        .converge(&placement(0.0), &views, &full_cfg, 30)
        .unwrap();

    let cfg = config(true);
    let mut r = Renderer::new(&db, &cfg).unwrap();
    r.set_transfer_function(1, &translucent()).unwrap();
    r.converge(&placement(0.0), &views, &full_cfg, 30).unwrap();
    r.sync_io = true;
    let mut out = Vec::new();
    for f in 0..4u64 {
        out.push(r.frame(f, &placement(0.0), &views, &cfg).unwrap().images[0].clone());
    }
    let first = psnr(&out[0], &reference.images[0]);
    eprintln!("static: one sub-frame, PSNR {first:.1} dB against the full render");
    assert!(
        out[0] != reference.images[0],
        "one sub-frame is an estimate"
    );
    assert!(first > 25.0, "{first} dB");
    assert!(
        out[3] == reference.images[0],
        "four frames make the full render bit for bit"
    );

    // A rotation of 1° per frame: each reconstructed frame against the full
    // render of the same frame.
    let mut worst = f64::INFINITY;
    let mut sum = 0.0;
    let n = 12;
    for f in 0..n {
        let p = placement(1.0 + f as f64);
        let a = full.frame(f, &p, &views, &full_cfg).unwrap();
        let b = r.frame(4 + f, &p, &views, &cfg).unwrap();
        let q = psnr(&b.images[0], &a.images[0]);
        worst = worst.min(q);
        sum += q;
    }
    eprintln!(
        "rotation 1°/frame: PSNR mean {:.1} dB, worst {worst:.1} dB",
        sum / n as f64
    );
    assert!(worst > 25.0, "{worst} dB");

    // A new transfer function: once the cut is stable again, the frames
    // become the full render bit for bit (at most eight frames later).
    let tf2 = parallax_common::tf::TransferFunction::from_points(
        translucent()
            .points()
            .iter()
            .map(|p| parallax_common::tf::ControlPoint::new(p.value, [0.2, 0.9, 0.4], p.extinction))
            .collect(),
    )
    .unwrap();
    r.set_transfer_function(2, &tf2).unwrap();
    full.set_transfer_function(2, &tf2).unwrap();
    let p = placement(20.0);
    let want = full.converge(&p, &views, &full_cfg, 30).unwrap().images[0].clone();
    let mut stable = 0;
    let mut f = 100;
    let last = loop {
        let fr = r.frame(f, &p, &views, &cfg).unwrap();
        f += 1;
        stable = if fr.stats.adequate && fr.stats.uploaded == 0 {
            stable + 1
        } else {
            0
        };
        if stable == 8 || f > 140 {
            break fr.images[0].clone();
        }
    };
    assert_eq!(stable, 8, "the cut did not settle");
    assert!(last == want, "eight stable frames after a change are exact");
}

#[test]
fn the_filter_on_the_gpu_is_the_filter_on_the_cpu_for_several_views_of_odd_sizes() {
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("ml.pxo");
    import_volume(&marschner_lobb(48), &db, 16, BrickEncoding::U8Range);
    // Views one after the other in the image: odd sides, a thin one.
    let views = [
        View::window([96, 72], [0.4, 0.3], [0.0, 0.0, 0.8]),
        View::window([37, 23], [0.3, 0.2], [0.05, 0.02, 0.7]),
        View::window([1, 5], [0.01, 0.05], [0.0, 0.0, 0.8]),
    ];
    let cfg = config(true);
    let mut gpu = Renderer::new(&db, &cfg).unwrap();
    gpu.reconstruct_on_gpu = true;
    let mut cpu = Renderer::new(&db, &cfg).unwrap();
    cpu.reconstruct_on_gpu = false;
    let mut worst = 0.0f32;
    let mut pixels = 0usize;
    for r in [&mut gpu, &mut cpu] {
        r.set_transfer_function(1, &translucent()).unwrap();
        r.sync_io = true;
    }
    // A rotation (history kept), a jump (history forgotten), a rotation.
    let turns = (0..10)
        .map(|f| f as f64)
        .chain((0..6).map(|f| 45.0 + f as f64));
    for (f, turn) in turns.enumerate() {
        let a = gpu.frame(f as u64, &placement(turn), &views, &cfg).unwrap();
        let b = cpu.frame(f as u64, &placement(turn), &views, &cfg).unwrap();
        // The CPU filter's time is a stage of its own; on the GPU it is
        // part of the rays' dispatch.
        assert_eq!(a.stats.reconstruct_ms, 0.0);
        assert!(b.stats.reconstruct_ms > 0.0 && b.stats.reconstruct_ms < b.stats.total_ms);
        for (x, y) in a.images.iter().zip(&b.images) {
            assert_eq!(x.len(), y.len());
            for (p, q) in x.iter().zip(y) {
                for c in 0..4 {
                    assert!(p[c].is_finite());
                    worst = worst.max((p[c] - q[c]).abs());
                }
            }
            pixels += x.len();
        }
    }
    eprintln!("GPU filter against CPU filter: largest difference {worst:e} over {pixels} pixels");
    // The same arithmetic; a GPU may round a fused multiply-add once.
    assert!(worst <= 1e-6, "{worst}");
}
