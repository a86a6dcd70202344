//! The ray-casting shaders as WGSL modules (the way vello organises its
//! shaders): shared modules in `shaders/shared/` — bindings, the sample
//! state, pre-integration, sampling, traversal, compositing — steppers in
//! `shaders/steppers/`, enhancers in `shaders/enhancers/`, and the kernel
//! `shaders/raycast.wgsl`, which pulls modules in with `#import <name>` lines.
//!
//! G10 §5 "Custom compositing behavior": one kernel per combination of
//! stepper and enhancers. [`KernelKey`] names a combination; [`kernel`]
//! composes its source: the `chain` module is written for the key (the
//! stepper, the enhancers instantiated in chain order, and constants that
//! leave out what the combination does not need), then every `#import` is
//! resolved, each module once. A test parses and validates every
//! combination a scene can ask for with naga, without a GPU, and checks the
//! Rust mirrors of GPU structs against naga's layout.

use anyhow::{bail, Context, Result};
use parallax_common::tools::{EnhancerKind, MAX_ENHANCERS};
use std::fmt::Write;
use std::path::Path;

/// The importable modules, by name.
pub const MODULES: &[(&str, &str)] = &[
    (
        "bindings",
        include_str!("../../../shaders/shared/bindings.wgsl"),
    ),
    (
        "sample",
        include_str!("../../../shaders/shared/sample.wgsl"),
    ),
    (
        "preint",
        include_str!("../../../shaders/shared/preint.wgsl"),
    ),
    (
        "sampling",
        include_str!("../../../shaders/shared/sampling.wgsl"),
    ),
    (
        "traversal",
        include_str!("../../../shaders/shared/traversal.wgsl"),
    ),
    (
        "composite",
        include_str!("../../../shaders/shared/composite.wgsl"),
    ),
    ("dvr", include_str!("../../../shaders/steppers/dvr.wgsl")),
    ("iso", include_str!("../../../shaders/steppers/iso.wgsl")),
    (
        "mimda",
        include_str!("../../../shaders/steppers/mimda.wgsl"),
    ),
    (
        "refraction",
        include_str!("../../../shaders/steppers/refraction.wgsl"),
    ),
];

/// The enhancers, by kind: templates whose `ENH_` names and `ENH_INDEX`
/// are replaced per instance.
fn enhancer_source(kind: EnhancerKind) -> &'static str {
    match kind {
        EnhancerKind::PassThrough => include_str!("../../../shaders/enhancers/pass-through.wgsl"),
        EnhancerKind::ClipPlane => include_str!("../../../shaders/enhancers/clip-plane.wgsl"),
        EnhancerKind::ExitDirection => {
            include_str!("../../../shaders/enhancers/exit-direction.wgsl")
        }
    }
}

const KERNEL: &str = include_str!("../../../shaders/raycast.wgsl");

/// The pipeline-overridable constants of the kernel (each is also part of
/// a pipeline's identity).
pub const OVERRIDES: &[&str] = &[
    "SHADING",
    "HW_FILTER",
    "NO_DATA",
    "NO_DATA_TAP",
    "MACROCELLS",
    "COUNT_SAMPLES",
    "MULTILEVEL",
    "TRICUBIC",
    "END_PREINT",
    "GRID_PREINT",
    "ANALYTIC_PREINT",
    "TF_PIECES",
    "LOOKAHEAD",
];

/// One specialised kernel: the stepper and the enhancer chain.
#[derive(Clone, Debug, Default, PartialEq, Eq, Hash)]
pub struct KernelKey {
    /// MImDA compositing (G10 Eq. 3) instead of plain DVR.
    pub mimda: bool,
    /// Continuous refraction (G10 §4).
    pub refraction: bool,
    /// Isosurface stepper (G08 §5.3): the first crossing of the isovalue,
    /// shaded; excludes MImDA and refraction.
    pub iso: bool,
    /// Enhancers in chain order (at most [`MAX_ENHANCERS`]).
    pub enhancers: Vec<EnhancerKind>,
}

impl KernelKey {
    /// Every combination a scene can ask for.
    pub fn all() -> Vec<KernelKey> {
        let mut chains: Vec<Vec<EnhancerKind>> = vec![vec![]];
        let mut last = vec![vec![]];
        for _ in 0..MAX_ENHANCERS {
            let next: Vec<Vec<EnhancerKind>> = last
                .iter()
                .flat_map(|c: &Vec<EnhancerKind>| {
                    EnhancerKind::ALL.iter().map(move |&k| {
                        let mut c = c.clone();
                        c.push(k);
                        c
                    })
                })
                .collect();
            chains.extend(next.iter().cloned());
            last = next;
        }
        let mut out = Vec::new();
        for mimda in [false, true] {
            for refraction in [false, true] {
                for e in &chains {
                    out.push(KernelKey {
                        mimda,
                        refraction,
                        iso: false,
                        enhancers: e.clone(),
                    });
                }
            }
        }
        for e in &chains {
            out.push(KernelKey {
                iso: true,
                enhancers: e.clone(),
                ..Default::default()
            });
        }
        out
    }

    /// Plain DVR: no MImDA, refraction or isosurface, and every enhancer a
    /// pass-through. Such a kernel adds nothing where a ray meets no data.
    pub fn is_plain(&self) -> bool {
        !self.mimda
            && !self.refraction
            && !self.iso
            && self
                .enhancers
                .iter()
                .all(|&e| e == EnhancerKind::PassThrough)
    }

    /// The `chain` module of this combination.
    pub fn chain_module(&self) -> Result<String> {
        if self.enhancers.len() > MAX_ENHANCERS {
            bail!(
                "{} enhancers: at most {MAX_ENHANCERS} can be chained",
                self.enhancers.len()
            );
        }
        if self.iso && (self.mimda || self.refraction) {
            bail!("the isosurface stepper takes neither MImDA nor refraction");
        }
        let has = |k: EnhancerKind| self.enhancers.contains(&k);
        let clip = has(EnhancerKind::ClipPlane);
        let mut s = String::new();
        let _ = writeln!(
            s,
            "// The chain of this pipeline: {} stepper, refraction {}, enhancers {:?}.",
            if self.iso {
                "isosurface"
            } else if self.mimda {
                "MImDA"
            } else {
                "DVR"
            },
            if self.refraction { "on" } else { "off" },
            self.enhancers
        );
        s.push_str("#import sample\n#import composite\n#import refraction\n");
        s.push_str(if self.mimda {
            "#import mimda\n"
        } else {
            "#import dvr\n"
        });
        s.push_str("#import iso\n");
        let _ = writeln!(s, "const ISO: bool = {};", self.iso);
        let _ = writeln!(s, "const HAS_BREAKS: bool = {clip};");
        let _ = writeln!(s, "const MODIFIES_OPTICS: bool = {clip};");
        let _ = writeln!(
            s,
            "const NEEDS_AUX: bool = {};",
            self.mimda || self.refraction
        );
        let _ = writeln!(s, "const REFRACTION: bool = {};", self.refraction);
        // The gradient costs six samples: computed before the enhancers only
        // when one of them reads it (shading computes its own otherwise).
        let gradient = self
            .enhancers
            .iter()
            .any(|&k| enhancer_source(k).contains(".gradient"));
        let _ = writeln!(s, "const NEEDS_GRADIENT: bool = {gradient};");
        for (i, &k) in self.enhancers.iter().enumerate() {
            let text = enhancer_source(k)
                .replace("ENH_INDEX", &format!("{i}u"))
                .replace("ENH_", &format!("enh{i}_"));
            s.push_str(&text);
        }
        let calls = |stage: &str, args: &str| -> String {
            (0..self.enhancers.len())
                .map(|i| format!("    enh{i}_{stage}({args});\n"))
                .collect()
        };
        let _ = write!(
            s,
            "fn chain_start(ray: ptr<function, Ray>) {{\n{}}}\n\
             fn chain_sample(smp: ptr<function, Sample>) {{\n{}}}\n\
             fn chain_end(ray: ptr<function, Ray>, acc: ptr<function, Acc>) {{\n{}}}\n",
            calls("start", "ray"),
            calls("sample", "smp"),
            calls("end", "ray, acc")
        );
        Ok(s)
    }
}

/// `src` with every `#import name` line replaced by that module (and the
/// modules it imports), each module included once; `extra` adds modules
/// (the generated chain).
pub fn compose(name: &str, src: &str, extra: &[(&str, &str)]) -> Result<String> {
    let mut out = String::with_capacity(src.len() * 4);
    let mut done = Vec::new();
    expand(name, src, extra, &mut done, &mut Vec::new(), &mut out)?;
    Ok(out)
}

fn expand<'a>(
    name: &'a str,
    src: &'a str,
    extra: &[(&'a str, &'a str)],
    done: &mut Vec<&'a str>,
    stack: &mut Vec<&'a str>,
    out: &mut String,
) -> Result<()> {
    stack.push(name);
    for line in src.lines() {
        let Some(module) = line.trim().strip_prefix("#import ") else {
            out.push_str(line);
            out.push('\n');
            continue;
        };
        let module = module.trim();
        if done.contains(&module) {
            continue;
        }
        if stack.contains(&module) {
            bail!(
                "{name}: `#import {module}` is circular ({})",
                stack.join(" → ")
            );
        }
        let Some(&(m, text)) = MODULES
            .iter()
            .chain(extra.iter())
            .find(|(n, _)| *n == module)
        else {
            bail!("{name}: `#import {module}`: no such module");
        };
        expand(m, text, extra, done, stack, out)?;
        done.push(m);
    }
    stack.pop();
    Ok(())
}

/// The composed source of a kernel combination.
///
/// With `PARALLAX_KERNEL_DUMP=<path>` the composed source is also written
/// there (for reading what a combination compiles to, and for
/// `bench/kernel_profile.sh`). Variants of a kernel are made through its
/// [`KernelKey`] and the override constants, never by patching the text.
pub fn kernel(key: &KernelKey) -> Result<String> {
    let chain = key.chain_module()?;
    let src = compose("raycast.wgsl", KERNEL, &[("chain", &chain)])?;
    if let Some(path) = std::env::var_os("PARALLAX_KERNEL_DUMP") {
        std::fs::write(&path, &src).with_context(|| {
            format!(
                "PARALLAX_KERNEL_DUMP: writing {}",
                Path::new(&path).display()
            )
        })?;
    }
    Ok(src)
}

#[cfg(test)]
mod tests {
    use super::*;
    use wgpu::naga;

    fn parse(what: &str, src: &str) -> naga::Module {
        naga::front::wgsl::parse_str(src)
            .unwrap_or_else(|e| panic!("{what}:\n{}", e.emit_to_string(src)))
    }

    fn validate(what: &str, src: &str, m: &naga::Module) -> naga::valid::ModuleInfo {
        naga::valid::Validator::new(
            naga::valid::ValidationFlags::all(),
            naga::valid::Capabilities::all(),
        )
        .validate(m)
        .unwrap_or_else(|e| panic!("{what}:\n{}", e.emit_to_string(src)))
    }

    /// Every combination of stepper and enhancers a scene can ask for,
    /// composed as its pipeline gets it, parses and validates; so do its
    /// override values, specialised as the device would (all combinations
    /// but in the last override, which meets each value of the others).
    #[test]
    fn every_kernel_combination_validates_without_a_gpu() {
        let keys = KernelKey::all();
        // (DVR/MImDA × refraction off/on, and the isosurface) × chains of
        // 0–3 of 3 kinds.
        assert_eq!(keys.len(), (2 * 2 + 1) * (1 + 3 + 9 + 27));
        for key in &keys {
            let what = format!("{key:?}");
            let src = kernel(key).unwrap();
            let module = parse(&what, &src);
            let info = validate(&what, &src, &module);
            for (_, o) in module.overrides.iter() {
                let name = o.name.clone().unwrap();
                assert!(
                    OVERRIDES.contains(&name.as_str()),
                    "override {name} is not listed"
                );
            }
            // The override combinations of the plain and the fullest
            // kernels: every combination of all but the last, which takes
            // the parity of the others' values, so that it meets both
            // values of every other override and every pair of them. The
            // three pre-integration paths, of which a pipeline sets at most
            // one, count as one override of four values (two bits), and
            // TF_PIECES, a count, takes its largest value (the whole
            // uniform array).
            const PATHS: [&str; 3] = ["END_PREINT", "GRID_PREINT", "ANALYTIC_PREINT"];
            if key.enhancers.len() == MAX_ENHANCERS || key.enhancers.is_empty() {
                let flags: Vec<&str> = OVERRIDES
                    .iter()
                    .copied()
                    .filter(|n| *n != "TF_PIECES" && !PATHS.contains(n))
                    .collect();
                // The path's two bits come first, then the flags.
                let n = 2 + flags.len() - 1;
                for bits in 0..1u32 << n {
                    let mut constants = naga::back::PipelineConstants::default();
                    let bits = bits | (bits.count_ones() & 1) << n;
                    for (i, p) in PATHS.iter().enumerate() {
                        constants.insert(p.to_string(), f64::from(bits & 3 == i as u32 + 1));
                    }
                    for (i, f) in flags.iter().enumerate() {
                        constants.insert(f.to_string(), ((bits >> (i + 2)) & 1) as f64);
                    }
                    constants.insert(
                        "TF_PIECES".to_string(),
                        parallax_common::tf::closed::MAX_PIECES as f64,
                    );
                    let (m, _) = naga::back::pipeline_constants::process_overrides(
                        &module,
                        &info,
                        Some((naga::ShaderStage::Compute, "main")),
                        &constants,
                    )
                    .unwrap_or_else(|e| panic!("{what} {constants:?}: {e}"));
                    validate(&what, &src, &m);
                }
            }
        }
    }

    /// The path where an enhancer reads the gradient (none of today's does)
    /// validates too.
    #[test]
    fn the_gradient_path_validates() {
        let key = KernelKey {
            enhancers: vec![EnhancerKind::ClipPlane],
            ..Default::default()
        };
        let src = kernel(&key).unwrap();
        assert!(src.contains("const NEEDS_GRADIENT: bool = false;"));
        let src = src.replace(
            "const NEEDS_GRADIENT: bool = false;",
            "const NEEDS_GRADIENT: bool = true;",
        );
        validate("gradient", &src, &parse("gradient", &src));
    }

    /// Every module and enhancer file is used by some combination (none can
    /// rot unseen), and a bad import is an error.
    #[test]
    fn every_module_is_used() {
        let all: Vec<String> = KernelKey::all()
            .iter()
            .map(|k| kernel(k).unwrap())
            .collect();
        for (name, text) in MODULES {
            let first = text.lines().find(|l| !l.trim().is_empty()).unwrap();
            assert!(
                all.iter().any(|k| k.contains(first)),
                "module {name} is in no kernel"
            );
        }
        for kind in EnhancerKind::ALL {
            let key = KernelKey {
                enhancers: vec![kind],
                ..Default::default()
            };
            assert!(kernel(&key).unwrap().contains("fn enh0_sample("));
        }
        assert!(compose("x", "#import nope\n", &[]).is_err());
        assert!(KernelKey {
            enhancers: vec![EnhancerKind::PassThrough; 4],
            ..Default::default()
        }
        .chain_module()
        .is_err());
    }

    /// The Rust mirrors of the GPU structs against naga's layout of the WGSL:
    /// the same size, and every field at the same offset.
    #[test]
    fn rust_mirrors_match_the_wgsl_layout() {
        use super::super::params::{GpuFrame, GpuView, ToolParams};
        use crate::index::IndexNode;
        use std::mem::{offset_of, size_of};
        let src = kernel(&KernelKey::default()).unwrap();
        let module = parse("raycast.wgsl", &src);
        let layout = |name: &str| -> (u32, Vec<(String, u32)>) {
            let ty = module
                .types
                .iter()
                .find(|(_, t)| t.name.as_deref() == Some(name))
                .unwrap_or_else(|| panic!("no struct {name}"))
                .1;
            match &ty.inner {
                naga::TypeInner::Struct { members, span } => (
                    *span,
                    members
                        .iter()
                        .map(|m| (m.name.clone().unwrap(), m.offset))
                        .collect(),
                ),
                _ => panic!("{name} is not a struct"),
            }
        };
        macro_rules! check {
            ($wgsl:literal, $rust:ty, [$($f:ident),* $(,)?]) => {{
                let (span, members) = layout($wgsl);
                assert_eq!(span as usize, size_of::<$rust>(), "{} size", $wgsl);
                let rust: Vec<(String, u32)> =
                    vec![$((stringify!($f).to_string(), offset_of!($rust, $f) as u32)),*];
                assert_eq!(members, rust, "{} fields and offsets", $wgsl);
            }};
        }
        check!("GpuView", GpuView, [region, eye, observer, size]);
        check!(
            "GpuFrame",
            GpuFrame,
            [
                rt0, rt1, rt2, center, extent, domain, spacing, tf, render, light, counts, pool,
                optics, aux, iso, predict, tf_offsets, tf_mids, lod, splits, dispatch, recip, grid
            ]
        );
        check!("IndexNode", IndexNode, [tree, data, range, nx, ny, nz]);
        check!("ToolParams", ToolParams, [a, b, c, d]);
        // The closed form's uniform: its header and MAX_PIECES pieces.
        let (span, _) = layout("TfPieces");
        assert_eq!(
            span as usize,
            size_of::<parallax_common::tf::closed::GpuPieces>(),
            "TfPieces size"
        );
    }
}
