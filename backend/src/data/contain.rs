//! Third-party decoders (dicom-rs, the tiff crate) run under
//! `catch_unwind`: a panic of theirs on a malformed file (the fuzzers found
//! an RLE segment that indexes past its buffer in dicom-rs 0.10.1) becomes
//! an error naming the file, not the end of an import or a live session.
//! [`install_hook`] keeps such a contained panic quiet (the error says what
//! happened) and leaves every other panic to the hook before it.

use anyhow::{bail, Result};
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::panic::{catch_unwind, AssertUnwindSafe};

thread_local! {
    static DEPTH: Cell<u32> = const { Cell::new(0) };
    static CAP: Cell<usize> = const { Cell::new(usize::MAX) };
}

/// The system allocator, refusing (null, which `try_reserve` reports as an
/// error) any single uninitialised allocation above the calling thread's
/// cap while a decoder runs under [`contained`]: dicom-rs allocates and zeroes an
/// element's declared length before reading it, so a crafted 1 KB file
/// could otherwise take seconds and gigabytes to be refused. The binaries
/// declare it `#[global_allocator]` (`src/main.rs`, the fuzzer, the fuzz
/// tests); elsewhere the cap is not enforced.
pub struct CappedAlloc;

fn cap() -> usize {
    CAP.try_with(Cell::get).unwrap_or(usize::MAX)
}

// SAFETY: every call goes to `System` unchanged, or returns null, which
// the GlobalAlloc contract allows for any request.
unsafe impl GlobalAlloc for CappedAlloc {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        if l.size() > cap() {
            return std::ptr::null_mut();
        }
        System.alloc(l)
    }
    // Not capped: a zeroed allocation (`vec![0; n]`, which cannot fail
    // gracefully) is mapped lazily and costs nothing until it is touched;
    // dicom-rs sizes its RLE segment table so from a crafted count.
    unsafe fn alloc_zeroed(&self, l: Layout) -> *mut u8 {
        System.alloc_zeroed(l)
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, size: usize) -> *mut u8 {
        if size > cap() {
            return std::ptr::null_mut();
        }
        System.realloc(p, l, size)
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        System.dealloc(p, l)
    }
}

/// Runs `f`, a call into a decoder; its panic is an error: `{label}: {what}
/// failed on this file: …`. No single allocation of its may exceed
/// `max_bytes` (with [`CappedAlloc`]).
pub fn contained<T>(
    label: &str,
    what: &str,
    max_bytes: usize,
    f: impl FnOnce() -> Result<T>,
) -> Result<T> {
    DEPTH.with(|d| d.set(d.get() + 1));
    let before = CAP.with(|c| c.replace(max_bytes.min(c.get())));
    let r = catch_unwind(AssertUnwindSafe(f));
    CAP.with(|c| c.set(before));
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
