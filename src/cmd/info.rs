//! `parallax info`: what a database holds; `--verify` checks every brick.
//! Given a scene file, its volume (a series' first step, the others
//! verified with `--verify`) and each of its registered layers.

use anyhow::{Context, Result};
use parallax_backend::store::{info, OctreeDb};
use std::path::{Path, PathBuf};

/// Describe a database (or a scene's volume and layers); --verify decodes
/// and checks every brick.
#[derive(clap::Args)]
pub struct Args {
    /// A `.pxo` database, or a scene file (`.toml`).
    database: PathBuf,
    #[arg(long)]
    verify: bool,
}

pub fn run(a: Args) -> Result<()> {
    if a.database.extension().is_some_and(|e| e == "toml") {
        let scene = parallax_common::config::Scene::load(&a.database)?;
        println!("scene:         {}", a.database.display());
        if let (Some(first), Some(last)) = (scene.series.first(), scene.series.last()) {
            println!(
                "series:        {} time steps, {} … {} (the first described; with --verify every one checked)",
                scene.series.len(),
                first.display(),
                last.display()
            );
            if a.verify {
                for (i, p) in scene.series.iter().enumerate().skip(1) {
                    let db = OctreeDb::open(p).with_context(|| format!("series[{i}]"))?;
                    let r = info::verify(&db).with_context(|| format!("series[{i}]"))?;
                    println!(
                        "series[{i}]:     ok, {} bricks decoded and checked",
                        r.bricks
                    );
                }
            }
        }
        describe(&scene.volume, a.verify)?;
        for (i, l) in scene.layers.iter().enumerate() {
            println!();
            println!(
                "layer[{i}]:      {} {}, opacity {}{}{}",
                if l.is_labels() {
                    "labels"
                } else {
                    "transfer function"
                },
                l.function_file().1.display(),
                l.opacity,
                if l.visible { "" } else { ", hidden" },
                l.view_opacity.map_or(String::new(), |v| format!(
                    ", view opacity about {:?} from {}° to {}°",
                    v.axis, v.angles_deg[0], v.angles_deg[1]
                ))
            );
            match (&l.transform, l.affine()) {
                (Some(parallax_common::config::LayerTransform::Scanner), _) => {
                    println!("transform:     scanner (both databases' scanner geometry)")
                }
                (_, Some((m, t))) => println!(
                    "transform:     layer space → the volume's: rows {m:?}, translation {t:?}"
                ),
                _ => {}
            }
            describe(&l.volume, a.verify).with_context(|| format!("layer[{i}].volume"))?;
        }
        return Ok(());
    }
    describe(&a.database, a.verify)
}

fn describe(path: &Path, verify: bool) -> Result<()> {
    let db = OctreeDb::open(path)?;
    print!("{}", info::describe(&db));
    if verify {
        let r = info::verify(&db)?;
        println!(
            "verify:        ok, {} bricks ({} bytes) decoded and checked",
            r.bricks, r.bytes
        );
    }
    Ok(())
}
