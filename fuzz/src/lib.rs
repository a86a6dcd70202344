//! The fuzzers' harness: one function per parser that takes the fuzzer's
//! bytes, hands them to the parser as a user's file (or a page's message,
//! or a rank's) would reach it, and checks what every parser promises:
//! it reads, or it fails with an error that names the file; it never
//! panics, and a header cannot make it allocate or loop beyond the input.
//!
//! `fuzz_targets/parallax_fuzz.rs` runs it under libFuzzer (coverage
//! guided, `scripts/fuzz.sh`); `tests/fuzz.rs` replays the corpora and
//! every input a fuzzer once broke the project with (`fuzz/regressions/`)
//! through the same functions, without instrumentation.

use anyhow::Result;
use parallax_backend::data::{self, InputOptions, RawParams};
use parallax_backend::store::OctreeDb;
use parallax_backend::volume::{VolumeSource, VoxelType};
use parallax_common::config::{Display, Scene};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// The parsers, by the name `PARALLAX_FUZZ` and the corpus folders use.
pub const TARGETS: [&str; 12] = [
    "nrrd", "nhdr", "nifti", "raw", "dicom", "tiff", "pxo", "toml", "preset", "live", "wire",
    "zarr",
];

/// Runs `target` on one input; panics where a parser broke its promise.
pub fn run(target: &str, input: &[u8]) {
    // A decoder's panic that the readers contain (and turn into an error)
    // is not a finding; every other panic still is.
    static HOOK: std::sync::Once = std::sync::Once::new();
    HOOK.call_once(parallax_backend::data::install_hook);
    let dir = workdir();
    match target {
        "nrrd" => file(dir, "f.nrrd", input, volume),
        "nhdr" => file(dir, "f.nhdr", input, volume),
        "nifti" => {
            file(dir, "f.nii", input, volume);
            let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
            gz.write_all(input).unwrap();
            file(dir, "f.nii.gz", &gz.finish().unwrap(), volume);
        }
        "raw" => raw(dir, input),
        "dicom" => {
            let folder = dir.join("dcm");
            std::fs::create_dir_all(&folder).unwrap();
            std::fs::write(folder.join("a.dcm"), input).unwrap();
            expect(volume(&folder), "dcm");
        }
        "tiff" => file(dir, "f.tif", input, volume),
        "pxo" => file(dir, "f.pxo", input, pxo),
        "toml" => toml(dir, input),
        "preset" => preset(input),
        "live" => live(input),
        "wire" => wire(input),
        "zarr" => zarr(dir, input),
        other => panic!("PARALLAX_FUZZ={other}: not one of {TARGETS:?}"),
    }
}

/// A folder of this process's own (on tmpfs where there is one), with the
/// files the inputs may refer to: a detached header's data `d.raw`, a
/// scene's volume, transfer function and display.
fn workdir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let base = if Path::new("/dev/shm").is_dir() {
            PathBuf::from("/dev/shm")
        } else {
            std::env::temp_dir()
        };
        let dir = base.join(format!("parallax-fuzz-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("p")).unwrap();
        let d: Vec<u8> = (0..4096u32).map(|i| (i * 7 % 251) as u8).collect();
        std::fs::write(dir.join("d.raw"), d).unwrap();
        for (name, text) in [
            ("tf.toml", TF),
            ("display.toml", DISPLAY),
            ("p/left.toml", PROJECTOR),
            ("scene.toml", SCENE),
        ] {
            std::fs::write(dir.join(name), text).unwrap();
        }
        dir
    })
}

const TF: &str = "[[point]]\nvalue = 0\ncolor = [0, 0, 0]\nextinction = 0\n\
[[point]]\nvalue = 100\ncolor = [1, 0.8, 0.6]\nextinction = 2\nimportance = 0.5\n\
[[point]]\nvalue = 255\ncolor = [1, 1, 1]\nextinction = 4\n";
const DISPLAY: &str =
    "[screen]\nsize = [0.4, 0.3]\npixel_size = 0.005\nangular_accuracy_deg = 0.8\n\
[observer]\nposition = [0, 0, 0.8]\nprojectors = \"p/\"\n";
const PROJECTOR: &str =
    "id = \"left\"\nposition = [-0.05, 0, 0.8]\nresolution = [32, 24]\nrank = 1\n";
const SCENE: &str =
    "volume = \"v.pxo\"\ntransfer_function = \"tf.toml\"\ndisplay = \"display.toml\"\n\
[placement]\ncenter = [0, 0, 0]\nsize = 0.2\nrotation_deg = [10, 20, 0]\n\
[render]\neta = 0.5\nshading = \"phong\"\n\
[[tool]]\nkind = \"band-picker\"\nband = [10, 20, 30, 40]\n\
[[layer]]\nvolume = \"v.pxo\"\ntransfer_function = \"tf.toml\"\nopacity = 0.5\n";

/// An OME-Zarr image (NGFF 0.5, Zarr v3: a group, one 4×4×4 u8 array
/// `s0` of one gzip chunk). The first byte chooses the file the rest
/// replaces: the group's `zarr.json` (the NGFF metadata), the array's
/// `zarr.json`, or the chunk.
fn zarr(dir: &Path, input: &[u8]) {
    let root = dir.join("z.ome.zarr");
    let _ = std::fs::remove_dir_all(&root);
    std::fs::create_dir_all(root.join("s0/c/0/0")).unwrap();
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    gz.write_all(&(0..64u8).collect::<Vec<u8>>()).unwrap();
    let files = [
        ("zarr.json", ZARR_GROUP.as_bytes().to_vec()),
        ("s0/zarr.json", ZARR_ARRAY.as_bytes().to_vec()),
        ("s0/c/0/0/0", gz.finish().unwrap()),
    ];
    let (which, body) = input.split_first().unwrap_or((&0, &[]));
    for (i, (name, default)) in files.iter().enumerate() {
        let bytes = if i == *which as usize % files.len() {
            body
        } else {
            default
        };
        std::fs::write(root.join(name), bytes).unwrap();
    }
    expect(volume(&root), "z.ome.zarr");
}

const ZARR_GROUP: &str = r#"{"zarr_format": 3, "node_type": "group", "attributes": {"ome": {"version": "0.5", "multiscales": [{"axes": [{"name": "z", "type": "space", "unit": "micrometer"}, {"name": "y", "type": "space", "unit": "micrometer"}, {"name": "x", "type": "space", "unit": "micrometer"}], "datasets": [{"path": "s0", "coordinateTransformations": [{"type": "scale", "scale": [2.0, 0.5, 0.5]}]}]}]}}}"#;
const ZARR_ARRAY: &str = r#"{"zarr_format": 3, "node_type": "array", "shape": [4, 4, 4], "data_type": "uint8", "chunk_grid": {"name": "regular", "configuration": {"chunk_shape": [4, 4, 4]}}, "chunk_key_encoding": {"name": "default", "configuration": {"separator": "/"}}, "fill_value": 0, "codecs": [{"name": "bytes"}, {"name": "gzip", "configuration": {"level": 1}}]}"#;

/// Writes `input` as `dir/name` and parses it; an error must name the file.
fn file(dir: &Path, name: &str, input: &[u8], parse: fn(&Path) -> Result<()>) {
    let path = dir.join(name);
    std::fs::write(&path, input).unwrap();
    expect(parse(&path), name);
}

fn expect(r: Result<()>, name: &str) {
    if let Err(e) = r {
        let msg = format!("{e:#}");
        assert!(msg.contains(name), "the error does not name {name}: {msg}");
    }
}

/// Opens a volume and reads it through.
fn volume(path: &Path) -> Result<()> {
    let mut src = data::open_with(path, &InputOptions::default())?;
    read_through(src.as_mut())
}

/// Reads a source through, slice by slice, unless its header claims more
/// than a fuzzer should allocate (an import refuses those by its memory
/// budget before reading; `tests/inputs.rs` checks that).
pub fn read_through(src: &mut (dyn VolumeSource + Send)) -> Result<()> {
    let info = src.info().clone();
    if info.voxel_count() > 1 << 22 || info.slice_len() > 1 << 20 {
        return Ok(());
    }
    let mut slice = vec![0f32; info.slice_len()];
    for _ in 0..info.dims[2] {
        src.read_slices(&mut slice)?;
    }
    Ok(())
}

/// A headerless file: its first 8 bytes choose the dims (1–16 each), the
/// type, the byte order and an offset, as `--raw` would; the rest is the
/// file.
fn raw(dir: &Path, input: &[u8]) {
    let Some((head, body)) = input.split_at_checked(8) else {
        return;
    };
    let params = RawParams {
        dims: [
            1 + (head[0] % 16) as usize,
            1 + (head[1] % 16) as usize,
            1 + (head[2] % 16) as usize,
        ],
        voxel_type: VoxelType::ALL[(head[3] % 8) as usize],
        spacing: [1.0, 0.5 + head[4] as f64 / 64.0, 2.0],
        byte_offset: head[5] as u64,
        big_endian: head[6] & 1 == 1,
    };
    let path = dir.join("f.raw");
    std::fs::write(&path, body).unwrap();
    let opts = InputOptions {
        raw: Some(params),
        nan_empty: head[7] & 1 == 1,
        ..Default::default()
    };
    expect(
        data::open_with(&path, &opts).and_then(|mut s| read_through(s.as_mut())),
        "f.raw",
    );
}

/// A `.pxo` opened and every brick read (each checked against its
/// checksum).
fn pxo(path: &Path) -> Result<()> {
    let db = OctreeDb::open(path)?;
    for n in db.nodes.clone() {
        db.read_brick(n.key)?;
    }
    Ok(())
}

/// The first byte chooses the file: a transfer function, a display, one
/// of its projectors, a scene or an interaction script.
fn toml(dir: &Path, input: &[u8]) {
    type Parse = fn(&Path) -> Result<()>;
    // Each file, what it holds between inputs (the shared ones go back),
    // and how it is read.
    const FILES: [(&str, Option<&str>, Parse); 5] = [
        ("tf.toml", Some(TF), |p| {
            parallax_common::tf::TransferFunction::load(p).map(|_| ())
        }),
        ("display.toml", Some(DISPLAY), |p| {
            Display::load(p).map(|_| ())
        }),
        ("p/left.toml", Some(PROJECTOR), |p| {
            Display::load(&p.parent().unwrap().parent().unwrap().join("display.toml")).map(|_| ())
        }),
        ("scene.toml", Some(SCENE), |p| Scene::load(p).map(|_| ())),
        ("script.toml", None, |p| {
            parallax_frontend::script::Script::load(p).map(|_| ())
        }),
    ];
    let Some((&which, text)) = input.split_first() else {
        return;
    };
    let (name, original, parse) = FILES[which as usize % FILES.len()];
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    let r = parse(&path);
    if let Some(t) = original {
        std::fs::write(&path, t).unwrap();
    }
    expect(r, name.rsplit('/').next().unwrap());
}

/// A transfer-function preset of any format (Slicer `.vp`, `presets.xml`,
/// ParaView JSON), as `parallax tf import` reads it.
fn preset(input: &[u8]) {
    let Ok(text) = std::str::from_utf8(input) else {
        return;
    };
    let opts = parallax_backend::data::presets::ImportOptions::default();
    if let Err(e) = parallax_backend::data::presets::import_preset(text, "f.vp", None, &opts) {
        let msg = format!("{e:#}");
        assert!(msg.contains("f.vp"), "the error does not name f.vp: {msg}");
    }
}

/// A page's WebSocket message against the state of `SCENE`: refused, or a
/// state that the server would send, and that then applies again whole
/// from its link and equals itself (every state the server sends can be
/// re-applied), but for `recording`, which a link leaves as it is.
fn live(input: &[u8]) {
    static START: OnceLock<(parallax_frontend::live::LiveState, Display)> = OnceLock::new();
    let (state, display) = START.get_or_init(|| {
        let dir = workdir();
        let scene = Scene::load(&dir.join("scene.toml")).unwrap();
        let display = Display::load(&dir.join("display.toml")).unwrap();
        let tf = parallax_common::tf::TransferFunction::load(dir.join("tf.toml")).unwrap();
        let layer_tfs = vec![tf.clone(); scene.layers.len()];
        (
            parallax_frontend::live::LiveState::from_scene(&scene, &display, tf, layer_tfs),
            display,
        )
    });
    let Ok(text) = std::str::from_utf8(input) else {
        return;
    };
    let Ok(next) = parallax_frontend::live::apply_message(state, display, text) else {
        return;
    };
    let link = serde_json::json!({"type": "state", "state": next}).to_string();
    match parallax_frontend::live::apply_message(state, display, &link) {
        // A link neither starts nor stops a recording.
        Ok(mut again) => {
            again.recording = next.recording;
            assert!(
                again == next,
                "a state re-applied from its link differs: {text}"
            )
        }
        Err(e) => panic!("the server's own state is refused from its link: {e} (after {text})"),
    }
}

/// A rank's message as the other side decodes it: every kind the
/// protocol carries either decodes or is malformed.
fn wire(input: &[u8]) {
    use parallax_common::protocol::{decode, FrameStats, ToBackend};
    let _ = decode::<ToBackend>(input);
    let _ = decode::<Vec<FrameStats>>(input);
    let _ = decode::<FrameStats>(input);
}
