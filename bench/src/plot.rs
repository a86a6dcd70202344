//! The work–precision plot of [`crate::sweep`].

use crate::sweep::Point;
use anyhow::Result;
use std::path::Path;

/// RMSE (log) against frame time, one series per knob, as SVG.
pub fn work_precision(path: &Path, points: &[Point]) -> Result<()> {
    use plotters::prelude::*;
    let root = SVGBackend::new(path, (800, 560)).into_drawing_area();
    root.fill(&WHITE)?;
    let tmax = points.iter().map(|p| p.frame_ms).fold(1.0, f64::max) * 1.1;
    let emin = points.iter().map(|p| p.rmse.max(1e-7)).fold(1.0, f64::min) / 2.0;
    let emax = points.iter().map(|p| p.rmse).fold(1e-6, f64::max) * 2.0;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "error against the exact integral vs frame time",
            ("sans-serif", 20),
        )
        .margin(16)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(0.0..tmax, (emin..emax).log_scale())?;
    chart
        .configure_mesh()
        .x_desc("frame time (ms)")
        .y_desc("RMSE (premultiplied RGBA)")
        .draw()?;
    let series = [
        ("step_factor", "full", RED),
        (
            "step_factor_without_macrocells",
            "full",
            RGBColor(120, 120, 120),
        ),
        ("adaptive_step", "full", RGBColor(230, 140, 0)),
        ("multilevel", "full", RGBColor(0, 160, 160)),
        ("tricubic", "full", RGBColor(140, 70, 20)),
        ("preintegration_exact", "full", RGBColor(60, 60, 160)),
        ("preintegration_2d", "full", RGBColor(120, 0, 200)),
        ("preintegration_analytic", "full", RGBColor(200, 0, 120)),
        ("accuracy", "full", BLUE),
        ("early_termination", "full", GREEN),
        ("refinement", "full", RGBColor(200, 160, 0)),
        ("opaque_detail", "full", RGBColor(120, 60, 160)),
        ("step_factor", "8-bit", MAGENTA),
    ];
    for (knob, bricks, color) in series {
        let pts: Vec<(f64, f64)> = points
            .iter()
            .filter(|p| p.knob == knob && p.bricks == bricks)
            .map(|p| (p.frame_ms, p.rmse.max(1e-7)))
            .collect();
        chart
            .draw_series(LineSeries::new(pts.clone(), color.stroke_width(2)))?
            .label(format!("{knob} ({bricks} bricks)"))
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
            });
        chart.draw_series(pts.iter().map(|&p| Circle::new(p, 4, color.filled())))?;
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}
