//! VTK's curves evaluated exactly: colour spaces (RGB, HSV, Lab, diverging),
//! the midpoint/sharpness segments and steps.

#[allow(unused_imports)]
use super::*;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Side {
    Left,
    Right,
}

/// Where x lies among a function's nodes.
pub(super) enum Loc {
    Before,
    After,
    /// On nodes i0..=i1 (several when the function steps there).
    On(usize, usize),
    /// Strictly inside the segment from node k to node k + 1.
    Inside(usize),
}

pub(super) fn locate<V>(nodes: &[Node<V>], x: f64) -> Loc {
    let lo = nodes.partition_point(|n| n.x < x);
    let hi = nodes.partition_point(|n| n.x <= x);
    if hi > lo {
        Loc::On(lo, hi - 1)
    } else if lo == 0 {
        Loc::Before
    } else if lo == nodes.len() {
        Loc::After
    } else {
        Loc::Inside(lo - 1)
    }
}

/// VTK's midpoint, clamped away from the ends as VTK does.
pub(super) fn vtk_midpoint(m: f64) -> f64 {
    m.clamp(0.00001, 0.99999)
}

/// Where a sharpness > 0.99 segment jumps (VTK: at its midpoint).
pub(super) fn step_x<V>(n0: &Node<V>, n1: &Node<V>) -> f64 {
    n0.x + vtk_midpoint(n0.midpoint) * (n1.x - n0.x)
}

/// The shape of a VTK segment at one x (vtkPiecewiseFunction /
/// vtkColorTransferFunction `GetTable`).
pub(super) enum Param {
    First,
    Second,
    Linear(f64),
    /// Sharpened position and sharpness, for the modified Hermite curve.
    Hermite(f64, f64),
}

pub(super) fn segment_param<V>(n0: &Node<V>, n1: &Node<V>, x: f64, side: Side) -> Param {
    let sharp = n0.sharpness;
    if sharp > 0.99 {
        let xs = step_x(n0, n1);
        return if x < xs || (x == xs && side == Side::Left) {
            Param::First
        } else {
            Param::Second
        };
    }
    let m = vtk_midpoint(n0.midpoint);
    let s = ((x - n0.x) / (n1.x - n0.x)).clamp(0.0, 1.0);
    let s = if s < m {
        0.5 * s / m
    } else {
        0.5 + 0.5 * (s - m) / (1.0 - m)
    };
    if sharp < 0.01 {
        return Param::Linear(s);
    }
    let s = if s < 0.5 {
        0.5 * (s * 2.0).powf(1.0 + 10.0 * sharp)
    } else if s > 0.5 {
        1.0 - 0.5 * ((1.0 - s) * 2.0).powf(1.0 + 10.0 * sharp)
    } else {
        s
    };
    Param::Hermite(s, sharp)
}

/// VTK's modified Hermite curve from `a` to `b` (one slope for both ends).
pub(super) fn hermite(a: f64, b: f64, s: f64, sharp: f64) -> f64 {
    let ss = s * s;
    let sss = ss * s;
    let h1 = 2.0 * sss - 3.0 * ss + 1.0;
    let h2 = -2.0 * sss + 3.0 * ss;
    let h3 = sss - 2.0 * ss + s;
    let h4 = sss - ss;
    let t = (1.0 - sharp) * (b - a);
    h1 * a + h2 * b + h3 * t + h4 * t
}

/// α at x (vtkPiecewiseFunction with clamping on); at a step, `side`
/// chooses the limit.
pub(super) fn eval_alpha(nodes: &[Node<f64>], x: f64, side: Side) -> f64 {
    match locate(nodes, x) {
        Loc::Before => nodes[0].v,
        Loc::After => nodes[nodes.len() - 1].v,
        Loc::On(i0, i1) => match side {
            Side::Left => nodes[i0].v,
            Side::Right => nodes[i1].v,
        },
        Loc::Inside(k) => {
            let (n0, n1) = (&nodes[k], &nodes[k + 1]);
            let (a, b) = (n0.v, n1.v);
            match segment_param(n0, n1, x, side) {
                Param::First => a,
                Param::Second => b,
                Param::Linear(s) => (1.0 - s) * a + s * b,
                Param::Hermite(s, sharp) => hermite(a, b, s, sharp).clamp(a.min(b), a.max(b)),
            }
        }
    }
}

/// Display colour at x (vtkColorTransferFunction with clamping on).
pub(super) fn eval_color(
    nodes: &[Node<[f64; 3]>],
    space: ColorSpace,
    x: f64,
    side: Side,
) -> [f64; 3] {
    match locate(nodes, x) {
        Loc::Before => nodes[0].v,
        Loc::After => nodes[nodes.len() - 1].v,
        Loc::On(i0, i1) => match side {
            Side::Left => nodes[i0].v,
            // A step map takes the next node's colour right after a node.
            Side::Right if space == ColorSpace::Step && i1 + 1 < nodes.len() => nodes[i1 + 1].v,
            Side::Right => nodes[i1].v,
        },
        Loc::Inside(k) => {
            let (n0, n1) = (&nodes[k], &nodes[k + 1]);
            let c = match segment_param(n0, n1, x, side) {
                Param::First => n0.v,
                Param::Second => n1.v,
                _ if space == ColorSpace::Step => n1.v,
                Param::Linear(s) => interp_color(space, n0.v, n1.v, s, None),
                Param::Hermite(s, sharp) => interp_color(space, n0.v, n1.v, s, Some(sharp)),
            };
            c.map(|v| v.clamp(0.0, 1.0))
        }
    }
}

/// Interpolation in a colour space at (already midpoint-adjusted) `s`:
/// linear, or VTK's Hermite curve per coordinate when `sharp` is given.
pub(super) fn interp_color(
    space: ColorSpace,
    c1: [f64; 3],
    c2: [f64; 3],
    s: f64,
    sharp: Option<f64>,
) -> [f64; 3] {
    let mix = |a: f64, b: f64| match sharp {
        None => (1.0 - s) * a + s * b,
        Some(sh) => hermite(a, b, s, sh),
    };
    match space {
        ColorSpace::Rgb => [mix(c1[0], c2[0]), mix(c1[1], c2[1]), mix(c1[2], c2[2])],
        ColorSpace::Step => c2,
        ColorSpace::Hsv { wrap } => {
            let (mut h1, mut h2) = (rgb_to_hsv(c1), rgb_to_hsv(c2));
            if wrap && (h1[0] - h2[0]).abs() > 0.5 {
                if h1[0] > h2[0] {
                    h1[0] -= 1.0;
                } else {
                    h2[0] -= 1.0;
                }
            }
            let mut h = [mix(h1[0], h2[0]), mix(h1[1], h2[1]), mix(h1[2], h2[2])];
            if h[0] < 0.0 {
                h[0] += 1.0;
            }
            hsv_to_rgb(h)
        }
        ColorSpace::Lab => {
            let (l1, l2) = (rgb_to_lab(c1), rgb_to_lab(c2));
            lab_to_rgb([mix(l1[0], l2[0]), mix(l1[1], l2[1]), mix(l1[2], l2[2])])
        }
        ColorSpace::Diverging => interp_diverging(s, c1, c2),
    }
}

// VTK's colour conversions (vtkMath): sRGB with D65 white, the constants
// VTK uses, so that interpolated colours match VTK's.

pub(super) fn rgb_to_lab(c: [f64; 3]) -> [f64; 3] {
    let lin = |v: f64| {
        if v > 0.04045 {
            ((v + 0.055) / 1.055).powf(2.4)
        } else {
            v / 12.92
        }
    };
    let (r, g, b) = (lin(c[0]), lin(c[1]), lin(c[2]));
    let x = r * 0.4124 + g * 0.3576 + b * 0.1805;
    let y = r * 0.2126 + g * 0.7152 + b * 0.0722;
    let z = r * 0.0193 + g * 0.1192 + b * 0.9505;
    let f = |v: f64| {
        if v > 0.008856 {
            v.powf(1.0 / 3.0)
        } else {
            7.787 * v + 16.0 / 116.0
        }
    };
    let (fx, fy, fz) = (f(x / 0.9505), f(y / 1.0), f(z / 1.089));
    [116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)]
}

pub(super) fn lab_to_rgb(lab: [f64; 3]) -> [f64; 3] {
    let fy = (lab[0] + 16.0) / 116.0;
    let fx = lab[1] / 500.0 + fy;
    let fz = fy - lab[2] / 200.0;
    let inv = |v: f64| {
        if v.powi(3) > 0.008856 {
            v.powi(3)
        } else {
            (v - 16.0 / 116.0) / 7.787
        }
    };
    let (x, y, z) = (0.9505 * inv(fx), inv(fy), 1.089 * inv(fz));
    let r = x * 3.2406 + y * -1.5372 + z * -0.4986;
    let g = x * -0.9689 + y * 1.8758 + z * 0.0415;
    let b = x * 0.0557 + y * -0.2040 + z * 1.0570;
    let enc = |v: f64| {
        if v > 0.0031308 {
            1.055 * v.powf(1.0 / 2.4) - 0.055
        } else {
            12.92 * v
        }
    };
    let mut rgb = [enc(r), enc(g), enc(b)];
    let max = rgb[0].max(rgb[1]).max(rgb[2]);
    if max > 1.0 {
        rgb = rgb.map(|v| v / max);
    }
    rgb.map(|v| v.max(0.0))
}

pub(super) fn rgb_to_hsv(c: [f64; 3]) -> [f64; 3] {
    let [r, g, b] = c;
    let max = r.max(g).max(b);
    let min = r.min(g).min(b);
    let v = max;
    let s = if max > 0.0 { (max - min) / max } else { 0.0 };
    let h = if s > 0.0 {
        let d = max - min;
        let h = if r == max {
            (g - b) / d / 6.0
        } else if g == max {
            1.0 / 3.0 + (b - r) / d / 6.0
        } else {
            2.0 / 3.0 + (r - g) / d / 6.0
        };
        if h < 0.0 {
            h + 1.0
        } else {
            h
        }
    } else {
        0.0
    };
    [h, s, v]
}

pub(super) fn hsv_to_rgb(hsv: [f64; 3]) -> [f64; 3] {
    let [h, s, v] = hsv;
    let sixth = 1.0 / 6.0;
    let (r, g, b) = if h > sixth && h <= 2.0 * sixth {
        ((2.0 * sixth - h) / sixth, 1.0, 0.0)
    } else if h > 2.0 * sixth && h <= 0.5 {
        (0.0, 1.0, (h - 2.0 * sixth) / sixth)
    } else if h > 0.5 && h <= 4.0 * sixth {
        (0.0, (4.0 * sixth - h) / sixth, 1.0)
    } else if h > 4.0 * sixth && h <= 5.0 * sixth {
        ((h - 4.0 * sixth) / sixth, 0.0, 1.0)
    } else if h > 5.0 * sixth && h <= 1.0 {
        (1.0, 0.0, (1.0 - h) / sixth)
    } else {
        (1.0, h / sixth, 0.0)
    };
    [r, g, b].map(|c| (s * c + (1.0 - s)) * v)
}

/// Moreland's diverging interpolation through the Msh space (VTK's
/// `vtkColorTransferFunctionInterpolateDiverging`).
pub(super) fn interp_diverging(s: f64, c1: [f64; 3], c2: [f64; 3]) -> [f64; 3] {
    use std::f64::consts::PI;
    let to_msh = |lab: [f64; 3]| {
        let m = (lab[0] * lab[0] + lab[1] * lab[1] + lab[2] * lab[2]).sqrt();
        let sat = if m > 0.001 { (lab[0] / m).acos() } else { 0.0 };
        let hue = if sat > 0.001 {
            lab[2].atan2(lab[1])
        } else {
            0.0
        };
        [m, sat, hue]
    };
    let angle_diff = |a1: f64, a2: f64| {
        let mut d = (a1 - a2).abs();
        while d >= 2.0 * PI {
            d -= 2.0 * PI;
        }
        if d > PI {
            2.0 * PI - d
        } else {
            d
        }
    };
    let adjust_hue = |msh: [f64; 3], unsat_m: f64| {
        if msh[0] >= unsat_m - 0.1 {
            msh[2]
        } else {
            let spin =
                msh[1] * (unsat_m * unsat_m - msh[0] * msh[0]).sqrt() / (msh[0] * msh[1].sin());
            if msh[2] > -0.3 * PI {
                msh[2] + spin
            } else {
                msh[2] - spin
            }
        }
    };
    let mut m1 = to_msh(rgb_to_lab(c1));
    let mut m2 = to_msh(rgb_to_lab(c2));
    let mut s = s;
    if m1[1] > 0.05 && m2[1] > 0.05 && angle_diff(m1[2], m2[2]) > 0.33 * PI {
        let mid = m1[0].max(m2[0]).max(88.0);
        if s < 0.5 {
            m2 = [mid, 0.0, 0.0];
            s *= 2.0;
        } else {
            m1 = [mid, 0.0, 0.0];
            s = 2.0 * s - 1.0;
        }
    }
    if m1[1] < 0.05 && m2[1] > 0.05 {
        m1[2] = adjust_hue(m2, m1[0]);
    } else if m2[1] < 0.05 && m1[1] > 0.05 {
        m2[2] = adjust_hue(m1, m2[0]);
    }
    let m = [0, 1, 2].map(|i| (1.0 - s) * m1[i] + s * m2[i]);
    let lab = [
        m[0] * m[1].cos(),
        m[0] * m[1].sin() * m[2].cos(),
        m[0] * m[1].sin() * m[2].sin(),
    ];
    lab_to_rgb(lab)
}
