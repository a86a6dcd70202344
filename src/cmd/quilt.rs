//! `parallax quilt`: the scene as a Looking Glass quilt.

use super::args;
use anyhow::{bail, Result};
use parallax_backend::quilt;
use std::path::PathBuf;

/// The scene as a Looking Glass quilt (views left to right from the
/// bottom-left tile, `_qs{cols}x{rows}a{aspect}` in the file name).
#[derive(clap::Args)]
pub struct Args {
    #[arg(long)]
    scene: PathBuf,
    #[arg(long, default_value_t = 8)]
    cols: u32,
    #[arg(long, default_value_t = 6)]
    rows: u32,
    /// Tile size WxH.
    #[arg(long, default_value = "210x280", value_parser = args::size::<u32>)]
    tile: [u32; 2],
    /// The device's view cone (degrees).
    #[arg(long, default_value_t = 40.0)]
    cone: f64,
    /// Height of the focal plane rectangle (m); its width follows the tile aspect.
    #[arg(long, default_value_t = 0.3)]
    screen_height: f64,
    /// Viewing distance (m).
    #[arg(long, default_value_t = 0.8)]
    distance: f64,
    /// Output: a .png path or a folder (the layout suffix is added).
    #[arg(short, long)]
    output: PathBuf,
}

pub fn run(a: Args) -> Result<()> {
    let (cols, rows, tile) = (a.cols, a.rows, a.tile);
    if cols == 0 || rows == 0 || tile.contains(&0) {
        bail!("--cols, --rows and --tile must be at least 1");
    }
    let sc = parallax_common::config::Scene::load(&a.scene)?;
    let tf = parallax_common::tf::TransferFunction::load(&sc.transfer_function)?;
    let aspect = quilt::tile_aspect(tile);
    let views = quilt::quilt_views(
        [a.screen_height * aspect, a.screen_height],
        a.distance,
        a.cone,
        cols,
        rows,
        tile,
    );
    let mut r = parallax_backend::render::Renderer::with_layers(
        &sc.volume,
        &sc.layers,
        &sc.render,
        &parallax_backend::gpu::AdapterRequest::from_env(None, 0),
    )?;
    r.set_transfer_function(1, &tf)?;
    let f = r.converge(&sc.placement, &views, &sc.render, 64)?;
    let img = quilt::assemble(cols, rows, tile, &f.images)?;
    let path = if a.output.extension().is_some() {
        quilt::quilt_path(&a.output, cols, rows, aspect)
    } else {
        std::fs::create_dir_all(&a.output)?;
        let stem = a
            .scene
            .file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or("quilt");
        a.output
            .join(quilt::quilt_file_name(stem, cols, rows, aspect))
    };
    parallax_backend::output::write_png(&path, cols * tile[0], rows * tile[1], &img)?;
    println!("wrote {}", path.display());
    Ok(())
}
