//! VESA MPCDI import (`parallax calibrate mpcdi`): the standard interchange
//! of multi-projector calibration. A `.mpcdi` file is a zip holding
//! `mpcdi.xml` and, per region (one projector's part of a buffer), a 2D
//! geometry warp (`.pfm`) and an alpha (blend) map (`.png`). Each region
//! of a `2d` profile file becomes the `[calibration]` of the projector
//! whose id is the region's id: its warp and blend map are written beside
//! the projector file and named there (backend/src/calibrate.rs applies
//! them). Tag and attribute names are matched without case, as the
//! standard says, so MPCDI 1.0 files (`level`, `xsize`) read too.

use crate::calibrate::parse_pfm;
use anyhow::{bail, ensure, Context, Result};
use std::io::Read;
use std::path::Path;

/// One region's files, as the archive holds them.
pub struct Region {
    pub id: String,
    pub warp: Vec<u8>,
    /// The alpha map and its embedded gamma.
    pub alpha: Option<(Vec<u8>, f64)>,
}

fn named<'a>(n: roxmltree::Node<'a, 'a>, name: &str) -> bool {
    n.is_element() && n.tag_name().name().eq_ignore_ascii_case(name)
}

fn attr<'a>(n: roxmltree::Node<'a, 'a>, name: &str) -> Option<&'a str> {
    n.attributes()
        .find(|a| a.name().eq_ignore_ascii_case(name))
        .map(|a| a.value())
}

/// The text of child `name` of `n`, trimmed.
fn child_text<'a>(n: roxmltree::Node<'a, 'a>, name: &str) -> Option<&'a str> {
    n.children()
        .find(|c| named(*c, name))
        .and_then(|c| c.text())
        .map(str::trim)
}

/// The regions of a `2d` profile `.mpcdi` file, with their files.
pub fn read(path: &Path) -> Result<Vec<Region>> {
    let f = path.display().to_string();
    let file = std::fs::File::open(path).with_context(|| format!("{f}: cannot read"))?;
    let mut zip = zip::ZipArchive::new(file)
        .with_context(|| format!("{f}: not an MPCDI file (a zip archive)"))?;
    let mut entry = |name: &str| -> Result<Vec<u8>> {
        let mut e = zip
            .by_name(name)
            .with_context(|| format!("{f}: the archive has no '{name}'"))?;
        ensure!(e.size() < 1 << 30, "{f}: {name}: larger than 1 GiB");
        let mut v = Vec::with_capacity(e.size() as usize);
        e.read_to_end(&mut v)
            .with_context(|| format!("{f}: {name}: cannot unpack"))?;
        Ok(v)
    };
    let xml = String::from_utf8(entry("mpcdi.xml")?)
        .with_context(|| format!("{f}: mpcdi.xml is not UTF-8"))?;
    let doc = roxmltree::Document::parse(&xml).with_context(|| format!("{f}: mpcdi.xml"))?;
    let root = doc.root_element();
    ensure!(
        named(root, "MPCDI"),
        "{f}: mpcdi.xml: the root element is not <MPCDI>"
    );
    let profile = attr(root, "profile").unwrap_or("");
    if !profile.eq_ignore_ascii_case("2d") {
        bail!("{f}: mpcdi.xml: profile '{profile}': only the 2d profile (media: 2D warps) imports");
    }
    let regions: Vec<&str> = root
        .descendants()
        .filter(|n| named(*n, "region"))
        .map(|n| attr(n, "id").unwrap_or(""))
        .collect();
    ensure!(!regions.is_empty(), "{f}: mpcdi.xml: no <region>");
    let mut out = Vec::new();
    for id in regions {
        ensure!(!id.is_empty(), "{f}: mpcdi.xml: a <region> without an id");
        let set = root
            .descendants()
            .find(|n| named(*n, "fileset") && attr(*n, "region") == Some(id))
            .with_context(|| format!("{f}: mpcdi.xml: no <fileset> for region '{id}'"))?;
        let warp = set
            .children()
            .find(|c| named(*c, "geometryWarpFile"))
            .and_then(|w| child_text(w, "path"))
            .with_context(|| format!("{f}: region '{id}': no geometryWarpFile path"))?;
        let warp_bytes = entry(warp)?;
        parse_pfm(&warp_bytes, &format!("{f}: {warp}"))?;
        let alpha = match set.children().find(|c| named(*c, "alphaMap")) {
            None => None,
            Some(a) => {
                let p = child_text(a, "path")
                    .with_context(|| format!("{f}: region '{id}': alphaMap without a path"))?;
                let gamma = match child_text(a, "gammaEmbedded") {
                    None => 1.0,
                    Some(g) => g
                        .parse::<f64>()
                        .ok()
                        .filter(|g| g.is_finite() && *g > 0.0 && *g < 10.0)
                        .with_context(|| {
                            format!("{f}: region '{id}': gammaEmbedded '{g}' is not a gamma")
                        })?,
                };
                Some((entry(p)?, gamma))
            }
        };
        out.push(Region {
            id: id.to_string(),
            warp: warp_bytes,
            alpha,
        });
    }
    Ok(out)
}

/// Imports every region of `mpcdi` into the projector file of the same id
/// in `dir`: writes `<id>.warp.pfm` (and `<id>.blend.png`) there and sets
/// the file's `[calibration]`. Returns the ids. Nothing is written unless
/// every region has its projector file.
pub fn import(mpcdi: &Path, dir: &Path) -> Result<Vec<String>> {
    let regions = read(mpcdi)?;
    let file_of = |id: &str| dir.join(format!("{id}.toml"));
    for r in &regions {
        parallax_common::paths::check_file_component(
            &r.id,
            &format!("{}: region id", mpcdi.display()),
        )?;
        ensure!(
            file_of(&r.id).is_file(),
            "{}: region '{}': no projector file {}",
            mpcdi.display(),
            r.id,
            file_of(&r.id).display()
        );
    }
    for r in &regions {
        let pf = file_of(&r.id);
        let text = std::fs::read_to_string(&pf)
            .with_context(|| format!("{}: cannot read", pf.display()))?;
        let mut t: toml::Table = text
            .parse()
            .with_context(|| format!("{}: not TOML", pf.display()))?;
        let mut cal = toml::Table::new();
        let warp = format!("{}.warp.pfm", r.id);
        parallax_common::atomic::write(&dir.join(&warp), &r.warp)?;
        cal.insert("mesh".into(), warp.into());
        if let Some((png, gamma)) = &r.alpha {
            let blend = format!("{}.blend.png", r.id);
            parallax_common::atomic::write(&dir.join(&blend), png)?;
            cal.insert("blend".into(), blend.into());
            cal.insert("blend_gamma".into(), (*gamma).into());
        }
        t.insert("calibration".into(), cal.into());
        parallax_common::atomic::write(&pf, toml::to_string(&t)?.as_bytes())?;
    }
    Ok(regions.into_iter().map(|r| r.id).collect())
}
