//! A Looking Glass: a lenticular light field panel. Its views fill a quilt
//! (columns × rows of tiles, view 0 at the bottom left, then left to right
//! and bottom to top), and each sub-pixel of the panel shows one view
//! through the slanted lenses in front of it. The device carries its
//! calibration as `visual.json` (every number wrapped as `{"value": x}`);
//! this is that calibration and the published mapping from a panel
//! sub-pixel to its view (Looking Glass WebXR, `LookingGlassConfig.ts` and
//! the lenticular shader of `HoloPlayXRWebGLLayer.js`, Apache-2.0):
//!
//! - pitch_u = pitch · screenW / DPI · cos(atan(1 / slope)) lens periods
//!   across the panel's width, tilt = screenH / (screenW · slope) (negated
//!   with flipImageX), subp = 1 / (3 · screenW) (likewise);
//! - for sub-pixel c ∈ {0, 1, 2} (red, green, blue) of the panel point
//!   (u, v) (u to the right, v up, both in [0, 1]): its lens phase k = c
//!   (with flipSubp, red takes phase 2 and blue phase 0: the Unity SDK's
//!   `ri`/`bi`), a = (u + k·subp + v·tilt)·pitch_u − center, the view
//!   fraction f = fract(a) (1 − fract(a) with invView), and the view
//!   ⌊f·N⌋ of N, whose channel c the sub-pixel shows, sampled (nearest) at
//!   (u, v) flipped where flipImageX/Y say (as the Unity SDK's shader
//!   samples; the WebXR one leaves the flags to the signs of tilt and
//!   subp).

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};

/// The calibration of one device, and the quilt its views fill.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LookingGlass {
    /// Lenticules per inch, across the lenses.
    pub pitch: f64,
    /// The lenses' slant, in pixels of x per pixel of y.
    pub slope: f64,
    /// The view phase at the panel's left edge.
    pub center: f64,
    /// The angle the views span (degrees).
    pub view_cone_deg: f64,
    /// Views counted from the other end of the lens period.
    #[serde(default)]
    pub inv_view: bool,
    /// The panel: pixels per inch, and its pixels across and down.
    pub dpi: f64,
    pub screen: [u32; 2],
    #[serde(default)]
    pub flip_x: bool,
    #[serde(default)]
    pub flip_y: bool,
    /// Red and blue sub-pixels swapped.
    #[serde(default)]
    pub flip_subp: bool,
    /// Quilt columns and rows: the views, cols × rows of them.
    pub quilt: [u32; 2],
}

/// What the interleaving needs per panel, in the shader's order.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lenticular {
    pub pitch: f64,
    pub tilt: f64,
    pub subp: f64,
    pub center: f64,
    pub views: u32,
}

impl LookingGlass {
    /// Reads a device's `visual.json` (numbers as `{"value": x}` or plain),
    /// with the quilt to render; errors name the file and the field.
    pub fn from_visual_json(text: &str, quilt: [u32; 2], file: &str) -> Result<Self> {
        let v: serde_json::Value =
            serde_json::from_str(text).with_context(|| format!("{file}: not JSON"))?;
        let num = |k: &str| -> Result<f64> {
            let x = v
                .get(k)
                .with_context(|| format!("{file}: missing \"{k}\""))?;
            let x = x.get("value").unwrap_or(x);
            x.as_f64()
                .filter(|f| f.is_finite())
                .with_context(|| format!("{file}: {k}: expected a number, got {x}"))
        };
        let flag = |k: &str| -> Result<bool> {
            Ok(match v.get(k) {
                None => false,
                Some(_) => num(k)? >= 0.5,
            })
        };
        let side = |k: &str| -> Result<u32> {
            let x = num(k)?;
            if !(1.0..=32768.0).contains(&x) || x.fract() != 0.0 {
                bail!("{file}: {k}: expected a whole number of pixels from 1 to 32768, got {x}");
            }
            Ok(x as u32)
        };
        let lg = LookingGlass {
            pitch: num("pitch")?,
            slope: num("slope")?,
            center: num("center")?,
            view_cone_deg: num("viewCone")?,
            inv_view: flag("invView")?,
            dpi: num("DPI")?,
            screen: [side("screenW")?, side("screenH")?],
            flip_x: flag("flipImageX")?,
            flip_y: flag("flipImageY")?,
            flip_subp: flag("flipSubp")?,
            quilt,
        };
        lg.check(file)?;
        Ok(lg)
    }

    /// The values a device can have; `what` names the file in errors.
    pub fn check(&self, what: &str) -> Result<()> {
        if !(self.pitch.is_finite() && self.pitch > 0.0) {
            bail!("{what}: pitch must be > 0 (got {})", self.pitch);
        }
        if !(self.slope.is_finite() && self.slope.abs() >= 1e-3) {
            bail!(
                "{what}: slope must be a finite slant, not 0 (got {})",
                self.slope
            );
        }
        if !self.center.is_finite() {
            bail!("{what}: center must be finite (got {})", self.center);
        }
        if !(self.dpi.is_finite() && self.dpi > 0.0) {
            bail!("{what}: DPI must be > 0 (got {})", self.dpi);
        }
        if !(self.view_cone_deg > 0.0 && self.view_cone_deg < 170.0) {
            bail!(
                "{what}: the view cone must be in (0°, 170°) (got {})",
                self.view_cone_deg
            );
        }
        if self.quilt.contains(&0) || self.quilt[0] * self.quilt[1] > 1024 {
            bail!(
                "{what}: quilt: columns × rows from 1 to 1024 views (got {:?})",
                self.quilt
            );
        }
        Ok(())
    }

    pub fn views(&self) -> u32 {
        self.quilt[0] * self.quilt[1]
    }

    /// The panel's size (m).
    pub fn size_m(&self) -> [f64; 2] {
        self.screen.map(|p| p as f64 / self.dpi * 0.0254)
    }

    /// The mapping's constants (the published conversion).
    pub fn lenticular(&self) -> Lenticular {
        let [w, h] = self.screen.map(f64::from);
        let flip = if self.flip_x { -1.0 } else { 1.0 };
        Lenticular {
            pitch: self.pitch * w / self.dpi * (1.0 / self.slope).atan().cos(),
            tilt: h / (w * self.slope) * flip,
            subp: 1.0 / (3.0 * w) * flip,
            center: self.center,
            views: self.views(),
        }
    }

    /// The angle of view `i` from the panel's normal (radians): the views
    /// span the cone evenly, view 0 at its left end.
    pub fn view_angle(&self, i: u32) -> f64 {
        let f = (i as f64 + 0.5) / self.views() as f64 - 0.5;
        (self.view_cone_deg * f).to_radians()
    }
}

impl LookingGlass {
    /// Writes `dir/display.toml` (this device as the screen, the views as
    /// its projectors in quilt order, the calibration as `[looking_glass]`)
    /// and `dir/views/vNN.toml`: view i is a camera at distance `distance`
    /// (m) in front of the panel, moved along x to D·tan θᵢ, its frustum
    /// through the whole panel (the off-axis camera of Looking Glass's
    /// software, which is the multiple-centre-of-projection ray of G10 Eq. 1
    /// with η = 1 and the observer at the same distance).
    pub fn write_display(
        &self,
        dir: &std::path::Path,
        view: [u32; 2],
        distance: f64,
    ) -> Result<()> {
        use std::fmt::Write;
        self.check("the Looking Glass")?;
        if !(distance.is_finite() && distance > 0.0) {
            bail!("the viewing distance must be > 0 m (got {distance})");
        }
        let vdir = dir.join("views");
        std::fs::create_dir_all(&vdir)
            .with_context(|| format!("{}: cannot create", vdir.display()))?;
        let [w, h] = self.size_m();
        let n = self.views();
        let mut d = String::new();
        let _ = writeln!(
            d,
            "# A Looking Glass: a {}×{} panel at {} DPI, {} views ({}×{} quilt) over {}°, each {}×{},\n\
             # seen from {distance} m. Render it with η = 1 (render.eta) and one back end.\n\
             [screen]\nsize = [{w}, {h}]\npixel_size = {}\nangular_accuracy_deg = {}\n\n\
             [observer]\nposition = [0, 0, {distance}]\nprojectors = \"views/\"\n",
            self.screen[0],
            self.screen[1],
            self.dpi,
            n,
            self.quilt[0],
            self.quilt[1],
            self.view_cone_deg,
            view[0],
            view[1],
            0.0254 / self.dpi,
            self.view_cone_deg / n as f64,
        );
        let table = toml::to_string(self).context("the calibration as TOML")?;
        let _ = write!(d, "[looking_glass]\n{table}");
        crate::atomic::write(&dir.join("display.toml"), d.as_bytes())?;
        let digits = (n - 1).to_string().len().max(2);
        for i in 0..n {
            let id = format!("v{i:0digits$}");
            let x = distance * self.view_angle(i).tan();
            let text = format!(
                "id = \"{id}\"\nposition = [{x:.9}, 0, {distance}]\nresolution = [{}, {}]\n",
                view[0], view[1]
            );
            crate::atomic::write(&vdir.join(format!("{id}.toml")), text.as_bytes())?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const PORTRAIT: &str = r#"{ "configVersion": "3.0", "serial": "LKG-P0XXXX",
      "pitch": {"value": 52.59267044067383}, "slope": {"value": -7.083540916442871},
      "center": {"value": 0.8167931437492371}, "viewCone": {"value": 40.0},
      "invView": {"value": 1.0}, "verticalAngle": {"value": 0.0}, "DPI": {"value": 324.0},
      "screenW": {"value": 1536.0}, "screenH": {"value": 2048.0},
      "flipImageX": {"value": 0.0}, "flipImageY": {"value": 0.0}, "flipSubp": {"value": 0.0} }"#;

    #[test]
    fn the_published_conversion() {
        let lg = LookingGlass::from_visual_json(PORTRAIT, [8, 6], "visual.json").unwrap();
        let l = lg.lenticular();
        // The figures worked out from the same formulas by hand.
        assert!((l.pitch - 246.8802).abs() < 1e-3, "{}", l.pitch);
        assert!((l.tilt - -0.188230).abs() < 1e-6, "{}", l.tilt);
        assert!((l.subp - 2.17014e-4).abs() < 1e-9);
        assert_eq!(l.views, 48);
        assert!(lg.inv_view && !lg.flip_x);
        let [w, h] = lg.size_m();
        assert!((w - 0.12041).abs() < 1e-4 && (h - 0.16055).abs() < 1e-4);
    }

    #[test]
    fn bad_calibrations_are_named() {
        let err = |t: &str| {
            LookingGlass::from_visual_json(t, [8, 6], "v.json")
                .unwrap_err()
                .to_string()
        };
        assert!(err("{").contains("v.json: not JSON"));
        assert!(err(&PORTRAIT.replace("\"DPI\"", "\"dpi\"")).contains("missing \"DPI\""));
        assert!(err(&PORTRAIT.replace("1536.0", "15.5")).contains("screenW"));
        assert!(err(&PORTRAIT.replace("-7.083540916442871", "0")).contains("slope"));
        assert!(LookingGlass::from_visual_json(PORTRAIT, [0, 6], "v.json")
            .unwrap_err()
            .to_string()
            .contains("quilt"));
    }

    #[test]
    fn a_written_display_loads_with_its_views_in_quilt_order() {
        let lg = LookingGlass::from_visual_json(PORTRAIT, [4, 3], "visual.json").unwrap();
        let dir = tempfile::tempdir().unwrap();
        lg.write_display(dir.path(), [30, 40], 0.6).unwrap();
        let d = crate::config::Display::load(&dir.path().join("display.toml")).unwrap();
        assert_eq!(d.looking_glass.as_ref(), Some(&lg));
        assert_eq!(d.projectors.len(), 12);
        assert_eq!(d.projectors[0].id, "v00");
        // The views sweep the cone from the left, symmetric about the axis.
        let x: Vec<f64> = d.projectors.iter().map(|p| p.position[0]).collect();
        assert!(x.windows(2).all(|w| w[0] < w[1]));
        assert!((x[0] + x[11]).abs() < 1e-9);
        assert!((x[11] - 0.6 * (40f64 * (11.5 / 12.0 - 0.5)).to_radians().tan()).abs() < 1e-6);
        assert!((d.screen.size[0] - lg.size_m()[0]).abs() < 1e-12);
    }
}
