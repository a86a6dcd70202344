//! `parallax display-gen`: a HoloVizio-like light field wall, or a Looking
//! Glass from its calibration.

use super::args;
use anyhow::Result;
use std::path::PathBuf;

/// Write a HoloVizio-like light field wall: DIR/display.toml and one
/// file per projector (defaults: the 72-projector wall of G10 §6).
#[derive(clap::Args)]
pub struct Args {
    #[arg(long, default_value_t = 72)]
    projectors: usize,
    /// Per projector, WxH.
    #[arg(long, default_value = "800x600", value_parser = args::size::<u32>)]
    resolution: [u32; 2],
    /// Screen size WxH in metres.
    #[arg(long, default_value = "1.6x0.9", value_parser = args::size::<f64>)]
    screen: [f64; 2],
    /// Pixel size s0 on the screen (m).
    #[arg(long, default_value_t = 0.0015)]
    pixel_size: f64,
    /// Angular accuracy Φ (degrees). Default: the projectors' spacing
    /// (field of view / projectors), at least G10's 0.8°, so that
    /// neighbouring projectors leave no dark gaps between them.
    #[arg(long)]
    angular_accuracy: Option<f64>,
    /// Horizontal field of view (degrees).
    #[arg(long, default_value_t = 50.0)]
    fov: f64,
    /// Projector distance behind the screen (m).
    #[arg(long, default_value_t = 2.0)]
    distance: f64,
    /// Observer position x,y,z (m).
    #[arg(long, default_value = "0,0,2", allow_hyphen_values = true, value_parser = args::list::<f64, 3>)]
    observer: [f64; 3],
    /// arc | line
    #[arg(long, default_value = "arc", value_parser = args::layout)]
    layout: parallax_common::wall::Layout,
    /// A Looking Glass instead of a wall: its calibration file
    /// (`visual.json`, on the device's drive under LKG_calibration/).
    #[arg(long)]
    looking_glass: Option<PathBuf>,
    /// With --looking-glass: the quilt, COLSxROWS views.
    #[arg(long, default_value = "8x6", value_parser = args::size::<u32>)]
    quilt: [u32; 2],
    /// With --looking-glass: each view's WxH (pixels).
    #[arg(long, default_value = "420x560", value_parser = args::size::<u32>)]
    view_size: [u32; 2],
    /// With --looking-glass: the viewing distance (m; default: where the
    /// panel's height spans 14°, as Looking Glass's cameras see it).
    #[arg(long)]
    view_distance: Option<f64>,
    #[arg(short, long)]
    output: PathBuf,
}

pub fn run(a: Args) -> Result<()> {
    if let Some(file) = &a.looking_glass {
        return looking_glass(file, &a);
    }
    let spec = parallax_common::wall::WallSpec {
        projectors: a.projectors,
        resolution: a.resolution,
        screen: a.screen,
        pixel_size: a.pixel_size,
        angular_accuracy_deg: a
            .angular_accuracy
            .unwrap_or_else(|| (a.fov / a.projectors.max(1) as f64).max(0.8)),
        fov_deg: a.fov,
        distance: a.distance,
        observer: a.observer,
        layout: a.layout,
    };
    spec.write(&a.output)?;
    println!(
        "wrote {}/display.toml and {} projector files",
        a.output.display(),
        a.projectors
    );
    Ok(())
}

fn looking_glass(file: &std::path::Path, a: &Args) -> Result<()> {
    use anyhow::Context;
    let f = file.display().to_string();
    let text = std::fs::read_to_string(file).with_context(|| format!("{f}: cannot read"))?;
    let lg = parallax_common::lenticular::LookingGlass::from_visual_json(&text, a.quilt, &f)?;
    let distance = a
        .view_distance
        .unwrap_or_else(|| 0.5 * lg.size_m()[1] / 7f64.to_radians().tan());
    lg.write_display(&a.output, a.view_size, distance)?;
    println!(
        "wrote {}/display.toml and {} views of {}×{} (render with η = 1 and one back end; the panel is panel.png)",
        a.output.display(),
        lg.views(),
        a.view_size[0],
        a.view_size[1]
    );
    Ok(())
}
