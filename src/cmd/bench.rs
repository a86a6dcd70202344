//! `parallax bench <study>`: the studies of the `parallax-bench` crate.

use super::args;
use anyhow::Result;
use clap::Subcommand;
use parallax_backend::data;
use parallax_backend::store::BrickEncoding;
use parallax_bench::sequence::{self, Sequence};
use std::path::{Path, PathBuf};

/// Measure the renderer: error against the exact integral and time.
#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    study: Study,
}

/// Where the studies of Colin27 find their inputs.
#[derive(clap::Args)]
struct Inputs {
    /// A volume file (the reference integral needs it in memory).
    #[arg(long, default_value = "/usr/share/mricron/templates/ch2.nii.gz")]
    volume: PathBuf,
    /// Transfer function file.
    #[arg(long, default_value = "configs/tf/colin27-brain.toml")]
    tf: PathBuf,
    /// Image size WxH.
    #[arg(long, default_value = "160x120", value_parser = args::size::<u32>)]
    size: [u32; 2],
    #[arg(long, default_value = "out/bench")]
    out: PathBuf,
}

/// The interaction script a sequence study runs.
#[derive(clap::Args)]
struct ScriptArg {
    /// Its first N frames are the study's frames.
    #[arg(long, default_value = "configs/scripts/rotate-1deg.toml")]
    script: PathBuf,
}

#[derive(Subcommand)]
enum Study {
    /// Error against the exact integral beside frame time for a sweep of
    /// every quality knob, and the cost of each kernel combination:
    /// DIR/bench.csv, DIR/bench.svg, DIR/orders.csv and DIR/kernels.csv.
    Sweep {
        #[command(flatten)]
        inputs: Inputs,
        /// Timed frames per setting (the median is reported).
        #[arg(long, default_value_t = 3)]
        repeats: usize,
        /// Only the cost of each kernel combination (enhancers, MImDA,
        /// refraction): DIR/kernels.csv.
        #[arg(long)]
        kernels_only: bool,
    },
    /// What each tool and stepper costs against no tool, placed where it
    /// changes nothing (its image must be no tool's, bit for bit) and in
    /// place, at the default settings, for each transfer function
    /// (DIR/tools.csv).
    Tools {
        /// A volume file.
        #[arg(long, default_value = "/usr/share/mricron/templates/ch2.nii.gz")]
        volume: PathBuf,
        /// Transfer function files.
        #[arg(
            long,
            value_delimiter = ',',
            default_value = "configs/tf/colin27-skin.toml,configs/tf/colin27-brain.toml"
        )]
        tf: Vec<PathBuf>,
        /// Image size WxH.
        #[arg(long, default_value = "512x384", value_parser = args::size::<u32>)]
        size: [u32; 2],
        /// Timed rounds (the median is reported).
        #[arg(long, default_value_t = 7)]
        rounds: usize,
        #[arg(long, default_value = "out/bench")]
        out: PathBuf,
    },
    /// The brick codecs on these volumes: ratio, encode and decode speed of
    /// each candidate (DIR/codecs.csv).
    Codecs {
        #[arg(value_delimiter = ',', num_args = 1.., required = true)]
        volumes: Vec<PathBuf>,
        /// Quantisation of the bricks: u8 | u16 | none.
        #[arg(long, default_value = "u8", value_parser = args::encoding)]
        quantize: BrickEncoding,
        #[arg(long, default_value = "out/bench")]
        out: PathBuf,
    },
    /// Frame reconstruction against full rendering along the script, this
    /// many frames (DIR/reconstruction.csv).
    Reconstruction {
        frames: usize,
        #[command(flatten)]
        inputs: Inputs,
        #[command(flatten)]
        script: ScriptArg,
    },
    /// The isosurface prediction buffer against full traversal along the
    /// script, this many frames per κ (DIR/prediction.csv).
    Prediction {
        frames: usize,
        /// The isovalue.
        #[arg(long, default_value_t = 80.0)]
        isovalue: f64,
        #[command(flatten)]
        inputs: Inputs,
        #[command(flatten)]
        script: ScriptArg,
    },
    /// The level-of-detail error on a CT phantom with 4 mm slices against
    /// the same phantom with isotropic voxels (DIR/anisotropy.csv).
    Anisotropy {
        #[arg(long, default_value = "out/bench")]
        out: PathBuf,
    },
    /// The steps at level changes between bricks, one level of detail per
    /// brick against multilevel sampling (DIR/seams.csv and the images).
    Seams {
        #[arg(long, default_value = "out/bench")]
        out: PathBuf,
    },
    /// Playing a time series: the volume moving 2 voxels a step along x,
    /// each step its own database; each step change followed until the
    /// cut has converged, with the next step read ahead and without
    /// (DIR/series.csv).
    Series {
        /// A volume file.
        #[arg(long, default_value = "/usr/share/mricron/templates/ch2.nii.gz")]
        volume: PathBuf,
        /// Transfer function file.
        #[arg(long, default_value = "configs/tf/colin27-brain.toml")]
        tf: PathBuf,
        /// Time steps.
        #[arg(long, default_value_t = 12)]
        steps: usize,
        /// Image size WxH.
        #[arg(long, default_value = "512x384", value_parser = args::size::<u32>)]
        size: [u32; 2],
        #[arg(long, default_value = "out/bench")]
        out: PathBuf,
    },
    /// What registered layers cost against the volume alone: one and two
    /// aligned layers (the volume again, the extinction shared so that the
    /// image stays the volume's), one on another grid placed by a
    /// transform, and an empty layer, at the default settings
    /// (DIR/layers.csv).
    Layers {
        /// A volume file.
        #[arg(long, default_value = "/usr/share/mricron/templates/ch2.nii.gz")]
        volume: PathBuf,
        /// Transfer function file.
        #[arg(long, default_value = "configs/tf/colin27-brain.toml")]
        tf: PathBuf,
        /// Image size WxH.
        #[arg(long, default_value = "512x384", value_parser = args::size::<u32>)]
        size: [u32; 2],
        /// Timed rounds (the median is reported).
        #[arg(long, default_value_t = 7)]
        rounds: usize,
        #[arg(long, default_value = "out/bench")]
        out: PathBuf,
    },
}

pub fn run(a: Args) -> Result<()> {
    match a.study {
        Study::Sweep {
            inputs,
            repeats,
            kernels_only,
        } => sweep(&inputs, repeats, kernels_only),
        Study::Tools {
            volume,
            tf,
            size,
            rounds,
            out,
        } => tools(&volume, &tf, size, rounds, &out),
        Study::Codecs {
            volumes,
            quantize,
            out,
        } => {
            let points = parallax_bench::codecs::run(&volumes, quantize, &out)?;
            parallax_bench::codecs::print(&points);
            wrote(&out, "codecs.csv")
        }
        Study::Reconstruction {
            frames,
            inputs,
            script,
        } => {
            let s = sequence_of(&inputs, &script.script, frames)?;
            let points = sequence::reconstruction(&s, &inputs.out)?;
            sequence::print_reconstruction(&s, &script.script, &points);
            wrote(&inputs.out, "reconstruction.csv")
        }
        Study::Prediction {
            frames,
            isovalue,
            inputs,
            script,
        } => {
            let s = sequence_of(&inputs, &script.script, frames)?;
            let points = sequence::prediction(&s, isovalue, &sequence::KAPPAS, &inputs.out)?;
            sequence::print_prediction(&s, &script.script, isovalue, &points);
            wrote(&inputs.out, "prediction.csv")
        }
        Study::Anisotropy { out } => {
            parallax_bench::anisotropy::run_anisotropy(&out)?;
            wrote(&out, "anisotropy.csv")
        }
        Study::Seams { out } => {
            parallax_bench::seams::run_seams(&out)?;
            wrote(&out, "seams.csv")
        }
        Study::Layers {
            volume,
            tf,
            size,
            rounds,
            out,
        } => layers(&volume, &tf, size, rounds, &out),
        Study::Series {
            volume,
            tf,
            steps,
            size,
            out,
        } => series(&volume, &tf, steps, size, &out),
    }
}

fn series(volume: &Path, tf: &Path, steps: usize, size: [u32; 2], out: &Path) -> Result<()> {
    anyhow::ensure!(steps >= 2, "--steps {steps}: a series has at least 2");
    let (_, placement, view) = desktop_shot(volume, size, out, "series-0.pxo")?;
    let vol = parallax_backend::volume::Volume::read_all(data::open(volume, None)?.as_mut())?;
    let paths = parallax_bench::series::import_series(&vol, steps, out)?;
    let tf = parallax_common::tf::TransferFunction::load(tf)?;
    let p = parallax_bench::series::run(&paths, &tf, &placement, &view, out)?;
    parallax_bench::series::print(&p);
    wrote(out, "series.csv")
}

fn layers(volume: &Path, tf: &Path, size: [u32; 2], rounds: usize, out: &Path) -> Result<()> {
    let (db, placement, view) = desktop_shot(volume, size, out, "layers.pxo")?;
    let tf = parallax_common::tf::TransferFunction::load(tf)?;
    let shot = parallax_bench::measure::Shot {
        db: &db,
        tf: &tf,
        placement: &placement,
        view: &view,
    };
    // The volume again on another grid (bricks of 16), for the layer
    // placed by a transform.
    let other = out.join("layers-b16.pxo");
    parallax_backend::store::import(
        data::open(volume, None)?.as_mut(),
        &other,
        &volume.display().to_string(),
        &parallax_backend::store::ImportOptions {
            brick: 16,
            ..Default::default()
        },
    )?;
    let cfg = parallax_common::config::RenderConfig::default();
    let p = parallax_bench::layers::run(shot, &other, &cfg, rounds, out)?;
    parallax_bench::layers::print(&p);
    parallax_bench::layers::write_csv(&out.join("layers.csv"), &p)?;
    wrote(out, "layers.csv")
}

/// `volume` imported into `out/name`, placed upright, face to the viewer,
/// 25 cm tall, and a desktop window of `size` pixels onto it (Colin27's
/// desktop view).
fn desktop_shot(
    volume: &Path,
    size: [u32; 2],
    out: &Path,
    name: &str,
) -> Result<(
    PathBuf,
    parallax_common::camera::Placement,
    parallax_common::camera::View,
)> {
    use parallax_common::camera::{Placement, View};
    parallax_bench::measure::create_out(out)?;
    let db = out.join(name);
    parallax_backend::store::import(
        data::open(volume, None)?.as_mut(),
        &db,
        &volume.display().to_string(),
        &Default::default(),
    )?;
    let placement = Placement {
        center: [0.0; 3],
        rotation_deg: [-90.0, 180.0, 0.0],
        size: 0.25,
    };
    let aspect = size[1] as f64 / size[0] as f64;
    let view = View::window(size, [0.3, 0.3 * aspect], [0.0, 0.0, 0.8]);
    Ok((db, placement, view))
}

fn tools(volume: &Path, tfs: &[PathBuf], size: [u32; 2], rounds: usize, out: &Path) -> Result<()> {
    let (db, placement, view) = desktop_shot(volume, size, out, "tools.pxo")?;
    let cfg = parallax_common::config::RenderConfig::default();
    let mut points = Vec::new();
    for tf_path in tfs {
        let tf = parallax_common::tf::TransferFunction::load(tf_path)?;
        let name = tf_path
            .file_stem()
            .map_or("tf".into(), |s| s.to_string_lossy().into_owned());
        let shot = parallax_bench::measure::Shot {
            db: &db,
            tf: &tf,
            placement: &placement,
            view: &view,
        };
        let p = parallax_bench::tools::run(shot, &name, &cfg, rounds)?;
        parallax_bench::tools::print(&p);
        points.extend(p);
    }
    parallax_bench::tools::write_csv(&out.join("tools.csv"), &points)?;
    wrote(out, "tools.csv")
}

fn sequence_of(inputs: &Inputs, script: &Path, frames: usize) -> Result<Sequence> {
    Sequence::new(&inputs.volume, &inputs.tf, script, frames, inputs.size)
}

fn sweep(inputs: &Inputs, repeats: usize, kernels_only: bool) -> Result<()> {
    let mut src = data::open(&inputs.volume, None)?;
    let vol = parallax_backend::volume::Volume::read_all(src.as_mut())?;
    let tf = parallax_common::tf::TransferFunction::load(&inputs.tf)?;
    parallax_bench::sweep::run(&parallax_bench::sweep::BenchOptions {
        volume: &vol,
        tf: &tf,
        placement: sequence::START,
        view: sequence::desktop_view(inputs.size),
        out: &inputs.out,
        repeats,
        kernels_only,
    })?;
    if kernels_only {
        wrote(&inputs.out, "kernels.csv")
    } else {
        println!(
            "wrote {0}/bench.csv, {0}/bench.svg, {0}/orders.csv and {0}/kernels.csv",
            inputs.out.display()
        );
        Ok(())
    }
}

fn wrote(out: &Path, file: &str) -> Result<()> {
    println!("wrote {}/{file}", out.display());
    Ok(())
}
