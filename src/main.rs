//! `parallax`: the command line (DESIGN.md "Command line").

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand, ValueEnum};
use parallax::launch;
use parallax_backend::data::{self, synth::SynthKind, RawParams};
use parallax_backend::store::codec::Codec;
use parallax_backend::store::{self, info, ImportOptions};
use parallax_backend::store::{BrickEncoding, OctreeDb};
use parallax_backend::volume::VoxelType;
use std::io::IsTerminal;
use std::path::PathBuf;

#[derive(Parser)]
#[command(
    name = "parallax",
    version,
    about = "Massive volumes on light field displays and ordinary screens"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Write a procedural volume as NRRD (streamed: any size fits in memory).
    Synth {
        /// marschner-lobb | shells | shepp-logan | constant | plane | noise | stiff | ct
        /// (ct: a head in Hounsfield units with scanner noise; use --type i16)
        #[arg(value_parser = synth_kind)]
        kind: SynthKind,
        #[arg(long)]
        size: usize,
        /// u8 | i8 | u16 | i16 | u32 | i32 | f32 | f64
        #[arg(long = "type", default_value = "u8", value_parser = voxel_type)]
        voxel_type: VoxelType,
        #[arg(short, long)]
        output: PathBuf,
    },
    /// Import a volume into the out-of-core octree database (.pxo).
    Import {
        /// .nrrd | .nhdr | .nii | .nii.gz | .raw (with --dims/--type/--spacing)
        /// | .tif/.tiff (multi-page) | a folder of DICOM slices or of TIFFs
        input: PathBuf,
        #[arg(short, long)]
        output: PathBuf,
        /// Brick side in voxels (overlap excluded).
        #[arg(long, default_value_t = 32)]
        brick: usize,
        /// Drop bricks whose values are all below this value.
        #[arg(long, allow_hyphen_values = true)]
        empty_below: Option<f32>,
        /// u8 | u16 (quantised against each brick's range) | none (full precision)
        #[arg(long, default_value = "u8", value_parser = encoding)]
        quantize: BrickEncoding,
        /// Brick compression: lz4 | zstd | zstdN (level 1–19), each optionally
        /// +delta (a delta pre-filter) or +auto (per brick, the smaller of
        /// the two).
        #[arg(long, default_value = "zstd1+auto", value_parser = parse_codec)]
        codec: Codec,
        /// Memory budget of the import (MiB).
        #[arg(long, default_value_t = 2048)]
        memory_mb: usize,
        /// Halve all three axes at every level even over thick slices (by
        /// default the levels above anisotropic voxels halve the finer axes
        /// first, until the voxels are near-cubic)
        #[arg(long)]
        isotropic_levels: bool,
        /// Raw input: X,Y,Z
        #[arg(long, value_parser = list::<usize, 3>)]
        dims: Option<[usize; 3]>,
        /// Raw input: u8 | i8 | u16 | i16 | u32 | i32 | f32 | f64
        #[arg(long = "type", value_parser = voxel_type)]
        voxel_type: Option<VoxelType>,
        /// Raw or TIFF input: sx,sy,sz (raw default 1,1,1; TIFF default from
        /// ImageJ metadata, else 1,1,1)
        #[arg(long, value_parser = list::<f64, 3>)]
        spacing: Option<[f64; 3]>,
        /// DICOM folder with several series: the SeriesInstanceUID to import
        /// (or its number in the listing)
        #[arg(long)]
        series: Option<String>,
        /// NaN in float input: refuse (an error naming the voxel) or empty
        /// ("no data": never shown, never blended into its neighbours)
        #[arg(long, value_enum, default_value_t = NanPolicy::Refuse)]
        nan: NanPolicy,
        /// Raw input: bytes to skip before the data
        #[arg(long, default_value_t = 0)]
        byte_offset: u64,
        /// Raw input: big-endian samples
        #[arg(long)]
        big_endian: bool,
    },
    /// Render a scene's display: PNG per projector (and .npy with --float),
    /// stats.jsonl per frame.
    Render {
        #[arg(long)]
        scene: PathBuf,
        /// Display file (default: the scene's `display`).
        #[arg(long)]
        display: Option<PathBuf>,
        /// Frames to render (default: the script's length, or until the cut
        /// has converged).
        #[arg(long, default_value_t = 0)]
        frames: u64,
        /// Interaction script (keyframes of placement, observer, η, transfer function).
        #[arg(long)]
        script: Option<PathBuf>,
        /// Output folder: DIR/frame_NNNNN/<projector>.png, DIR/stats.jsonl
        /// (default: out/<scene name>).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Also write float32 .npy images (linear, premultiplied).
        #[arg(long)]
        float: bool,
        /// Wait for every posted brick read before each frame (reproducible
        /// frames; otherwise the loader never blocks).
        #[arg(long)]
        sync: bool,
        /// Back-end threads in the embedded (single-process) mode (default:
        /// the highest rank the display's projector files name, or 1).
        #[arg(long)]
        backends: Option<usize>,
        /// Seconds to wait for a back end's frame before naming it and
        /// ending the run (0: wait forever).
        #[arg(long, default_value_t = parallax_common::protocol::DEFAULT_WATCHDOG.as_secs_f64())]
        watchdog: f64,
    },
    /// Live: serve a control page and drive the display from a browser
    /// (embedded, or from rank 0 under `mpirun`). Prints the page's URL,
    /// with its access token.
    Serve {
        #[arg(long)]
        scene: PathBuf,
        /// Display file (default: the scene's `display`).
        #[arg(long)]
        display: Option<PathBuf>,
        /// Address to listen on. The default is this machine only; another
        /// address exposes the page to the network (the token guards it).
        #[arg(long, default_value = "127.0.0.1:8080")]
        bind: std::net::SocketAddr,
        /// The access token (default: a random one, printed in the URL).
        #[arg(long)]
        token: Option<String>,
        /// Also write every frame's images and stats here, as `render` does.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Wait for every posted brick read before each frame (a recording
        /// then replays bit for bit).
        #[arg(long)]
        sync: bool,
        /// Record the whole session from its first frame into this folder
        /// (script.toml, written when the session ends).
        #[arg(long)]
        record: Option<PathBuf>,
        /// Where the page's record control writes its sessions.
        #[arg(long, default_value = "out/live")]
        record_dir: PathBuf,
        /// Embedded back-end threads (default: from the display).
        #[arg(long)]
        backends: Option<usize>,
        /// Seconds to wait for a back end's frame before naming it and
        /// ending the session (0: wait forever).
        #[arg(long, default_value_t = parallax_common::protocol::DEFAULT_WATCHDOG.as_secs_f64())]
        watchdog: f64,
    },
    /// Error against the exact integral beside frame time for a sweep of
    /// every quality knob: DIR/bench.csv and DIR/bench.svg.
    Bench {
        /// A volume file (the reference integral needs it in memory).
        #[arg(long, default_value = "/usr/share/mricron/templates/ch2.nii.gz")]
        volume: PathBuf,
        /// Transfer function file.
        #[arg(long, default_value = "configs/tf/colin27-brain.toml")]
        tf: PathBuf,
        /// Image size WxH.
        #[arg(long, default_value = "160x120", value_parser = size::<u32>)]
        size: [u32; 2],
        #[arg(long, default_value_t = 3)]
        repeats: usize,
        #[arg(long, default_value = "out/bench")]
        out: PathBuf,
        /// Only the cost of each kernel combination (enhancers, MImDA,
        /// refraction): DIR/kernels.csv.
        #[arg(long)]
        kernels_only: bool,
        /// Only the brick codecs, on these volumes: ratio, encode and decode
        /// speed of each candidate (DIR/codecs.csv).
        #[arg(long, value_delimiter = ',', num_args = 1..)]
        codecs: Vec<PathBuf>,
        /// Quantisation of the bricks for --codecs: u8 | u16 | none.
        #[arg(long, default_value = "u8", value_parser = encoding)]
        quantize: BrickEncoding,
        /// Only frame reconstruction against full rendering on a rotation of
        /// 1° per frame, this many frames (DIR/reconstruction.csv).
        #[arg(long)]
        reconstruction: Option<usize>,
        /// Only the isosurface prediction buffer against full traversal on a
        /// rotation of 1° per frame, this many frames per κ
        /// (DIR/prediction.csv).
        #[arg(long)]
        prediction: Option<usize>,
        /// The isovalue of --prediction.
        #[arg(long, default_value_t = 80.0)]
        isovalue: f64,
        /// Only the level-of-detail error on a CT phantom with 4 mm slices
        /// against the same phantom with isotropic voxels
        /// (DIR/anisotropy.csv).
        #[arg(long)]
        anisotropy: bool,
        /// Only the steps at level changes between bricks, one level of
        /// detail per brick against multilevel sampling (DIR/seams.csv and
        /// the images).
        #[arg(long)]
        seams: bool,
        /// The interaction script --reconstruction and --prediction run
        /// (its first N frames).
        #[arg(long, default_value = "configs/scripts/rotate-1deg.toml")]
        script: PathBuf,
    },
    /// Transfer functions: import ParaView and 3D Slicer presets.
    Tf {
        #[command(subcommand)]
        action: TfAction,
    },
    /// Write a HoloVizio-like light field wall: DIR/display.toml and one
    /// file per projector (defaults: the 72-projector wall of G10 §6).
    DisplayGen {
        #[arg(long, default_value_t = 72)]
        projectors: usize,
        /// Per projector, WxH.
        #[arg(long, default_value = "800x600", value_parser = size::<u32>)]
        resolution: [u32; 2],
        /// Screen size WxH in metres.
        #[arg(long, default_value = "1.6x0.9", value_parser = size::<f64>)]
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
        #[arg(long, default_value = "0,0,2", allow_hyphen_values = true, value_parser = list::<f64, 3>)]
        observer: [f64; 3],
        /// arc | line
        #[arg(long, default_value = "arc", value_parser = layout)]
        layout: parallax_common::wall::Layout,
        #[arg(short, long)]
        output: PathBuf,
    },
    /// What an eye sees on a light field display, from the projector images
    /// of one rendered frame (several --eye: a strip, left to right).
    Simulate {
        #[arg(long)]
        display: PathBuf,
        /// A frame folder written by `render` (DIR/frame_NNNNN).
        #[arg(long)]
        frames: PathBuf,
        /// Eye position x,y,z (m); repeat for a strip.
        #[arg(long, required = true, allow_hyphen_values = true)]
        eye: Vec<String>,
        /// Sweep: this many eyes evenly from the first --eye to the second.
        #[arg(long)]
        sweep: Option<usize>,
        /// Output resolution WxH (default: screen size / pixel size, capped).
        #[arg(long, value_parser = size::<u32>)]
        resolution: Option<[u32; 2]>,
        #[arg(short, long)]
        output: PathBuf,
    },
    /// The scene as a Looking Glass quilt (views left to right from the
    /// bottom-left tile, `_qs{cols}x{rows}a{aspect}` in the file name).
    Quilt {
        #[arg(long)]
        scene: PathBuf,
        #[arg(long, default_value_t = 8)]
        cols: u32,
        #[arg(long, default_value_t = 6)]
        rows: u32,
        /// Tile size WxH.
        #[arg(long, default_value = "210x280", value_parser = size::<u32>)]
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
    },
    /// Describe a database; --verify decodes and checks every brick.
    Info {
        database: PathBuf,
        #[arg(long)]
        verify: bool,
    },
}

fn main() {
    ensure_runtime_dir();
    parallax_backend::gpu::spread_cpu_device_work();
    init_logging();
    if let Err(e) = run(Cli::parse()) {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Synth {
            kind,
            size,
            voxel_type,
            output,
        } => {
            let vt = voxel_type;
            if size == 0 {
                bail!("--size 0: a volume needs at least one voxel");
            }
            let bar = progress(size as u64, "synth");
            data::synth::write_synth(kind, size, vt, &output, |_| bar.inc(1))?;
            bar.finish_and_clear();
            println!("wrote {} ({size}³ {})", output.display(), vt.name());
        }
        Command::Import {
            input,
            output,
            brick,
            empty_below,
            quantize,
            codec,
            memory_mb,
            isotropic_levels,
            dims,
            voxel_type,
            spacing,
            byte_offset,
            big_endian,
            series,
            nan,
        } => {
            let encoding = quantize;
            let raw = match (dims, voxel_type) {
                (Some(d), Some(t)) => Some(RawParams {
                    dims: d,
                    voxel_type: t,
                    spacing: spacing.unwrap_or([1.0; 3]),
                    byte_offset,
                    big_endian,
                }),
                (None, None) => None,
                _ => bail!("raw input needs both --dims and --type"),
            };
            let mut src = data::open_with(
                &input,
                &data::InputOptions {
                    raw,
                    series,
                    spacing,
                    nan_empty: nan == NanPolicy::Empty,
                },
            )?;
            let described = src.describe();
            if let Some(d) = &described {
                eprintln!("note: {d}");
            }
            let opts = ImportOptions {
                brick,
                encoding,
                codec,
                empty_below,
                memory_mb,
                progress: std::io::stderr().is_terminal(),
                isotropic_levels,
            };
            let name = input.display().to_string();
            let source = match &described {
                Some(d) => format!("{name} ({d})"),
                None => name.clone(),
            };
            let r = store::import(src.as_mut(), &output, &source, &opts)?;
            if let Some(note) = src.conversion_note() {
                eprintln!("note: {note}");
            }
            if r.no_data_voxels > 0 {
                eprintln!(
                    "note: {} voxels are NaN: no data (never shown, never blended into their neighbours)",
                    r.no_data_voxels
                );
            }
            println!(
                "imported {} → {}: {} nodes ({} stored, {} empty), {:.1} MB → {:.1} MB in {:.2} s ({:.0} MB/s of source)",
                name,
                output.display(),
                r.nodes,
                r.stored,
                r.empty,
                r.source_bytes as f64 / 1e6,
                r.file_bytes as f64 / 1e6,
                r.seconds,
                r.source_bytes as f64 / 1e6 / r.seconds.max(1e-9)
            );
            if let Some(kb) = peak_rss_kib() {
                println!("peak resident memory: {:.1} MiB", kb as f64 / 1024.0);
            }
        }
        Command::Render {
            scene,
            display,
            frames,
            script,
            out,
            float,
            sync,
            backends,
            watchdog,
        } => {
            if !(watchdog.is_finite() && watchdog >= 0.0) {
                bail!("--watchdog {watchdog}: expected seconds ≥ 0 (0: wait forever)");
            }
            let out = Some(out.unwrap_or_else(|| {
                let stem = scene.file_stem().unwrap_or_default();
                PathBuf::from("out").join(stem)
            }));
            let opts = parallax_frontend::RunOptions {
                scene,
                display,
                frames,
                out: out.clone(),
                float,
                sync_io: sync,
                script,
                verbose: true,
                watchdog: (watchdog > 0.0).then(|| std::time::Duration::from_secs_f64(watchdog)),
            };
            let role = launch::session(&opts.scene, opts.display.as_ref(), backends, |t| {
                parallax_frontend::run(&opts, t).map(|_| ())
            })?;
            if let (launch::Role::Coordinator, Some(o)) = (role, out) {
                println!("images and stats.jsonl in {}", o.display());
            }
        }
        Command::Serve {
            scene,
            display,
            bind,
            token,
            out,
            sync,
            record,
            record_dir,
            backends,
            watchdog,
        } => {
            if !(watchdog.is_finite() && watchdog >= 0.0) {
                bail!("--watchdog {watchdog}: expected seconds ≥ 0 (0: wait forever)");
            }
            let opts = parallax_frontend::live::ServeOptions {
                scene: scene.clone(),
                display: display.clone(),
                bind,
                token,
                out,
                sync_io: sync,
                record,
                record_dir,
                watchdog: (watchdog > 0.0).then(|| std::time::Duration::from_secs_f64(watchdog)),
                ready: None,
                eye_view: launch::eye_view,
            };
            launch::session(&scene, display.as_ref(), backends, |t| {
                parallax_frontend::live::serve(opts, t)
            })?;
        }
        Command::Bench {
            volume,
            tf,
            size,
            repeats,
            out,
            kernels_only,
            codecs,
            quantize,
            reconstruction,
            prediction,
            isovalue,
            script,
            anisotropy,
            seams,
        } => {
            if seams {
                parallax_backend::bench::run_seams(&out)?;
                println!("wrote {}/seams.csv", out.display());
                return Ok(());
            }
            if anisotropy {
                parallax_backend::bench::run_anisotropy(&out)?;
                println!("wrote {}/anisotropy.csv", out.display());
                return Ok(());
            }
            // The placements of the first `n` frames of the script, from the
            // desktop view of Colin27.
            let script_placements = |n: usize| -> Result<Vec<parallax_common::camera::Placement>> {
                let s = parallax_frontend::script::Script::load(&script)?;
                let start = parallax_common::camera::Placement {
                    center: [0.0, 0.0, 0.0],
                    rotation_deg: [-90.0, 180.0, 0.0],
                    size: 0.25,
                };
                anyhow::ensure!(
                    n as u64 <= s.frames,
                    "{}: has {} frames, {n} asked for",
                    script.display(),
                    s.frames
                );
                Ok((0..n as u64)
                    .map(|f| s.at(f, &start, [0.0, 0.0, 0.8], 0.0).placement)
                    .collect())
            };
            if !codecs.is_empty() {
                let points = parallax_backend::bench::run_codecs(&codecs, quantize, &out)?;
                println!(
                    "volume                 codec         ratio  encode MB/s  decode MB/s (in)"
                );
                for p in points {
                    println!(
                        "{:<22} {:<12} {:>6.2}  {:>11.0}  {:>11.0} ({:.0})",
                        p.volume,
                        p.codec,
                        p.source_bytes as f64 / p.stored_bytes as f64,
                        p.encode_mb_s,
                        p.decode_mb_s,
                        p.decode_in_mb_s
                    );
                }
                println!("wrote {}/codecs.csv", out.display());
                return Ok(());
            }
            let [w, h] = size;
            // What --prediction and --reconstruction share: the transfer
            // function, the volume imported to a temporary database, the
            // script's placements and the desktop view.
            let sequence_setup = |frames: usize| -> Result<_> {
                let tf = parallax_common::tf::TransferFunction::load(&tf)?;
                let tmp = tempfile::tempdir()?;
                let db = tmp.path().join("bench.pxo");
                let mut src = data::open(&volume, None)?;
                store::import(
                    src.as_mut(),
                    &db,
                    &volume.display().to_string(),
                    &ImportOptions::default(),
                )?;
                let placements = script_placements(frames)?;
                let view =
                    parallax_common::camera::View::window([w, h], [0.4, 0.3], [0.0, 0.0, 0.8]);
                Ok((tf, tmp, db, placements, view))
            };
            if let Some(frames) = prediction {
                let (tf, _tmp, db, placements, view) = sequence_setup(frames)?;
                let kappas = [[0.1, 0.3], [0.2, 0.6], [0.5, 1.0], [1.0, 2.0], [2.0, 2.0]];
                let pts = parallax_backend::bench::run_prediction(
                    &db,
                    &tf,
                    isovalue,
                    &placements,
                    view,
                    &kappas,
                    &out,
                )?;
                println!(
                    "{frames} frames of {} per κ, {w}×{h}, isovalue {isovalue}:",
                    script.display()
                );
                for k in kappas {
                    let q: Vec<_> = pts.iter().filter(|p| p.kappa == k).collect();
                    let full: f64 = q.iter().map(|p| p.full_ms).sum();
                    let pred: f64 = q.iter().map(|p| p.predicted_ms).sum();
                    let steered: Vec<_> = q.iter().filter(|p| p.predicted).collect();
                    let mean_diff = steered.iter().map(|p| p.differing).sum::<f64>()
                        / steered.len().max(1) as f64;
                    let worst = steered.iter().map(|p| p.differing).fold(0.0, f64::max);
                    let psnr = steered.iter().map(|p| p.psnr_db).sum::<f64>()
                        / steered.len().max(1) as f64;
                    let fulls = q.iter().filter(|p| !p.predicted).count();
                    let exact = q.iter().filter(|p| !p.predicted && p.identical).count();
                    println!(
                        "  κ {:?}: full traversal {:.1} ms/frame, prediction buffer {:.1} ms/frame: speed-up {:.2}×; \
                         pixels differing by over 1/255 {:.2} % mean, {:.2} % worst, PSNR {psnr:.1} dB; periodic full traversals equal to full: {exact} of {fulls}",
                        k,
                        full / q.len() as f64,
                        pred / q.len() as f64,
                        full / pred,
                        100.0 * mean_diff,
                        100.0 * worst
                    );
                }
                println!("wrote {}/prediction.csv", out.display());
                return Ok(());
            }
            if let Some(frames) = reconstruction {
                let (tf, _tmp, db, placements, view) = sequence_setup(frames)?;
                let pts =
                    parallax_backend::bench::run_reconstruction(&db, &tf, &placements, view, &out)?;
                let full: f64 = pts.iter().map(|p| p.full_ms).sum();
                let rec: f64 = pts.iter().map(|p| p.reconstructed_ms).sum();
                let mean = pts.iter().map(|p| p.psnr_db).sum::<f64>() / pts.len().max(1) as f64;
                let worst = pts.iter().map(|p| p.psnr_db).fold(f64::INFINITY, f64::min);
                println!(
                    "{frames} frames of {}, {w}×{h}: full {:.1} ms/frame, reconstructed {:.1} ms/frame: speed-up {:.2}×; PSNR against full mean {mean:.1} dB, worst {worst:.1} dB",
                    script.display(),
                    full / frames as f64,
                    rec / frames as f64,
                    full / rec
                );
                println!("wrote {}/reconstruction.csv", out.display());
                return Ok(());
            }
            let mut src = data::open(&volume, None)?;
            let vol = parallax_backend::volume::Volume::read_all(src.as_mut())?;
            let tf = parallax_common::tf::TransferFunction::load(&tf)?;
            let placement = parallax_common::camera::Placement {
                center: [0.0, 0.0, 0.0],
                rotation_deg: [-90.0, 180.0, 0.0],
                size: 0.25,
            };
            let view = parallax_common::camera::View::window([w, h], [0.4, 0.3], [0.0, 0.0, 0.8]);
            parallax_backend::bench::run(&parallax_backend::bench::BenchOptions {
                volume: &vol,
                tf: &tf,
                placement,
                view,
                out: &out,
                repeats,
                kernels_only,
            })?;
            if kernels_only {
                println!("wrote {}/kernels.csv", out.display());
            } else {
                println!(
                    "wrote {0}/bench.csv, {0}/bench.svg and {0}/kernels.csv",
                    out.display()
                );
            }
        }
        Command::Tf {
            action:
                TfAction::Import {
                    input,
                    name,
                    list,
                    range,
                    unit,
                    missing_opacity,
                    display_colours,
                    output,
                },
        } => {
            use parallax_common::tf::presets;
            if list {
                let text = std::fs::read_to_string(&input)
                    .with_context(|| format!("{}: cannot read", input.display()))?;
                for n in presets::preset_names(&text, &input.display().to_string())? {
                    println!("{n}");
                }
                return Ok(());
            }
            let opts = presets::ImportOptions {
                range: range
                    .map(|[lo, hi]| {
                        anyhow::ensure!(lo < hi, "--range {lo},{hi}: expected lo < hi");
                        Ok((lo, hi))
                    })
                    .transpose()?,
                unit,
                missing_opacity,
                linearize: !display_colours,
                ..Default::default()
            };
            if let Some(u) = unit {
                anyhow::ensure!(
                    u.is_finite() && u > 0.0,
                    "--unit {u}: expected a positive length"
                );
            }
            let p = presets::import_preset_file(&input, name.as_deref(), &opts)?;
            for n in &p.notes {
                eprintln!("note: {n}");
            }
            let output = output.context("-o/--output: where to write the transfer function")?;
            parallax_common::atomic::write(&output, p.to_toml().as_bytes())?;
            println!(
                "wrote {} ({} \"{}\", {} points)",
                output.display(),
                p.format.description(),
                p.name,
                p.tf.points().len()
            );
        }
        Command::DisplayGen {
            projectors,
            resolution,
            screen,
            pixel_size,
            angular_accuracy,
            fov,
            distance,
            observer,
            layout,
            output,
        } => {
            let spec = parallax_common::wall::WallSpec {
                projectors,
                resolution,
                screen,
                pixel_size,
                angular_accuracy_deg: angular_accuracy
                    .unwrap_or_else(|| (fov / projectors.max(1) as f64).max(0.8)),
                fov_deg: fov,
                distance,
                observer,
                layout,
            };
            spec.write(&output)?;
            println!(
                "wrote {}/display.toml and {projectors} projector files",
                output.display()
            );
        }
        Command::Simulate {
            display,
            frames,
            eye,
            sweep,
            resolution,
            output,
        } => {
            use parallax_backend::simulate as sim;
            let disp = parallax_common::config::Display::load(&display)?;
            let images = sim::load_frame(&disp, &frames)?;
            let mut eyes = eye
                .iter()
                .map(|e| sim::parse_eye(e))
                .collect::<Result<Vec<_>>>()?;
            if let Some(n) = sweep {
                if eyes.len() != 2 || n < 2 {
                    bail!("--sweep N needs exactly two --eye positions (from, to) and N ≥ 2");
                }
                eyes = sim::sweep(eyes[0], eyes[1], n);
            }
            let res = match resolution {
                Some(r) => r,
                None => sim::default_resolution(&disp, sim::DEFAULT_MAX_SIDE),
            };
            let (w, h, px) = sim::strip(&disp, &images, &eyes, res)?;
            parallax_backend::output::write_png(&output, w, h, &px)?;
            println!(
                "wrote {} ({} eye{}, {w}×{h})",
                output.display(),
                eyes.len(),
                if eyes.len() > 1 { "s" } else { "" }
            );
        }
        Command::Quilt {
            scene,
            cols,
            rows,
            tile,
            cone,
            screen_height,
            distance,
            output,
        } => {
            use parallax_backend::quilt;

            if cols == 0 || rows == 0 || tile.contains(&0) {
                bail!("--cols, --rows and --tile must be at least 1");
            }
            let sc = parallax_common::config::Scene::load(&scene)?;
            let tf = parallax_common::tf::TransferFunction::load(&sc.transfer_function)?;
            let aspect = quilt::tile_aspect(tile);
            let views = quilt::quilt_views(
                [screen_height * aspect, screen_height],
                distance,
                cone,
                cols,
                rows,
                tile,
            );
            let mut r = parallax_backend::render::Renderer::new(&sc.volume, &sc.render)?;
            r.set_transfer_function(1, &tf)?;
            let f = r.converge(&sc.placement, &views, &sc.render, 64)?;
            let img = quilt::assemble(cols, rows, tile, &f.images)?;
            let path = if output.extension().is_some() {
                quilt::quilt_path(&output, cols, rows, aspect)
            } else {
                std::fs::create_dir_all(&output)?;
                let stem = scene
                    .file_stem()
                    .and_then(|s| s.to_str())
                    .unwrap_or("quilt");
                output.join(quilt::quilt_file_name(stem, cols, rows, aspect))
            };
            parallax_backend::output::write_png(&path, cols * tile[0], rows * tile[1], &img)?;
            println!("wrote {}", path.display());
        }
        Command::Info { database, verify } => {
            let db = OctreeDb::open(&database)?;
            print!("{}", info::describe(&db));
            if verify {
                let r = info::verify(&db)?;
                println!(
                    "verify:        ok, {} bricks ({} bytes) decoded and checked",
                    r.bricks, r.bytes
                );
            }
        }
    }
    Ok(())
}

/// The Vulkan stack wants a per-user runtime folder and prints an error line
/// on every start without one (a headless shell, a batch job, an MPI rank):
/// give it one, private to this user, before any GPU work.
fn ensure_runtime_dir() {
    use std::os::unix::fs::{MetadataExt, PermissionsExt};
    let usable = std::env::var_os("XDG_RUNTIME_DIR")
        .map(PathBuf::from)
        .is_some_and(|p| p.is_absolute() && p.is_dir());
    if usable {
        return;
    }
    let uid = std::fs::metadata("/proc/self").map_or(0, |m| m.uid());
    let dir = std::env::temp_dir().join(format!("parallax-runtime-{uid}"));
    if std::fs::create_dir_all(&dir).is_ok()
        && std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o700)).is_ok()
    {
        // Single-threaded here: nothing else reads the environment yet.
        std::env::set_var("XDG_RUNTIME_DIR", &dir);
    }
}

/// Diagnostics on standard error, chosen with `RUST_LOG` (default: warnings
/// and errors only): the adapter choice, wgpu's own messages, the loader's
/// decisions, MPI start-up. Per-frame figures go to `stats.jsonl`.
fn init_logging() {
    use tracing_subscriber::EnvFilter;
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("warn"));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal())
        .try_init();
}

/// clap value parsers: each argument is parsed into its type, and a bad
/// value is reported by clap with the flag's name.
fn synth_kind(s: &str) -> std::result::Result<SynthKind, String> {
    SynthKind::parse(s).ok_or_else(|| {
        "expected marschner-lobb, shells, shepp-logan, constant, plane, noise, stiff or ct".into()
    })
}

fn voxel_type(s: &str) -> std::result::Result<VoxelType, String> {
    VoxelType::parse(s).ok_or_else(|| "expected u8, i8, u16, i16, u32, i32, f32 or f64".into())
}

fn encoding(s: &str) -> std::result::Result<BrickEncoding, String> {
    BrickEncoding::parse(s).ok_or_else(|| "expected u8, u16 or none".into())
}

fn layout(s: &str) -> std::result::Result<parallax_common::wall::Layout, String> {
    match s {
        "arc" => Ok(parallax_common::wall::Layout::Arc),
        "line" => Ok(parallax_common::wall::Layout::Line),
        _ => Err("expected arc or line".into()),
    }
}

/// `WxH`.
fn size<T: std::str::FromStr>(s: &str) -> std::result::Result<[T; 2], String> {
    let (a, b) = s.split_once('x').ok_or("expected WxH, e.g. 160x120")?;
    let p = |t: &str| {
        t.trim()
            .parse::<T>()
            .map_err(|_| format!("'{t}' is not a number"))
    };
    Ok([p(a)?, p(b)?])
}

/// `N` comma-separated numbers.
fn list<T: std::str::FromStr, const N: usize>(s: &str) -> std::result::Result<[T; N], String> {
    let v: Vec<T> = s
        .split(',')
        .map(|t| {
            t.trim()
                .parse::<T>()
                .map_err(|_| format!("'{}' is not a number", t.trim()))
        })
        .collect::<std::result::Result<_, _>>()?;
    let n = v.len();
    v.try_into()
        .map_err(|_| format!("expected {N} comma-separated numbers, got {n}"))
}

fn progress(len: u64, what: &str) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::with_draw_target(
        Some(len),
        indicatif::ProgressDrawTarget::stderr(),
    );
    bar.set_style(
        indicatif::ProgressStyle::with_template(&format!(
            "{what} {{bar:40}} {{pos}}/{{len}} ({{eta}} left)"
        ))
        .unwrap(),
    );
    bar
}

/// Peak resident set size of this process (Linux: VmHWM), in KiB.
fn peak_rss_kib() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

fn parse_codec(s: &str) -> std::result::Result<Codec, String> {
    Codec::parse(s).ok_or_else(|| {
        format!(
            "'{s}': expected lz4, zstd or zstdN (N = 1–19), optionally followed by +delta or +auto"
        )
    })
}

/// What NaN in float input means.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum NanPolicy {
    /// An error naming the voxel.
    Refuse,
    /// No data: never shown, never blended into its neighbours.
    Empty,
}

#[derive(Subcommand)]
enum TfAction {
    /// Convert a ParaView colour-map JSON (with or without opacity points),
    /// a 3D Slicer presets.xml, .vp or .vp.json into Parallax's TOML.
    Import {
        input: PathBuf,
        /// The preset in a file of several (exact, unique case-insensitive
        /// match, or #N); --list shows them.
        #[arg(long)]
        name: Option<String>,
        /// List the presets in the file and stop.
        #[arg(long)]
        list: bool,
        /// lo,hi: stretch the preset over this data range (as ParaView
        /// applies a preset; needed for normalised colour maps).
        #[arg(long, allow_hyphen_values = true, value_parser = list::<f64, 2>)]
        range: Option<[f64; 2]>,
        /// VTK's scalar opacity unit distance, in data length units
        /// (default: the file's, else 1).
        #[arg(long)]
        unit: Option<f64>,
        /// Opacity of a preset that has none: ramp | ramp:LOW,HIGH | const:A |
        /// reject.
        #[arg(long, default_value = "ramp")]
        missing_opacity: parallax_common::tf::presets::MissingOpacity,
        /// Keep colours as the preset's display values instead of decoding
        /// sRGB to linear.
        #[arg(long)]
        display_colours: bool,
        /// The TOML file to write (needed unless --list).
        #[arg(short, long, required_unless_present = "list")]
        output: Option<PathBuf>,
    },
}
