//! The ray-casting shaders as WGSL modules (the way vello organises its
//! shaders): shared modules in `shaders/shared/` — bindings, pre-integration,
//! sampling, traversal, compositing — and one file per kernel in `shaders/`,
//! which pulls modules in with `#import <name>` lines. [`compose`] resolves
//! the imports exactly as the pipelines get them: each module once, where it
//! is first imported, its own imports first. A test parses and validates
//! every kernel and every override combination with naga without a GPU, and
//! checks the Rust mirrors of GPU structs against naga's layout.

use anyhow::{bail, Result};

/// The shared modules, by import name.
pub const MODULES: &[(&str, &str)] = &[
    (
        "bindings",
        include_str!("../../../shaders/shared/bindings.wgsl"),
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
];

/// The kernels: (file name, source).
pub const KERNELS: &[(&str, &str)] = &[(
    "raycast.wgsl",
    include_str!("../../../shaders/raycast.wgsl"),
)];

/// The pipeline-overridable constants of each kernel and the values a scene
/// can ask for: every combination is a pipeline the renderer may build.
pub const OVERRIDES: &[(&str, &[&str])] = &[("raycast.wgsl", &["SHADING", "HW_FILTER"])];

/// `src` with every `#import name` line replaced by that module (and the
/// modules it imports), each module included once.
pub fn compose(name: &str, src: &str) -> Result<String> {
    let mut out = String::with_capacity(src.len() * 4);
    let mut done = Vec::new();
    expand(name, src, &mut done, &mut Vec::new(), &mut out)?;
    Ok(out)
}

fn expand<'a>(
    name: &'a str,
    src: &'a str,
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
        let Some(&(m, text)) = MODULES.iter().find(|(n, _)| *n == module) else {
            bail!("{name}: `#import {module}`: no module shaders/shared/{module}.wgsl");
        };
        expand(m, text, done, stack, out)?;
        done.push(m);
    }
    stack.pop();
    Ok(())
}

/// A kernel's composed source, by file name.
pub fn kernel(file: &str) -> Result<String> {
    match KERNELS.iter().find(|(n, _)| *n == file) {
        Some((n, src)) => compose(n, src),
        None => bail!("no kernel shaders/{file}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use wgpu::naga;

    fn parse(file: &str, src: &str) -> naga::Module {
        naga::front::wgsl::parse_str(src)
            .unwrap_or_else(|e| panic!("{file}:\n{}", e.emit_to_string(src)))
    }

    fn validate(file: &str, src: &str, m: &naga::Module) -> naga::valid::ModuleInfo {
        naga::valid::Validator::new(
            naga::valid::ValidationFlags::all(),
            naga::valid::Capabilities::all(),
        )
        .validate(m)
        .unwrap_or_else(|e| panic!("{file}:\n{}", e.emit_to_string(src)))
    }

    /// Every kernel, composed as the pipelines get it, parses and validates;
    /// so does every combination of its override values, specialised as
    /// the device would.
    #[test]
    fn every_kernel_and_override_combination_validates_without_a_gpu() {
        for (file, _) in KERNELS {
            let src = kernel(file).unwrap();
            let module = parse(file, &src);
            let info = validate(file, &src, &module);
            let names = OVERRIDES.iter().find(|(k, _)| k == file).unwrap().1;
            for (name, _) in module.overrides.iter().map(|(_, o)| (o.name.clone(), ())) {
                let name = name.unwrap();
                assert!(
                    names.contains(&name.as_str()),
                    "{file}: override {name} is not listed"
                );
            }
            for bits in 0..1u32 << names.len() {
                let mut constants = naga::back::PipelineConstants::default();
                for (i, n) in names.iter().enumerate() {
                    constants.insert(n.to_string(), ((bits >> i) & 1) as f64);
                }
                let (m, _) = naga::back::pipeline_constants::process_overrides(
                    &module,
                    &info,
                    Some((naga::ShaderStage::Compute, "main")),
                    &constants,
                )
                .unwrap_or_else(|e| panic!("{file} {constants:?}: {e}"));
                validate(file, &src, &m);
            }
        }
    }

    /// Every shared module is imported by some kernel (none can rot unseen)
    /// and parses on its own with its imports.
    #[test]
    fn every_module_is_used_and_stands_with_its_imports() {
        for (name, text) in MODULES {
            let used = KERNELS
                .iter()
                .any(|(_, k)| k.lines().any(|l| l.trim() == format!("#import {name}")));
            assert!(used, "shaders/shared/{name}.wgsl is imported by no kernel");
            let src = compose(name, text).unwrap();
            // A module alone may use a kernel's override (none does today)
            // but must parse.
            parse(name, &src);
        }
        assert!(compose("x", "#import nope\n").is_err());
    }

    /// The Rust mirrors of the GPU structs against naga's layout of the WGSL:
    /// the same size, and every field at the same offset.
    #[test]
    fn rust_mirrors_match_the_wgsl_layout() {
        use super::super::params::{GpuFrame, GpuView};
        use crate::index::IndexNode;
        use std::mem::{offset_of, size_of};
        let src = kernel("raycast.wgsl").unwrap();
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
                tf_offsets
            ]
        );
        check!("IndexNode", IndexNode, [tree, data, range, nx, ny, nz]);
    }
}
