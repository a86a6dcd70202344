//! Fuzz-style tests of every parser: thousands of mutated inputs each (bit
//! flips, bytes set to edge values, insertions, deletions, duplicated runs,
//! truncation; numbers and lines swapped in text formats), from a valid
//! seed, with a fixed random sequence so a failure repeats. Each input must
//! either read or fail with an error that names the file; none may panic.
//! A failing input is kept under the cargo target's temporary folder;
//! `FUZZ_SLOW=1` prints the inputs that take over 50 ms.

use parallax_backend::data::{self, InputOptions};
use parallax_backend::store::{self, BrickEncoding, ImportOptions, OctreeDb};
use parallax_backend::volume::{MemorySource, Volume, VolumeSource, VoxelType};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};

/// xorshift64*: a small deterministic generator.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

const EDGE_BYTES: [u8; 8] = [0x00, 0x01, 0x7f, 0x80, 0xff, b'-', b'9', b'\n'];
const EDGE_NUMBERS: [&str; 12] = [
    "0",
    "-1",
    "1e308",
    "-1e308",
    "nan",
    "inf",
    "-inf",
    "1e-320",
    "4294967297",
    "-0.0",
    "1e9",
    "\"x\"",
];

/// One binary mutation: `focus` bytes at the start get most of them (a
/// header), the rest anywhere.
fn mutate_bytes(rng: &mut Rng, seed: &[u8], focus: usize) -> Vec<u8> {
    let mut b = seed.to_vec();
    for _ in 0..1 + rng.below(4) {
        if b.is_empty() {
            b.push(0);
        }
        let span = if rng.below(4) > 0 {
            focus.min(b.len())
        } else {
            b.len()
        };
        let at = rng.below(span);
        match rng.below(7) {
            0 => b[at] ^= 1 << rng.below(8),
            1 => b[at] = EDGE_BYTES[rng.below(EDGE_BYTES.len())],
            2 => {
                let n = 1 + rng.below(8);
                let bytes: Vec<u8> = (0..n).map(|_| rng.next() as u8).collect();
                b.splice(at..at, bytes);
            }
            3 => {
                let end = (at + 1 + rng.below(16)).min(b.len());
                b.drain(at..end);
            }
            4 => {
                let end = (at + 1 + rng.below(32)).min(b.len());
                let run = b[at..end].to_vec();
                b.splice(at..at, run);
            }
            5 => b.truncate(at),
            _ => {
                // a 4-byte field set to an edge integer
                let v: u32 = [0, 1, 0xffff_ffff, 0x8000_0000, 0x7fff_ffff][rng.below(5)];
                let end = (at + 4).min(b.len());
                let n = end - at;
                b[at..end].copy_from_slice(&v.to_le_bytes()[..n]);
            }
        }
    }
    b
}

/// One text mutation: a number replaced by an edge value, a line removed or
/// duplicated or moved, or a binary mutation.
fn mutate_text(rng: &mut Rng, seed: &str) -> Vec<u8> {
    let mut lines: Vec<String> = seed.lines().map(str::to_string).collect();
    for _ in 0..1 + rng.below(3) {
        if lines.is_empty() {
            lines.push(String::new());
        }
        let i = rng.below(lines.len());
        match rng.below(5) {
            0 | 1 => {
                // replace the k-th number of the line
                let line = lines[i].clone();
                let starts: Vec<usize> = line
                    .char_indices()
                    .filter(|&(k, c)| {
                        (c.is_ascii_digit() || c == '-')
                            && (k == 0 || !line.as_bytes()[k - 1].is_ascii_alphanumeric())
                    })
                    .map(|(k, _)| k)
                    .collect();
                if let Some(&k) = starts.get(rng.below(starts.len().max(1))) {
                    let end = line[k..]
                        .find(|c: char| !(c.is_ascii_alphanumeric() || "+-.".contains(c)))
                        .map_or(line.len(), |e| k + e);
                    let num = EDGE_NUMBERS[rng.below(EDGE_NUMBERS.len())];
                    lines[i] = format!("{}{}{}", &line[..k], num, &line[end..]);
                }
            }
            2 => {
                lines.remove(i);
            }
            3 => {
                let l = lines[i].clone();
                let j = rng.below(lines.len());
                lines.insert(j, l);
            }
            _ => {
                let text = lines.join("\n");
                let b = mutate_bytes(rng, text.as_bytes(), text.len());
                return b;
            }
        }
    }
    lines.join("\n").into_bytes()
}

/// Runs `parse` on `iterations` mutations of `seed` written to `file`;
/// errors must name `name`. Returns (accepted, refused).
fn fuzz(
    what: &str,
    iterations: usize,
    file: &Path,
    mut mutate: impl FnMut(&mut Rng) -> Vec<u8>,
    parse: impl Fn(&Path) -> anyhow::Result<()>,
    name: &str,
) -> (usize, usize) {
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15 ^ what.len() as u64);
    let (mut ok, mut refused) = (0, 0);
    let start = std::time::Instant::now();
    for i in 0..iterations {
        let input = mutate(&mut rng);
        std::fs::write(file, &input).unwrap();
        let keep = || {
            let p = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("fuzz-{what}-{i}"));
            std::fs::write(&p, &input).unwrap();
            p
        };
        let t0 = std::time::Instant::now();
        let res = catch_unwind(AssertUnwindSafe(|| parse(file)));
        if std::env::var("FUZZ_SLOW").is_ok() && t0.elapsed().as_millis() > 50 {
            eprintln!(
                "{what} #{i}: {} ms: {:?}",
                t0.elapsed().as_millis(),
                res.as_ref()
                    .map(|r| r.as_ref().map_err(|e| format!("{e:#}")))
            );
        }
        match res {
            Ok(Ok(())) => ok += 1,
            Ok(Err(e)) => {
                let msg = format!("{e:#}");
                if !msg.contains(name) {
                    panic!(
                        "{what} #{i}: the error does not name {name}: {msg} (input: {})",
                        keep().display()
                    );
                }
                refused += 1;
            }
            Err(_) => panic!("{what} #{i}: panicked (input: {})", keep().display()),
        }
    }
    eprintln!(
        "{what}: {iterations} inputs, {ok} read, {refused} refused with a clear error, {:.1} s",
        start.elapsed().as_secs_f64()
    );
    (ok, refused)
}

/// Reads a source through ([`harness::read_through`]).
fn read_through(mut src: Box<dyn VolumeSource + Send>) -> anyhow::Result<()> {
    harness::read_through(src.as_mut())
}

fn small_volume() -> Volume {
    Volume::from_fn([6, 5, 4], [0.5, 0.7, 1.25], VoxelType::U8, |i, j, k| {
        ((i * 37 + j * 11 + k * 5) % 256) as f32
    })
}

#[test]
fn nrrd_headers_and_data() {
    let d = tempfile::tempdir().unwrap();
    let mut seed = b"NRRD0004\n# a comment\ntype: uint8\ndimension: 3\nsizes: 6 5 4\n\
space directions: (0.5,0,0) (0,0.7,0) (0,0,1.25)\nendian: little\nencoding: raw\n\n"
        .to_vec();
    seed.extend(small_volume().data.iter().map(|&v| v as u8));
    let file = d.path().join("f.nrrd");
    let (ok, refused) = fuzz(
        "nrrd",
        4000,
        &file,
        |r| mutate_bytes(r, &seed, 160),
        |p| read_through(data::open(p, None)?),
        "f.nrrd",
    );
    assert!(ok > 100 && refused > 1000, "{ok} {refused}");
    // gzip-encoded data, mutated anywhere
    let mut gz =
        b"NRRD0004\ntype: int16\ndimension: 3\nsizes: 6 5 4\nendian: big\nencoding: gzip\n\n"
            .to_vec();
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    use std::io::Write;
    for v in &small_volume().data {
        enc.write_all(&(*v as i16 * 100).to_be_bytes()).unwrap();
    }
    gz.extend(enc.finish().unwrap());
    let file = d.path().join("g.nrrd");
    fuzz(
        "nrrd-gzip",
        2000,
        &file,
        |r| mutate_bytes(r, &gz, gz.len()),
        |p| read_through(data::open(p, None)?),
        "g.nrrd",
    );
}

/// A NIfTI-1 single file: 348-byte header, 4 bytes of extension flag, data.
fn nifti_seed() -> Vec<u8> {
    let mut h = vec![0u8; 352];
    let put = |h: &mut Vec<u8>, at: usize, b: &[u8]| h[at..at + b.len()].copy_from_slice(b);
    put(&mut h, 0, &348i32.to_le_bytes());
    for (i, d) in [3u16, 6, 5, 4, 1, 1, 1, 1].iter().enumerate() {
        put(&mut h, 40 + 2 * i, &d.to_le_bytes());
    }
    put(&mut h, 70, &2i16.to_le_bytes()); // uint8
    put(&mut h, 72, &8i16.to_le_bytes());
    for (i, p) in [1.0f32, 0.5, 0.7, 1.25].iter().enumerate() {
        put(&mut h, 76 + 4 * i, &p.to_le_bytes());
    }
    put(&mut h, 108, &352.0f32.to_le_bytes());
    put(&mut h, 112, &1.0f32.to_le_bytes());
    put(&mut h, 344, b"n+1\0");
    h.extend(small_volume().data.iter().map(|&v| v as u8));
    h
}

#[test]
fn nifti_headers_and_data() {
    let d = tempfile::tempdir().unwrap();
    let seed = nifti_seed();
    let file = d.path().join("f.nii");
    assert!(read_through(
        data::open(
            &{
                std::fs::write(&file, &seed).unwrap();
                file.clone()
            },
            None
        )
        .unwrap()
    )
    .is_ok());
    let (ok, refused) = fuzz(
        "nifti",
        4000,
        &file,
        |r| mutate_bytes(r, &seed, 352),
        |p| read_through(data::open(p, None)?),
        "f.nii",
    );
    assert!(ok > 100 && refused > 500, "{ok} {refused}");
}

mod support;

/// The DICOM series and TIFF stacks written by pydicom and tifffile.
fn inputs() -> PathBuf {
    support::inputs("fuzz-inputs")
}

#[test]
fn dicom_folders() {
    let d = tempfile::tempdir().unwrap();
    let series = d.path().join("series");
    std::fs::create_dir(&series).unwrap();
    let src = inputs().join("dicom-rle");
    let mut names: Vec<_> = std::fs::read_dir(&src)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    names.sort();
    for n in names.iter().take(3) {
        std::fs::copy(src.join(n), series.join(n)).unwrap();
    }
    let victim = series.join(&names[1]);
    let seed = std::fs::read(&victim).unwrap();
    let (ok, refused) = fuzz(
        "dicom",
        // dicom-rs allocates an element's declared length before reading
        // it, so a mutated length costs up to a second: fewer runs here.
        500,
        &victim,
        |r| mutate_bytes(r, &seed, 1200),
        |_| read_through(data::open_with(&series, &InputOptions::default())?),
        "series",
    );
    assert!(ok > 20 && refused > 200, "{ok} {refused}");
}

#[test]
fn tiff_files() {
    let d = tempfile::tempdir().unwrap();
    for (seed_name, runs) in [("stack.tif", 1500), ("stack-f32.tif", 1000)] {
        let seed = std::fs::read(inputs().join(seed_name)).unwrap();
        let file = d.path().join(seed_name);
        let (ok, refused) = fuzz(
            seed_name,
            runs,
            &file,
            |r| {
                // the directory (at the end for tifffile) and the first bytes
                let mut b = mutate_bytes(r, &seed, 64);
                if r.below(2) == 0 {
                    let tail = seed.len().saturating_sub(400);
                    let m = mutate_bytes(r, &seed[tail..], 400);
                    b = seed[..tail].to_vec();
                    b.extend(m);
                }
                b
            },
            |p| read_through(data::open_with(p, &InputOptions::default())?),
            seed_name,
        );
        assert!(ok > 20 && refused > 200, "{seed_name}: {ok} {refused}");
    }
}

#[test]
fn pxo_footer_index_and_bricks() {
    let d = tempfile::tempdir().unwrap();
    let vol = Volume::from_fn([16, 16, 16], [1.0; 3], VoxelType::U8, |i, j, k| {
        ((i * 7 + j * 3 + k) % 200) as f32
    });
    let db = d.path().join("seed.pxo");
    store::import(
        &mut MemorySource::new(&vol),
        &db,
        "seed",
        &ImportOptions {
            brick: 8,
            encoding: BrickEncoding::U8Range,
            ..Default::default()
        },
    )
    .unwrap();
    let seed = std::fs::read(&db).unwrap();
    let file = d.path().join("f.pxo");
    let read_all = |p: &Path| -> anyhow::Result<()> {
        let o = OctreeDb::open(p)?;
        for n in o.nodes.clone() {
            o.read_brick(n.key)?;
        }
        Ok(())
    };
    let (ok, refused) = fuzz(
        "pxo",
        4000,
        &file,
        |r| {
            // mostly the header, the node table and the footer at the end
            match r.below(3) {
                0 => mutate_bytes(r, &seed, 200),
                1 => {
                    let tail = seed.len().saturating_sub(600);
                    let mut b = seed[..tail].to_vec();
                    b.extend(mutate_bytes(r, &seed[tail..], 600));
                    b
                }
                _ => mutate_bytes(r, &seed, seed.len()),
            }
        },
        read_all,
        "f.pxo",
    );
    assert!(ok > 5 && refused > 2000, "{ok} {refused}");
}

#[test]
fn scene_display_projector_tf_and_script_toml() {
    let d = tempfile::tempdir().unwrap();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let tf_seed = std::fs::read_to_string(root.join("configs/tf/ct-bone.toml")).unwrap();
    let display_seed =
        "[screen]\nsize = [0.4, 0.3]\npixel_size = 0.005\nangular_accuracy_deg = 0.8\n\
[observer]\nposition = [0, 0, 0.8]\nprojectors = \"p/\"\n";
    let projector_seed =
        "id = \"left\"\nposition = [-0.05, 0, 0.8]\nresolution = [32, 24]\nrank = 1\n";
    let scene_seed = "volume = \"v.pxo\"\ntransfer_function = \"tf.toml\"\ndisplay = \"display.toml\"\n\
[placement]\ncenter = [0, 0, 0]\nsize = 0.2\nrotation_deg = [10, 20, 0]\n\
[render]\neta = 0.5\nshading = \"phong\"\nmode = \"mimda\"\ngamma = 0.3\naccuracy = 1.0\nstep_factor = 0.5\n\
early_termination = 0.99\ncpu_cache_mb = 64\ngpu_cache_mb = 32\nupload_budget = 16\n\
[[tool]]\nkind = \"clip-plane\"\npoint = [0, 0, 0]\nnormal = [0, 0, 1]\nthickness = 0.01\ncontext = [0.3, 0.7]\n";
    let script_seed = "frames = 12\n[[key]]\nframe = 0\nplacement = { rotation_deg = [0, 0, 0] }\neta = 0\n\
transfer_function = \"tf.toml\"\n[[key]]\nframe = 10\nplacement = { rotation_deg = [0, 90, 0], size = 0.3 }\ngamma = 1\n";
    std::fs::create_dir(d.path().join("p")).unwrap();
    std::fs::write(d.path().join("tf.toml"), &tf_seed).unwrap();
    std::fs::write(d.path().join("display.toml"), display_seed).unwrap();
    std::fs::write(d.path().join("p/left.toml"), projector_seed).unwrap();
    std::fs::write(d.path().join("scene.toml"), scene_seed).unwrap();
    std::fs::write(d.path().join("script.toml"), script_seed).unwrap();
    use parallax_common::config::{Display, Scene};
    assert!(Scene::load(&d.path().join("scene.toml")).is_ok());
    assert!(Display::load(&d.path().join("display.toml")).is_ok());
    parallax_frontend::script::Script::load(&d.path().join("script.toml")).unwrap();
    type Parser<'a> = &'a dyn Fn(&Path) -> anyhow::Result<()>;
    let cases: [(&str, &str, PathBuf, Parser); 5] = [
        ("tf", &tf_seed, d.path().join("tf.toml"), &|p| {
            parallax_common::tf::TransferFunction::load(p).map(|_| ())
        }),
        (
            "display",
            display_seed,
            d.path().join("display.toml"),
            &|p| Display::load(p).map(|_| ()),
        ),
        (
            "projector",
            projector_seed,
            d.path().join("p/left.toml"),
            &|_| Display::load(&d.path().join("display.toml")).map(|_| ()),
        ),
        ("scene", scene_seed, d.path().join("scene.toml"), &|p| {
            Scene::load(p).map(|_| ())
        }),
        ("script", script_seed, d.path().join("script.toml"), &|p| {
            parallax_frontend::script::Script::load(p).map(|_| ())
        }),
    ];
    for (what, seed, file, parse) in cases {
        let name = file.file_name().unwrap().to_string_lossy().into_owned();
        let (ok, refused) = fuzz(what, 2000, &file, |r| mutate_text(r, seed), parse, &name);
        std::fs::write(&file, seed).unwrap();
        assert!(refused > 300, "{what}: {ok} {refused}");
    }
}

/// The coverage-guided fuzzers' harness (`fuzz/src/lib.rs`), here without
/// instrumentation: the same checks on the committed corpora and on every
/// input a fuzzer once broke a parser with.
#[path = "../fuzz/src/lib.rs"]
mod harness;

/// As the binary and the fuzzer: decoders' single allocations capped.
#[global_allocator]
static ALLOC: parallax_backend::data::CappedAlloc = parallax_backend::data::CappedAlloc;

/// Every file of `fuzz/corpus/<target>/` (the seeds: real files of every
/// format and encoding) and `fuzz/regressions/<target>/` (what the
/// fuzzers found, each fixed) goes through its target's checks.
#[test]
fn the_fuzzers_corpora_and_regressions_replay() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz");
    for target in harness::TARGETS {
        let mut seeds = 0;
        for kind in ["corpus", "regressions"] {
            let Ok(dir) = std::fs::read_dir(root.join(kind).join(target)) else {
                continue;
            };
            let mut files: Vec<PathBuf> = dir.map(|e| e.unwrap().path()).collect();
            files.sort();
            for f in files {
                let input = std::fs::read(&f).unwrap();
                let r = catch_unwind(AssertUnwindSafe(|| harness::run(target, &input)));
                assert!(r.is_ok(), "{target}: {} broke the parser", f.display());
                seeds += (kind == "corpus") as usize;
            }
        }
        println!("{target}: {seeds} seeds");
        assert!(
            seeds >= 2,
            "{target}: {seeds} seeds in fuzz/corpus/{target}"
        );
    }
}

/// The wire seeds: messages of every kind a rank sends, encoded by the
/// protocol as it stands. With `PARALLAX_WRITE_SEEDS=1` they are written
/// to `fuzz/corpus/wire/` (`fuzz/make_seeds.sh`); otherwise the committed
/// ones must still decode, so the corpus follows the protocol.
#[test]
fn wire_seeds() {
    use parallax_common::protocol::{decode, encode, FrameState, FrameStats, Ready, ToBackend};
    use parallax_common::tools::{BandPicker, ClipPlane, Probe, Tool};
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let tf =
        parallax_common::tf::TransferFunction::load(root.join("configs/tf/ct-bone.toml")).unwrap();
    let frame = FrameState {
        frame: 7,
        placement: parallax_common::camera::Placement {
            center: [0.0, 0.01, -0.02],
            rotation_deg: [10.0, 20.0, 0.0],
            size: 0.25,
        },
        observer: [0.0, 0.0, 1.0],
        eta: 0.5,
        render: Default::default(),
        tf_version: 2,
        tools_version: 3,
        stream: vec![0, 3],
        pick: Some([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]]),
        grow: Some(0.05),
        layers: Vec::new(),
        step: 0,
    };
    let tools = vec![
        Tool::ClipPlane(ClipPlane {
            point: [0.0; 3],
            normal: [0.0, 0.0, 1.0],
            thickness: 0.01,
            context: [0.3, 0.7],
        }),
        Tool::Probe(Probe::new([0.0, 0.02, 0.0], 0.05)),
        Tool::BandPicker(BandPicker {
            band: [1.0, 2.0, 3.0, 4.0],
            points: Some([1, 2]),
            axis: [0.0, 0.0, 1.0],
            alignment: [0.7, 0.95],
        }),
    ];
    let stats = FrameStats {
        rank: 1,
        frame: 7,
        views: 2,
        render_ms: 12.5,
        ready: Some(Ready {
            protocol: 3,
            build: "parallax 0.1.0".into(),
            database: 42,
        }),
        ..Default::default()
    };
    let messages: Vec<(&str, Vec<u8>)> = vec![
        ("to-frame", encode(&ToBackend::Frame(frame)).unwrap()),
        (
            "to-tf",
            encode(&ToBackend::TransferFunction {
                version: 2,
                tf: tf.clone(),
            })
            .unwrap(),
        ),
        (
            "to-tools",
            encode(&ToBackend::Tools { version: 3, tools }).unwrap(),
        ),
        (
            "to-present",
            encode(&ToBackend::Present { frame: 7 }).unwrap(),
        ),
        ("to-quit", encode(&ToBackend::Quit).unwrap()),
        (
            "to-layer-functions",
            encode(&ToBackend::LayerFunctions {
                version: 2,
                tfs: vec![Some(tf), None],
            })
            .unwrap(),
        ),
        ("stats", encode(&stats).unwrap()),
    ];
    let dir = root.join("fuzz/corpus/wire");
    if std::env::var("PARALLAX_WRITE_SEEDS").is_ok() {
        std::fs::create_dir_all(&dir).unwrap();
        for (name, bytes) in &messages {
            std::fs::write(dir.join(format!("{name}.bin")), bytes).unwrap();
        }
        return;
    }
    for (name, bytes) in &messages {
        let committed = std::fs::read(dir.join(format!("{name}.bin"))).unwrap();
        let ok = if name.starts_with("to-") {
            decode::<ToBackend>(&committed).is_ok()
        } else {
            decode::<FrameStats>(&committed).is_ok()
        };
        assert!(
            ok,
            "fuzz/corpus/wire/{name}.bin no longer decodes: run fuzz/make_seeds.sh"
        );
        assert!(!bytes.is_empty());
    }
}
