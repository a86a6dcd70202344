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
use parallax_common::tools::{EnhancerKind, EnhancerSpec, MAX_ENHANCERS};
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
    (
        "layers",
        include_str!("../../../shaders/shared/layers.wgsl"),
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

/// The enhancers' WGSL files (every `shaders/enhancers/*.wgsl`, listed by
/// `backend/build.rs`), by the name their [`EnhancerSpec`] declares:
/// templates whose `ENH_` names and `ENH_INDEX` are replaced per instance.
/// An enhancer that reads the gradient or the importance also defines
/// `ENH_active(smp) -> bool`, where it acts: the kernel computes those
/// inputs only there.
const ENHANCER_FILES: &[(&str, &str)] = include!(concat!(env!("OUT_DIR"), "/enhancers.rs"));

fn enhancer_source(kind: EnhancerKind) -> &'static str {
    let name = kind.spec().name;
    ENHANCER_FILES
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, src)| *src)
        .unwrap_or_else(|| panic!("shaders/enhancers/{name}.wgsl is not in ENHANCER_FILES"))
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
    "TOOL_TILES",
    "REFINE",
    "REFINE_DEPTH",
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
    /// Registered layers combined with the volume (DVR only; at most
    /// [`parallax_common::config::MAX_LAYERS`]): shared/layers.wgsl.
    pub layers: u32,
    /// Every layer's table allows pre-integrating from the segments' ends
    /// (`TfTable::layers_end_path`): five reads a sample and layer.
    pub layer_end: bool,
    /// Which layers are label layers (bit k: layer k), read at the nearest
    /// voxel with each label's own optics; 0 compiles none of that in.
    pub labels: u32,
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
        let mut out = Self::with_steppers(&chains);
        for layers in 1..=parallax_common::config::MAX_LAYERS as u32 {
            for layer_end in [false, true] {
                for mimda in [false, true] {
                    for labels in 0..1u32 << layers {
                        out.extend(chains.iter().map(|e| KernelKey {
                            enhancers: e.clone(),
                            layers,
                            layer_end,
                            mimda,
                            labels,
                            ..Default::default()
                        }));
                    }
                }
            }
        }
        out
    }

    /// The combinations the naga test compiles: every stepper with no
    /// enhancer, each kind alone and each kind filling the chain, and with
    /// DVR and with MImDA and refraction every ordered pair of kinds. Each
    /// enhancer is instantiated under its own names and meets the others
    /// only through the chain's constants (the OR of their declarations)
    /// and the order of calls, so the pairs meet every interaction of two
    /// kinds and the full chains every slot, without the 8³ chains × 5
    /// steppers of [`KernelKey::all`].
    pub fn covering() -> Vec<KernelKey> {
        let mut chains: Vec<Vec<EnhancerKind>> = vec![vec![]];
        for k in EnhancerKind::ALL {
            chains.push(vec![k]);
            chains.push(vec![k; MAX_ENHANCERS]);
        }
        let mut out = Self::with_steppers(&chains);
        // Registered layers, from their tables' ends or not, with DVR and
        // MImDA, alone and under a clip plane and a probe; and label
        // layers among them.
        for layers in 1..=parallax_common::config::MAX_LAYERS as u32 {
            for mimda in [false, true] {
                out.push(KernelKey {
                    layers,
                    labels: 1 << (layers - 1),
                    mimda,
                    ..Default::default()
                });
            }
        }
        for layers in 1..=parallax_common::config::MAX_LAYERS as u32 {
            for layer_end in [false, true] {
                for mimda in [false, true] {
                    for enhancers in [vec![], vec![EnhancerKind::ClipPlane, EnhancerKind::Probe]] {
                        out.push(KernelKey {
                            layers,
                            layer_end,
                            mimda,
                            enhancers,
                            ..Default::default()
                        });
                    }
                }
            }
        }
        // The pass-through compiles to nothing and the gradient diagnostic
        // only reads: under MImDA with refraction their pairs meet nothing
        // that DVR's pairs and their full chains have not.
        let plain = |k: &EnhancerKind| {
            !matches!(
                k,
                EnhancerKind::PassThrough | EnhancerKind::GradientDirection
            )
        };
        for (mimda, refraction) in [(false, false), (true, true)] {
            let kinds: Vec<EnhancerKind> = EnhancerKind::ALL
                .into_iter()
                .filter(|k| !mimda || plain(k))
                .collect();
            for &a in &kinds {
                for &b in &kinds {
                    out.push(KernelKey {
                        mimda,
                        refraction,
                        enhancers: vec![a, b],
                        ..Default::default()
                    });
                }
            }
        }
        out
    }

    /// DVR and MImDA, each with refraction off and on, and the isosurface,
    /// with each of `chains`.
    fn with_steppers(chains: &[Vec<EnhancerKind>]) -> Vec<KernelKey> {
        let mut out = Vec::new();
        for mimda in [false, true] {
            for refraction in [false, true] {
                for e in chains {
                    out.push(KernelKey {
                        mimda,
                        refraction,
                        enhancers: e.clone(),
                        ..Default::default()
                    });
                }
            }
        }
        for e in chains {
            out.push(KernelKey {
                iso: true,
                enhancers: e.clone(),
                ..Default::default()
            });
        }
        out
    }

    /// The declarations of the chain's enhancers.
    fn specs(&self) -> impl Iterator<Item = &'static EnhancerSpec> + '_ {
        self.enhancers.iter().map(|k| k.spec())
    }

    /// Whether a segment with τ̄ = 0 adds exactly nothing to a ray, so that
    /// the kernel may step over empty macrocells and leave out tiles whose
    /// rays meet no data: DVR and MImDA (whose largest importance counts
    /// only segments with extinction) with enhancers that add no opacity.
    /// Refraction bends rays in empty space too, and the isosurface stepper
    /// looks for its value, not for extinction.
    pub fn skips_empty_space(&self) -> bool {
        !self.refraction && !self.iso && self.specs().all(|s| !s.needs.adds_opacity)
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
        if self.layers > 0 && (self.iso || self.refraction) {
            bail!("registered layers are combined by the DVR and MImDA steppers only");
        }
        if self.layers as usize > parallax_common::config::MAX_LAYERS {
            bail!(
                "{} layers: the kernel combines at most {}",
                self.layers,
                parallax_common::config::MAX_LAYERS
            );
        }
        let any = |f: fn(&EnhancerSpec) -> bool| self.specs().any(f);
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
        let _ = writeln!(s, "const LAYERS: u32 = {}u;", self.layers);
        let _ = writeln!(s, "const MIMDA: bool = {};", self.mimda);
        let _ = writeln!(s, "const LAYER_END: bool = {};", self.layer_end);
        let _ = writeln!(s, "const LABELS: u32 = {}u;", self.labels);
        let _ = writeln!(s, "const HAS_BREAKS: bool = {};", any(|e| e.needs.breaks));
        let _ = writeln!(
            s,
            "const MODIFIES_OPTICS: bool = {};",
            any(|e| e.needs.optics)
        );
        let _ = writeln!(
            s,
            "const NEEDS_AUX: bool = {};",
            self.mimda || self.refraction
        );
        let _ = writeln!(s, "const REFRACTION: bool = {};", self.refraction);
        // The gradient costs six samples and the importance a table read:
        // computed before the enhancers only where one that reads them is
        // active (shading computes its own gradient otherwise).
        let _ = writeln!(
            s,
            "const NEEDS_GRADIENT: bool = {};",
            any(|e| e.needs.gradient)
        );
        let _ = writeln!(s, "const TOOL_AUX: bool = {};", any(|e| e.needs.importance));
        let _ = writeln!(
            s,
            "const COARSE_GRADIENTS: bool = {};",
            any(|e| e.needs.coarse_gradients)
        );
        let _ = writeln!(s, "const TOOL_SHADES: bool = {};", any(|e| e.needs.shades));
        let _ = writeln!(
            s,
            "const TOOL_IMPORTANCE: bool = {};",
            any(|e| e.needs.sets_importance)
        );
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
        let active: Vec<String> = self
            .specs()
            .enumerate()
            .filter(|(_, e)| e.needs.gradient || e.needs.importance || e.needs.coarse_gradients)
            .map(|(i, _)| format!("enh{i}_active(smp)"))
            .collect();
        let _ = writeln!(
            s,
            "fn chain_active(smp: ptr<function, Sample>) -> bool {{\n    return {};\n}}",
            if active.is_empty() {
                "false".to_string()
            } else {
                active.join(" || ")
            }
        );
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

    /// The covering combinations of stepper and enhancers
    /// ([`KernelKey::covering`]), composed as their pipelines get them,
    /// parse and validate; so do their override values, specialised as the
    /// device would (all combinations but in the last override, which meets
    /// each value of the others), for the empty and the full chains.
    #[test]
    fn every_kernel_combination_validates_without_a_gpu() {
        let keys = KernelKey::covering();
        let kinds = EnhancerKind::ALL.len();
        // (DVR/MImDA × refraction off/on, and the isosurface) × (no
        // enhancer, each kind alone, each kind three times), every ordered
        // pair under DVR and those of all but two under MImDA with
        // refraction; and 1–3 layers (from their ends or not, DVR or MImDA,
        // alone or under a clip plane and a probe; the last a label layer,
        // DVR or MImDA).
        assert_eq!(
            keys.len(),
            (2 * 2 + 1) * (1 + 2 * kinds)
                + 10 * parallax_common::config::MAX_LAYERS
                + kinds * kinds
                + (kinds - 2) * (kinds - 2)
        );
        // Spread over the cores: naga is single-threaded.
        let threads = std::thread::available_parallelism().map_or(2, |n| n.get());
        std::thread::scope(|scope| {
            for t in 0..threads {
                let keys = &keys;
                scope.spawn(move || {
                    for key in keys.iter().skip(t).step_by(threads) {
                        validate_key(key);
                    }
                });
            }
        });
    }

    /// One kernel of [`every_kernel_combination_validates_without_a_gpu`]
    /// and, for the empty and full chains, its override values.
    fn validate_key(key: &KernelKey) {
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
        // kernels: every combination of all but the last two, which
        // follow from the others' values (below), so that each meets
        // both values of every other override and every pair of them. The
        // three pre-integration paths, of which a pipeline sets at most
        // one, count as one override of four values (two bits), and
        // TF_PIECES, a count, takes its largest value (the whole
        // uniform array), REFINE_DEPTH its one value.
        const PATHS: [&str; 3] = ["END_PREINT", "GRID_PREINT", "ANALYTIC_PREINT"];
        // Overrides that are values, not flags: each gets the pipeline's.
        const VALUES: [&str; 2] = ["TF_PIECES", "REFINE_DEPTH"];
        if (key.enhancers.len() == MAX_ENHANCERS || key.enhancers.is_empty()) && key.layers == 0 {
            let flags: Vec<&str> = OVERRIDES
                .iter()
                .copied()
                .filter(|n| !VALUES.contains(n) && !PATHS.contains(n))
                .collect();
            // The path's two bits come first, then the flags. The last
            // two flags follow from the others: the last is their parity,
            // the one before it that parity flipped by the first bit.
            // Each flag still meets both values of every other, and every
            // pair of them all four combinations, in half the runs.
            let n = 2 + flags.len() - 2;
            for bits in 0..1u32 << n {
                let mut constants = naga::back::PipelineConstants::default();
                let parity = bits.count_ones() & 1;
                let bits = bits | (parity ^ (bits & 1)) << n | parity << (n + 1);
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
                constants.insert("REFINE_DEPTH".to_string(), crate::raycast::REFINE_DEPTH);
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

    /// The chain's constants follow from the enhancers' declarations: the
    /// probe reads the gradient and importance where it is active, the clip
    /// plane neither; only an enhancer that adds opacity costs the kernel
    /// its skipping of empty space.
    #[test]
    fn declarations_set_the_chain_constants() {
        let key = |e: Vec<EnhancerKind>| KernelKey {
            enhancers: e,
            ..Default::default()
        };
        let clip = key(vec![EnhancerKind::ClipPlane]).chain_module().unwrap();
        assert!(clip.contains("const NEEDS_GRADIENT: bool = false;"));
        assert!(clip.contains("const HAS_BREAKS: bool = true;"));
        assert!(clip.contains("return false;"));
        let probe = key(vec![EnhancerKind::PassThrough, EnhancerKind::Probe])
            .chain_module()
            .unwrap();
        assert!(probe.contains("const NEEDS_GRADIENT: bool = true;"));
        assert!(probe.contains("const TOOL_AUX: bool = true;"));
        assert!(probe.contains("return enh1_active(smp);"));
        assert!(key(vec![EnhancerKind::ClipPlane, EnhancerKind::Probe]).skips_empty_space());
        assert!(!key(vec![EnhancerKind::ExitDirection]).skips_empty_space());
        assert!(!KernelKey {
            refraction: true,
            ..Default::default()
        }
        .skips_empty_space());
        // Every declared kind has its file, and the order of ENHANCERS is
        // EnhancerKind's.
        for (i, k) in EnhancerKind::ALL.iter().enumerate() {
            assert_eq!(parallax_common::tools::ENHANCERS[i].kind, *k);
            assert!(enhancer_source(*k).contains("fn ENH_sample("));
        }
        assert_eq!(ENHANCER_FILES.len(), EnhancerKind::ALL.len());
    }

    /// Every module and enhancer file is used by some combination (none can
    /// rot unseen), and a bad import is an error.
    #[test]
    fn every_module_is_used() {
        let all: Vec<String> = KernelKey::covering()
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
        use super::super::params::{GpuFrame, GpuView, LayerParams, ToolParams};
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
        check!("LayerParams", LayerParams, [table, at, axis, angles, aux]);
        // The closed form's buffer: its header and MAX_PIECES pieces.
        let (span, _) = layout("TfPieces");
        assert_eq!(
            span as usize,
            size_of::<parallax_common::tf::closed::GpuPieces>(),
            "TfPieces size"
        );
    }
}
