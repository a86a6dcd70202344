//! Procedural volumes (`parallax synth <kind> --size N [--type u8|u16|f32] -o
//! vol.nrrd`, docs/design.md "Command line").
//!
//! Each kind is a known signal that exercises one part of the pipeline: the
//! Marschner–Lobb signal measures reconstruction (filtering) error, Shepp–Logan
//! is the standard tomography head, shells and the plane have analytically
//! known surfaces, constant and noise stress the empty-brick and variance
//! paths, and the stiff checkerboard stresses every place where neighbouring
//! voxels are blended (brick overlap, gradients, 8-bit quantisation).
//!
//! Voxel (i, j, k) of an N³ volume is sampled at its centre, mapped to the
//! cube [−1, 1]³: x = −1 + (2i + 1)/N (likewise y from j, z from k), the
//! volume-space convention of docs/design.md with the box scaled to [−1, 1].

use std::f64::consts::PI;
use std::path::Path;

use crate::volume::VoxelType;
use anyhow::{ensure, Result};
use rayon::prelude::*;

use super::nrrd::NrrdWriter;

/// The procedural volumes `parallax synth` can write.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SynthKind {
    MarschnerLobb,
    Shells,
    SheppLogan,
    Constant,
    Plane,
    Noise,
    Stiff,
    Ct,
}

impl SynthKind {
    pub const ALL: [SynthKind; 8] = [
        SynthKind::MarschnerLobb,
        SynthKind::Shells,
        SynthKind::SheppLogan,
        SynthKind::Constant,
        SynthKind::Plane,
        SynthKind::Noise,
        SynthKind::Stiff,
        SynthKind::Ct,
    ];

    /// The command-line name.
    pub fn name(self) -> &'static str {
        match self {
            SynthKind::MarschnerLobb => "marschner-lobb",
            SynthKind::Shells => "shells",
            SynthKind::SheppLogan => "shepp-logan",
            SynthKind::Constant => "constant",
            SynthKind::Plane => "plane",
            SynthKind::Noise => "noise",
            SynthKind::Stiff => "stiff",
            SynthKind::Ct => "ct",
        }
    }

    /// Parses a command-line name.
    pub fn parse(s: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.name() == s)
    }
}

/// Centre of voxel `i` of `n`, on [−1, 1].
#[inline]
pub fn coord(i: usize, n: usize) -> f64 {
    -1.0 + (2 * i + 1) as f64 / n as f64
}

/// The Marschner–Lobb test signal (Marschner & Lobb 1994) with α = 0.25,
/// f_M = 6: ρ = (1 − sin(πz/2) + α(1 + ρ_r(√(x²+y²)))) / (2(1 + α)),
/// ρ_r(r) = cos(2π f_M cos(πr/2)). Its range is [0, 1].
pub fn marschner_lobb(x: f64, y: f64, z: f64) -> f64 {
    const ALPHA: f64 = 0.25;
    const F_M: f64 = 6.0;
    let r = (x * x + y * y).sqrt();
    let rho_r = (2.0 * PI * F_M * (PI * r / 2.0).cos()).cos();
    (1.0 - (PI * z / 2.0).sin() + ALPHA * (1.0 + rho_r)) / (2.0 * (1.0 + ALPHA))
}

/// One ellipsoid of the Shepp–Logan head: density, semi-axes (a, b, c),
/// centre (x0, y0, z0), Euler angles (φ, θ, ψ) in degrees.
struct Ellipsoid {
    density: f64,
    axes: [f64; 3],
    centre: [f64; 3],
    euler_deg: [f64; 3],
}

/// The ten ellipsoids of the 3-D Shepp–Logan head (Kak & Slaney geometry,
/// as tabulated in Toft's thesis and used by most 3-D phantom generators),
/// with the original Shepp–Logan densities (2, −0.98, −0.02, −0.02, 0.01…),
/// not the higher-contrast "modified" ones: with those the ventricles sum to
/// exactly 0 and would be indistinguishable from the air outside the head.
const SHEPP_LOGAN: [Ellipsoid; 10] = [
    Ellipsoid {
        density: 2.0,
        axes: [0.69, 0.92, 0.81],
        centre: [0.0, 0.0, 0.0],
        euler_deg: [0.0, 0.0, 0.0],
    },
    Ellipsoid {
        density: -0.98,
        axes: [0.6624, 0.874, 0.78],
        centre: [0.0, -0.0184, 0.0],
        euler_deg: [0.0, 0.0, 0.0],
    },
    Ellipsoid {
        density: -0.02,
        axes: [0.11, 0.31, 0.22],
        centre: [0.22, 0.0, 0.0],
        euler_deg: [-18.0, 0.0, 10.0],
    },
    Ellipsoid {
        density: -0.02,
        axes: [0.16, 0.41, 0.28],
        centre: [-0.22, 0.0, 0.0],
        euler_deg: [18.0, 0.0, 10.0],
    },
    Ellipsoid {
        density: 0.01,
        axes: [0.21, 0.25, 0.41],
        centre: [0.0, 0.35, -0.15],
        euler_deg: [0.0, 0.0, 0.0],
    },
    Ellipsoid {
        density: 0.01,
        axes: [0.046, 0.046, 0.05],
        centre: [0.0, 0.1, 0.25],
        euler_deg: [0.0, 0.0, 0.0],
    },
    Ellipsoid {
        density: 0.01,
        axes: [0.046, 0.046, 0.05],
        centre: [0.0, -0.1, 0.25],
        euler_deg: [0.0, 0.0, 0.0],
    },
    Ellipsoid {
        density: 0.01,
        axes: [0.046, 0.023, 0.05],
        centre: [-0.08, -0.605, 0.0],
        euler_deg: [0.0, 0.0, 0.0],
    },
    Ellipsoid {
        density: 0.01,
        axes: [0.023, 0.023, 0.02],
        centre: [0.0, -0.606, 0.0],
        euler_deg: [0.0, 0.0, 0.0],
    },
    Ellipsoid {
        density: 0.01,
        axes: [0.023, 0.046, 0.02],
        centre: [0.06, -0.605, 0.0],
        euler_deg: [0.0, 0.0, 0.0],
    },
];

/// Largest summed Shepp–Logan density (the skull, 2.0): divides the sum so
/// the phantom spans [0, 1] (skull 1, brain ≈ 0.51).
const SHEPP_LOGAN_MAX: f64 = 2.0;

/// Whether `p` lies inside the ellipsoid (rotated about its own centre by
/// the z-x-z Euler angles φ, θ, ψ).
fn inside(e: &Ellipsoid, p: [f64; 3]) -> bool {
    let [phi, theta, psi] = e.euler_deg.map(f64::to_radians);
    let (sf, cf) = phi.sin_cos();
    let (st, ct) = theta.sin_cos();
    let (sp, cp) = psi.sin_cos();
    let r = [
        [cp * cf - ct * sf * sp, cp * sf + ct * cf * sp, sp * st],
        [-sp * cf - ct * sf * cp, -sp * sf + ct * cf * cp, cp * st],
        [st * sf, -st * cf, ct],
    ];
    let d = [p[0] - e.centre[0], p[1] - e.centre[1], p[2] - e.centre[2]];
    let mut s = 0.0;
    for (row, axis) in r.iter().zip(e.axes) {
        let q = row[0] * d[0] + row[1] * d[1] + row[2] * d[2];
        s += (q / axis).powi(2);
    }
    s <= 1.0
}

/// The 3-D Shepp–Logan head at `p` ∈ [−1, 1]³, normalised to [0, 1].
pub fn shepp_logan(p: [f64; 3]) -> f64 {
    let sum: f64 = SHEPP_LOGAN
        .iter()
        .filter(|e| inside(e, p))
        .map(|e| e.density)
        .sum();
    (sum / SHEPP_LOGAN_MAX).clamp(0.0, 1.0)
}

/// Nested spherical shells: four smooth (Gaussian-profile) shells of radii
/// 0.2, 0.4, 0.6, 0.8 and peak values 1, 0.75, 0.5, 0.25, centred in the
/// volume. Isosurfaces are spheres, so rendered silhouettes are known.
fn shells(p: [f64; 3]) -> f64 {
    const SHELLS: [(f64, f64); 4] = [(0.2, 1.0), (0.4, 0.75), (0.6, 0.5), (0.8, 0.25)];
    const WIDTH: f64 = 0.04;
    let r = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
    SHELLS
        .iter()
        .map(|&(radius, peak)| peak * (-0.5 * ((r - radius) / WIDTH).powi(2)).exp())
        .fold(0.0, f64::max)
}

/// A 64-bit lattice hash to [0, 1): deterministic across platforms and runs.
fn lattice(x: i64, y: i64, z: i64, octave: u64) -> f64 {
    let mut h = (x as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (y as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
        ^ (z as u64).wrapping_mul(0x1656_67B1_9E37_79F9)
        ^ octave.wrapping_mul(0xD6E8_FEB8_6659_FD93);
    h ^= h >> 30;
    h = h.wrapping_mul(0xBF58_476D_1CE4_E5B9);
    h ^= h >> 27;
    h = h.wrapping_mul(0x94D0_49BB_1331_11EB);
    h ^= h >> 31;
    (h >> 11) as f64 / (1u64 << 53) as f64
}

/// Value noise: lattice values blended with a C² (quintic) fade, four
/// octaves from 4 cells across the volume, amplitudes halving; the weighted
/// mean of values in [0, 1) stays in [0, 1). The same at every size, so a
/// small volume is a downsampled large one.
fn noise(p: [f64; 3]) -> f64 {
    const OCTAVES: u64 = 4;
    let fade = |t: f64| t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
    let (mut sum, mut total, mut amp, mut freq) = (0.0, 0.0, 1.0, 4.0);
    for o in 0..OCTAVES {
        let u = p.map(|c| (c + 1.0) * 0.5 * freq);
        let cell = u.map(|c| c.floor());
        let w = [
            fade(u[0] - cell[0]),
            fade(u[1] - cell[1]),
            fade(u[2] - cell[2]),
        ];
        let c = cell.map(|c| c as i64);
        let mut v = 0.0;
        for corner in 0..8 {
            let (dx, dy, dz) = (corner & 1, (corner >> 1) & 1, (corner >> 2) & 1);
            let weight = (if dx == 1 { w[0] } else { 1.0 - w[0] })
                * (if dy == 1 { w[1] } else { 1.0 - w[1] })
                * (if dz == 1 { w[2] } else { 1.0 - w[2] });
            v += weight * lattice(c[0] + dx, c[1] + dy, c[2] + dz, o);
        }
        sum += amp * v;
        total += amp;
        amp *= 0.5;
        freq *= 2.0;
    }
    sum / total
}

/// Hounsfield units of the CT phantom's [0, 1] range ends: −1024 … 3071,
/// the span CT scanners store.
pub const CT_HU: (f64, f64) = (-1024.0, 3071.0);

/// A CT-like head: the Shepp–Logan geometry in Hounsfield units (air −1000,
/// skull +1000, brain 40, ventricles 20, small lesions 50) with scanner-like
/// noise (uniform ±20 HU per voxel, deterministic), mostly air around it.
/// Returned on [0, 1] over [`CT_HU`].
fn ct(p: [f64; 3], i: usize, j: usize, k: usize) -> f64 {
    ct_scanned(ct_hu(p), i, j, k)
}

/// The CT phantom's Hounsfield units at p, without noise.
fn ct_hu(p: [f64; 3]) -> f64 {
    let sum: f64 = SHEPP_LOGAN
        .iter()
        .filter(|e| inside(e, p))
        .map(|e| e.density)
        .sum();
    if sum <= 0.5 {
        -1000.0
    } else if sum >= 1.5 {
        1000.0
    } else {
        40.0 + (sum - 1.02) * 1000.0
    }
}

/// `hu` as voxel (i, j, k) of the scanner stores it: with its noise
/// (uniform ±20 HU, deterministic), on [0, 1] over [`CT_HU`].
fn ct_scanned(hu: f64, i: usize, j: usize, k: usize) -> f64 {
    let noise = (lattice(i as i64, j as i64, k as i64, 99) - 0.5) * 40.0;
    ((hu + noise - CT_HU.0) / (CT_HU.1 - CT_HU.0)).clamp(0.0, 1.0)
}

/// Sub-samples across a thick slice's thickness.
const SLICE_PROFILE: usize = 8;

/// Voxel (i, j, k) of the CT phantom scanned in `slices` thick slices over
/// the cube an n³ scan covers (n × n × slices voxels): the mean of the
/// anatomy across the slice's thickness at [`SLICE_PROFILE`] depths (the
/// partial volume a thick slice averages, as a scanner's slice profile
/// does), with the scanner's per-voxel noise. On [0, 1] over [`CT_HU`].
pub fn thick_ct_value(i: usize, j: usize, k: usize, n: usize, slices: usize) -> f64 {
    let (x, y) = (coord(i, n), coord(j, n));
    let thickness = 2.0 / slices as f64;
    let hu = (0..SLICE_PROFILE)
        .map(|s| {
            let z = -1.0 + thickness * (k as f64 + (s as f64 + 0.5) / SLICE_PROFILE as f64);
            ct_hu([x, y, z])
        })
        .sum::<f64>()
        / SLICE_PROFILE as f64;
    ct_scanned(hu, i, j, k)
}

/// Width in voxels of the stiff checkerboard's cells.
const STIFF_CELL: usize = 4;

/// The value of voxel (i, j, k) of an n³ volume of `kind`, in [0, 1].
pub fn synth_value(kind: SynthKind, i: usize, j: usize, k: usize, n: usize) -> f64 {
    let p = [coord(i, n), coord(j, n), coord(k, n)];
    match kind {
        SynthKind::MarschnerLobb => marschner_lobb(p[0], p[1], p[2]),
        SynthKind::Shells => shells(p),
        SynthKind::SheppLogan => shepp_logan(p),
        SynthKind::Constant => 0.5,
        SynthKind::Plane => {
            if k == n / 2 {
                1.0
            } else {
                0.0
            }
        }
        SynthKind::Noise => noise(p),
        SynthKind::Stiff => ((i / STIFF_CELL + j / STIFF_CELL + k / STIFF_CELL) % 2) as f64,
        SynthKind::Ct => ct(p, i, j, k),
    }
}

/// Where a synthetic volume goes: a NRRD, or an OME-Zarr image where the
/// name ends in `.zarr` (spacing in millimetres, as a scanner's).
enum Sink {
    Nrrd(NrrdWriter),
    Zarr(Box<super::zarr::ZarrWriter>),
}

impl Sink {
    fn create(
        path: &Path,
        dims: [usize; 3],
        voxel_type: VoxelType,
        spacing: [f64; 3],
    ) -> Result<Self> {
        let name = path.to_string_lossy().to_lowercase();
        Ok(if name.trim_end_matches('/').ends_with(".zarr") {
            Sink::Zarr(Box::new(super::zarr::ZarrWriter::create(
                path,
                dims,
                voxel_type,
                spacing,
                "millimeter",
            )?))
        } else {
            Sink::Nrrd(NrrdWriter::create(path, dims, voxel_type, spacing)?)
        })
    }

    fn write_slices(&mut self, values: &[f32]) -> Result<()> {
        match self {
            Sink::Nrrd(w) => w.write_slices(values),
            Sink::Zarr(w) => w.write_slices(values),
        }
    }

    fn finish(self) -> Result<()> {
        match self {
            Sink::Nrrd(w) => w.finish(),
            Sink::Zarr(w) => w.finish(),
        }
    }
}

/// Writes an n³ volume of `kind` as a NRRD, or an OME-Zarr image where
/// the name ends in `.zarr` (spacing 1), one z-slice at a
/// time, so that even 1024³ never lives in memory; each slice is computed in
/// parallel over its rows. [0, 1] maps to the full range of an integer type
/// (0..255, 0..65535; −32768..32767 for i16) and is kept as is for f32.
/// `progress` receives the number of slices written so far.
pub fn write_synth(
    kind: SynthKind,
    n: usize,
    voxel_type: VoxelType,
    path: &Path,
    progress: impl FnMut(u64),
) -> Result<()> {
    ensure!(n > 0, "{}: --size must be at least 1", path.display());
    let writer = Sink::create(path, [n; 3], voxel_type, [1.0; 3])?;
    write_slices(
        writer,
        kind,
        n,
        n,
        voxel_type,
        |i, j, k| synth_value(kind, i, j, k, n),
        progress,
    )
}

/// Writes the CT phantom as a thick-slice scan (`parallax synth ct --slices
/// N`): n × n × `slices` voxels of 1 × 1 × n/slices ([`thick_ct_value`]), so
/// that it covers the cube an n³ scan does.
pub fn write_thick_ct(
    n: usize,
    slices: usize,
    voxel_type: VoxelType,
    path: &Path,
    progress: impl FnMut(u64),
) -> Result<()> {
    ensure!(n > 0, "{}: --size must be at least 1", path.display());
    ensure!(
        (1..=n).contains(&slices),
        "{}: --slices must be in 1..=--size (got {slices})",
        path.display()
    );
    let thickness = n as f64 / slices as f64;
    let writer = Sink::create(path, [n, n, slices], voxel_type, [1.0, 1.0, thickness])?;
    write_slices(
        writer,
        SynthKind::Ct,
        n,
        slices,
        voxel_type,
        |i, j, k| thick_ct_value(i, j, k, n, slices),
        progress,
    )
}

/// Writes `slices` z-slices of n × n voxels of `value` (on [0, 1]), each
/// computed in parallel over its rows. [0, 1] maps to the full range of an
/// integer type, or to Hounsfield units for the CT phantom where the type
/// holds them, and is kept as is for floats.
fn write_slices(
    mut writer: Sink,
    kind: SynthKind,
    n: usize,
    slices: usize,
    voxel_type: VoxelType,
    value: impl Fn(usize, usize, usize) -> f64 + Sync,
    mut progress: impl FnMut(u64),
) -> Result<()> {
    let (lo, hi) = match (kind, voxel_type) {
        // The CT phantom keeps Hounsfield units where the type can hold them.
        (SynthKind::Ct, t) if !matches!(t, VoxelType::U8 | VoxelType::U16 | VoxelType::I8) => CT_HU,
        (_, VoxelType::F32 | VoxelType::F64) => (0.0, 1.0),
        (_, t) => t.limits(),
    };
    let mut slice = vec![0f32; n * n];
    for k in 0..slices {
        slice.par_chunks_mut(n).enumerate().for_each(|(j, row)| {
            for (i, v) in row.iter_mut().enumerate() {
                *v = (lo + value(i, j, k) * (hi - lo)) as f32;
            }
        });
        writer.write_slices(&slice)?;
        progress(k as u64 + 1);
    }
    writer.finish()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::volume::Volume;

    #[test]
    fn ct_is_in_hounsfield_units_with_noise() {
        let n = 64;
        let hu = |i, j, k| CT_HU.0 + synth_value(SynthKind::Ct, i, j, k, n) * (CT_HU.1 - CT_HU.0);
        let air = hu(0, 0, 0);
        assert!((-1020.0..=-980.0).contains(&air), "{air}");
        let brain = hu(n / 2, n / 2 + 8, n / 2);
        assert!((10.0..=70.0).contains(&brain), "{brain}");
        assert_ne!(hu(0, 0, 0), hu(1, 0, 0), "noise");
        // mostly air: a CT's large empty fraction
        let air_voxels = (0..n)
            .flat_map(|k| (0..n).map(move |j| (j, k)))
            .filter(|&(j, k)| hu(n / 2, j, k) < -900.0)
            .count();
        assert!(air_voxels * 4 > n * n, "{air_voxels}");
    }

    #[test]
    fn a_thick_slice_averages_the_anatomy_across_its_thickness() {
        let (n, slices) = (64, 8);
        let hu = |v: f64| CT_HU.0 + v * (CT_HU.1 - CT_HU.0);
        // Air stays air; the noise is the scanner's, per voxel.
        let air = hu(thick_ct_value(0, 0, 0, n, slices));
        assert!((-1020.0..=-980.0).contains(&air), "{air}");
        // A thick slice is the mean of the thin slices it spans, and where
        // it holds air and tissue, neither (partial volume).
        let thin = |i, j, k| hu(synth_value(SynthKind::Ct, i, j, k, n));
        let (i, j) = (n / 2, n / 2 + 8);
        let per = n / slices;
        let mut worst: f64 = 0.0;
        for k in 0..slices {
            let thick = hu(thick_ct_value(i, j, k, n, slices));
            let mean = (0..per).map(|d| thin(i, j, k * per + d)).sum::<f64>() / per as f64;
            worst = worst.max((thick - mean).abs());
        }
        // Both carry ±20 HU of noise and sample the slab at other depths.
        assert!(worst < 200.0, "{worst}");
        let values: Vec<f64> = (0..slices)
            .map(|k| hu(thick_ct_value(i, j, k, n, slices)))
            .collect();
        assert!(
            values.iter().any(|&v| v > -900.0 && v < -100.0),
            "a slice mixing air and tissue (partial volume): {values:?}"
        );
    }

    #[test]
    fn names_round_trip() {
        for k in SynthKind::ALL {
            assert_eq!(SynthKind::parse(k.name()), Some(k));
        }
        assert_eq!(
            SynthKind::parse("marschner-lobb"),
            Some(SynthKind::MarschnerLobb)
        );
        assert_eq!(SynthKind::parse("shepp-logan"), Some(SynthKind::SheppLogan));
        assert_eq!(SynthKind::parse("sphere"), None);
    }

    #[test]
    fn marschner_lobb_matches_formula() {
        // Centre voxel of an odd-sized volume: x = y = z = 0, so
        // ρ = (1 − 0 + 0.25·(1 + cos(12π))) / 2.5 = 1.5 / 2.5.
        assert!((synth_value(SynthKind::MarschnerLobb, 20, 20, 20, 41) - 0.6).abs() < 1e-12);
        // An arbitrary voxel against the formula written out independently.
        let n = 41;
        let (i, j, k) = (3usize, 17usize, 29usize);
        let x = -1.0 + (2.0 * 3.0 + 1.0) / 41.0;
        let y = -1.0 + (2.0 * 17.0 + 1.0) / 41.0;
        let z = -1.0 + (2.0 * 29.0 + 1.0) / 41.0;
        let r = f64::hypot(x, y);
        let rho_r = (2.0 * PI * 6.0 * (PI * r / 2.0).cos()).cos();
        let want = (1.0 - (PI * z / 2.0).sin() + 0.25 * (1.0 + rho_r)) / (2.0 * 1.25);
        assert!((synth_value(SynthKind::MarschnerLobb, i, j, k, n) - want).abs() < 1e-12);
        // Top and bottom of the cube: z → ±1 gives the extremes of the sin term.
        assert!((marschner_lobb(0.0, 0.0, -1.0) - 1.0).abs() < 1e-12);
        assert!(
            (marschner_lobb(1.0, 0.0, 1.0)
                - 0.25 * (1.0 + (12.0 * PI * (PI / 2.0).cos()).cos()) / 2.5)
                .abs()
                < 1e-12
        );
    }

    #[test]
    fn shepp_logan_inside_positive_outside_zero() {
        let n = 40;
        let (mut inside_count, mut outside_count) = (0, 0);
        for k in 0..n {
            for j in 0..n {
                for i in 0..n {
                    let p = [coord(i, n), coord(j, n), coord(k, n)];
                    let e = (p[0] / 0.69).powi(2) + (p[1] / 0.92).powi(2) + (p[2] / 0.81).powi(2);
                    let v = synth_value(SynthKind::SheppLogan, i, j, k, n);
                    if e <= 1.0 {
                        assert!(v > 0.0, "({i},{j},{k}) inside the head is {v}");
                        inside_count += 1;
                    } else {
                        assert_eq!(v, 0.0, "({i},{j},{k}) outside the head");
                        outside_count += 1;
                    }
                }
            }
        }
        assert!(inside_count > 1000 && outside_count > 1000);
        // Skull = 2/2, brain = (2 − 0.98)/2, a ventricle = (2 − 0.98 − 0.02)/2.
        assert_eq!(shepp_logan([0.0, 0.905, 0.0]), 1.0);
        assert!((shepp_logan([0.0, 0.0, 0.0]) - 0.51).abs() < 1e-12);
        assert!((shepp_logan([0.22, 0.0, 0.0]) - 0.5).abs() < 1e-12);
    }

    #[test]
    fn simple_kinds_have_their_values() {
        let n = 16;
        assert_eq!(synth_value(SynthKind::Constant, 3, 4, 5, n), 0.5);
        assert_eq!(synth_value(SynthKind::Plane, 3, 4, 8, n), 1.0);
        assert_eq!(synth_value(SynthKind::Plane, 3, 4, 7, n), 0.0);
        assert_eq!(synth_value(SynthKind::Plane, 3, 4, 9, n), 0.0);
        // Stiff: full-range jump across a cell face, constant inside a cell.
        assert_eq!(synth_value(SynthKind::Stiff, 0, 0, 0, n), 0.0);
        assert_eq!(synth_value(SynthKind::Stiff, 3, 3, 3, n), 0.0);
        assert_eq!(synth_value(SynthKind::Stiff, 4, 0, 0, n), 1.0);
        assert_eq!(synth_value(SynthKind::Stiff, 4, 4, 0, n), 0.0);
        // Shells peak on their radii: voxel centres of a 10³ volume at x = 0.1 + …
        assert!((shells([0.2, 0.0, 0.0]) - 1.0).abs() < 1e-12);
        assert!((shells([0.0, -0.6, 0.0]) - 0.5).abs() < 1e-12);
        assert!(shells([0.0, 0.0, 0.0]) < 1e-5);
        // Noise is deterministic, in [0, 1), and not constant.
        let mut lo = f64::INFINITY;
        let mut hi = f64::NEG_INFINITY;
        for k in 0..n {
            for j in 0..n {
                for i in 0..n {
                    let v = synth_value(SynthKind::Noise, i, j, k, n);
                    assert_eq!(v, synth_value(SynthKind::Noise, i, j, k, n));
                    lo = lo.min(v);
                    hi = hi.max(v);
                }
            }
        }
        assert!(
            (0.0..1.0).contains(&lo) && (0.0..1.0).contains(&hi) && hi - lo > 0.2,
            "{lo}..{hi}"
        );
        for kind in SynthKind::ALL {
            for (i, j, k) in [(0, 0, 0), (15, 15, 15), (7, 3, 11)] {
                let v = synth_value(kind, i, j, k, n);
                assert!((0.0..=1.0).contains(&v), "{kind:?} {v}");
            }
        }
    }

    #[test]
    fn write_synth_streams_exact_size_and_values() {
        let dir = tempfile::tempdir().unwrap();
        let n = 12;
        for t in [VoxelType::U8, VoxelType::U16, VoxelType::F32] {
            let path = dir.path().join(format!("ml-{}.nrrd", t.name()));
            let mut calls = Vec::new();
            write_synth(SynthKind::MarschnerLobb, n, t, &path, |d| calls.push(d)).unwrap();
            assert_eq!(calls, (1..=n as u64).collect::<Vec<_>>());
            assert!(!std::fs::read_dir(dir.path()).unwrap().any(|e| e
                .unwrap()
                .file_name()
                .to_string_lossy()
                .ends_with(".tmp")));

            let bytes = std::fs::read(&path).unwrap();
            let header_len = bytes.windows(2).position(|w| w == b"\n\n").unwrap() + 2;
            assert_eq!(bytes.len(), header_len + n * n * n * t.bytes());

            let mut src = crate::data::open(&path, None).unwrap();
            assert_eq!(src.info().dims, [n; 3]);
            assert_eq!(src.info().spacing, [1.0; 3]);
            assert_eq!(src.info().voxel_type, t);
            let v = Volume::read_all(&mut *src).unwrap();
            let scale = match t {
                VoxelType::U8 => 255.0,
                VoxelType::U16 => 65535.0,
                _ => 1.0,
            };
            for (i, j, k) in [(0, 0, 0), (5, 6, 7), (11, 0, 3)] {
                let want = synth_value(SynthKind::MarschnerLobb, i, j, k, n) * scale;
                let want = if t == VoxelType::F32 {
                    want as f32
                } else {
                    want.round() as f32
                };
                assert_eq!(v.voxel(i, j, k), want, "{t:?} ({i},{j},{k})");
            }
        }
    }
}
