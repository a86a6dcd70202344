//! Tile culling (backend/src/raycast/tiles.rs): the dispatch runs only the
//! 8×8 tiles whose rays can meet data. Every image must be the one with
//! every tile run, bit for bit, and the tiles run must fall; each test
//! prints by how much.

mod support;
use parallax_backend::data::{write_synth, SynthKind};
use parallax_backend::render::Renderer;
use parallax_backend::store::BrickEncoding;
use parallax_backend::volume::VoxelType;
use parallax_common::camera::{Placement, View};
use parallax_common::config::RenderConfig;
use parallax_common::tf::TransferFunction;
use parallax_common::tools::{ClipPlane, Tool};
use std::path::Path;
use support::{colin27, colin_placement, configs, import_file};

struct Case<'a> {
    what: &'a str,
    db: &'a Path,
    tf: &'a TransferFunction,
    tools: &'a [Tool],
    placement: Placement,
    views: &'a [View],
    cfg: RenderConfig,
}

/// Renders the converged frame with and without tile culling; asserts
/// every view's image is the same bit for bit and that fewer tiles ran;
/// returns the fraction of tiles run.
fn compare(c: &Case) -> f64 {
    let run = |culling: bool| {
        let mut r = Renderer::new(c.db, &c.cfg).unwrap();
        r.set_transfer_function(1, c.tf).unwrap();
        r.set_tools(1, c.tools).unwrap();
        r.tile_culling = culling;
        let f = r.converge(&c.placement, c.views, &c.cfg, 64).unwrap();
        // With frame reconstruction, the four sub-frames of the converged
        // cut.
        let mut f = f;
        if c.cfg.reconstruction {
            for k in 0..4 {
                f = r.frame(100 + k, &c.placement, c.views, &c.cfg).unwrap();
            }
        }
        (f.images, f.stats.tiles)
    };
    let (on, t_on) = run(true);
    let (off, t_off) = run(false);
    let pixels: usize = on.iter().map(Vec::len).sum();
    let lit: usize = on
        .iter()
        .map(|img| img.iter().filter(|p| p[3] > 0.01).count())
        .sum();
    println!(
        "{}: tiles run {t_off} → {t_on} ({:.1}% fewer); {lit} of {pixels} pixels lit",
        c.what,
        100.0 * (1.0 - t_on as f64 / t_off as f64),
    );
    assert!(lit > pixels / 20, "{}: the volume is visible", c.what);
    for (a, b) in on.iter().zip(&off) {
        let differing = a
            .iter()
            .zip(b)
            .filter(|(p, q)| p.map(f32::to_bits) != q.map(f32::to_bits))
            .count();
        assert_eq!(
            differing, 0,
            "{}: pixels that differ with tile culling",
            c.what
        );
    }
    assert!(t_on < t_off, "{}: tiles {t_off} → {t_on}", c.what);
    t_on as f64 / t_off as f64
}

#[test]
fn colin27_views_unchanged_with_fewer_tiles() {
    let dir = tempfile::tempdir().unwrap();
    let Some(db) = colin27(dir.path(), BrickEncoding::U8Range) else {
        return;
    };
    let window = [View::window([160, 160], [0.3, 0.3], [0.0, 0.0, 0.8])];
    // Three multi-centre views of a light field display (G10 Eq. 1), one
    // looking past the head's side.
    let lightfield: Vec<View> = [-0.5, 0.0, 0.7]
        .iter()
        .map(|&ex| View {
            resolution: [96, 96],
            region: [-0.15, -0.15, 0.3, 0.3],
            eye: [ex, 0.0, 1.5],
            observer: [0.1, 0.02, 0.9],
            eta: 1.0,
        })
        .collect();
    let skin = TransferFunction::load(configs().join("tf/colin27-skin.toml")).unwrap();
    let brain = TransferFunction::load(configs().join("tf/colin27-brain.toml")).unwrap();
    let no_macrocells = RenderConfig {
        macrocells: false,
        ..RenderConfig::default()
    };
    let reconstruction = RenderConfig {
        reconstruction: true,
        ..RenderConfig::default()
    };
    let clip = [Tool::ClipPlane(ClipPlane {
        point: [0.0, 0.0, 0.02],
        normal: [0.0, 0.0, 1.0],
        thickness: 0.01,
        context: [0.3, 0.7],
    })];
    let cases = [
        (
            "skin, macrocells",
            &skin,
            &[][..],
            &window[..],
            RenderConfig::default(),
        ),
        (
            "skin, leaves only",
            &skin,
            &[][..],
            &window[..],
            no_macrocells,
        ),
        (
            "brain",
            &brain,
            &[][..],
            &window[..],
            RenderConfig::default(),
        ),
        (
            "brain, light field",
            &brain,
            &[][..],
            &lightfield[..],
            RenderConfig::default(),
        ),
        (
            "skin, sub-frames",
            &skin,
            &[][..],
            &window[..],
            reconstruction,
        ),
        (
            "brain, clip plane",
            &brain,
            &clip[..],
            &window[..],
            RenderConfig::default(),
        ),
    ];
    for (what, tf, tools, views, cfg) in cases {
        let f = compare(&Case {
            what: &format!("Colin27 {what}"),
            db: &db,
            tf,
            tools,
            placement: colin_placement(),
            views,
            cfg,
        });
        // Where the kernel is plain and its macrocells are marked, the
        // cells of the head leave out over a third of the window's tiles.
        if what == "skin, macrocells" || what == "brain" {
            assert!(f < 0.65, "{what}: {f:.2} of the tiles run");
        }
    }
}

/// The 96³ CT phantom under the CT-Bone preset, compared as `compare` does.
fn compare_ct(what: &str, cfg: RenderConfig) -> f64 {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("ct.nrrd");
    write_synth(SynthKind::Ct, 96, VoxelType::I16, &src, |_| {}).unwrap();
    let db = dir.path().join("ct.pxo");
    import_file(&src, &db, BrickEncoding::U8Range);
    let tf = TransferFunction::load(configs().join("tf/ct-bone.toml")).unwrap();
    compare(&Case {
        what,
        db: &db,
        tf: &tf,
        tools: &[],
        placement: Placement {
            center: [0.0; 3],
            rotation_deg: [-70.0, 30.0, 0.0],
            size: 0.25,
        },
        views: &[View::window([160, 120], [0.4, 0.3], [0.0, 0.0, 0.8])],
        cfg,
    })
}

#[test]
fn a_ct_with_much_air_runs_a_fraction_of_its_tiles() {
    let f = compare_ct("CT phantom, bone", RenderConfig::default());
    assert!(f < 0.8, "{f:.2} of the tiles run");
}

/// With multilevel sampling a leaf's samples blend in its parent and
/// grandparent, whose data reach where the leaf's own cells are empty:
/// tiles are culled by the leaves with data, and the image is still the
/// one with every tile run.
#[test]
fn multilevel_sampling_is_culled_by_leaves() {
    let cfg = RenderConfig {
        multilevel: true,
        accuracy: 2.0,
        ..RenderConfig::default()
    };
    let f = compare_ct("CT phantom, bone, multilevel", cfg);
    assert!(f < 1.0, "{f:.2} of the tiles run");
}
