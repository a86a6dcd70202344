//! Lists the enhancers' WGSL files (`shaders/enhancers/*.wgsl`) for the
//! kernel's composer: each is found by the name its kind declares in
//! `ENHANCERS` (common/src/tools.rs), so adding a kind adds no line here.

use std::fmt::Write;
use std::path::Path;

fn main() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shaders/enhancers");
    println!("cargo:rerun-if-changed={}", dir.display());
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .expect("shaders/enhancers/ is readable")
        .map(|e| e.expect("an entry of shaders/enhancers/").path())
        .filter(|p| p.extension().is_some_and(|e| e == "wgsl"))
        .collect();
    files.sort();
    let mut out = String::from("&[\n");
    for f in &files {
        let name = f.file_stem().expect("a file name").to_string_lossy();
        let path = f.canonicalize().expect("an enhancer's path");
        let _ = writeln!(
            out,
            "    ({name:?}, include_str!({:?})),",
            path.display().to_string()
        );
    }
    out.push(']');
    let dest = Path::new(&std::env::var("OUT_DIR").expect("OUT_DIR")).join("enhancers.rs");
    std::fs::write(dest, out).expect("writing the enhancers' list");
}
