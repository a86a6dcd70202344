//! What `parallax info` reports about a database, and `--verify`: decode
//! every stored brick and check it.

use crate::store::OctreeDb;
use anyhow::{bail, Result};
use rayon::prelude::*;
use std::fmt::Write;

/// Bricks per level: (stored, empty).
pub fn bricks_per_level(db: &OctreeDb) -> Vec<(usize, usize)> {
    let mut v = vec![(0, 0); db.layout().levels as usize];
    for n in &db.nodes {
        let e = &mut v[n.key.level as usize];
        if n.is_stored() {
            e.0 += 1;
        } else {
            e.1 += 1;
        }
    }
    v
}

/// A human-readable description of the database.
pub fn describe(db: &OctreeDb) -> String {
    let h = &db.header;
    let l = db.layout();
    let s = &db.summary;
    let mut o = String::new();
    let _ = writeln!(o, "file:          {}", db.path().display());
    let _ = writeln!(o, "source:        {}", h.source);
    let _ = writeln!(
        o,
        "dimensions:    {} × {} × {} {}",
        h.info.dims[0],
        h.info.dims[1],
        h.info.dims[2],
        h.info.voxel_type.name()
    );
    let _ = writeln!(
        o,
        "spacing:       {} × {} × {}",
        h.info.spacing[0], h.info.spacing[1], h.info.spacing[2]
    );
    let _ = writeln!(o, "value range:   {} … {}", s.value_min, s.value_max);
    if let Some(w) = &s.world {
        let r = |k: usize| w[k].map(|x| (x * 1e4).round() / 1e4);
        let _ = writeln!(
            o,
            "scanner:       volume space → patient LPS mm: rows {:?} {:?} {:?}",
            r(0),
            r(1),
            r(2)
        );
    }
    if let Some(l) = &s.labels {
        let _ = writeln!(o, "labels:        {}", label_list(l));
    }
    let _ = writeln!(
        o,
        "bricks:        {}³ (+{} overlap), encoding {}, empty below {}",
        l.brick,
        crate::store::OVERLAP,
        h.encoding.name(),
        h.empty_below
            .map(|t| t.to_string())
            .unwrap_or_else(|| "(none)".into())
    );
    let _ = writeln!(o, "levels:        {}", l.levels);
    for (lvl, (stored, empty)) in bricks_per_level(db).iter().enumerate() {
        let d = l.level_dims(lvl as u32);
        let sc = l.voxel_scale(lvl as u32);
        let e: [f64; 3] = std::array::from_fn(|a| sc[a] as f64 * h.info.spacing[a]);
        let _ = writeln!(
            o,
            "  level {lvl}: {:>5} × {:>5} × {:>5} voxels of {} × {} × {}, {stored:>8} stored, {empty:>8} empty",
            d[0], d[1], d[2], e[0], e[1], e[2]
        );
    }
    let src = h.info.source_bytes();
    let _ = writeln!(
        o,
        "bytes:         {} (source {}, compression ratio {:.2})",
        db.file_len(),
        src,
        src as f64 / db.file_len() as f64
    );
    let _ = writeln!(
        o,
        "quantisation:  RMS {:.4}, max {:.4} (data units, over {} source voxels)",
        s.quant_rms, s.quant_max, s.quant_samples
    );
    o
}

#[derive(Debug, Clone)]
pub struct VerifyReport {
    pub bricks: usize,
    pub bytes: u64,
}

/// Decodes every stored brick, checking its checksum, its size, and that its
/// values lie within the range its node record claims. Fails naming the
/// first bad brick.
pub fn verify(db: &OctreeDb) -> Result<VerifyReport> {
    let errors: Vec<String> = db
        .nodes
        .par_iter()
        .filter(|n| n.is_stored())
        .filter_map(|n| match db.read_brick(n.key) {
            Err(e) => Some(format!("{e:#}")),
            Ok(Some(v)) => {
                let (lo, hi) = crate::store::codec::value_range(&v);
                let slack = (n.max - n.min).abs() * 1e-6 + f32::EPSILON * n.max.abs().max(1.0);
                (lo < n.min - slack || hi > n.max + slack).then(|| {
                    format!(
                        "{}: brick {}: values {lo}…{hi} outside the recorded range {}…{}",
                        db.path().display(),
                        n.key,
                        n.min,
                        n.max
                    )
                })
            }
            Ok(None) => None,
        })
        .collect();
    if let Some(first) = errors.first() {
        bail!(
            "{first}{}",
            if errors.len() > 1 {
                format!(" (and {} more bad bricks)", errors.len() - 1)
            } else {
                String::new()
            }
        );
    }
    let stored: Vec<_> = db.nodes.iter().filter(|n| n.is_stored()).collect();
    Ok(VerifyReport {
        bricks: stored.len(),
        bytes: stored.iter().map(|n| n.len as u64).sum(),
    })
}

/// A label volume's labels as a short list: runs of consecutive labels as
/// ranges ("0–3, 7, 10–12"), at most 20 entries then the count.
pub fn label_list(labels: &[u32]) -> String {
    let mut runs: Vec<(u32, u32)> = Vec::new();
    for &l in labels {
        match runs.last_mut() {
            Some((_, hi)) if *hi + 1 == l => *hi = l,
            _ => runs.push((l, l)),
        }
    }
    let mut parts: Vec<String> = runs
        .iter()
        .take(20)
        .map(|&(a, b)| {
            if a == b {
                a.to_string()
            } else {
                format!("{a}–{b}")
            }
        })
        .collect();
    if runs.len() > 20 {
        parts.push("…".into());
    }
    format!("{} ({} labels)", parts.join(", "), labels.len())
}
