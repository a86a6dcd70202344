//! 3D Slicer volume properties: `presets.xml` and scene files, `.vp` and
//! `.vp.json`.

#[allow(unused_imports)]
use super::*;

/// Parses a Slicer "N v1 … vN" list (N counts the numbers) of groups of
/// `group` numbers; an empty text is an empty list.
pub(super) fn slicer_numbers(
    text: &str,
    group: usize,
    group_name: &str,
) -> std::result::Result<Vec<f64>, String> {
    let mut tokens = text.split_whitespace();
    let Some(first) = tokens.next() else {
        return Ok(Vec::new());
    };
    let count: usize = first.parse().map_err(|_| {
        format!("the leading count {first:?} is not a whole number (expected \"N v1 … vN\")")
    })?;
    let values: Vec<&str> = tokens.collect();
    if values.len() != count {
        return Err(format!(
            "the count says {count} values but {} follow",
            values.len()
        ));
    }
    if count / group * group != count {
        return Err(format!(
            "{count} values do not make whole {group_name} groups of {group}"
        ));
    }
    values
        .iter()
        .enumerate()
        .map(|(i, t)| {
            let v: f64 = t
                .parse()
                .map_err(|_| format!("value {} ({t:?}) is not a number", i + 1))?;
            if v.is_finite() {
                Ok(v)
            } else {
                Err(format!("value {} ({t}) is not finite", i + 1))
            }
        })
        .collect()
}

/// Builds a Slicer source from its three transfer-function strings
/// (scalar opacity, gradient opacity, colour), each with the name errors
/// use for it.
pub(super) fn slicer_source(
    name: &str,
    [(so_name, so), (go_name, go), (ct_name, ct)]: [(&str, Option<&str>); 3],
    ctx: &str,
    mut notes: Vec<String>,
) -> Result<Source> {
    let opacity = match so {
        None => None,
        Some(t) => {
            let v =
                slicer_numbers(t, 2, "(x, alpha)").map_err(|e| anyhow!("{ctx}: {so_name}: {e}"))?;
            let nodes: Vec<Node<f64>> = v
                .chunks_exact(2)
                .map(|c| Node::linear(c[0], c[1]))
                .collect();
            check_nodes(&nodes, |a| vec![*a], "alpha")
                .map_err(|e| anyhow!("{ctx}: {so_name}: {e}"))?;
            Some(nodes)
        }
    };
    if let Some(t) = go {
        let v = slicer_numbers(t, 2, "(gradient, alpha)")
            .map_err(|e| anyhow!("{ctx}: {go_name}: {e}"))?;
        if v.chunks_exact(2).any(|c| c[1] != 1.0) {
            notes.push(format!(
                "Gradient opacity \"{}\" was dropped (Parallax transfer functions depend on the value only).",
                t.trim()
            ));
        }
    }
    let Some(ct) = ct else {
        bail!("{ctx}: {ct_name}: missing (the colour transfer function)");
    };
    let v = slicer_numbers(ct, 4, "(x, r, g, b)").map_err(|e| anyhow!("{ctx}: {ct_name}: {e}"))?;
    if v.is_empty() {
        bail!("{ctx}: {ct_name}: no colour points");
    }
    let color: Vec<Node<[f64; 3]>> = v
        .chunks_exact(4)
        .map(|c| Node::linear(c[0], [c[1], c[2], c[3]]))
        .collect();
    check_nodes(&color, |c| c.to_vec(), "colour component")
        .map_err(|e| anyhow!("{ctx}: {ct_name}: {e}"))?;
    Ok(Source {
        name: name.to_string(),
        color,
        space: ColorSpace::Rgb,
        opacity,
        unit: None,
        normalized_check: false,
        notes,
    })
}

/// The note for Slicer's shading parameters, when shading is on.
pub(super) fn slicer_shading_note(
    shade: Option<&str>,
    params: [(&str, Option<&str>); 4],
) -> Vec<String> {
    let on = shade.is_some_and(|s| {
        let s = s.trim();
        s == "1" || s.eq_ignore_ascii_case("true")
    });
    if !on {
        return Vec::new();
    }
    let list: Vec<String> = params
        .iter()
        .filter_map(|(k, v)| v.map(|v| format!("{k} {}", v.trim())))
        .collect();
    vec![format!(
        "Slicer shades this preset ({}); shading is set in the Parallax scene, not in the transfer function.",
        if list.is_empty() {
            "shade on".to_string()
        } else {
            list.join(", ")
        }
    )]
}

/// The `<VolumeProperty>` elements of a Slicer XML file, with their names
/// (the `name` attribute, else the `id`, else "VolumeProperty N").
pub(super) fn slicer_xml_properties(text: &str, origin: &str) -> Result<Vec<(String, XmlElement)>> {
    let elements = parse_xml(text).map_err(|e| anyhow!("{origin}: not well-formed XML: {e}"))?;
    let props: Vec<(String, XmlElement)> = elements
        .into_iter()
        .filter(|e| e.name == "VolumeProperty")
        .enumerate()
        .map(|(i, e)| {
            let name = e
                .attr("name")
                .or_else(|| e.attr("id"))
                .map_or_else(|| format!("VolumeProperty {}", i + 1), str::to_string);
            (name, e)
        })
        .collect();
    if props.is_empty() {
        bail!("{origin}: no <VolumeProperty> elements (expected 3D Slicer's presets.xml)");
    }
    Ok(props)
}

/// The points of a `.vp.json` function: x and the point object.
pub(super) type SortedPoints<'a> = Vec<(f64, &'a Map<String, Value>)>;

/// Where a `.vp.json` file's converted component lies.
const COMPONENT: &str = "volumeProperties[0].components[0]";

/// The component of a `.vp.json` file that is converted, read with errors
/// that name the file (`ctx`) and the field.
struct Component<'a> {
    comp: &'a Value,
    ctx: &'a str,
}

impl<'a> Component<'a> {
    fn number(&self, v: &Value, field: &str) -> Result<f64> {
        let ctx = self.ctx;
        v.as_f64()
            .filter(|f| f.is_finite())
            .ok_or_else(|| anyhow!("{ctx}: {field}: expected a number, got {}", json_kind(v)))
    }

    /// The points of one function, stably sorted by x as Slicer does.
    fn points(&self, field: &str) -> Result<Option<SortedPoints<'a>>> {
        let (ctx, at) = (self.ctx, COMPONENT);
        let Some(f) = self.comp.get(field) else {
            return Ok(None);
        };
        let path = format!("{at}.{field}.points");
        let arr = f
            .get("points")
            .and_then(Value::as_array)
            .ok_or_else(|| anyhow!("{ctx}: {at}.{field}: no \"points\" array"))?;
        let mut out = Vec::with_capacity(arr.len());
        for (i, p) in arr.iter().enumerate() {
            let obj = p.as_object().ok_or_else(|| {
                anyhow!(
                    "{ctx}: {path}[{i}]: expected an object, got {}",
                    json_kind(p)
                )
            })?;
            let x = obj
                .get("x")
                .ok_or_else(|| anyhow!("{ctx}: {path}[{i}]: missing \"x\""))?;
            out.push((self.number(x, &format!("{path}[{i}].x"))?, obj));
        }
        out.sort_by(|a, b| a.0.total_cmp(&b.0));
        Ok(Some(out))
    }

    /// A point's midpoint and sharpness (0.5 and 0 where not given).
    fn shape(&self, obj: &Map<String, Value>, path: &str) -> Result<(f64, f64)> {
        let get = |k: &str, default: f64| match obj.get(k) {
            None => Ok(default),
            Some(v) => self.number(v, &format!("{path}.{k}")),
        };
        Ok((get("midpoint", 0.5)?, get("sharpness", 0.0)?))
    }

    /// The scalar opacity unit distance, where given (> 0).
    fn unit(&self) -> Result<Option<f64>> {
        let (ctx, at) = (self.ctx, COMPONENT);
        match self.comp.get("scalarOpacityUnitDistance") {
            None => Ok(None),
            Some(v) => {
                let u = self.number(v, &format!("{at}.scalarOpacityUnitDistance"))?;
                if u <= 0.0 {
                    bail!("{ctx}: {at}.scalarOpacityUnitDistance: must be > 0 (got {u})");
                }
                Ok(Some(u))
            }
        }
    }

    /// The colour function's nodes.
    fn color(&self) -> Result<Vec<Node<[f64; 3]>>> {
        let (ctx, at) = (self.ctx, COMPONENT);
        let color_pts = self
            .points("rgbTransferFunction")?
            .ok_or_else(|| anyhow!("{ctx}: {at}: no rgbTransferFunction"))?;
        let mut color = Vec::with_capacity(color_pts.len());
        for (i, (x, obj)) in color_pts.iter().enumerate() {
            let path = format!("{at}.rgbTransferFunction.points[{i}]");
            let c = obj
                .get("color")
                .ok_or_else(|| anyhow!("{ctx}: {path}: missing \"color\""))?;
            let c = json_numbers(c, &format!("{path}.color"), ctx)?;
            if c.len() != 3 {
                bail!(
                    "{ctx}: {path}.color: expected 3 numbers [r, g, b], got {}",
                    c.len()
                );
            }
            let (midpoint, sharpness) = self.shape(obj, &path)?;
            color.push(Node {
                x: *x,
                v: [c[0], c[1], c[2]],
                midpoint,
                sharpness,
            });
        }
        if color.is_empty() {
            bail!("{ctx}: {at}.rgbTransferFunction: no points");
        }
        check_nodes(&color, |c| c.to_vec(), "colour component")
            .map_err(|e| anyhow!("{ctx}: {at}.rgbTransferFunction (sorted by x): {e}"))?;
        Ok(color)
    }

    /// The scalar opacity function's nodes, where there is one.
    fn opacity(&self) -> Result<Option<Vec<Node<f64>>>> {
        let (ctx, at) = (self.ctx, COMPONENT);
        let Some(pts) = self.points("scalarOpacity")? else {
            return Ok(None);
        };
        let mut nodes = Vec::with_capacity(pts.len());
        for (i, (x, obj)) in pts.iter().enumerate() {
            let path = format!("{at}.scalarOpacity.points[{i}]");
            let y = obj
                .get("y")
                .ok_or_else(|| anyhow!("{ctx}: {path}: missing \"y\""))?;
            let (midpoint, sharpness) = self.shape(obj, &path)?;
            nodes.push(Node {
                x: *x,
                v: self.number(y, &format!("{path}.y"))?,
                midpoint,
                sharpness,
            });
        }
        check_nodes(&nodes, |a| vec![*a], "alpha")
            .map_err(|e| anyhow!("{ctx}: {at}.scalarOpacity (sorted by x): {e}"))?;
        Ok(Some(nodes))
    }

    /// What the conversion leaves out: a gradient opacity other than 1, and
    /// the shading parameters.
    fn dropped(&self, notes: &mut Vec<String>) -> Result<()> {
        let comp = self.comp;
        let gradient_used = json_flag(comp.get("disableGradientOpacity")) != Some(true);
        if let (true, Some(g)) = (gradient_used, self.points("gradientOpacity")?) {
            let constant_one = g
                .iter()
                .all(|(_, o)| o.get("y").and_then(Value::as_f64) == Some(1.0));
            if !constant_one {
                notes.push(
                    "The gradient opacity was dropped (Parallax transfer functions depend on the value only)."
                        .to_string(),
                );
            }
        }
        if json_flag(comp.get("shade")) == Some(true) {
            let lighting = comp.get("lighting").and_then(Value::as_object);
            let param = |k: &str| lighting.and_then(|l| l.get(k)).map(|v| v.to_string());
            let p1 = param("ambient");
            let p2 = param("diffuse");
            let p3 = param("specular");
            let p4 = param("specularPower");
            notes.extend(slicer_shading_note(
                Some("1"),
                [
                    ("ambient", p1.as_deref()),
                    ("diffuse", p2.as_deref()),
                    ("specular", p3.as_deref()),
                    ("specularPower", p4.as_deref()),
                ],
            ));
        }
        Ok(())
    }
}

pub(super) fn slicer_vp_json_source(root: &Value, origin: &str) -> Result<Source> {
    let name = file_stem(origin);
    let ctx = origin.to_string();
    let vps = root
        .get("volumeProperties")
        .and_then(Value::as_array)
        .ok_or_else(|| anyhow!("{ctx}: no \"volumeProperties\" array"))?;
    let vp = vps
        .first()
        .ok_or_else(|| anyhow!("{ctx}: volumeProperties is empty"))?;
    let mut notes = Vec::new();
    if vps.len() > 1 {
        notes.push(format!(
            "The file holds {} volume properties; the first was converted, as Slicer reads it.",
            vps.len()
        ));
    }
    let comps = vp
        .get("components")
        .and_then(Value::as_array)
        .ok_or_else(|| anyhow!("{ctx}: volumeProperties[0]: no \"components\" array"))?;
    let comp = comps
        .first()
        .ok_or_else(|| anyhow!("{ctx}: volumeProperties[0].components is empty"))?;
    if comps.len() > 1 {
        notes.push(format!(
            "The volume property has {} components; the first was converted.",
            comps.len()
        ));
    }
    let c = Component { comp, ctx: &ctx };
    let unit = c.unit()?;
    let color = c.color()?;
    let opacity = c.opacity()?;
    c.dropped(&mut notes)?;
    Ok(Source {
        name,
        color,
        space: ColorSpace::Rgb,
        opacity,
        unit,
        normalized_check: false,
        notes,
    })
}

// ---------------------------------------------------------------------- XML

/// One element of an XML file: its name and attributes (entities decoded).
#[derive(Clone, Debug)]
pub(super) struct XmlElement {
    pub(super) name: String,
    pub(super) attrs: Vec<(String, String)>,
}

impl XmlElement {
    pub(super) fn attr(&self, name: &str) -> Option<&str> {
        self.attrs
            .iter()
            .find(|(k, _)| k == name)
            .map(|(_, v)| v.as_str())
    }
}

/// Reads the elements of an XML document in document order (roxmltree:
/// the document must be well formed). Errors name the line.
pub(super) fn parse_xml(text: &str) -> std::result::Result<Vec<XmlElement>, String> {
    let opts = roxmltree::ParsingOptions {
        allow_dtd: true,
        ..Default::default()
    };
    let doc = roxmltree::Document::parse_with_options(text.trim_start_matches('\u{feff}'), opts)
        .map_err(|e| e.to_string())?;
    Ok(doc
        .descendants()
        .filter(|n| n.is_element())
        .map(|n| XmlElement {
            name: n.tag_name().name().to_string(),
            attrs: n
                .attributes()
                .map(|a| (a.name().to_string(), a.value().to_string()))
                .collect(),
        })
        .collect())
}
