use super::*;

// ---------------------------------------------------------------- helpers

/// Small deterministic LCG (Knuth's MMIX constants), uniform f64 in [0, 1).
struct Lcg(u64);

impl Lcg {
    fn next_f64(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }

    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next_f64()
    }
}

fn all_channels(o: &Optics) -> [f64; Channel::COUNT] {
    Channel::ALL.map(|c| c.of(o))
}

/// ∫ₐᵇ f by composite Simpson, split at the breakpoints inside (a, b) so that
/// each piece is smooth; about `intervals` intervals in total.
fn simpson(
    f: &dyn Fn(f64) -> [f64; Channel::COUNT],
    a: f64,
    b: f64,
    breaks: &[f64],
    intervals: usize,
) -> [f64; Channel::COUNT] {
    let mut cuts = vec![a];
    cuts.extend(breaks.iter().copied().filter(|&x| x > a && x < b));
    cuts.push(b);
    cuts.sort_by(f64::total_cmp);
    cuts.dedup();
    let mut total = [0.0; Channel::COUNT];
    for w in cuts.windows(2) {
        let (p, q) = (w[0], w[1]);
        let mut m = ((intervals as f64) * (q - p) / (b - a)).ceil() as usize;
        m = m.max(2);
        m += m % 2;
        let h = (q - p) / m as f64;
        let mut acc = [0.0; Channel::COUNT];
        for i in 0..=m {
            let x = if i == m { q } else { p + i as f64 * h };
            let wgt = if i == 0 || i == m {
                1.0
            } else if i % 2 == 1 {
                4.0
            } else {
                2.0
            };
            let v = f(x);
            for c in 0..Channel::COUNT {
                acc[c] += wgt * v[c];
            }
        }
        for c in 0..Channel::COUNT {
            total[c] += acc[c] * h / 3.0;
        }
    }
    total
}

fn close(got: f64, want: f64, rel: f64) -> bool {
    (got - want).abs() <= rel * got.abs().max(want.abs()) + 1e-300
}

/// Bound on |τ′·c′| over the pieces of a transfer function, per colour
/// channel: linearising k̃ = τ·c within a bin of width Δ errs by at most
/// |τ′c′|·Δ²/4.
fn emission_curvature(tf: &TransferFunction) -> [f64; 3] {
    let mut out = [0.0f64; 3];
    for w in tf.points().windows(2) {
        let dv = w[1].value - w[0].value;
        if dv <= 0.0 {
            continue;
        }
        let dtau = (w[1].extinction - w[0].extinction) / dv;
        for (k, o) in out.iter_mut().enumerate() {
            let dc = (w[1].color[k] - w[0].color[k]) / dv;
            *o = o.max((dtau * dc).abs());
        }
    }
    out
}

/// Checks `table.average` on [a, b] against (1) Simpson on the table's own
/// in-bin-linear f (all channels, relative `rel`) and (2) Simpson on the exact
/// transfer function (τ, ι, ν to `rel`; emission within the linearisation
/// bound). Control points must lie on table nodes and inside [vmin, vmax].
fn check_segment(tf: &TransferFunction, table: &PreintTable, a: f64, b: f64, rel: f64) {
    const INTERVALS: usize = 100_000;
    let seg = table.segment(a, b);
    let got = [
        seg.tau,
        seg.emission[0],
        seg.emission[1],
        seg.emission[2],
        seg.importance,
        seg.refraction,
    ];
    for (c, &g) in got.iter().enumerate() {
        assert!(g.is_finite() && g >= 0.0, "channel {c} on [{a}, {b}]: {g}");
        assert_eq!(g, table.average(Channel::ALL[c], b, a), "swapped bounds");
    }
    let (lo, hi) = (a.min(b), a.max(b));
    if hi - lo <= 0.0 {
        return;
    }
    let mut table_breaks: Vec<f64> = (0..=table.n_bins())
        .map(|i| table.vmin() + i as f64 * table.bin_width())
        .filter(|&x| x > lo && x < hi)
        .collect();
    table_breaks.push(table.vmax());
    let by_table = simpson(&|s| table.values(s), lo, hi, &table_breaks, INTERVALS);
    let mut tf_breaks = tf.control_values();
    tf_breaks.extend([table.vmin(), table.vmax()]);
    let by_tf = simpson(
        &|s| all_channels(&tf.eval(s)),
        lo,
        hi,
        &tf_breaks,
        INTERVALS,
    );
    let len = hi - lo;
    let curv = emission_curvature(tf);
    let dx = table.bin_width();
    for c in 0..Channel::COUNT {
        let want_table = by_table[c] / len;
        let want_tf = by_tf[c] / len;
        assert!(
            close(got[c], want_table, rel),
            "channel {c} on [{a}, {b}]: table {:e}, Simpson on table f {:e}, rel err {:e}",
            got[c],
            want_table,
            (got[c] - want_table).abs() / want_table.abs()
        );
        let ok = match Channel::ALL[c] {
            Channel::EmissionR | Channel::EmissionG | Channel::EmissionB => {
                let bound = curv[c - 1] * dx * dx / 4.0;
                (got[c] - want_tf).abs() <= bound * (1.0 + 1e-6) + rel * want_tf.abs() + 1e-300
            }
            _ => close(got[c], want_tf, rel),
        };
        assert!(
            ok,
            "channel {c} on [{a}, {b}]: table {:e}, Simpson on exact TF {:e}",
            got[c], want_tf
        );
    }
}

fn tf_from_toml(text: &str) -> TransferFunction {
    TransferFunction::from_toml_str(text, "tf.toml").unwrap()
}

fn err_of(text: &str) -> String {
    format!(
        "{:#}",
        TransferFunction::from_toml_str(text, "tf.toml").unwrap_err()
    )
}

// ---------------------------------------------------------------- parsing

const GOOD: &str = r#"
# A CT skin/bone transfer function.
[[point]]
value = -1000
color = [0, 0, 0]
extinction = 0

[[point]]
value = 200
color = [0.8, 0.5, 0.4]
extinction = 0.02
importance = 0.25

[[point]]
value = 1200.5
color = [1.0, 1.0, 0.9]
extinction = 4.0
importance = 0.9
refraction = 1.5
"#;

#[test]
fn parse_good_file() {
    let tf = tf_from_toml(GOOD);
    let p = tf.points();
    assert_eq!(p.len(), 3);
    assert_eq!(p[0].value, -1000.0);
    assert_eq!(p[0].color, [0.0, 0.0, 0.0]);
    assert_eq!(p[0].importance, 0.5, "default importance");
    assert_eq!(p[0].refraction, 1.0, "default refraction");
    assert_eq!(p[1].extinction, 0.02);
    assert_eq!(p[1].importance, 0.25);
    assert_eq!(p[2].value, 1200.5);
    assert_eq!(p[2].color, [1.0, 1.0, 0.9]);
    assert_eq!(p[2].refraction, 1.5);
    assert_eq!(tf.control_values(), vec![-1000.0, 200.0, 1200.5]);
    assert_eq!(tf.max_importance(), 0.9);
    assert_eq!(tf.max_extinction(), 4.0);

    // Through a file, and through serde (serialize, parse back).
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("tf.toml");
    std::fs::write(&path, GOOD).unwrap();
    assert_eq!(TransferFunction::load(&path).unwrap(), tf);
    let text = toml::to_string(&tf).unwrap();
    assert_eq!(tf_from_toml(&text), tf);
    let direct: TransferFunction = toml::from_str(GOOD).unwrap();
    assert_eq!(direct, tf);
}

#[test]
fn parse_errors_name_file_and_field() {
    let point = |body: &str| {
        format!("[[point]]\nvalue = 0\ncolor = [1, 1, 1]\nextinction = 1\n\n[[point]]\n{body}\n")
    };
    let cases: Vec<(String, &str)> = vec![
        (point("color = [1, 0, 0]\nextinction = 1"), "value"),
        (
            point("value = 5\ncolor = [1, 0, 0]\nextinction = -1"),
            "extinction",
        ),
        (
            point("value = 5\ncolor = [1, 0, 0]\nextinction = nan"),
            "extinction",
        ),
        (
            point("value = 5\ncolor = [1, 0, 0]\nextinction = inf"),
            "extinction",
        ),
        (
            point("value = 5\ncolor = [1, 0, 0]\nextinction = 1e31"),
            "extinction",
        ),
        (point("value = 5\ncolor = [1, 0, 0]"), "extinction"),
        (
            point("value = 5\ncolor = [1, 0, 0]\nextinction = 1\nimportance = 0"),
            "importance",
        ),
        (
            point("value = 5\ncolor = [1, 0, 0]\nextinction = 1\nimportance = 1"),
            "importance",
        ),
        (
            point("value = 5\ncolor = [1, 0, 0]\nextinction = 1\nimportance = nan"),
            "importance",
        ),
        (
            point("value = 5\ncolor = [1, 0, 0]\nextinction = 1\nrefraction = 0"),
            "refraction",
        ),
        (
            point("value = 5\ncolor = [1, 0, 0]\nextinction = 1\nrefraction = -inf"),
            "refraction",
        ),
        (
            point("value = nan\ncolor = [1, 0, 0]\nextinction = 1"),
            "value",
        ),
        (
            point("value = -5\ncolor = [1, 0, 0]\nextinction = 1"),
            "value",
        ),
        (
            point("value = 5\ncolor = [1, nan, 0]\nextinction = 1"),
            "color",
        ),
        (
            point("value = 5\ncolor = [1, 1.5, 0]\nextinction = 1"),
            "color",
        ),
        (point("value = 5\ncolor = [1, 0]\nextinction = 1"), "color"),
        (point("value = 5\nextinction = 1"), "color"),
        (
            point("value = 5\ncolor = [1, 0, 0]\nextintion = 1"),
            "extintion",
        ),
        (String::new(), "point"),
        ("point = []\n".to_string(), "point"),
    ];
    for (text, field) in cases {
        let msg = err_of(&text);
        assert!(
            msg.contains("tf.toml"),
            "no file name in {msg:?} for\n{text}"
        );
        assert!(msg.contains(field), "no `{field}` in {msg:?} for\n{text}");
        if !text.is_empty() && field != "extintion" && text.contains("[[point]]") {
            assert!(msg.contains("point 2"), "no point number in {msg:?}");
        }
    }
    assert_eq!(
        err_of(&point("value = 5\ncolor = [1, 0, 0]\nextinction = -1")),
        "tf.toml: point 2: extinction must be finite and >= 0 (got -1)"
    );

    // Through a file: the message names the path.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad-tf.toml");
    std::fs::write(
        &path,
        point("value = 5\ncolor = [1, 0, 0]\nextinction = 1\nimportance = 0"),
    )
    .unwrap();
    let msg = format!("{:#}", TransferFunction::load(&path).unwrap_err());
    assert!(
        msg.contains("bad-tf.toml") && msg.contains("importance"),
        "{msg}"
    );
    let msg = format!(
        "{:#}",
        TransferFunction::load(dir.path().join("missing.toml")).unwrap_err()
    );
    assert!(msg.contains("missing.toml"), "{msg}");

    // from_points validates the same way.
    assert!(TransferFunction::from_points(vec![]).is_err());
    let bad = ControlPoint::new(0.0, [0.5; 3], f64::NAN);
    let msg = format!(
        "{:#}",
        TransferFunction::from_points(vec![bad]).unwrap_err()
    );
    assert!(
        msg.contains("point 1") && msg.contains("extinction"),
        "{msg}"
    );
}

// ---------------------------------------------------------------- eval

fn step_tf() -> TransferFunction {
    TransferFunction::from_points(vec![
        ControlPoint::new(0.0, [1.0, 0.0, 0.0], 2.0).with_importance(0.2),
        ControlPoint::new(10.0, [0.0, 1.0, 0.0], 4.0)
            .with_importance(0.6)
            .with_refraction(2.0),
        ControlPoint::new(10.0, [0.0, 0.0, 1.0], 8.0).with_importance(0.4),
        ControlPoint::new(20.0, [0.0, 0.0, 0.5], 0.0).with_refraction(3.0),
    ])
    .unwrap()
}

#[test]
fn eval_between_points_at_steps_and_beyond_ends() {
    let tf = step_tf();
    // Between the first two points, a quarter of the way.
    let o = tf.eval(2.5);
    assert_eq!(o.tau, 2.5);
    assert_eq!(o.color, [0.75, 0.25, 0.0]);
    assert_eq!(o.emission, [2.5 * 0.75, 2.5 * 0.25, 0.0]);
    assert!((o.importance - 0.3).abs() < 1e-15);
    assert_eq!(o.refraction, 1.25);
    // Just below the step: the left point's limit.
    let o = tf.eval(10.0 - 1e-12);
    assert!((o.tau - 4.0).abs() < 1e-11 && (o.color[1] - 1.0).abs() < 1e-12);
    // At the step: the right-hand point.
    let o = tf.eval(10.0);
    assert_eq!(o.tau, 8.0);
    assert_eq!(o.color, [0.0, 0.0, 1.0]);
    assert_eq!(o.emission, [0.0, 0.0, 8.0]);
    assert_eq!(o.importance, 0.4);
    assert_eq!(o.refraction, 1.0);
    // After the step, half way to the last point: τ and c linear, k̃ = τ·c.
    let o = tf.eval(15.0);
    assert_eq!(o.tau, 4.0);
    assert_eq!(o.color, [0.0, 0.0, 0.75]);
    assert_eq!(o.emission, [0.0, 0.0, 3.0]);
    assert_eq!(o.refraction, 2.0);
    // Beyond the ends: constant.
    assert_eq!(tf.eval(-1e9), tf.eval(0.0));
    assert_eq!(tf.eval(-1.0).tau, 2.0);
    assert_eq!(tf.eval(20.0).tau, 0.0);
    assert_eq!(tf.eval(1e300).color, [0.0, 0.0, 0.5]);
    assert_eq!(tf.eval(f64::INFINITY).refraction, 3.0);
    assert_eq!(tf.eval(f64::NAN), tf.eval(f64::NEG_INFINITY));
    assert_eq!(tf.control_values(), vec![0.0, 10.0, 10.0, 20.0]);
    assert_eq!(tf.max_importance(), 0.6);

    // A single point is constant everywhere.
    let one = TransferFunction::from_points(vec![ControlPoint::new(3.0, [0.5; 3], 1.0)]).unwrap();
    assert_eq!(one.eval(-5.0), one.eval(1e6));
    assert_eq!(one.eval(0.0).emission, [0.5; 3]);
}

// ---------------------------------------------------------------- pre-integration

fn smooth_tf() -> TransferFunction {
    let points = (0..=40)
        .map(|i| {
            let v = -1000.0 + 100.0 * i as f64;
            let x = i as f64 / 40.0;
            let color = [
                0.5 + 0.5 * (7.0 * x).sin(),
                0.5 + 0.4 * (3.0 * x + 1.0).cos(),
                x,
            ];
            ControlPoint::new(v, color, 0.5 + 0.45 * (5.0 * x).sin())
                .with_importance(0.1 + 0.8 * x)
                .with_refraction(1.0 + x)
        })
        .collect();
    TransferFunction::from_points(points).unwrap()
}

#[test]
fn preint_smooth_tf_matches_quadrature() {
    let tf = smooth_tf();
    let table = PreintTable::new(&tf, -1000.0, 3000.0, 4000).unwrap();
    assert_eq!(table.bin_width(), 1.0);
    let mut rng = Lcg(1);
    for i in 0..120 {
        let (a, b) = if i % 4 == 0 {
            // Short segments, possibly inside one bin.
            let a = rng.range(-1100.0, 3100.0);
            (a, a + rng.range(-2.0, 2.0))
        } else {
            (rng.range(-1100.0, 3100.0), rng.range(-1100.0, 3100.0))
        };
        check_segment(&tf, &table, a, b, 1e-9);
    }
}

fn huge_range_tf() -> TransferFunction {
    TransferFunction::from_points(vec![
        ControlPoint::new(0.0, [0.2, 0.4, 0.6], 1e-6),
        ControlPoint::new(100.0, [1.0, 0.5, 0.0], 1e6),
        ControlPoint::new(101.0, [0.9, 0.1, 0.3], 1e-6),
        ControlPoint::new(150.0, [0.1, 0.7, 0.3], 3e-6).with_importance(0.9),
        ControlPoint::new(200.0, [0.5, 0.5, 0.5], 1e-6),
    ])
    .unwrap()
}

#[test]
fn preint_extinction_1e_minus_6_to_1e6_keeps_relative_precision() {
    let tf = huge_range_tf();
    let table = PreintTable::new(&tf, 0.0, 200.0, 200).unwrap();
    let mut rng = Lcg(2);
    // Inside the tiny region after the huge one: the cancellation trap.
    for _ in 0..120 {
        let a = rng.range(101.0, 200.0);
        let b = if rng.next_f64() < 0.3 {
            a + rng.range(-0.5, 0.5)
        } else {
            rng.range(101.0, 200.0)
        };
        let b = b.clamp(101.0, 200.0);
        check_segment(&tf, &table, a, b, 1e-6);
        // ... where in fact the precision is far better than 1e-6.
        let (lo, hi) = (a.min(b), a.max(b));
        if hi > lo {
            let want = simpson(
                &|s| all_channels(&tf.eval(s)),
                lo,
                hi,
                &tf.control_values(),
                1000,
            )[0] / (hi - lo);
            assert!(close(table.average(Channel::Tau, a, b), want, 1e-12));
        }
    }
    // Everywhere else, including across the 1e6 peak and outside [0, 200].
    for _ in 0..120 {
        let (a, b) = (rng.range(-20.0, 220.0), rng.range(-20.0, 220.0));
        check_segment(&tf, &table, a, b, 1e-9);
    }
}

/// What the trap looks like: G10's running integral F(s) = ∫₀ˢ τ, even in
/// f64, cannot resolve τ = 1e-6 after the τ = 1e6 region; the pyramid can.
#[test]
fn running_integral_loses_the_tiny_region_but_the_table_does_not() {
    let tf = huge_range_tf();
    let table = PreintTable::new(&tf, 0.0, 200.0, 200).unwrap();
    // F at the nodes (bin width 1), accumulated as G10 does.
    let nodes = table.nodes(Channel::Tau);
    let mut running = vec![0.0f64];
    for w in nodes.windows(2) {
        running.push(running.last().unwrap() + 0.5 * (w[0] + w[1]));
    }
    let naive_f32 =
        |a: usize, b: usize| ((running[b] as f32 - running[a] as f32) / (b - a) as f32) as f64;
    let naive_f64 = |a: usize, b: usize| (running[b] - running[a]) / (b - a) as f64;
    let (a, b) = (150usize, 151usize);
    let exact = 0.5 * (tf.tau(150.0) + tf.tau(151.0));
    let rel = |x: f64| (x - exact).abs() / exact;
    assert!(
        rel(naive_f64(a, b)) > 1e-6,
        "f64 running integral: {:e}",
        rel(naive_f64(a, b))
    );
    assert!(
        rel(naive_f32(a, b)) > 0.5,
        "f32 running integral: {:e}",
        rel(naive_f32(a, b))
    );
    assert!(rel(table.average(Channel::Tau, 150.0, 151.0)) < 1e-15);
    // A tiny segment (where Eq. 2 would fall back to f(s_i)) is exact too.
    let tiny = table.average(Channel::Tau, 150.0, 150.0 + 1e-9);
    assert!(close(tiny, tf.tau(150.0 + 0.5e-9), 1e-12), "{tiny:e}");
}

#[test]
fn preint_delta_peak_with_bin_width_one() {
    let v = 100.0;
    let tf = TransferFunction::from_points(vec![
        ControlPoint::new(0.0, [0.0, 0.0, 0.0], 0.0),
        ControlPoint::new(v, [1.0, 0.0, 0.0], 0.0),
        ControlPoint::new(v + 1.0, [0.2, 0.9, 0.0], 1e3).with_importance(0.95),
        ControlPoint::new(v + 2.0, [0.0, 0.0, 1.0], 0.0),
        ControlPoint::new(255.0, [0.0, 0.0, 0.0], 0.0),
    ])
    .unwrap();
    let n = PreintTable::suggested_bins(0.0, 255.0, true);
    assert_eq!(n, 255);
    let table = PreintTable::new(&tf, 0.0, 255.0, n).unwrap();
    // The whole peak: ∫ τ = 1e3 (a triangle of base 2, height 1e3).
    assert_eq!(table.integral(Channel::Tau, 0.0, 255.0), 1e3);
    assert_eq!(table.integral(Channel::Tau, v, v + 2.0), 1e3);
    assert_eq!(table.average(Channel::Tau, v - 10.0, v + 10.0), 50.0);
    assert_eq!(table.average(Channel::Tau, v + 0.5, v + 1.5), 750.0);
    assert_eq!(table.average(Channel::Tau, 0.0, v), 0.0);
    assert_eq!(table.average(Channel::Tau, v + 2.0, 300.0), 0.0);
    let mut rng = Lcg(3);
    for i in 0..150 {
        let (a, b) = if i % 2 == 0 {
            (rng.range(v - 3.0, v + 5.0), rng.range(v - 3.0, v + 5.0))
        } else {
            (rng.range(-10.0, 265.0), rng.range(-10.0, 265.0))
        };
        check_segment(&tf, &table, a, b, 1e-9);
    }
}

#[test]
fn preint_never_nan_or_negative() {
    let tfs = [smooth_tf(), huge_range_tf(), step_tf()];
    let specials = [
        f64::NAN,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::MAX,
        -f64::MAX,
        1e300,
        -1e300,
        0.0,
        -0.0,
        1e-300,
    ];
    for tf in &tfs {
        for (vmin, vmax, n) in [
            (0.0, 200.0, 200),
            (-5.0, 25.0, 7),
            (3.0, 3.0, 1),
            (0.0, 1e-3, 4096),
        ] {
            let table = PreintTable::new(tf, vmin, vmax, n).unwrap();
            let mut rng = Lcg(4);
            let mut xs: Vec<f64> = specials.to_vec();
            xs.extend((0..40).map(|_| rng.range(vmin - 50.0, vmax + 50.0)));
            xs.extend([vmin, vmax, table.vmin() + 0.5 * table.bin_width()]);
            for &a in &xs {
                for &b in &xs {
                    for c in Channel::ALL {
                        let avg = table.average(c, a, b);
                        assert!(
                            avg.is_finite() && avg >= 0.0,
                            "{c:?} avg [{a}, {b}] = {avg}"
                        );
                        let int = table.integral(c, a, b);
                        assert!(
                            !int.is_nan() && int >= 0.0,
                            "{c:?} integral [{a}, {b}] = {int}"
                        );
                        assert!(int <= f64::MAX);
                    }
                    let seg = table.segment(a, b);
                    for d in [0.0, 1e-12, 1.0, 1e4, f64::INFINITY] {
                        let al = seg.alpha(d);
                        assert!((0.0..=1.0).contains(&al), "alpha {al}");
                        for col in seg.premultiplied_color(d) {
                            assert!(col.is_finite() && col >= 0.0, "colour {col}");
                        }
                    }
                }
            }
            // a == b and both outside on one side: the constant extension.
            assert_eq!(
                table.average(Channel::Tau, 7.5, 7.5),
                table.value(Channel::Tau, 7.5)
            );
            assert_eq!(
                table.average(Channel::Refraction, -1e9, -1e8),
                table.nodes(Channel::Refraction)[0]
            );
            assert_eq!(
                table.average(Channel::Importance, 1e9, 1e8),
                *table.nodes(Channel::Importance).last().unwrap()
            );
            assert_eq!(
                table.average(Channel::Tau, f64::NAN, f64::NAN),
                table.nodes(Channel::Tau)[0]
            );
        }
    }
    // τ average 0: zero alpha, zero colour.
    let tf = TransferFunction::from_points(vec![ControlPoint::new(0.0, [1.0; 3], 0.0)]).unwrap();
    let table = PreintTable::new(&tf, 0.0, 10.0, 10).unwrap();
    let seg = table.segment(2.0, 7.0);
    assert_eq!(seg.tau, 0.0);
    assert_eq!(seg.alpha(3.0), 0.0);
    assert_eq!(seg.premultiplied_color(3.0), [0.0; 3]);
    assert_eq!(table.integral(Channel::Tau, -1e300, 1e300), 0.0);
}

#[test]
fn preint_integral_and_average_edge_cases() {
    let tf = step_tf();
    let table = PreintTable::new(&tf, 0.0, 20.0, 20).unwrap();
    // Outside the range f is constant: 2 below, 0 above (τ).
    assert_eq!(table.integral(Channel::Tau, -10.0, -5.0), 10.0);
    assert_eq!(table.integral(Channel::Tau, -5.0, -10.0), 10.0);
    assert_eq!(table.average(Channel::Tau, -30.0, -20.0), 2.0);
    assert_eq!(table.average(Channel::Tau, 25.0, 40.0), 0.0);
    // Straddling vmin: 10 below at τ = 2 plus ∫₀¹ (2 + 0.2 s) ds = 2.1.
    assert!((table.integral(Channel::Tau, -10.0, 1.0) - 22.1).abs() < 1e-13);
    assert!((table.average(Channel::Tau, -10.0, 1.0) - 22.1 / 11.0).abs() < 1e-15);
    // Same-bin averages are exact midpoints of the linear f.
    assert_eq!(table.average(Channel::Tau, 2.0, 3.0), 2.5);
    assert_eq!(table.average(Channel::Tau, 2.25, 2.25), 2.45);
    // The table sees the step as a ramp across the bin [9, 10]: f(9) = 3.8,
    // f(10) = 8 (the right-hand point at the node).
    assert_eq!(table.value(Channel::Tau, 10.0), 8.0);
    assert!((table.value(Channel::Tau, 9.5) - 5.9).abs() < 1e-15);
    // Whole range: trapezoids of the nodes.
    let nodes = table.nodes(Channel::Tau);
    let trap: f64 = nodes.windows(2).map(|w| 0.5 * (w[0] + w[1])).sum();
    assert!((table.integral(Channel::Tau, 0.0, 20.0) - trap).abs() < 1e-13);
    // Suggested bins.
    assert_eq!(PreintTable::suggested_bins(0.0, 255.0, true), 255);
    assert_eq!(PreintTable::suggested_bins(-1024.0, 3071.0, true), 4095);
    assert_eq!(PreintTable::suggested_bins(0.0, 65535.0, true), 65535);
    assert_eq!(PreintTable::suggested_bins(0.0, 0.0, true), 1);
    assert_eq!(
        PreintTable::suggested_bins(-40000.0, 40000.0, true),
        DEFAULT_BINS
    );
    assert_eq!(PreintTable::suggested_bins(0.0, 1.0, false), DEFAULT_BINS);
    // Bad ranges.
    assert!(PreintTable::new(&tf, 1.0, 0.0, 10).is_err());
    assert!(PreintTable::new(&tf, f64::NAN, 0.0, 10).is_err());
    assert!(PreintTable::new(&tf, 0.0, 1.0, 0).is_err());
    assert!(PreintTable::new(&tf, 0.0, 1.0, MAX_BINS + 1).is_err());
    // A degenerate range is widened.
    let t = PreintTable::new(&tf, 5.0, 5.0, 1).unwrap();
    assert_eq!((t.vmin(), t.vmax()), (5.0, 6.0));
}

// ---------------------------------------------------------------- alpha and colour

#[test]
fn alpha_and_colour_are_stable() {
    // Tiny optical depth: α ≈ τ·d with full relative precision.
    let (tau, d) = (1e-12, 1.0);
    let a = alpha(tau, d);
    assert!(((a - 1e-12) / 1e-12).abs() < 1e-11, "alpha {a:e}");
    assert!(((alpha(1e-300, 1.0) - 1e-300) / 1e-300).abs() < 1e-15);
    // Colour k̃/τ·α → k̃·d as τ·d → 0.
    let col = premultiplied_color([0.5e-12, 1e-12, 0.0], tau, d);
    assert!(((col[0] - 0.5e-12) / 0.5e-12).abs() < 1e-11, "{col:?}");
    assert!(((col[1] - 1e-12) / 1e-12).abs() < 1e-11);
    assert_eq!(col[2], 0.0);
    assert!(((emission_weight(1e-20, 3.0) - 3.0) / 3.0).abs() < 1e-15);
    // Moderate: exact formula.
    let a = alpha(0.5, 2.0);
    assert!((a - (1.0 - (-1.0f64).exp())).abs() < 1e-15);
    let col = premultiplied_color([0.25, 0.5, 0.0], 0.5, 2.0);
    assert!((col[0] - 0.5 * a).abs() < 1e-15 && (col[1] - a).abs() < 1e-15);
    // Huge: α exactly 1, colour = k̃/τ, finite.
    for (tau, d) in [
        (1e6, 1e4),
        (1e6, 1.0),
        (1e30, 1e4),
        (1.0, f64::INFINITY),
        (f64::INFINITY, 1.0),
    ] {
        assert_eq!(alpha(tau, d), 1.0, "tau {tau} d {d}");
    }
    let col = premultiplied_color([0.8e6, 0.2e6, 1e6], 1e6, 1e4);
    for (got, want) in col.iter().zip([0.8, 0.2, 1.0]) {
        assert!(close(*got, want, 1e-15), "{col:?}");
    }
    let col = premultiplied_color([0.3, 0.0, 1.0], 1.0, f64::INFINITY);
    assert_eq!(col, [0.3, 0.0, 1.0]);
    assert_eq!(premultiplied_color([1.0; 3], f64::INFINITY, 1.0), [0.0; 3]);
    // τ = 0 (or nonsense input): α = 0, colour 0.
    assert_eq!(alpha(0.0, 5.0), 0.0);
    assert_eq!(premultiplied_color([0.0; 3], 0.0, 5.0), [0.0; 3]);
    assert_eq!(premultiplied_color([1.0; 3], 0.0, 5.0), [0.0; 3]);
    assert_eq!(alpha(f64::NAN, 1.0), 0.0);
    assert_eq!(alpha(-1.0, 1.0), 0.0);
    assert_eq!(alpha(1.0, -1.0), 0.0);
    assert_eq!(alpha(0.0, f64::INFINITY), 0.0);
    assert_eq!(
        premultiplied_color([f64::NAN, -1.0, 1.0], 1.0, 0.0),
        [0.0; 3]
    );
    let col = premultiplied_color([f64::NAN, -1.0, f64::INFINITY], 1.0, 1.0);
    assert!(col.iter().all(|c| c.is_finite() && *c >= 0.0), "{col:?}");
}

// ---------------------------------------------------------------- GPU layout

/// The segment average as a shader would compute it from the f32 array.
fn gpu_average(data: &[f32], l: &PreintLayout, c: Channel, a: f64, b: f64) -> f64 {
    let base = c.index() * l.channel_stride as usize;
    let nodes = &data[base..base + l.n_bins as usize + 1];
    let n = l.n_bins as usize;
    let to_u = |s: f64| (((s - l.vmin) / l.bin_width) as f32).clamp(0.0, n as f32);
    let (mut ua, mut ub) = (to_u(a), to_u(b));
    if ua > ub {
        std::mem::swap(&mut ua, &mut ub);
    }
    let mids = &data[base + l.mid_offset as usize..base + l.mid_offset as usize + n];
    // shaders/shared/preint.wgsl `bin_average`
    let bin = |j: usize, ta: f32, tb: f32| {
        let (a, b, m) = (nodes[j], nodes[j + 1], mids[j]);
        let t = 0.5 * (ta + tb);
        let w = tb - ta;
        let f = a * ((1.0 - t) * (1.0 - 2.0 * t))
            + m * (4.0 * t * (1.0 - t))
            + b * (t * (2.0 * t - 1.0));
        (f + (a + b - 2.0 * m) * (w * w / 6.0)).max(0.0)
    };
    let ja = (ua as usize).min(n - 1);
    if ub <= (ja + 1) as f32 {
        return bin(ja, ua - ja as f32, (ub - ja as f32).min(1.0)) as f64;
    }
    let jb = (ub as usize).min(n);
    let mut sum = ((ja + 1) as f32 - ua) * bin(ja, ua - ja as f32, 1.0);
    let mut lo = ja + 1;
    let top = l.levels as usize - 1;
    while lo < jb {
        let mut k = if lo == 0 {
            top
        } else {
            (lo.trailing_zeros() as usize).min(top)
        };
        while (1usize << k) > jb - lo {
            k -= 1;
        }
        sum += data[base + l.level_offsets[k] as usize + (lo >> k)];
        lo += 1 << k;
    }
    if jb < n {
        sum += (ub - jb as f32) * bin(jb, 0.0, ub - jb as f32);
    }
    (sum / (ub - ua)) as f64
}

#[test]
fn gpu_layout_offsets_and_f32_lookup() {
    let tf = huge_range_tf();
    let table = PreintTable::new(&tf, 0.0, 200.0, 200).unwrap();
    let (data, layout) = table.gpu_layout();
    assert_eq!(layout.n_bins, 200);
    assert_eq!(layout.levels, 8); // 200, 100, 50, 25, 12, 6, 3, 1 entries
    assert_eq!(layout.channels, 6);
    // nodes, the pyramid, the bin midpoints
    let stride = 201 + 200 + 100 + 50 + 25 + 12 + 6 + 3 + 1 + 200;
    assert_eq!(layout.channel_stride as usize, stride);
    assert_eq!(layout.mid_offset, 598);
    assert_eq!(data.len(), 6 * stride);
    assert_eq!(
        &layout.level_offsets[..8],
        &[201, 401, 501, 551, 576, 588, 594, 597]
    );
    assert_eq!(
        (layout.vmin, layout.vmax, layout.bin_width),
        (0.0, 200.0, 1.0)
    );
    for c in Channel::ALL {
        let base = c.index() * stride;
        for (i, &x) in table.nodes(c).iter().enumerate() {
            assert_eq!(data[base + i], x as f32);
        }
        for k in 0..table.levels() {
            let off = base + layout.level_offsets[k] as usize;
            for (j, &x) in table.level(c, k).iter().enumerate() {
                assert_eq!(data[off + j], x as f32);
            }
        }
    }
    assert!(data.iter().all(|x| x.is_finite() && *x >= 0.0));
    // The f32 lookup keeps f32-level relative precision in the tiny region
    // after the huge one (the running integral in f32 would be all noise).
    let mut rng = Lcg(5);
    for _ in 0..500 {
        let (a, b) = (rng.range(101.0, 200.0), rng.range(101.0, 200.0));
        for c in Channel::ALL {
            let want = table.average(c, a, b);
            let got = gpu_average(&data, &layout, c, a, b);
            assert!(
                close(got, want, 1e-5),
                "{c:?} [{a}, {b}]: gpu {got:e}, cpu {want:e}"
            );
        }
    }
}

// ---------------------------------------------------------------- emptiness

fn ramp_tf() -> TransferFunction {
    TransferFunction::from_points(vec![
        ControlPoint::new(0.0, [0.0; 3], 0.0),
        ControlPoint::new(50.0, [0.0; 3], 0.0),
        ControlPoint::new(60.0, [1.0; 3], 1.0),
        ControlPoint::new(80.0, [1.0; 3], 0.0),
    ])
    .unwrap()
}

#[test]
fn emptiness_examples() {
    let tf = ramp_tf();
    let empty = EmptinessTable::new(&tf, 0.0, 100.0, 100).unwrap();
    assert!(empty.is_empty(0.0, 49.9));
    assert!(empty.is_empty(0.0, 50.0));
    assert!(!empty.is_empty(0.0, 55.0));
    assert!(empty.is_empty(81.0, 200.0));
    assert!(empty.is_empty(80.0, 200.0));
    assert!(!empty.is_empty(79.0, 90.0));
    assert!(!empty.is_empty(90.0, 79.0), "swapped bounds");
    assert!(empty.is_empty(-50.0, -10.0));
    assert!(empty.is_empty(-1e300, 30.0));
    assert!(!empty.is_empty(-1e300, 1e300));
    assert!(!empty.is_empty(f64::NAN, 10.0));
    assert!(!empty.is_empty(65.0, 65.0));
    assert_eq!(empty.prefix_counts().len(), 101);
    assert_eq!(*empty.prefix_counts().last().unwrap(), 30); // bins 50..80

    // τ > 0 beyond the table's range counts for the outside parts.
    let wide = TransferFunction::from_points(vec![
        ControlPoint::new(-100.0, [1.0; 3], 1.0),
        ControlPoint::new(-90.0, [1.0; 3], 0.0),
        ControlPoint::new(300.0, [1.0; 3], 0.0),
        ControlPoint::new(310.0, [1.0; 3], 2.0),
    ])
    .unwrap();
    let e = EmptinessTable::new(&wide, 0.0, 100.0, 10).unwrap();
    assert!(e.is_empty(0.0, 100.0));
    assert!(!e.is_empty(-200.0, 50.0));
    assert!(!e.is_empty(50.0, 1000.0));
}

/// τ > 0 somewhere on [lo, hi]? Exact for a piecewise-linear τ ≥ 0 without
/// steps at lo: τ at both ends and at the control points inside.
fn brute_nonzero(tf: &TransferFunction, lo: f64, hi: f64) -> bool {
    tf.tau(lo) > 0.0
        || tf.tau(hi) > 0.0
        || tf
            .points()
            .iter()
            .any(|p| p.extinction > 0.0 && p.value >= lo && p.value <= hi)
}

#[test]
fn emptiness_matches_brute_force_on_a_grid() {
    let tfs = [ramp_tf(), step_tf(), huge_range_tf()];
    for tf in &tfs {
        for (vmin, vmax, n) in [(0.0, 100.0, 100), (0.0, 100.0, 7), (-3.0, 130.0, 19)] {
            let e = EmptinessTable::new(tf, vmin, vmax, n).unwrap();
            let dx = (vmax - vmin) / n as f64;
            let node = |j: usize| if j >= n { vmax } else { vmin + j as f64 * dx };
            let grid: Vec<f64> = (0..=300).map(|i| -40.0 + 0.7 * i as f64).collect();
            for &min in &grid {
                for &max in &grid {
                    if max < min {
                        continue;
                    }
                    let answer = e.is_empty(min, max);
                    // Dense sampling: any τ > 0 found forbids "empty".
                    let sampled =
                        (0..=64).any(|k| tf.tau(min + (max - min) * k as f64 / 64.0) > 0.0);
                    assert!(
                        !(answer && sampled),
                        "claims empty on [{min}, {max}] (sampled τ > 0)"
                    );
                    if answer {
                        assert!(!brute_nonzero(tf, min, max), "[{min}, {max}]");
                    }
                    assert_eq!(answer, e.is_empty(max, min));
                    // Inside the table: exact at bin granularity.
                    if min >= vmin && max <= vmax {
                        // Bins [x_j, x_{j+1}] that [min, max] needs: from the
                        // last node <= min to the first node >= max.
                        let jlo = (0..n).rev().find(|&j| node(j) <= min).unwrap_or(0);
                        let jhi = (0..n)
                            .find(|&j| node(j + 1) >= max)
                            .unwrap_or(n - 1)
                            .max(jlo);
                        let (lo, hi) = (node(jlo), node(jhi + 1));
                        assert_eq!(
                            answer,
                            !brute_nonzero(tf, lo, hi),
                            "[{min}, {max}] bins {jlo}..={jhi}"
                        );
                    }
                }
            }
        }
    }
}

// ------------------------------------------------- quadratic emission in bins

/// Integer control values on a bin-width-1 table: every bin lies between
/// two control points, so the table's f is the transfer function itself —
/// the emission k̃ = τ·c, quadratic there, included — and segment averages
/// match quadrature of the transfer function at any length. (A table of
/// node values alone linearises k̃: for this one-value peak, τ = 3 from
/// blue to white, its red emission average over the rising bin is 1.5
/// instead of 1.)
#[test]
fn preint_emission_is_exact_between_integer_control_points() {
    let tf = TransferFunction::from_points(vec![
        ControlPoint::new(0.0, [0.0; 3], 0.0),
        ControlPoint::new(150.0, [0.0, 0.0, 1.0], 0.0),
        ControlPoint::new(151.0, [1.0, 1.0, 1.0], 3.0),
        ControlPoint::new(152.0, [0.0, 0.0, 1.0], 0.0),
        ControlPoint::new(200.0, [0.9, 0.5, 0.2], 1.0),
        ControlPoint::new(200.0, [0.2, 0.5, 0.9], 4.0), // a step on a node
        ControlPoint::new(255.0, [1.0; 3], 0.5),
    ])
    .unwrap();
    let table = PreintTable::new(&tf, 0.0, 255.0, 255).unwrap();
    let mut rng = Lcg(11);
    for _ in 0..2000 {
        let s = rng.range(0.0, 255.0);
        let want = tf.eval(s);
        for (c, w) in [
            (Channel::Tau, want.tau),
            (Channel::EmissionR, want.emission[0]),
            (Channel::EmissionB, want.emission[2]),
        ] {
            let got = table.value(c, s);
            // the bins beside the step stay linear (its upper value at the node)
            if (199.0..201.0).contains(&s) {
                assert!(got >= 0.0);
                continue;
            }
            assert!((got - w).abs() < 1e-12, "{c:?} at {s}: {got} vs {w}");
        }
    }
    // Averages over segments inside and across the peak against midpoint
    // quadrature of the transfer function.
    let quad = |c: Channel, a: f64, b: f64| {
        let n = 20_000;
        (0..n)
            .map(|i| {
                let o = tf.eval(a + (b - a) * (i as f64 + 0.5) / n as f64);
                match c {
                    Channel::Tau => o.tau,
                    _ => o.emission[0],
                }
            })
            .sum::<f64>()
            / n as f64
    };
    for (a, b) in [
        (150.0, 151.0),
        (150.2, 150.7),
        (149.5, 152.5),
        (140.0, 160.3),
    ] {
        for c in [Channel::Tau, Channel::EmissionR] {
            let got = table.average(c, a, b);
            let want = quad(c, a, b);
            assert!(
                (got - want).abs() < 1e-7,
                "{c:?} [{a}, {b}]: {got} vs {want}"
            );
        }
    }
    assert!((table.average(Channel::EmissionR, 150.0, 151.0) - 1.0).abs() < 1e-12);
}

// ---------------------------------------------------------------- closed form

/// ∫ of (τ, k̃) over [lo, hi] exactly: between control points f is a
/// quadratic, integrated exactly by Milne's open rule (interior points
/// only, so a step at an end does not enter).
fn exact_dvr_integral(tf: &TransferFunction, lo: f64, hi: f64) -> [f64; 4] {
    let mut cuts = vec![lo];
    cuts.extend(
        tf.control_values()
            .into_iter()
            .filter(|&x| x > lo && x < hi),
    );
    cuts.push(hi);
    let f = |x: f64| {
        let o = tf.eval(x);
        [o.tau, o.emission[0], o.emission[1], o.emission[2]]
    };
    let mut sum = [0.0; 4];
    for w in cuts.windows(2) {
        let (p, h) = (w[0], w[1] - w[0]);
        let (a, b, c) = (f(p + 0.25 * h), f(p + 0.5 * h), f(p + 0.75 * h));
        for k in 0..4 {
            sum[k] += h / 3.0 * (2.0 * a[k] - b[k] + 2.0 * c[k]);
        }
    }
    sum
}

/// The closed form's averages against the exact integral of the transfer
/// function, over random segments (some short, some of zero length, some
/// reaching past the range), relative to the channel's largest value. Ends
/// beyond the range are clamped to it, as the kernel clamps every sample
/// value.
fn closed_matches_exact(tf: &TransferFunction, vmin: f64, vmax: f64, seed: u64) {
    let cf = closed::ClosedForm::new(tf, vmin, vmax).expect("few pieces");
    // Each channel's largest value over the range.
    let mut scale = [1e-300f64; 4];
    for i in 0..=1000 {
        let o = tf.eval(vmin + (vmax - vmin) * i as f64 / 1000.0);
        for (m, v) in scale
            .iter_mut()
            .zip([o.tau, o.emission[0], o.emission[1], o.emission[2]])
        {
            *m = m.max(v);
        }
    }
    let mut rng = Lcg(seed);
    let span = vmax - vmin;
    for i in 0..2000 {
        let a = rng.range(vmin - 0.1 * span, vmax + 0.1 * span);
        let b = match i % 4 {
            0 => a + rng.range(-1e-3, 1e-3) * span,
            1 => a,
            _ => rng.range(vmin - 0.1 * span, vmax + 0.1 * span),
        };
        let got = cf.average(a, b);
        let (lo, hi) = (a.min(b).clamp(vmin, vmax), a.max(b).clamp(vmin, vmax));
        let short = hi - lo < cf.eps;
        let want = if short {
            // Widened to eps about the middle: the function there, to
            // within its change over eps.
            let o = tf.eval(0.5 * (lo + hi));
            [o.tau, o.emission[0], o.emission[1], o.emission[2]]
        } else {
            exact_dvr_integral(tf, lo, hi).map(|x| x / (hi - lo))
        };
        let slack = if short { 1e-3 } else { 1e-9 };
        for c in 0..4 {
            assert!(
                got[c].is_finite() && got[c] >= 0.0,
                "channel {c} on [{a}, {b}]: {}",
                got[c]
            );
            assert!(
                (got[c] - want[c]).abs() <= slack * scale[c],
                "channel {c} on [{a}, {b}]: closed form {:e}, exact {:e}",
                got[c],
                want[c]
            );
        }
    }
}

/// The translucent brain of the VTK comparison.
fn brain_tf() -> TransferFunction {
    TransferFunction::load(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../configs/tf/colin27-brain.toml"
    ))
    .unwrap()
}

#[test]
fn closed_form_matches_the_exact_integral() {
    closed_matches_exact(&brain_tf(), 0.0, 255.0, 1);
    // Steps (equal values), a τ = 0 end, and data beyond the last point.
    closed_matches_exact(&step_tf(), -5.0, 30.0, 2);
    // Data inside the points only, a τ ≡ 0 piece first.
    closed_matches_exact(&ramp_tf(), 10.0, 70.25, 3);
    // Extinction 1e-6 beside 1e6 on a piece one value wide.
    closed_matches_exact(&huge_range_tf(), 0.0, 200.0, 4);
}
#[test]
fn closed_form_leaves_out_empty_pieces_and_declines_what_it_cannot_hold() {
    let cf = closed::ClosedForm::new(&brain_tf(), 0.0, 255.0).unwrap();
    // [0, 25] has τ ≡ 0; [25, 75], [75, 105], [105, 125] and [125, 255]
    // remain, the last going on by eps past the range.
    assert_eq!(cf.pieces.len(), 4, "{:?}", cf.pieces);
    assert!(cf.pieces[0].start == 25.0 && cf.pieces[0].width == 50.0);
    assert_eq!(cf.pieces[3].start + cf.pieces[3].width, 255.0 + cf.eps);
    assert_eq!(cf.gpu()[0][3], 4.0);
    // 41 points: more pieces than the kernel holds.
    assert!(closed::ClosedForm::new(&smooth_tf(), -1000.0, 3000.0).is_none());
    // An extinction near the cap over a sliver: too large for f32 sums.
    let huge = TransferFunction::from_points(vec![
        ControlPoint::new(0.0, [1.0; 3], 0.0),
        ControlPoint::new(1e-9, [1.0; 3], MAX_EXTINCTION),
    ])
    .unwrap();
    assert!(closed::ClosedForm::new(&huge, 0.0, 1.0).is_none());
    // τ ≡ 0: no pieces, every average 0.
    let clear = TransferFunction::from_points(vec![ControlPoint::new(0.0, [1.0; 3], 0.0)]).unwrap();
    let cf = closed::ClosedForm::new(&clear, 0.0, 1.0).unwrap();
    assert!(cf.pieces.is_empty());
    assert_eq!(cf.average(0.2, 0.7), [0.0; 4]);
}

/// The largest extinction over a range equals the largest of the function
/// sampled densely over it (a step included), and is 0 for a reversed or
/// NaN range.
#[test]
fn max_extinction_in_a_range_is_the_sampled_maximum() {
    let tf = TransferFunction::from_points(vec![
        ControlPoint::new(-1000.0, [0.0; 3], 0.0),
        ControlPoint::new(-100.0, [1.0; 3], 0.0),
        ControlPoint::new(0.0, [1.0; 3], 2.0),
        ControlPoint::new(300.0, [1.0; 3], 0.5),
        ControlPoint::new(300.0, [1.0; 3], 6.0),
        ControlPoint::new(900.0, [1.0; 3], 1.0),
    ])
    .unwrap();
    let ranges = [
        (-2000.0, -1500.0),
        (-1000.0, -100.0),
        (-200.0, -50.0),
        (-50.0, 50.0),
        (10.0, 290.0),
        (10.0, 300.0),
        (310.0, 2000.0),
        (1000.0, 1200.0),
        (-3000.0, 3000.0),
    ];
    for (lo, hi) in ranges {
        let sampled = (0..=20_000)
            .map(|i| tf.tau(lo + (hi - lo) * f64::from(i) / 20_000.0))
            .fold(0.0, f64::max);
        let got = tf.max_extinction_in(lo, hi);
        assert!(
            (got - sampled).abs() <= 1e-3 * sampled.max(1.0),
            "[{lo}, {hi}]: {got} against sampled {sampled}"
        );
    }
    assert_eq!(tf.max_extinction_in(5.0, 1.0), 0.0);
    assert_eq!(tf.max_extinction_in(f64::NAN, 1.0), 0.0);
}
