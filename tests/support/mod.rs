//! What the binary-level tests share.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

/// The DICOM series and TIFF stacks that pydicom and tifffile write
/// (`tests/data/make_inputs.py`), made once per test binary in `name` under
/// cargo's temporary folder. The test command installs python3-pydicom,
/// python3-tifffile and python3-numpy.
pub fn inputs(name: &str) -> PathBuf {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
        let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/make_inputs.py");
        let o = Command::new("/usr/bin/python3")
            .arg(&script)
            .arg(&dir)
            .output()
            .expect("run /usr/bin/python3");
        assert!(
            o.status.success(),
            "{} failed (the test command installs python3-pydicom, python3-tifffile, python3-numpy):\n{}",
            script.display(),
            String::from_utf8_lossy(&o.stderr)
        );
        dir
    })
    .clone()
}

/// The volume most binary-level tests render: `parallax synth <kind> --size
/// <size>` imported with bricks of 16 as `dir/v.pxo`, and a three-point
/// transfer function `dir/tf.toml`.
pub fn volume(dir: &Path, kind: &str, size: u32) {
    let bin = env!("CARGO_BIN_EXE_parallax");
    let (nrrd, pxo) = (dir.join("v.nrrd"), dir.join("v.pxo"));
    let size = size.to_string();
    for args in [
        vec!["synth", kind, "--size", &size, "-o", nrrd.to_str().unwrap()],
        vec![
            "import",
            nrrd.to_str().unwrap(),
            "-o",
            pxo.to_str().unwrap(),
            "--brick",
            "16",
        ],
    ] {
        let o = Command::new(bin).args(&args).output().unwrap();
        assert!(
            o.status.success(),
            "parallax {args:?}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
    }
    std::fs::write(
        dir.join("tf.toml"),
        "[[point]]\nvalue = 0\ncolor = [0, 0, 0]\nextinction = 0\n[[point]]\nvalue = 100\ncolor = [0.2, 0.5, 1]\nextinction = 0.05\n[[point]]\nvalue = 255\ncolor = [1, 0.8, 0.4]\nextinction = 0.4\n",
    )
    .unwrap();
}
