//! Third-party decoders (dicom-rs, the tiff crate) run under
//! `catch_unwind`: a panic of theirs on a malformed file (the fuzzers found
//! an RLE segment that indexes past its buffer in dicom-rs 0.10.1) becomes
//! an error naming the file, not the end of an import or a live session.
//! [`install_hook`] keeps such a contained panic quiet (the error says what
//! happened) and leaves every other panic to the hook before it.

use anyhow::{bail, Result};
use std::cell::Cell;
use std::panic::{catch_unwind, AssertUnwindSafe};

thread_local! {
    static DEPTH: Cell<u32> = const { Cell::new(0) };
}

/// Runs `f`, a call into a decoder; its panic is an error: `{label}: {what}
/// failed on this file: …`.
pub fn contained<T>(label: &str, what: &str, f: impl FnOnce() -> Result<T>) -> Result<T> {
    DEPTH.with(|d| d.set(d.get() + 1));
    let r = catch_unwind(AssertUnwindSafe(f));
    DEPTH.with(|d| d.set(d.get() - 1));
    match r {
        Ok(r) => r,
        Err(p) => {
            let why = p
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| p.downcast_ref::<String>().cloned())
                .unwrap_or_default();
            bail!("{label}: {what} failed on this file (the file is malformed: {why})")
        }
    }
}

/// Wraps the panic hook so that a panic inside [`contained`] is not
/// reported by it (nor, under a fuzzer, turned into an abort).
pub fn install_hook() {
    let before = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        if DEPTH.with(|d| d.get()) == 0 {
            before(info);
        }
    }));
}
