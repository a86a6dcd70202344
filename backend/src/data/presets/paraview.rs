//! ParaView colour-map presets (`.json`, as jsoncpp reads them).

#[allow(unused_imports)]
use super::*;

/// ParaView reads presets with jsoncpp, which allows `//` and `/* */`
/// comments and trailing commas; they are blanked out here (newlines kept,
/// so serde_json's line numbers stay right).
pub(super) fn relax_json(text: &str) -> String {
    let b = text.as_bytes();
    let mut out = b.to_vec();
    let mut i = 0;
    let mut in_string = false;
    let mut pending_comma: Option<usize> = None;
    while i < b.len() {
        let c = b[i];
        if in_string {
            match c {
                b'\\' => i += 2,
                b'"' => {
                    in_string = false;
                    i += 1;
                }
                _ => i += 1,
            }
            continue;
        }
        match c {
            b'"' => {
                in_string = true;
                pending_comma = None;
                i += 1;
            }
            b'/' if b.get(i + 1) == Some(&b'/') => {
                while i < b.len() && b[i] != b'\n' {
                    out[i] = b' ';
                    i += 1;
                }
            }
            b'/' if b.get(i + 1) == Some(&b'*') => {
                let start = i;
                i += 2;
                while i < b.len() && !(b[i] == b'*' && b.get(i + 1) == Some(&b'/')) {
                    i += 1;
                }
                let end = (i + 2).min(b.len());
                for o in &mut out[start..end] {
                    if *o != b'\n' {
                        *o = b' ';
                    }
                }
                i = end;
            }
            b',' => {
                pending_comma = Some(i);
                i += 1;
            }
            b']' | b'}' => {
                if let Some(p) = pending_comma.take() {
                    out[p] = b' ';
                }
                i += 1;
            }
            c if c.is_ascii_whitespace() => i += 1,
            _ => {
                pending_comma = None;
                i += 1;
            }
        }
    }
    // Only whole UTF-8 sequences (inside comments) were replaced, byte by
    // byte, with spaces.
    String::from_utf8(out).unwrap_or_else(|_| text.to_string())
}

pub(super) fn parse_json(text: &str, origin: &str) -> Result<Value> {
    let text = text.trim_start_matches('\u{feff}');
    serde_json::from_str(&relax_json(text)).map_err(|e| anyhow!("{origin}: not valid JSON: {e}"))
}

pub(super) fn json_kind(v: &Value) -> String {
    match v {
        Value::Null => "null".into(),
        Value::Bool(b) => format!("{b}"),
        Value::Number(n) => format!("the number {n}"),
        Value::String(s) if s.chars().count() > 40 => {
            format!("a string ({:?}…)", s.chars().take(40).collect::<String>())
        }
        Value::String(s) => format!("the string {s:?}"),
        Value::Array(_) => "an array".into(),
        Value::Object(_) => "an object".into(),
    }
}

/// The presets of a ParaView JSON file, with their names ("entry N" for an
/// unnamed one).
pub(super) fn paraview_entries<'a>(
    root: &'a Value,
    origin: &str,
) -> Result<Vec<(String, &'a Map<String, Value>)>> {
    let items: Vec<&Value> = match root {
        Value::Array(a) => a.iter().collect(),
        Value::Object(_) => vec![root],
        other => bail!(
            "{origin}: expected a JSON array of ParaView presets or one preset object, got {}",
            json_kind(other)
        ),
    };
    if items.is_empty() {
        bail!("{origin}: the JSON array holds no presets");
    }
    items
        .into_iter()
        .enumerate()
        .map(|(i, v)| {
            let obj = v.as_object().ok_or_else(|| {
                anyhow!(
                    "{origin}: entry {}: expected a preset object, got {}",
                    i + 1,
                    json_kind(v)
                )
            })?;
            let name = match obj.get("Name") {
                None => format!("entry {}", i + 1),
                Some(Value::String(s)) => s.clone(),
                Some(other) => bail!(
                    "{origin}: entry {}: Name: expected a string, got {}",
                    i + 1,
                    json_kind(other)
                ),
            };
            Ok((name, obj))
        })
        .collect()
}

pub(super) fn json_numbers(v: &Value, field: &str, ctx: &str) -> Result<Vec<f64>> {
    let arr = v.as_array().ok_or_else(|| {
        anyhow!(
            "{ctx}: {field}: expected an array of numbers, got {}",
            json_kind(v)
        )
    })?;
    arr.iter()
        .enumerate()
        .map(|(i, x)| {
            x.as_f64().filter(|f| f.is_finite()).ok_or_else(|| {
                anyhow!(
                    "{ctx}: {field}[{i}]: expected a number, got {}",
                    json_kind(x)
                )
            })
        })
        .collect()
}

pub(super) fn json_flag(v: Option<&Value>) -> Option<bool> {
    match v? {
        Value::Bool(b) => Some(*b),
        Value::Number(n) => Some(n.as_f64() != Some(0.0)),
        _ => None,
    }
}

pub(super) fn paraview_source(
    name: &str,
    obj: &Map<String, Value>,
    origin: &str,
) -> Result<Source> {
    let ctx = format!("{origin}: preset {name:?}");
    if json_flag(obj.get("UseLogScale")) == Some(true) {
        bail!("{ctx}: UseLogScale: colour maps interpolated in log scale are not supported");
    }
    let rgb = match obj.get("RGBPoints") {
        Some(v) => json_numbers(v, "RGBPoints", &ctx)?,
        None if obj.contains_key("IndexedColors") => bail!(
            "{ctx}: a categorical colour map (IndexedColors, no RGBPoints) has no transfer function to convert"
        ),
        None => bail!("{ctx}: no RGBPoints"),
    };
    if rgb.is_empty() {
        bail!("{ctx}: RGBPoints is empty");
    }
    if rgb.len() % 4 != 0 {
        bail!(
            "{ctx}: RGBPoints: {} numbers do not make whole (x, r, g, b) groups of 4",
            rgb.len()
        );
    }
    let color: Vec<Node<[f64; 3]>> = rgb
        .chunks_exact(4)
        .map(|c| Node::linear(c[0], [c[1], c[2], c[3]]))
        .collect();
    check_nodes(&color, |c| c.to_vec(), "colour component")
        .map_err(|e| anyhow!("{ctx}: RGBPoints: {e}"))?;

    let mut notes = Vec::new();
    let wrap = json_flag(obj.get("HSVWrap")).unwrap_or(false);
    let space = match obj.get("ColorSpace") {
        None => {
            notes.push(
                "The preset names no ColorSpace: colours were interpolated in Lab, \
                 the default of a new ParaView colour map."
                    .to_string(),
            );
            ColorSpace::Lab
        }
        Some(Value::String(s)) => match s.to_ascii_lowercase().as_str() {
            "rgb" => ColorSpace::Rgb,
            "hsv" => ColorSpace::Hsv { wrap },
            "lab" | "cielab" => ColorSpace::Lab,
            "diverging" => ColorSpace::Diverging,
            "step" => ColorSpace::Step,
            "lab/ciede2000" => {
                notes.push(
                    "ColorSpace Lab/CIEDE2000 was approximated by Lab interpolation.".to_string(),
                );
                ColorSpace::Lab
            }
            _ => bail!(
                "{ctx}: ColorSpace: unknown colour space {s:?} \
                 (known: RGB, HSV, Lab, CIELAB, Lab/CIEDE2000, Diverging, Step)"
            ),
        },
        Some(other) => bail!(
            "{ctx}: ColorSpace: expected a string, got {}",
            json_kind(other)
        ),
    };

    let opacity = match obj.get("Points") {
        None | Some(Value::Null) => None,
        Some(v) => {
            let p = json_numbers(v, "Points", &ctx)?;
            if p.len() % 4 != 0 {
                bail!(
                    "{ctx}: Points: {} numbers do not make whole (x, alpha, midpoint, sharpness) groups of 4",
                    p.len()
                );
            }
            let nodes: Vec<Node<f64>> = p
                .chunks_exact(4)
                .map(|c| Node {
                    x: c[0],
                    v: c[1],
                    midpoint: c[2],
                    sharpness: c[3],
                })
                .collect();
            check_nodes(&nodes, |a| vec![*a], "alpha")
                .map_err(|e| anyhow!("{ctx}: Points: {e}"))?;
            Some(nodes)
        }
    };
    Ok(Source {
        name: name.to_string(),
        color,
        space,
        opacity,
        unit: None,
        normalized_check: true,
        notes,
    })
}
