//! The kernel's pipelines: one per combination of stepper, enhancers and
//! override values a frame has used (G10 §5), built on first use.

use super::{shader, KernelKey, Raycaster};
use crate::gpu::Gpu;
use anyhow::Result;

impl Raycaster {
    /// The pipeline of a kernel combination, built on first use.
    pub(super) fn pipeline(
        &mut self,
        gpu: &Gpu,
        kernel: &KernelKey,
        flags: [bool; 12],
        tf_pieces: u32,
    ) -> Result<&wgpu::ComputePipeline> {
        let [shading, no_data, macrocells, count, multilevel, tricubic, end_preint, grid_preint, analytic_preint, lookahead, tool_tiles, refine] =
            flags;
        let key = (kernel.clone(), flags, tf_pieces);
        if !self.pipelines.contains_key(&key) {
            let source = shader::kernel(kernel)?;
            let module = gpu.validated("shaders/raycast.wgsl", || {
                gpu.device
                    .create_shader_module(wgpu::ShaderModuleDescriptor {
                        label: Some("raycast.wgsl"),
                        source: wgpu::ShaderSource::Wgsl(source.into()),
                    })
            })?;
            let flag = |b: bool| if b { 1.0 } else { 0.0 };
            let constants = [
                ("SHADING", flag(shading)),
                // Hardware filtering would blend the no-data value in.
                ("HW_FILTER", flag(self.hw_filter && !no_data)),
                ("NO_DATA", flag(no_data)),
                ("MACROCELLS", flag(macrocells)),
                ("COUNT_SAMPLES", flag(count)),
                ("MULTILEVEL", flag(multilevel)),
                ("TRICUBIC", flag(tricubic)),
                ("END_PREINT", flag(end_preint)),
                ("GRID_PREINT", flag(grid_preint)),
                ("ANALYTIC_PREINT", flag(analytic_preint)),
                // The closed form's pieces: a constant, so that their loop
                // unrolls (a pipeline per count, at most 17).
                ("TF_PIECES", tf_pieces as f64),
                // Sample values fetched one pass ahead (the kernel's
                // LOOKAHEAD): set for float pools read with the 2D table,
                // where the pool's wait for memory overlaps the table's
                // fetch, or with the closed form, where it overlaps the
                // arithmetic (docs/performance.md, "Kernel changes on a CPU device").
                ("LOOKAHEAD", flag(lookahead)),
                // The variant for the tiles that meet a tool's region: only
                // it computes what the enhancers read (`tiles::flag_regions`).
                ("TOOL_TILES", flag(tool_tiles)),
                // Opaque-segment refinement compiled in (`Raycaster::kernel`
                // says where a segment can be optically thick).
                ("REFINE", flag(refine)),
                // The optical depth above which a segment is refined: one
                // definition for the kernel, `can_be_opaque` and the loader.
                ("REFINE_DEPTH", super::REFINE_DEPTH),
                // A tap at or above this is a no-data voxel: the top code of
                // an 8-bit pool, NO_DATA_VALUE in a float pool.
                (
                    "NO_DATA_TAP",
                    if self.float_pool {
                        1.0e38
                    } else {
                        254.5 / 255.0
                    },
                ),
            ];
            let p = gpu.validated("ray casting pipeline", || {
                gpu.device
                    .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                        label: Some("raycast"),
                        layout: Some(&self.pipeline_layout),
                        module: &module,
                        entry_point: Some("main"),
                        compilation_options: wgpu::PipelineCompilationOptions {
                            constants: &constants,
                            ..Default::default()
                        },
                        cache: None,
                    })
            })?;
            self.pipelines.insert(key.clone(), p);
        }
        Ok(&self.pipelines[&key])
    }
}
