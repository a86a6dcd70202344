//! The coverage-guided fuzzer of every parser (libFuzzer): the parser is
//! chosen by `PARALLAX_FUZZ` (one of `parallax_fuzz::TARGETS`);
//! `scripts/fuzz.sh` builds it with coverage instrumentation and runs it.
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::sync::OnceLock;

fn target() -> &'static str {
    static T: OnceLock<String> = OnceLock::new();
    T.get_or_init(|| {
        std::env::var("PARALLAX_FUZZ")
            .unwrap_or_else(|_| panic!("set PARALLAX_FUZZ to one of {:?}", parallax_fuzz::TARGETS))
    })
}

#[global_allocator]
static ALLOC: parallax_backend::data::CappedAlloc = parallax_backend::data::CappedAlloc;

fuzz_target!(|data: &[u8]| {
    parallax_fuzz::run(target(), data);
});
