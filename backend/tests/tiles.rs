//! Tile culling (backend/src/raycast/tiles.rs): the dispatch runs only the
//! 8×8 tiles whose rays can meet data. Every image must be the one with
//! every tile run, bit for bit, and the tiles run must fall; each test
//! prints by how much.

mod support;
use parallax_backend::store::BrickEncoding;
use parallax_common::camera::View;
use parallax_common::config::RenderConfig;
use support::{
    clip_plane, colin27, colin27_lightfield, colin27_tfs, colin_placement, ct_bone, ct_placement,
    unchanged_by, Case,
};

/// Renders the converged frame with and without tile culling; asserts
/// every view's image is the same bit for bit and that fewer tiles ran;
/// returns the fraction of tiles run.
fn compare(c: &Case) -> f64 {
    let (on, off, lit, pixels) = unchanged_by(c, "tile culling", |r, on| r.tile_culling = on);
    let (t_on, t_off) = (on.tiles, off.tiles);
    println!(
        "{}: tiles run {t_off} → {t_on} ({:.1}% fewer); {lit} of {pixels} pixels lit",
        c.what,
        100.0 * (1.0 - t_on as f64 / t_off as f64),
    );
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
    let lightfield = colin27_lightfield(&[-0.5, 0.0, 0.7], 96);
    let (skin, brain) = colin27_tfs();
    let no_macrocells = RenderConfig {
        macrocells: false,
        ..RenderConfig::default()
    };
    let reconstruction = RenderConfig {
        reconstruction: true,
        ..RenderConfig::default()
    };
    let clip = clip_plane();
    let probe = [parallax_common::tools::Tool::Probe(
        parallax_common::tools::Probe::new([0.0, 0.02, 0.08], 0.05),
    )];
    let mimda = RenderConfig {
        mode: parallax_common::config::Mode::Mimda,
        gamma: 0.6,
        ..RenderConfig::default()
    };
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
        (
            "skin, probe",
            &skin,
            &probe[..],
            &window[..],
            RenderConfig::default(),
        ),
        ("brain, MImDA", &brain, &[][..], &window[..], mimda),
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
        // Where the kernel skips empty space (tools included) and its
        // macrocells are marked, the cells of the head leave out over a
        // third of the window's tiles.
        if !what.contains("leaves") && !what.contains("light field") && !what.contains("sub-frames")
        {
            assert!(f < 0.65, "{what}: {f:.2} of the tiles run");
        }
    }
}

/// The 96³ CT phantom under the CT-Bone preset, compared as `compare` does.
fn compare_ct(what: &str, cfg: RenderConfig) -> f64 {
    let dir = tempfile::tempdir().unwrap();
    let (db, tf) = ct_bone(dir.path(), BrickEncoding::U8Range);
    compare(&Case {
        what,
        db: &db,
        tf: &tf,
        tools: &[],
        placement: ct_placement(),
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
