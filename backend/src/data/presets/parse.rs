//! What the readers share: file stems, picking a preset by name, checking
//! a function's nodes.

#[allow(unused_imports)]
use super::*;

/// The file name without directories and the `.json` / `.vp` extensions.
pub(super) fn file_stem(origin: &str) -> String {
    let base = Path::new(origin)
        .file_name()
        .map_or_else(|| origin.to_string(), |f| f.to_string_lossy().into_owned());
    let mut s = base.as_str();
    for ext in [".json", ".vp", ".txt"] {
        if s.len() > ext.len() && s.to_ascii_lowercase().ends_with(ext) {
            s = &s[..s.len() - ext.len()];
        }
    }
    s.to_string()
}

/// Picks a preset by name ([`import_preset`] explains the rules).
pub(super) fn select_preset(names: &[String], wanted: Option<&str>, origin: &str) -> Result<usize> {
    let listing = || {
        let mut seen = std::collections::HashMap::new();
        for n in names {
            *seen.entry(n.as_str()).or_insert(0) += 1;
        }
        names
            .iter()
            .enumerate()
            .map(|(i, n)| {
                if seen[n.as_str()] > 1 {
                    format!("{n:?} (#{})", i + 1)
                } else {
                    format!("{n:?}")
                }
            })
            .collect::<Vec<_>>()
            .join(", ")
    };
    let Some(w) = wanted else {
        return match names.len() {
            1 => Ok(0),
            n => bail!(
                "{origin}: holds {n} presets; name the one to convert: {}",
                listing()
            ),
        };
    };
    let exact: Vec<usize> = (0..names.len()).filter(|&i| names[i] == w).collect();
    match exact.len() {
        1 => return Ok(exact[0]),
        0 => {}
        _ => bail!(
            "{origin}: {} presets are named {w:?} ({}); choose one by number, e.g. \"#{}\"",
            exact.len(),
            exact
                .iter()
                .map(|i| format!("#{}", i + 1))
                .collect::<Vec<_>>()
                .join(", "),
            exact[0] + 1
        ),
    }
    let folded: Vec<usize> = (0..names.len())
        .filter(|&i| names[i].eq_ignore_ascii_case(w))
        .collect();
    if folded.len() == 1 {
        return Ok(folded[0]);
    }
    if let Some(k) = w.strip_prefix('#').and_then(|k| k.parse::<usize>().ok()) {
        if (1..=names.len()).contains(&k) {
            return Ok(k - 1);
        }
        bail!(
            "{origin}: no preset #{k}: the file holds {} presets",
            names.len()
        );
    }
    bail!(
        "{origin}: no preset named {w:?}; the presets are: {}",
        listing()
    )
}

/// Checks a function's nodes: x non-decreasing, values in [0, 1], VTK's
/// midpoint and sharpness in [0, 1]. Points are numbered from 1.
pub(super) fn check_nodes<V: Copy>(
    nodes: &[Node<V>],
    values: impl Fn(&V) -> Vec<f64>,
    value_name: &str,
) -> std::result::Result<(), String> {
    for (i, n) in nodes.iter().enumerate() {
        let k = i + 1;
        if i > 0 && n.x < nodes[i - 1].x {
            return Err(format!(
                "point {k}: x = {} comes after x = {}; points must be in increasing x order",
                n.x,
                nodes[i - 1].x
            ));
        }
        for v in values(&n.v) {
            if !(0.0..=1.0).contains(&v) {
                return Err(format!("point {k}: {value_name} {v} is outside [0, 1]"));
            }
        }
        if !(0.0..=1.0).contains(&n.midpoint) {
            return Err(format!(
                "point {k}: midpoint {} is outside [0, 1]",
                n.midpoint
            ));
        }
        if !(0.0..=1.0).contains(&n.sharpness) {
            return Err(format!(
                "point {k}: sharpness {} is outside [0, 1]",
                n.sharpness
            ));
        }
    }
    Ok(())
}
