use super::*;

/// Four presets exactly as 3D Slicer ships them in
/// Modules/Loadable/VolumeRendering/Resources/presets.xml.
const SLICER_XML: &str = concat!(
        "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<MRML>\n",
        "  <VolumeProperty selected=\"false\" hideFromEditors=\"false\" name=\"CT-Bone\" gradientOpacity=\"4 0 1 255 1\" userTags=\"\" specularPower=\"10\" scalarOpacity=\"8 -3024 0 -16.4458 0 641.385 0.715686 3071 0.705882\" id=\"vtkMRMLVolumePropertyNode3\" specular=\"0.2\" shade=\"1\" ambient=\"0.1\" colorTransfer=\"16 -3024 0 0 0 -16.4458 0.729412 0.254902 0.301961 641.385 0.905882 0.815686 0.552941 3071 1 1 1\" selectable=\"true\" diffuse=\"0.9\" interpolation=\"1\" effectiveRange=\"-16.4458 641.385\"/>\n",
        "  <VolumeProperty selected=\"false\" hideFromEditors=\"false\" name=\"CT-Muscle\" gradientOpacity=\"4 0 1 255 1\" userTags=\"\" specularPower=\"10\" scalarOpacity=\"10 -3024 0 -155.407 0 217.641 0.676471 419.736 0.833333 3071 0.803922\" id=\"vtkMRMLVolumePropertyNode18\" specular=\"0.2\" shade=\"1\" ambient=\"0.1\" colorTransfer=\"20 -3024 0 0 0 -155.407 0.54902 0.25098 0.14902 217.641 0.882353 0.603922 0.290196 419.736 1 0.937033 0.954531 3071 0.827451 0.658824 1\" selectable=\"true\" diffuse=\"0.9\" interpolation=\"1\" effectiveRange=\"-155.407 419.736\"/>\n",
        "  <VolumeProperty selected=\"false\" hideFromEditors=\"false\" name=\"CT-Soft-Tissue\" gradientOpacity=\"4 0 1 255 1\" userTags=\"\" specularPower=\"1\" scalarOpacity=\"10 -2048 0 -167.01 0 -160 1 240 1 3661 1\" id=\"vtkMRMLVolumePropertyNode20\" specular=\"0\" shade=\"0\" ambient=\"0.2\" colorTransfer=\"20 -2048 0 0 0 -167.01 0 0 0 -160 0.0556356 0.0556356 0.0556356 240 1 1 1 3661 1 1 1\" selectable=\"true\" diffuse=\"1\" interpolation=\"1\" effectiveRange=\"-167.01 240\"/>\n",
        "  <VolumeProperty selected=\"false\" hideFromEditors=\"false\" name=\"MR-Default\" gradientOpacity=\"4 0 1 255 1\" userTags=\"\" specularPower=\"1\" scalarOpacity=\"12 0 0 20 0 40 0.15 120 0.3 220 0.375 1024 0.5\" id=\"vtkMRMLVolumePropertyNode24\" specular=\"0\" shade=\"1\" ambient=\"0.2\" colorTransfer=\"24 0 0 0 0 20 0.168627 0 0 40 0.403922 0.145098 0.0784314 120 0.780392 0.607843 0.380392 220 0.847059 0.835294 0.788235 1024 1 1 1\" selectable=\"true\" diffuse=\"1\" interpolation=\"1\" effectiveRange=\"0 220\"/>\n",
        "</MRML>\n"
    );

/// ParaView's own "Cool to Warm" (Remoting/Views/ColorMaps.json): no
/// opacity, normalised abscissae, diverging interpolation.
const COOL_TO_WARM: &str = r#"[
  {
    "ColorSpace": "Diverging",
    "Name": "Cool to Warm",
    "NanColor": [1, 1, 0],
    "DefaultMap": true,
    "RGBPoints": [
      0, 0.23137254902, 0.298039215686, 0.752941176471,
      0.5, 0.865, 0.865, 0.865,
      1, 0.705882352941, 0.0156862745098, 0.149019607843
    ]
  },
]
"#;

/// "Cool to Warm" as ParaView exports it from a data set with values
/// 0…255 and an edited opacity (with jsoncpp's comments and trailing
/// commas, which ParaView accepts).
const EXPORTED: &str = r#"[
    {
        // exported from ParaView
        "ColorSpace" : "Diverging",
        "Name" : "Cool to Warm",
        "NanColor" : [ 1, 1, 0 ],
        "Points" : [ 0, 0, 0.5, 0, 100, 0.2, 0.5, 0, 255, 1, 0.5, 0, ],
        "RGBPoints" : [
            0, 0.23137254902, 0.298039215686, 0.752941176471,
            127.5, 0.865, 0.865, 0.865,
            255, 0.705882352941, 0.0156862745098, 0.149019607843 /* warm */
        ]
    }
]"#;

fn exact() -> ImportOptions {
    ImportOptions {
        tolerance: None,
        ..ImportOptions::default()
    }
}

fn raw_exact() -> ImportOptions {
    ImportOptions {
        tolerance: None,
        linearize: false,
        ..ImportOptions::default()
    }
}

fn tau(alpha: f64) -> f64 {
    -(1.0 - alpha).ln()
}

fn assert_close(got: f64, want: f64, tol: f64, what: &str) {
    assert!(
        (got - want).abs() <= tol,
        "{what}: got {got}, want {want} (±{tol})"
    );
}

fn err_text<T: std::fmt::Debug>(r: Result<T>) -> String {
    format!("{:#}", r.expect_err("expected an error"))
}

fn values(tf: &TransferFunction) -> Vec<f64> {
    tf.points().iter().map(|p| p.value).collect()
}

// ------------------------------------------------------------ ParaView

#[test]
fn paraview_exported_preset_with_opacity() {
    let p = import_paraview(EXPORTED, "cool.json", None, &exact()).unwrap();
    assert_eq!(p.name, "Cool to Warm");
    assert_eq!(p.format, PresetFormat::ParaViewJson);
    let pts = p.tf.points();
    // Union of colour {0, 127.5, 255} and opacity {0, 100, 255}.
    assert_eq!(values(&p.tf), vec![0.0, 100.0, 127.5, 255.0]);
    let lin = |c: [f64; 3]| c.map(srgb_to_linear);
    assert_eq!(
        pts[0].color,
        lin([0.23137254902, 0.298039215686, 0.752941176471])
    );
    assert_eq!(pts[0].extinction, 0.0);
    assert_close(pts[1].extinction, tau(0.2), 1e-15, "τ at 100");
    assert_eq!(pts[2].color, lin([0.865; 3]));
    // α at 127.5 interpolates 0.2 → 1 linearly between 100 and 255.
    let a = 0.2 + 0.8 * (27.5 / 155.0);
    assert_close(pts[2].extinction, tau(a), 1e-14, "τ at 127.5");
    assert_eq!(
        pts[3].color,
        lin([0.705882352941, 0.0156862745098, 0.149019607843])
    );
    // α = 1 → the finite ln(1e6).
    assert_close(pts[3].extinction, 1e6f64.ln(), 1e-9, "τ at 255");
    // The colour at 100 is the diverging blend, blue-ish and light.
    let c = pts[1].color.map(linear_to_srgb);
    assert!(c[2] > c[1] && c[1] > c[0] && c[0] > 0.6, "{c:?}");
    // The unit distance divides τ.
    let half = import_paraview(
        EXPORTED,
        "cool.json",
        None,
        &ImportOptions {
            unit: Some(2.0),
            ..exact()
        },
    )
    .unwrap();
    assert_close(half.tf.points()[1].extinction, tau(0.2) / 2.0, 1e-15, "τ/u");
    assert_eq!(half.unit, 2.0);
}

#[test]
fn paraview_normalised_map_needs_a_range_and_an_opacity() {
    let e = err_text(import_paraview(COOL_TO_WARM, "maps.json", None, &exact()));
    assert!(e.starts_with("maps.json: preset \"Cool to Warm\":"), "{e}");
    assert!(e.contains("normalised") && e.contains("range"), "{e}");

    let ranged = ImportOptions {
        range: Some((-1000.0, 3000.0)),
        ..exact()
    };
    let p = import_paraview(COOL_TO_WARM, "maps.json", Some("Cool to Warm"), &ranged).unwrap();
    assert_eq!(values(&p.tf), vec![-1000.0, 1000.0, 3000.0]);
    // Default opacity: ParaView's ramp α 0 → 1 over the colour map.
    let pts = p.tf.points();
    assert_eq!(pts[0].extinction, 0.0);
    assert_close(pts[1].extinction, 2f64.ln(), 1e-15, "τ(α = 0.5)");
    assert!(pts[2].extinction.is_finite());
    assert!(
        p.notes.iter().any(|n| n.contains("no opacity")),
        "{:?}",
        p.notes
    );
    assert!(p.to_toml().contains("no opacity"));

    let constant = ImportOptions {
        missing_opacity: MissingOpacity::Constant(0.1),
        ..ranged.clone()
    };
    let p = import_paraview(COOL_TO_WARM, "maps.json", None, &constant).unwrap();
    for q in p.tf.points() {
        assert_close(q.extinction, tau(0.1), 1e-15, "constant α");
    }

    let reject = ImportOptions {
        missing_opacity: MissingOpacity::Reject,
        ..ranged
    };
    let e = err_text(import_paraview(COOL_TO_WARM, "maps.json", None, &reject));
    assert!(
        e.contains("\"Cool to Warm\"") && e.contains("no opacity"),
        "{e}"
    );
}

#[test]
fn paraview_range_rescales_colour_and_opacity_separately() {
    let opts = ImportOptions {
        range: Some((-100.0, 100.0)),
        ..exact()
    };
    let p = import_paraview(EXPORTED, "cool.json", None, &opts).unwrap();
    // Colour 0, 127.5, 255 → −100, 0, 100; opacity 0, 100, 255 → −100,
    // −100 + 200·100/255, 100.
    let mid = -100.0 + 200.0 * (100.0 / 255.0);
    assert_eq!(values(&p.tf), vec![-100.0, mid, 0.0, 100.0]);
    assert_close(p.tf.points()[1].extinction, tau(0.2), 1e-15, "τ");
}

#[test]
fn diverging_interpolation_matches_moreland() {
    // Moreland's cool–warm map passes through grey at the middle: the
    // 0.865 ParaView stores as the middle point of "Cool to Warm".
    let cool = [0.23137254902, 0.298039215686, 0.752941176471];
    let warm = [0.705882352941, 0.0156862745098, 0.149019607843];
    let mid = interp_diverging(0.5, cool, warm);
    for c in mid {
        assert_close(c, 0.865, 0.003, "diverging midpoint");
    }
    assert_eq!(
        interp_diverging(0.0, cool, warm).map(|c| (c * 255.0).round()),
        [59.0, 76.0, 192.0]
    );
    assert_eq!(
        interp_diverging(1.0, cool, warm).map(|c| (c * 255.0).round()),
        [180.0, 4.0, 38.0]
    );
    // Lab round trip of VTK's conversions.
    let c = [0.3, 0.6, 0.9];
    for (a, b) in lab_to_rgb(rgb_to_lab(c)).iter().zip(c) {
        assert_close(*a, b, 1e-3, "Lab round trip");
    }
}

#[test]
fn paraview_selection() {
    let two = r#"[
            {"Name": "Blues", "ColorSpace": "RGB", "RGBPoints": [0, 0, 0, 1, 10, 1, 1, 1]},
            {"Name": "Reds", "ColorSpace": "RGB", "RGBPoints": [0, 1, 0, 0, 10, 1, 1, 1]},
            {"Name": "Blues", "ColorSpace": "RGB", "RGBPoints": [0, 0, 0, 0.5, 10, 1, 1, 1]}
        ]"#;
    let e = err_text(import_paraview(two, "m.json", None, &exact()));
    assert!(
        e.contains("holds 3 presets") && e.contains("\"Reds\"") && e.contains("\"Blues\" (#3)"),
        "{e}"
    );
    let e = err_text(import_paraview(two, "m.json", Some("Greens"), &exact()));
    assert!(
        e.contains("no preset named \"Greens\"") && e.contains("\"Reds\""),
        "{e}"
    );
    let e = err_text(import_paraview(two, "m.json", Some("Blues"), &exact()));
    assert!(
        e.contains("2 presets are named \"Blues\"") && e.contains("#1, #3"),
        "{e}"
    );
    let p = import_paraview(two, "m.json", Some("#3"), &raw_exact()).unwrap();
    assert_eq!(p.tf.points()[0].color, [0.0, 0.0, 0.5]);
    let p = import_paraview(two, "m.json", Some("reds"), &raw_exact()).unwrap();
    assert_eq!(p.name, "Reds");
    // A single object is a file of one preset.
    let one = r#"{"Name": "Solo", "ColorSpace": "RGB", "RGBPoints": [0, 0, 0, 1, 10, 1, 1, 1]}"#;
    assert_eq!(
        import_preset(one, "solo.json", None, &exact())
            .unwrap()
            .name,
        "Solo"
    );
    assert_eq!(
        preset_names(two, "m.json").unwrap(),
        ["Blues", "Reds", "Blues"]
    );
}

#[test]
fn paraview_malformed() {
    let cases: &[(&str, &str)] = &[
        ("[{\"Name\": \"A\", ", "p.json: not valid JSON"),
        ("42", "p.json: expected a JSON array"),
        ("[]", "p.json: the JSON array holds no presets"),
        (
            r#"[{"Name": "A", "RGBPoints": [0, 0, 0, 1, 1, 1, 1]}]"#,
            "p.json: preset \"A\": RGBPoints: 7 numbers do not make whole (x, r, g, b) groups of 4",
        ),
        (
            r#"[{"Name": "A", "RGBPoints": [0, 0, 0, "x", 1, 1, 1, 1]}]"#,
            "p.json: preset \"A\": RGBPoints[3]: expected a number, got the string \"x\"",
        ),
        (
            r#"[{"Name": "A", "RGBPoints": [5, 0, 0, 0, 1, 1, 1, 1]}]"#,
            "p.json: preset \"A\": RGBPoints: point 2: x = 1 comes after x = 5",
        ),
        (
            r#"[{"Name": "A", "RGBPoints": [0, 0, 0, 0, 1, 1.5, 1, 1]}]"#,
            "p.json: preset \"A\": RGBPoints: point 2: colour component 1.5 is outside [0, 1]",
        ),
        (
            r#"[{"Name": "A", "RGBPoints": [0, 0, 0, 0, 9, 1, 1, 1], "Points": [0, 0, 0.5, 0, 9, 2, 0.5, 0]}]"#,
            "p.json: preset \"A\": Points: point 2: alpha 2 is outside [0, 1]",
        ),
        (
            r#"[{"Name": "A", "RGBPoints": [0, 0, 0, 0, 9, 1, 1, 1], "Points": [0, 0, 0.5]}]"#,
            "p.json: preset \"A\": Points: 3 numbers do not make whole",
        ),
        (
            r#"[{"Name": "A", "IndexedColors": [1, 0, 0]}]"#,
            "p.json: preset \"A\": a categorical colour map",
        ),
        (
            r#"[{"Name": "A", "UseLogScale": true, "RGBPoints": [1, 0, 0, 0, 9, 1, 1, 1]}]"#,
            "p.json: preset \"A\": UseLogScale",
        ),
        (
            r#"[{"Name": "A", "ColorSpace": "Rainbow", "RGBPoints": [0, 0, 0, 0, 9, 1, 1, 1]}]"#,
            "p.json: preset \"A\": ColorSpace: unknown colour space \"Rainbow\"",
        ),
        (
            r#"[{"Name": "A", "RGBPoints": [3, 0, 0, 0, 3, 1, 1, 1]}]"#,
            "",
        ),
    ];
    for (text, want) in cases {
        let r = import_paraview(text, "p.json", None, &exact());
        if want.is_empty() {
            // Two colours at one abscissa: a valid step.
            let p = r.unwrap();
            assert_eq!(values(&p.tf), vec![3.0, 3.0]);
            continue;
        }
        let e = err_text(r);
        assert!(e.starts_with(want), "want {want:?}\n got {e:?}");
    }
    // A range cannot stretch a function whose points share one abscissa.
    let e = err_text(import_paraview(
        r#"[{"Name": "A", "RGBPoints": [3, 0, 0, 0, 3, 1, 1, 1]}]"#,
        "p.json",
        None,
        &ImportOptions {
            range: Some((0.0, 1.0)),
            ..exact()
        },
    ));
    assert!(e.contains("no range to stretch"), "{e}");
}

#[test]
fn vtk_opacity_shapes() {
    // Sharpness 1 is a step at the midpoint (here 0.25 of the way).
    let text = r#"[{"Name": "S", "ColorSpace": "RGB",
            "RGBPoints": [0, 1, 1, 1, 100, 1, 1, 1],
            "Points": [0, 0, 0.25, 1, 100, 0.5, 0.5, 0]}]"#;
    let p = import_paraview(text, "s.json", None, &exact()).unwrap();
    assert_eq!(values(&p.tf), vec![0.0, 25.0, 25.0, 100.0]);
    let t: Vec<f64> = p.tf.points().iter().map(|q| q.extinction).collect();
    assert_eq!(t[0], 0.0);
    assert_eq!(t[1], 0.0);
    assert_close(t[2], tau(0.5), 1e-15, "after the step");
    // Sharpness 0.5 is a Hermite S-curve: refinement follows it.
    let text = r#"[{"Name": "H", "ColorSpace": "RGB",
            "RGBPoints": [0, 1, 1, 1, 100, 1, 1, 1],
            "Points": [0, 0, 0.5, 0.5, 100, 0.8, 0.5, 0]}]"#;
    let p = import_paraview(text, "h.json", None, &ImportOptions::default()).unwrap();
    assert!(p.tf.points().len() > 4);
    let nodes = [
        Node {
            x: 0.0,
            v: 0.0,
            midpoint: 0.5,
            sharpness: 0.5,
        },
        Node::linear(100.0, 0.8),
    ];
    let mut worst: f64 = 0.0;
    for i in 0..=1000 {
        let x = i as f64 * 0.1;
        let want = eval_alpha(&nodes, x, Side::Left);
        let got = -(-p.tf.tau(x)).exp_m1();
        worst = worst.max((got - want).abs());
    }
    eprintln!(
        "Hermite opacity: {} points, largest α error {worst:.2e}",
        p.tf.points().len()
    );
    assert!(worst <= 2.0 * DEFAULT_TOLERANCE, "{worst}");
}

#[test]
fn step_colour_space() {
    let text = r#"[{"Name": "S", "ColorSpace": "Step",
            "RGBPoints": [0, 1, 0, 0, 1, 0, 1, 0, 2, 0, 0, 1],
            "Points": [0, 0.5, 0.5, 0, 2, 0.5, 0.5, 0]}]"#;
    let p = import_paraview(text, "s.json", None, &raw_exact()).unwrap();
    // (0, 1] is green, (1, 2] blue: steps right after 0 and 1.
    let pts: Vec<(f64, [f64; 3])> = p.tf.points().iter().map(|q| (q.value, q.color)).collect();
    assert_eq!(
        pts,
        vec![
            (0.0, [1.0, 0.0, 0.0]),
            (0.0, [0.0, 1.0, 0.0]),
            (1.0, [0.0, 1.0, 0.0]),
            (1.0, [0.0, 0.0, 1.0]),
            (2.0, [0.0, 0.0, 1.0]),
        ]
    );
}

#[test]
fn hsv_interpolation_wraps_the_short_way() {
    // Red (h = 0) to magenta (h = 5/6): the short way passes h = 11/12.
    let mid = interp_color(
        ColorSpace::Hsv { wrap: true },
        [1.0, 0.0, 0.0],
        [1.0, 0.0, 1.0],
        0.5,
        None,
    );
    assert_close(mid[0], 1.0, 1e-12, "r");
    assert_close(mid[1], 0.0, 1e-12, "g");
    assert_close(mid[2], 0.5, 1e-12, "b");
    // Without wrap it runs through yellow, green, cyan, blue.
    let mid = interp_color(
        ColorSpace::Hsv { wrap: false },
        [1.0, 0.0, 0.0],
        [1.0, 0.0, 1.0],
        0.5,
        None,
    );
    assert_close(mid[0], 0.0, 1e-12, "r");
    assert_close(mid[1], 1.0, 1e-12, "g");
}

// --------------------------------------------------------------- Slicer

#[test]
fn slicer_ct_bone_and_mr_default() {
    let p = import_slicer_xml(SLICER_XML, "presets.xml", Some("CT-Bone"), &raw_exact()).unwrap();
    assert_eq!(p.name, "CT-Bone");
    assert_eq!(p.unit, 1.0);
    let want = [
        (-3024.0, [0.0, 0.0, 0.0], 0.0),
        (-16.4458, [0.729412, 0.254902, 0.301961], 0.0),
        (641.385, [0.905882, 0.815686, 0.552941], 0.715686),
        (3071.0, [1.0, 1.0, 1.0], 0.705882),
    ];
    assert_eq!(p.tf.points().len(), want.len());
    for (q, (x, c, a)) in p.tf.points().iter().zip(want) {
        assert_eq!(q.value, x);
        assert_eq!(q.color, c);
        assert_close(q.extinction, tau(a), 1e-15, "CT-Bone τ");
    }
    assert_close(
        p.tf.points()[2].extinction,
        1.257676,
        1e-6,
        "−ln(1 − 0.715686)",
    );
    assert!(p
        .notes
        .iter()
        .any(|n| n.contains("shades") && n.contains("specularPower 10")));

    let p = import_slicer_xml(SLICER_XML, "presets.xml", Some("MR-Default"), &exact()).unwrap();
    let want = [
        (0.0, [0.0, 0.0, 0.0], 0.0),
        (20.0, [0.168627, 0.0, 0.0], 0.0),
        (40.0, [0.403922, 0.145098, 0.0784314], 0.15),
        (120.0, [0.780392, 0.607843, 0.380392], 0.3),
        (220.0, [0.847059, 0.835294, 0.788235], 0.375),
        (1024.0, [1.0, 1.0, 1.0], 0.5),
    ];
    assert_eq!(p.tf.points().len(), want.len());
    for (q, (x, c, a)) in p.tf.points().iter().zip(want) {
        assert_eq!(q.value, x);
        assert_eq!(q.color, c.map(srgb_to_linear), "colour at {x}");
        assert_close(q.extinction, tau(a), 1e-15, "MR-Default τ");
    }
    // sRGB 0.780392 (199/255) is linear 0.571125.
    assert_close(p.tf.points()[3].color[0], 0.571125, 1e-6, "linearised");
}

#[test]
fn slicer_selection_lists_the_presets() {
    let e = err_text(import_slicer_xml(SLICER_XML, "presets.xml", None, &exact()));
    assert!(
        e.starts_with(
            "presets.xml: holds 4 presets; name the one to convert: \"CT-Bone\", \"CT-Muscle\""
        ),
        "{e}"
    );
    let e = err_text(import_slicer_xml(
        SLICER_XML,
        "presets.xml",
        Some("CT-Lung"),
        &exact(),
    ));
    assert!(
        e.starts_with("presets.xml: no preset named \"CT-Lung\"") && e.contains("\"MR-Default\""),
        "{e}"
    );
    assert_eq!(
        preset_names(SLICER_XML, "presets.xml").unwrap(),
        ["CT-Bone", "CT-Muscle", "CT-Soft-Tissue", "MR-Default"]
    );
    // Any format through the one entry point.
    let p = import_preset(SLICER_XML, "presets.xml", Some("ct-bone"), &exact()).unwrap();
    assert_eq!(p.format, PresetFormat::SlicerPresetsXml);
}

fn one_property(scalar_opacity: &str, color: &str) -> String {
    format!(
        "<MRML>\n  <VolumeProperty name=\"Bad\" scalarOpacity=\"{scalar_opacity}\" \
             colorTransfer=\"{color}\"/>\n</MRML>\n"
    )
}

#[test]
fn slicer_malformed_lists() {
    let good_color = "8 0 0 0 0 100 1 1 1";
    let cases = [
        (
            "8 -3024 0 -16.4458 0 641.385",
            good_color,
            "scalarOpacity: the count says 8 values but 5 follow",
        ),
        (
            "3 0 0 1",
            good_color,
            "scalarOpacity: 3 values do not make whole (x, alpha) groups of 2",
        ),
        (
            "4 0 0 abc 1",
            good_color,
            "scalarOpacity: value 3 (\"abc\") is not a number",
        ),
        (
            "4 0 0 nan 1",
            good_color,
            "scalarOpacity: value 3 (nan) is not finite",
        ),
        (
            "4 0 0 inf 1",
            good_color,
            "scalarOpacity: value 3 (inf) is not finite",
        ),
        (
            "4 10 0 5 1",
            good_color,
            "scalarOpacity: point 2: x = 5 comes after x = 10",
        ),
        (
            "4 0 0 5 1.5",
            good_color,
            "scalarOpacity: point 2: alpha 1.5 is outside [0, 1]",
        ),
        (
            "four 0 0 5 1",
            good_color,
            "scalarOpacity: the leading count \"four\" is not a whole number",
        ),
        (
            "4 0 0 100 1",
            "7 0 0 0 0 100 1 1",
            "colorTransfer: 7 values do not make whole (x, r, g, b) groups of 4",
        ),
        ("4 0 0 100 1", "0", "colorTransfer: no colour points"),
        (
            "4 0 0 100 1",
            "8 0 0 0 0 100 1 2 1",
            "colorTransfer: point 2: colour component 2 is outside [0, 1]",
        ),
    ];
    for (so, ct, want) in cases {
        let e = err_text(import_slicer_xml(
            &one_property(so, ct),
            "presets.xml",
            None,
            &exact(),
        ));
        let want = format!("presets.xml: preset \"Bad\": {want}");
        assert!(e.starts_with(&want), "want {want:?}\n got {e:?}");
    }
    let missing = "<MRML><VolumeProperty name=\"Bad\" scalarOpacity=\"4 0 0 1 1\"/></MRML>";
    let e = err_text(import_slicer_xml(missing, "presets.xml", None, &exact()));
    assert!(
        e.starts_with("presets.xml: preset \"Bad\": colorTransfer: missing"),
        "{e}"
    );
    // Two opacity points at one value are a step, kept as one.
    let p = import_slicer_xml(
        &one_property("6 0 0 50 0 50 1", good_color),
        "p.xml",
        None,
        &raw_exact(),
    )
    .unwrap();
    assert_eq!(values(&p.tf), vec![0.0, 50.0, 50.0, 100.0]);
    assert_eq!(p.tf.points()[1].extinction, 0.0);
    assert_eq!(p.tf.points()[2].extinction, alpha_to_extinction(1.0, 1.0));
}

#[test]
fn xml_that_is_not_well_formed() {
    // (text, the line roxmltree names; 0: none, the document just ends)
    let cases = [
        ("<MRML><VolumeProperty name=\"A/></MRML>", 1),
        ("<MRML>\n<VolumeProperty name=\"A\"></MRML>", 2),
        ("<MRML>\n<VolumeProperty name=\"A\"/>\n", 0),
        ("<MRML><VolumeProperty name=\"A\" name=\"B\"/></MRML>", 1),
        ("<MRML><VolumeProperty name=\"A&nbsp;\"/></MRML>", 1),
        ("<MRML><VolumeProperty name=A/></MRML>", 1),
        ("<MRML/><MRML/>", 1),
        ("junk <MRML/>", 1),
        ("<!-- only a comment -->", 0),
    ];
    for (text, line) in cases {
        let e = err_text(import_slicer_xml(text, "presets.xml", None, &exact()));
        let want = "presets.xml: not well-formed XML: ";
        assert!(e.starts_with(want), "{text:?}: {e:?}");
        if line > 0 {
            assert!(
                e.contains(&format!(" {line}:")),
                "{text:?}: line {line} in {e:?}"
            );
        }
    }
    let e = err_text(import_slicer_xml(
        "<MRML><Other/></MRML>",
        "presets.xml",
        None,
        &exact(),
    ));
    assert!(
        e.starts_with("presets.xml: no <VolumeProperty> elements"),
        "{e}"
    );
    // Entities, comments, a doctype and single quotes are read.
    let ok = "<?xml version='1.0'?>\n<!DOCTYPE MRML [<!ENTITY x \"y\">]>\n<!-- presets -->\n\
                  <MRML><VolumeProperty name='A &amp; B&#33;' scalarOpacity=\"4 0 0 1 1\" \
                  colorTransfer=\"8 0 0 0 0 1 1 1 1\"></VolumeProperty></MRML>";
    assert_eq!(
        import_slicer_xml(ok, "p.xml", None, &exact()).unwrap().name,
        "A & B!"
    );
}

/// Slicer's own test file
/// (Modules/Loadable/VolumeRendering/Testing/Data/Input/VolumeProperty.vp).
const SLICER_VP: &str = "1\n1\n0.42\n0.44\n0.46\n38.5\n8 -17 0 13 0 103 1 235 1\n4 -17 1 235 1\n\
        28 -17 1 0 0.498039215686275 13 1 0.333333333333333 1 35.5882339477539 1 0.333333333333333 \
        0.498039215686275 58.1764717102051 1 0.333333333333333 1 80.7647094726563 1 1 0.498039215686275 \
        103 0.333333333333333 0.666666666666667 1 235 1 1 1\n";

#[test]
fn slicer_vp_file() {
    let p = import_preset(SLICER_VP, "data/VolumeProperty.vp", None, &raw_exact()).unwrap();
    assert_eq!(p.format, PresetFormat::SlicerVp);
    assert_eq!(p.name, "VolumeProperty");
    assert_eq!(
        values(&p.tf),
        vec![
            -17.0,
            13.0,
            35.5882339477539,
            58.1764717102051,
            80.7647094726563,
            103.0,
            235.0
        ]
    );
    let q = p.tf.points();
    assert_eq!(q[0].color, [1.0, 0.0, 0.498039215686275]);
    assert_eq!(q[1].extinction, 0.0);
    // α between 13 (0) and 103 (1) at 58.18: linear in α, then τ.
    let a = (58.1764717102051 - 13.0) / 90.0;
    assert_close(q[3].extinction, tau(a), 1e-14, "τ at 58.18");
    assert_eq!(q[5].extinction, alpha_to_extinction(1.0, 1.0));
    assert!(p
        .notes
        .iter()
        .any(|n| n.contains("ambient 0.44") && n.contains("specularPower 38.5")));

    let short: String = SLICER_VP.lines().take(8).collect::<Vec<_>>().join("\n");
    let e = err_text(import_slicer_vp(&short, "x.vp", &exact()));
    assert!(e.starts_with("x.vp: a .vp file has 9 lines"), "{e}");
    let e = err_text(import_slicer_vp(
        &SLICER_VP.replacen("0.42", "diffuse", 1),
        "x.vp",
        &exact(),
    ));
    assert!(
        e.starts_with("x.vp: line 3 (diffuse): expected a number"),
        "{e}"
    );
    let e = err_text(import_slicer_vp(
        &SLICER_VP.replacen("8 -17", "6 -17", 1),
        "x.vp",
        &exact(),
    ));
    assert!(
        e.starts_with("x.vp: line 7 (scalar opacity): the count says 6 values but 8 follow"),
        "{e}"
    );
    let e = err_text(import_preset(SLICER_VP, "x.vp", Some("CT-Bone"), &exact()));
    assert!(e.contains("holds one transfer function"), "{e}");
}

/// The example of Slicer's developer guide (Docs/developer_guide/
/// modules/volumerendering.md), with the unit distance changed to 2.5
/// and the opacity points shuffled (Slicer sorts them).
const SLICER_VP_JSON: &str = r#"{
    "@schema": "https://raw.githubusercontent.com/slicer/slicer/main/Modules/Loadable/VolumeRendering/Resources/Schema/volume-property-schema-v1.0.0.json#",
    "volumeProperties": [
        {
            "effectiveRange": [0.0, 220.0],
            "components": [
                {
                    "shade": true,
                    "lighting": { "diffuse": 1.0, "ambient": 0.2, "specular": 0.0, "specularPower": 1.0 },
                    "rgbTransferFunction": {
                        "type": "colorTransferFunction",
                        "points": [
                            { "x": 0.0, "color": [0.0, 0.0, 0.0] },
                            { "x": 20.0, "color": [0.168627, 0.0, 0.0] },
                            { "x": 40.0, "color": [0.403922, 0.145098, 0.0784314] },
                            { "x": 40.0, "color": [0.403922, 0.145098, 0.0784314] },
                            { "x": 120.0, "color": [0.780392, 0.607843, 0.380392] },
                            { "x": 220.0, "color": [0.847059, 0.835294, 0.788235] },
                            { "x": 1024.0, "color": [1.0, 1.0, 1.0] }
                        ]
                    },
                    "scalarOpacityUnitDistance": 2.5,
                    "scalarOpacity": {
                        "type": "piecewiseLinearFunction",
                        "points": [
                            { "x": 120.0, "y": 0.3 },
                            { "x": 0.0, "y": 0.0 },
                            { "x": 220.0, "y": 0.375 },
                            { "x": 1024.0, "y": 0.5 }
                        ]
                    },
                    "gradientOpacity": {
                        "type": "piecewiseLinearFunction",
                        "points": [ { "x": 0.0, "y": 1.0 }, { "x": 255.0, "y": 1.0 } ]
                    }
                }
            ]
        }
    ]
}"#;

#[test]
fn slicer_vp_json_file() {
    let p = import_preset(SLICER_VP_JSON, "MR-Default.vp.json", None, &raw_exact()).unwrap();
    assert_eq!(p.format, PresetFormat::SlicerVpJson);
    assert_eq!(p.name, "MR-Default");
    assert_eq!(p.unit, 2.5);
    assert_eq!(values(&p.tf), vec![0.0, 20.0, 40.0, 120.0, 220.0, 1024.0]);
    let q = p.tf.points();
    assert_close(q[3].extinction, tau(0.3) / 2.5, 1e-15, "τ/u from the file");
    assert_close(
        q[1].extinction,
        tau(0.3 * 20.0 / 120.0) / 2.5,
        1e-15,
        "τ at 20",
    );
    assert_eq!(q[2].color, [0.403922, 0.145098, 0.0784314]);
    assert!(
        p.notes.iter().any(|n| n.contains("ambient 0.2")),
        "{:?}",
        p.notes
    );
    // An explicit unit wins over the file's.
    let p = import_slicer_vp_json(
        SLICER_VP_JSON,
        "MR-Default.vp.json",
        &ImportOptions {
            unit: Some(1.0),
            ..raw_exact()
        },
    )
    .unwrap();
    assert_close(p.tf.points()[3].extinction, tau(0.3), 1e-15, "τ with u = 1");
    let bad = SLICER_VP_JSON.replace("\"y\": 0.375", "\"y\": \"high\"");
    let e = err_text(import_preset(&bad, "v.vp.json", None, &exact()));
    assert!(
            e.starts_with("v.vp.json: volumeProperties[0].components[0].scalarOpacity.points[2].y: expected a number"),
            "{e}"
        );
}

// ------------------------------------------------------------ conversion

#[test]
fn alpha_one_gives_a_finite_extinction() {
    let t = alpha_to_extinction(1.0, 1.0);
    assert!(t.is_finite());
    assert_close(t, 1e6f64.ln(), 1e-9, "τ(1)");
    assert_close(
        alpha_to_extinction(1.0, 1e-3),
        1e3 * 1e6f64.ln(),
        1e-6,
        "τ(1)/u",
    );
    assert_eq!(alpha_to_extinction(0.0, 1.0), 0.0);
    assert_eq!(alpha_to_extinction(-0.0, 1.0).to_bits(), 0.0f64.to_bits());
    assert_close(alpha_to_extinction(1e-12, 1.0), 1e-12, 1e-24, "small α");
    // CT-Soft-Tissue is opaque (α = 1) above −160 HU.
    let p = import_slicer_xml(SLICER_XML, "presets.xml", Some("CT-Soft-Tissue"), &exact()).unwrap();
    assert!(p.tf.points().iter().all(|q| q.extinction.is_finite()));
    assert_close(p.tf.max_extinction(), 1e6f64.ln(), 1e-9, "max τ");
}

#[test]
fn refinement_follows_the_source_curves() {
    let cases: [(&str, Option<&str>, ImportOptions); 4] = [
        (SLICER_XML, Some("CT-Soft-Tissue"), ImportOptions::default()),
        (SLICER_XML, Some("MR-Default"), ImportOptions::default()),
        (SLICER_XML, Some("CT-Muscle"), ImportOptions::default()),
        (
            COOL_TO_WARM,
            None,
            ImportOptions {
                range: Some((0.0, 255.0)),
                missing_opacity: MissingOpacity::Constant(0.3),
                ..ImportOptions::default()
            },
        ),
    ];
    for (text, name, opts) in cases {
        let p = import_preset(text, "t", name, &opts).unwrap();
        let coarse = import_preset(
            text,
            "t",
            name,
            &ImportOptions {
                tolerance: None,
                ..opts.clone()
            },
        )
        .unwrap();
        // Every source breakpoint is there, with its exact optics.
        for c in coarse.tf.points() {
            assert!(p.tf.points().contains(c), "{}: lost {c:?}", p.name);
        }
        // Between them the curves stay close to VTK's.
        let src = match PresetFormat::detect(text) {
            PresetFormat::SlicerPresetsXml => {
                let props = slicer_xml_properties(text, "t").unwrap();
                let el = &props
                    .iter()
                    .find(|(n, _)| Some(n.as_str()) == name)
                    .unwrap()
                    .1;
                slicer_source(
                    name.unwrap(),
                    [
                        ("so", el.attr("scalarOpacity")),
                        ("go", el.attr("gradientOpacity")),
                        ("ct", el.attr("colorTransfer")),
                    ],
                    "t",
                    Vec::new(),
                )
                .unwrap()
            }
            _ => {
                let mut s = paraview_source(
                    "Cool to Warm",
                    paraview_entries(&parse_json(text, "t").unwrap(), "t").unwrap()[0].1,
                    "t",
                )
                .unwrap();
                s.color = rescale(s.color, 0.0, 255.0, "c").unwrap();
                s.opacity = Some(vec![Node::linear(0.0, 0.3)]);
                s
            }
        };
        let opacity = src.opacity.clone().unwrap();
        let (lo, hi) = (p.tf.points()[0].value, p.tf.points().last().unwrap().value);
        let (mut wa, mut wc) = (0.0f64, 0.0f64);
        for i in 0..=20000 {
            let x = lo + (hi - lo) * i as f64 / 20000.0;
            let o = p.tf.eval(x);
            let a = -(-o.tau).exp_m1();
            wa = wa.max((a - eval_alpha(&opacity, x, Side::Left).min(MAX_ALPHA)).abs());
            let truth = eval_color(&src.color, src.space, x, Side::Left);
            if o.tau == 0.0 && eval_alpha(&opacity, x, Side::Left) == 0.0 {
                continue; // nothing emitted, the colour is not seen
            }
            for (c, t) in o.color.iter().zip(truth) {
                wc = wc.max((linear_to_srgb(*c) - t).abs());
            }
        }
        eprintln!(
                "{}: {} points ({} without refinement), largest α error {wa:.2e}, colour error {wc:.2e}",
                p.name,
                p.tf.points().len(),
                coarse.tf.points().len()
            );
        assert!(wa <= 2.0 * DEFAULT_TOLERANCE && wc <= 2.0 * DEFAULT_TOLERANCE);
    }
}

#[test]
fn toml_round_trip_is_exact() {
    for name in ["CT-Bone", "CT-Soft-Tissue", "MR-Default"] {
        let p = import_slicer_xml(
            SLICER_XML,
            "presets.xml",
            Some(name),
            &ImportOptions::default(),
        )
        .unwrap();
        let text = p.to_toml();
        assert!(text.starts_with(&format!(
            "# 3D Slicer volume-rendering preset \"{name}\", from presets.xml."
        )));
        let back = TransferFunction::from_toml_str(&text, "round trip").unwrap();
        assert_eq!(back, p.tf, "{name}");
    }
    let tf = TransferFunction::from_points(vec![
        ControlPoint::new(-1e-7, [0.1, 0.2, 0.3], 1e-30).with_importance(0.9),
        ControlPoint::new(1e21, [1.0, 0.0, 1.0 / 3.0], 1e30).with_refraction(1.33),
    ])
    .unwrap();
    let text = tf_to_toml(&tf, &["two\nlines".to_string()]);
    assert!(text.starts_with("# two\n# lines\n\n[[point]]\n"), "{text}");
    assert_eq!(TransferFunction::from_toml_str(&text, "t").unwrap(), tf);
}

#[test]
fn options_and_detection() {
    assert_eq!(
        "ramp".parse::<MissingOpacity>().unwrap(),
        MissingOpacity::default()
    );
    assert_eq!(
        "ramp:0.1,0.9".parse::<MissingOpacity>().unwrap(),
        MissingOpacity::Ramp {
            low: 0.1,
            high: 0.9
        }
    );
    assert_eq!(
        "const:0.2".parse::<MissingOpacity>().unwrap(),
        MissingOpacity::Constant(0.2)
    );
    assert_eq!(
        "reject".parse::<MissingOpacity>().unwrap(),
        MissingOpacity::Reject
    );
    assert!("const:2".parse::<MissingOpacity>().is_err());
    assert!("ramp:0".parse::<MissingOpacity>().is_err());
    for m in [
        MissingOpacity::default(),
        MissingOpacity::Constant(0.25),
        MissingOpacity::Reject,
    ] {
        assert_eq!(m.to_string().parse::<MissingOpacity>().unwrap(), m);
    }
    assert_eq!(
        PresetFormat::detect(SLICER_XML),
        PresetFormat::SlicerPresetsXml
    );
    assert_eq!(
        PresetFormat::detect(COOL_TO_WARM),
        PresetFormat::ParaViewJson
    );
    assert_eq!(PresetFormat::detect(SLICER_VP), PresetFormat::SlicerVp);
    assert_eq!(
        PresetFormat::detect(SLICER_VP_JSON),
        PresetFormat::SlicerVpJson
    );
    for bad in [
        ImportOptions {
            unit: Some(0.0),
            ..exact()
        },
        ImportOptions {
            unit: Some(f64::NAN),
            ..exact()
        },
        ImportOptions {
            range: Some((5.0, 5.0)),
            ..exact()
        },
        ImportOptions {
            tolerance: Some(-1.0),
            ..exact()
        },
    ] {
        let e = err_text(import_slicer_xml(
            SLICER_XML,
            "presets.xml",
            Some("CT-Bone"),
            &bad,
        ));
        assert!(e.starts_with("presets.xml: preset \"CT-Bone\": "), "{e}");
    }
}

// ------------------------------------------------------- shipped presets

/// The presets shipped in configs/tf/: file, Slicer preset, what the
/// values are.
const SHIPPED: [(&str, &str, &str); 4] = [
    (
        "ct-bone.toml",
        "CT-Bone",
        "Values are Hounsfield units (CT).",
    ),
    (
        "ct-muscle.toml",
        "CT-Muscle",
        "Values are Hounsfield units (CT).",
    ),
    (
        "ct-soft-tissue.toml",
        "CT-Soft-Tissue",
        "Values are Hounsfield units (CT).",
    ),
    (
        "mr-default.toml",
        "MR-Default",
        "Values are MR intensities in scanner units (the preset expects roughly 0…1024).",
    ),
];

const SHIPPED_ORIGIN: &str =
    "3D Slicer's presets.xml (Modules/Loadable/VolumeRendering/Resources/presets.xml)";

fn shipped_dir() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/tf")
}

fn shipped_text(preset: &str, units: &str) -> (String, TransferFunction) {
    let p = import_slicer_xml(
        SLICER_XML,
        SHIPPED_ORIGIN,
        Some(preset),
        &ImportOptions::default(),
    )
    .unwrap();
    let mut header = p.header_lines();
    header.insert(1, units.to_string());
    (tf_to_toml(&p.tf, &header), p.tf)
}

/// Regenerates configs/tf/{ct-bone, ct-muscle, ct-soft-tissue,
/// mr-default}.toml: `cargo test -p parallax-common write_shipped_presets
/// -- --ignored`.
#[test]
#[ignore]
fn write_shipped_presets() {
    for (file, preset, units) in SHIPPED {
        let (text, _) = shipped_text(preset, units);
        std::fs::write(shipped_dir().join(file), text).unwrap();
    }
}

#[test]
fn shipped_presets_load_and_match_the_converter() {
    for (file, preset, units) in SHIPPED {
        let path = shipped_dir().join(file);
        let tf = TransferFunction::load(&path).unwrap();
        assert!(tf.points().len() >= 2, "{file}");
        let text = std::fs::read_to_string(&path).unwrap();
        let first = text.lines().next().unwrap();
        assert!(
            first.starts_with("# ") && first.contains(&format!("\"{preset}\"")),
            "{file}: {first}"
        );
        assert!(text.lines().nth(1).unwrap().contains(units), "{file}");
        // Regenerate with the ignored test above if the converter changes.
        assert_eq!(tf, shipped_text(preset, units).1, "{file} is out of date");
    }
}
