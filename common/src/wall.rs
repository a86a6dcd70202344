//! HoloVizio-like light field walls (G10 §3, §6): N projectors behind the
//! screen on a horizontal arc (or line), each covering the whole screen,
//! spread over the field of view so that neighbours are at most the screen's
//! angular accuracy Φ apart as seen from the screen centre.

use anyhow::{bail, Context, Result};
use std::fmt::Write;
use std::path::Path;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layout {
    Arc,
    Line,
}

#[derive(Clone, Debug)]
pub struct WallSpec {
    pub projectors: usize,
    pub resolution: [u32; 2],
    /// Screen width and height (m).
    pub screen: [f64; 2],
    /// s0 (m).
    pub pixel_size: f64,
    /// Φ (degrees).
    pub angular_accuracy_deg: f64,
    /// Horizontal field of view (degrees).
    pub fov_deg: f64,
    /// Projector distance behind the screen (m).
    pub distance: f64,
    /// Observer position V (m).
    pub observer: [f64; 3],
    pub layout: Layout,
}

impl WallSpec {
    /// The wall of G10 §6: 72 SVGA projectors, 160 × 90 cm screen, 50° field
    /// of view, 0.8° angular accuracy, 1.5 mm pixels.
    pub fn holovizio72() -> Self {
        WallSpec {
            projectors: 72,
            resolution: [800, 600],
            screen: [1.6, 0.9],
            pixel_size: 0.0015,
            angular_accuracy_deg: 0.8,
            fov_deg: 50.0,
            distance: 2.0,
            observer: [0.0, 0.0, 2.0],
            layout: Layout::Arc,
        }
    }

    /// Projector positions E, left to right.
    pub fn positions(&self) -> Vec<[f64; 3]> {
        let n = self.projectors;
        (0..n)
            .map(|k| {
                let a =
                    (-self.fov_deg / 2.0 + (k as f64 + 0.5) * self.fov_deg / n as f64).to_radians();
                match self.layout {
                    // Behind the screen (z < 0): a projector's rays cross the
                    // screen towards the viewers (G10 Eq. 1).
                    Layout::Arc => [self.distance * a.sin(), 0.0, -self.distance * a.cos()],
                    Layout::Line => [self.distance * a.tan(), 0.0, -self.distance],
                }
            })
            .collect()
    }

    fn check(&self) -> Result<()> {
        if self.projectors == 0 {
            bail!("--projectors 0: a wall needs at least one projector");
        }
        if self.resolution.contains(&0) {
            bail!("--resolution {:?}: must be at least 1×1", self.resolution);
        }
        if !(self.fov_deg > 0.0 && self.fov_deg < 180.0) {
            bail!("--fov {}: must be in (0, 180) degrees", self.fov_deg);
        }
        if !(self.distance > 0.0 && self.distance.is_finite()) {
            bail!("--distance {}: must be > 0", self.distance);
        }
        if !(self.angular_accuracy_deg > 0.0 && self.angular_accuracy_deg < 90.0) {
            bail!(
                "--angular-accuracy {}: must be in (0, 90) degrees",
                self.angular_accuracy_deg
            );
        }
        if self.observer[2] <= 0.0 {
            bail!("--observer: must be in front of the screen (z > 0)");
        }
        Ok(())
    }

    /// Writes `dir/display.toml` and `dir/projectors/pNN.toml`.
    pub fn write(&self, dir: &Path) -> Result<()> {
        self.check()?;
        let pdir = dir.join("projectors");
        std::fs::create_dir_all(&pdir)
            .with_context(|| format!("{}: cannot create", pdir.display()))?;
        let spacing = self.fov_deg / self.projectors as f64;
        let mut d = String::new();
        let _ = writeln!(
            d,
            "# {} projectors on a{} {} {} m behind the screen, {}° field of view, spaced {:.3}° apart\n\
             # (angular accuracy {}°{}).",
            self.projectors,
            if self.layout == Layout::Arc { "n" } else { "" },
            if self.layout == Layout::Arc { "arc" } else { "line" },
            self.distance,
            self.fov_deg,
            spacing,
            self.angular_accuracy_deg,
            if spacing > self.angular_accuracy_deg {
                ": coarser than Φ, the parallax shows steps"
            } else {
                ""
            }
        );
        let _ = writeln!(
            d,
            "[screen]\nsize = [{}, {}]\npixel_size = {}\nangular_accuracy_deg = {}\n",
            self.screen[0], self.screen[1], self.pixel_size, self.angular_accuracy_deg
        );
        let _ = writeln!(
            d,
            "[observer]\nposition = [{}, {}, {}]\nprojectors = \"projectors/\"",
            self.observer[0], self.observer[1], self.observer[2]
        );
        crate::atomic::write(&dir.join("display.toml"), d.as_bytes())?;
        let width = self.projectors.to_string().len().max(2);
        for (k, e) in self.positions().iter().enumerate() {
            let id = format!("p{k:0width$}");
            let text = format!(
                "id = \"{id}\"\nposition = [{:.6}, {:.6}, {:.6}]\nresolution = [{}, {}]\n",
                e[0], e[1], e[2], self.resolution[0], self.resolution[1]
            );
            crate::atomic::write(&pdir.join(format!("{id}.toml")), text.as_bytes())?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Display;

    #[test]
    fn the_g10_wall_loads_back() {
        let d = tempfile::tempdir().unwrap();
        let spec = WallSpec::holovizio72();
        spec.write(d.path()).unwrap();
        let disp = Display::load(&d.path().join("display.toml")).unwrap();
        assert_eq!(disp.projectors.len(), 72);
        let pixels: u64 = disp
            .projectors
            .iter()
            .map(|p| p.resolution[0] as u64 * p.resolution[1] as u64)
            .sum();
        assert_eq!(pixels, 34_560_000); // G10: "35Mpixels"
        assert_eq!(disp.screen.angular_accuracy_deg, 0.8);
        // spread over the field of view, all behind the screen
        let xs: Vec<f64> = disp.projectors.iter().map(|p| p.position[0]).collect();
        assert!(xs.windows(2).all(|w| w[1] > w[0]));
        assert!(disp.projectors.iter().all(|p| p.position[2] < 0.0));
        let a0 = (xs[0] / 2.0).asin().to_degrees();
        assert!((a0 + 25.0 - 50.0 / 144.0).abs() < 1e-4, "{a0}");
        // contiguous blocks over 4 back ends: 18 each
        let a = disp.assignment(4).unwrap();
        assert!(a.iter().all(|v| v.len() == 18));
    }

    #[test]
    fn bad_specs_are_refused() {
        let d = tempfile::tempdir().unwrap();
        let mut s = WallSpec::holovizio72();
        s.projectors = 0;
        assert!(s.write(d.path()).is_err());
        let mut s = WallSpec::holovizio72();
        s.fov_deg = 190.0;
        assert!(format!("{:#}", s.write(d.path()).unwrap_err()).contains("--fov"));
    }
}
