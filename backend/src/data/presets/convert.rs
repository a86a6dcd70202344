//! VTK curves to Parallax control points: the breakpoints, bisection to
//! the tolerance, rescaling to a data range.

#[allow(unused_imports)]
use super::*;

/// A source sample: display colour and α.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Sample {
    pub(super) color: [f64; 3],
    pub(super) alpha: f64,
}

pub(super) struct Converter<'a> {
    pub(super) color: &'a [Node<[f64; 3]>],
    pub(super) space: ColorSpace,
    pub(super) opacity: &'a [Node<f64>],
    pub(super) unit: f64,
    pub(super) linearize: bool,
}

impl Converter<'_> {
    pub(super) fn sample(&self, x: f64, side: Side) -> Sample {
        Sample {
            color: eval_color(self.color, self.space, x, side),
            alpha: eval_alpha(self.opacity, x, side),
        }
    }

    pub(super) fn point(&self, x: f64, s: &Sample) -> ControlPoint {
        let color = if self.linearize {
            s.color.map(srgb_to_linear)
        } else {
            s.color.map(|c| c.clamp(0.0, 1.0))
        };
        ControlPoint::new(x, color, alpha_to_extinction(s.alpha, self.unit))
    }

    /// How far the linear interpolation between `p0` and `p1` is from the
    /// source at fraction `t`: the larger of the α error and the displayed
    /// colour error (where anything is emitted).
    pub(super) fn error(
        &self,
        p0: &ControlPoint,
        p1: &ControlPoint,
        t: f64,
        truth: &Sample,
    ) -> f64 {
        let tau = (1.0 - t) * p0.extinction + t * p1.extinction;
        let alpha = -(-tau * self.unit).exp_m1();
        let mut err = (alpha - truth.alpha.clamp(0.0, MAX_ALPHA)).abs();
        // Where τ = 0 the colour emits nothing (k̃ = τ·c): no error to see.
        if alpha <= 0.0 && truth.alpha <= 0.0 {
            return err;
        }
        for k in 0..3 {
            let c = (1.0 - t) * p0.color[k] + t * p1.color[k];
            let shown = if self.linearize { linear_to_srgb(c) } else { c };
            err = err.max((shown - truth.color[k].clamp(0.0, 1.0)).abs());
        }
        err
    }

    /// Bisects (x0, x1) until linear interpolation is within `tol` of the
    /// source, pushing the points strictly inside in increasing order.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn refine(
        &self,
        x0: f64,
        s0: &Sample,
        x1: f64,
        s1: &Sample,
        tol: f64,
        depth: u32,
        out: &mut Vec<ControlPoint>,
    ) {
        if depth >= MAX_REFINE_DEPTH {
            return;
        }
        let (p0, p1) = (self.point(x0, s0), self.point(x1, s1));
        let mut worst: f64 = 0.0;
        for t in [0.25, 0.5, 0.75] {
            let x = x0 + t * (x1 - x0);
            if x > x0 && x < x1 {
                worst = worst.max(self.error(&p0, &p1, t, &self.sample(x, Side::Left)));
            }
        }
        let xm = x0 + 0.5 * (x1 - x0);
        if worst <= tol || !(xm > x0 && xm < x1) {
            return;
        }
        let sm = self.sample(xm, Side::Left);
        self.refine(x0, s0, xm, &sm, tol, depth + 1, out);
        out.push(self.point(xm, &sm));
        self.refine(xm, &sm, x1, s1, tol, depth + 1, out);
    }
}

/// Maps the abscissae first..last linearly onto lo..hi (ParaView's rescale);
/// a single node becomes two, at lo and hi.
pub(super) fn rescale<V: Copy>(
    nodes: Vec<Node<V>>,
    lo: f64,
    hi: f64,
    what: &str,
) -> Result<Vec<Node<V>>> {
    let (a, b) = (nodes[0].x, nodes[nodes.len() - 1].x);
    if nodes.len() == 1 {
        let n = nodes[0];
        return Ok(vec![Node { x: lo, ..n }, Node { x: hi, ..n }]);
    }
    if b <= a {
        bail!("{what}: every point is at x = {a}; there is no range to stretch onto {lo}..{hi}");
    }
    let last = nodes.len() - 1;
    Ok(nodes
        .into_iter()
        .enumerate()
        .map(|(i, n)| {
            let x = if i == 0 {
                lo
            } else if i == last {
                hi
            } else {
                (lo + (n.x - a) / (b - a) * (hi - lo)).clamp(lo, hi)
            };
            Node { x, ..n }
        })
        .collect())
}

pub(super) fn convert(
    src: Source,
    format: PresetFormat,
    origin: &str,
    opts: &ImportOptions,
) -> Result<ImportedPreset> {
    let ctx = format!("{origin}: preset {:?}", src.name);
    opts.validate().map_err(|e| anyhow!("{ctx}: {e}"))?;
    let unit = opts.unit.or(src.unit).unwrap_or(1.0);
    let mut notes = src.notes;
    let mut color = src.color;
    let mut opacity = src.opacity.filter(|o| !o.is_empty());
    if let Some((lo, hi)) = opts.range {
        color = rescale(color, lo, hi, "colour").map_err(|e| anyhow!("{ctx}: {e}"))?;
        if let Some(o) = opacity {
            opacity = Some(rescale(o, lo, hi, "opacity").map_err(|e| anyhow!("{ctx}: {e}"))?);
        }
    } else if src.normalized_check {
        let (a, b) = (color[0].x, color[color.len() - 1].x);
        if (a == 0.0 || a == -1.0) && b == 1.0 {
            bail!(
                "{ctx}: RGBPoints span [{a}, {b}], ParaView's normalised coordinates: give the data \
                 range to stretch the colour map over (a range of {a}..{b} keeps the values as they are)"
            );
        }
    }
    let opacity = match opacity {
        Some(o) => o,
        None => {
            let (a, b) = (color[0].x, color[color.len() - 1].x);
            match opts.missing_opacity {
                MissingOpacity::Reject => bail!(
                    "{ctx}: the preset has no opacity; choose a default opacity \
                     (a ramp or a constant)"
                ),
                MissingOpacity::Constant(alpha) => {
                    notes.push(format!(
                        "The preset has no opacity: α = {alpha} everywhere was used."
                    ));
                    vec![Node::linear(a, alpha)]
                }
                MissingOpacity::Ramp { low, high } => {
                    notes.push(format!(
                        "The preset has no opacity: α rising linearly from {low} at {a} to {high} at {b} was used."
                    ));
                    if b > a {
                        vec![Node::linear(a, low), Node::linear(b, high)]
                    } else {
                        vec![Node::linear(a, high)]
                    }
                }
            }
        }
    };

    // Every abscissa where either function has a node or an internal jump.
    let mut xs: Vec<f64> = color.iter().map(|n| n.x).collect();
    xs.extend(opacity.iter().map(|n| n.x));
    for w in color.windows(2) {
        if w[0].sharpness > 0.99 && w[1].x > w[0].x {
            xs.push(step_x(&w[0], &w[1]));
        }
    }
    for w in opacity.windows(2) {
        if w[0].sharpness > 0.99 && w[1].x > w[0].x {
            xs.push(step_x(&w[0], &w[1]));
        }
    }
    xs.sort_by(f64::total_cmp);
    xs.dedup();

    let conv = Converter {
        color: &color,
        space: src.space,
        opacity: &opacity,
        unit,
        linearize: opts.linearize,
    };
    let mut points = Vec::with_capacity(2 * xs.len());
    let mut prev: Option<(f64, Sample)> = None;
    for &x in &xs {
        let left = conv.sample(x, Side::Left);
        let right = conv.sample(x, Side::Right);
        if let (Some((px, ps)), Some(tol)) = (prev, opts.tolerance) {
            conv.refine(px, &ps, x, &left, tol, 0, &mut points);
        }
        points.push(conv.point(x, &left));
        if right != left {
            points.push(conv.point(x, &right));
        }
        prev = Some((x, right));
    }
    let tf = TransferFunction::from_points(points).map_err(|e| anyhow!("{ctx}: {e:#}"))?;
    Ok(ImportedPreset {
        name: src.name,
        format,
        origin: origin.to_string(),
        tf,
        unit,
        options: opts.clone(),
        notes,
    })
}
