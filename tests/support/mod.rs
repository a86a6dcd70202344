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
