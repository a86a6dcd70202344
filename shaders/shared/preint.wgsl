// shared/preint.wgsl: pre-integrated transfer function lookups.

#import bindings

// Pre-integration (G10 §4 Eq. 2) over the sum pyramid of common/src/tf
// (or, where the table allows, its running integral as an f32 pair):
// the average of four interleaved attributes over the data segment [a, b]:
// (τ, k̃r, k̃g, k̃b) in the table at `base` 0, (ι, ν, 0, 0) at `frame.aux.x`
// (G10 §4: "we employ preintegration for all attributes"). `prefix` is where
// that part's running integral starts, 0 when it has none.

// Read from the buffer itself: an array indexed by a value is best left
// where a GPU keeps it (a private copy would go to scratch memory).
fn tf_offset(k: u32) -> u32 {
    return frame_constants.tf_offsets[k >> 2u][k & 3u];
}

// The average over [j + ta, j + tb] (0 ≤ ta ≤ tb ≤ 1) of bin j's quadratic
// through its nodes a, b and midpoint value m (common/src/tf/preint.rs:
// in a bin without a control point inside, the transfer function exactly):
// f at the centre plus f''·w²/24, exact, no division.
fn bin_average(base: u32, j: u32, ta: f32, tb: f32) -> vec4<f32> {
    return quadratic_average(tf_entry(base + j), tf_entry(base + frame.tf_mids.x + j),
                             tf_entry(base + j + 1u), ta, tb);
}

// The same for the quadratic through a (0), m (½), b (1) given by value;
// ta and tb in either order.
fn quadratic_average(a: vec4<f32>, m: vec4<f32>, b: vec4<f32>, ta: f32, tb: f32) -> vec4<f32> {
    let t = 0.5 * (ta + tb);
    let w = tb - ta;
    let f = a * ((1.0 - t) * (1.0 - 2.0 * t)) + m * (4.0 * t * (1.0 - t)) + b * (t * (2.0 * t - 1.0));
    return max(f + (a + b - 2.0 * m) * (w * w / 6.0), vec4<f32>(0.0));
}

// ∫₀ˣ of the quadratic through a (0), m (½), b (1); with a and b swapped
// and 1 − x, the integral over [x, 1] (each without cancellation near its
// zero).
fn quadratic_integral(a: vec4<f32>, m: vec4<f32>, b: vec4<f32>, x: f32) -> vec4<f32> {
    let x2 = x * x;
    let x3 = x2 * x;
    return a * (x - 1.5 * x2 + (2.0 / 3.0) * x3) + m * (2.0 * x2 - (4.0 / 3.0) * x3)
        + b * ((2.0 / 3.0) * x3 - 0.5 * x2);
}

fn segment_average(base: u32, prefix: u32, sa: f32, sb: f32) -> vec4<f32> {
    let n = u32(frame.tf.z);
    var ua = clamp((sa - frame.tf.x) * frame.recip.w, 0.0, f32(n));
    var ub = clamp((sb - frame.tf.x) * frame.recip.w, 0.0, f32(n));
    if (ua > ub) {
        let t = ua;
        ua = ub;
        ub = t;
    }
    let ja = min(u32(ua), n - 1u);
    if (ub <= f32(ja + 1u)) {
        // Same bin: the exact average of the bin's quadratic, no division
        // (this is Eq. 2's "|s_i − s_{i−1}| ≤ ε" branch, made exact).
        return bin_average(base, ja, ua - f32(ja), min(ub - f32(ja), 1.0));
    }
    let jb = min(u32(ub), n);
    var sum = (f32(ja + 1u) - ua) * bin_average(base, ja, ua - f32(ja), 1.0);
    var lo = ja + 1u;
    if (prefix != 0u) {
        // Whole bins [ja+1, jb) by the running integral, an f32 pair per
        // node: (hi_b − hi_a) + (lo_b − lo_a); exact zero for no bins.
        let a = prefix + 2u * lo;
        let b = prefix + 2u * jb;
        sum = sum + (tf_entry(b) - tf_entry(a)) + (tf_entry(b + 1u) - tf_entry(a + 1u));
        lo = jb;
    }
    let top = frame.counts.z - 1u;
    // Whole bins as aligned dyadic blocks: every term ≥ 0, nothing cancels.
    while (lo < jb) {
        var k = top;
        if (lo != 0u) {
            k = min(countTrailingZeros(lo), top);
        }
        while ((1u << k) > jb - lo) {
            k = k - 1u;
        }
        sum = sum + tf_entry(base + tf_offset(k) + (lo >> k));
        lo = lo + (1u << k);
    }
    if (jb < n) {
        sum = sum + (ub - f32(jb)) * bin_average(base, jb, 0.0, ub - f32(jb));
    }
    return sum / (ub - ua);
}

// One end of a pre-integrated segment (table part at 0), for the march's
// fast path. Consecutive segments share an end, so each sample reads its
// bin once: five loads (its two nodes, its midpoint value, the running
// integral at its lower node as an f32 pair) and carries what the next
// segment needs, instead of reading both ends' bins again per segment.
// Used where the table allows it (END_PREINT: a running integral, and a
// range of bin integrals narrow enough for f32 partial bins); a pipeline
// constant, not a uniform, because a CPU device pays for both sides of a
// branch it cannot prove uniform.
struct TfEnd {
    u: f32,            // table coordinate, clamped to [0, N]
    j: u32,            // its bin
    hi: vec4<f32>,     // running integral at node j (f32 pair)
    lo: vec4<f32>,
    below: vec4<f32>,  // ∫ over [j, u] of bin j's quadratic
    above: vec4<f32>,  // ∫ over [u, j + 1]
    a: vec4<f32>,      // bin j: node values and midpoint value
    m: vec4<f32>,
    b: vec4<f32>,
}

override END_PREINT: bool = false;

// The 2D pre-integration table instead (PreintTable::grid): the averages
// over segments between its nodes, interpolated bilinearly by the texture
// unit, one fetch a segment.
override GRID_PREINT: bool = false;

fn grid_average(sa: f32, sb: f32) -> vec4<f32> {
    // Table node coordinates of the two values, by products (a division
    // per sample is a slow SIMD instruction on a CPU device).
    let g = clamp((vec2<f32>(sa, sb) - frame.tf.x) * frame.grid.x, vec2<f32>(0.0), vec2<f32>(frame.grid.y));
    return max(textureSampleLevel(preint_grid, grid_sampler, (g + 0.5) * frame.grid.z, 0.0),
               vec4<f32>(0.0));
}

// The exact average in closed form instead (`preintegration = "analytic"`,
// common/src/tf/closed.rs): between control points τ is linear and
// k̃ = τ·c quadratic in s, so the average over [ua, ub] of a piece is
// q0 + q1·(ua + ub) + q2·(ua² + ua·ub + ub²), with no difference of large
// numbers; the segment's is Σ (ub − ua)·that over hi − lo. No table read: on
// a CPU device a texture read is a gather per channel and lane, dearer than
// these products. A segment shorter than ε is widened to ε about its
// middle (the pieces reach ε past the data range), so that equal ends
// have a width to divide by; ends are clamped to the range, as the tables
// clamp them. ANALYTIC_PREINT, TF_PIECES and the pieces: bindings.wgsl.

fn analytic_average(sa: f32, sb: f32) -> vec4<f32> {
    let r = tf_pieces.range;
    let a = clamp(sa, r.x, r.y);
    let b = clamp(sb, r.x, r.y);
    let widen = 0.5 * max(r.z - abs(b - a), 0.0);
    let lo = min(a, b) - widen;
    let hi = max(a, b) + widen;
    var sum = vec4<f32>(0.0);
    for (var i = 0u; i < TF_PIECES; i = i + 1u) {
        let p = tf_pieces.piece[i];
        let ua = clamp(lo - p.span.x, 0.0, p.span.y);
        let ub = clamp(hi - p.span.x, 0.0, p.span.y);
        sum = sum + (ub - ua) * (p.q0 + p.q1 * (ua + ub) + p.q2 * (ua * ua + ua * ub + ub * ub));
    }
    // One division, not four: a SIMD division is slow on a CPU device.
    return max(sum * (1.0 / (hi - lo)), vec4<f32>(0.0));
}


fn tf_end(s: f32) -> TfEnd {
    if (!END_PREINT) {
        var e: TfEnd;
        return e;
    }
    return end_in(0u, frame.tf_mids.x, frame.counts.w, frame.tf.x, frame.recip.w,
                  u32(frame.tf.z), s);
}

// One end in a table part at `base` with its bin midpoints at `mids` and its
// running integral at `prefix`, over n bins from vmin (`recip`: 1 / the bin
// width): the volume's (`tf_end`) or a registered layer's (`layer_end`).
fn end_in(base: u32, mids: u32, prefix: u32, vmin: f32, recip: f32, n: u32, s: f32) -> TfEnd {
    var e: TfEnd;
    e.u = clamp((s - vmin) * recip, 0.0, f32(n));
    e.j = min(u32(e.u), n - 1u);
    let x = e.u - f32(e.j);
    e.a = tf_entry(base + e.j);
    e.b = tf_entry(base + e.j + 1u);
    e.m = tf_entry(mids + e.j);
    let p = prefix + 2u * e.j;
    e.hi = tf_entry(p);
    e.lo = tf_entry(p + 1u);
    e.below = quadratic_integral(e.a, e.m, e.b, x);
    e.above = quadratic_integral(e.b, e.m, e.a, 1.0 - x);
    return e;
}

// The average of (τ, k̃) over the data segment between two ends (`e1` the
// newer one, whose bin's values it carries): what segment_average(0, …)
// gives, from the ends alone. One bin: bin_average's exact form. Adjacent
// bins: the part of each bin on the segment's side, nothing subtracted.
// Further apart: the running integral between the two lower nodes, less the
// lower end's part below it, plus the upper end's (the segment spans more
// than a bin, so the difference keeps f32's precision relative to the
// table's largest bin, which the range check on the CPU bounds).
fn end_average(e0: TfEnd, e1: TfEnd) -> vec4<f32> {
    if (e0.j == e1.j) {
        let j = f32(e1.j);
        return quadratic_average(e1.a, e1.m, e1.b, e0.u - j, e1.u - j);
    }
    let up = e1.u > e0.u;
    var sum: vec4<f32>;
    if (up && e1.j == e0.j + 1u) {
        sum = e0.above + e1.below;
    } else if (!up && e0.j == e1.j + 1u) {
        sum = e1.above + e0.below;
    } else {
        sum = ((e1.hi - e0.hi) + (e1.lo - e0.lo)) + (e1.below - e0.below);
        if (!up) {
            sum = -sum;
        }
    }
    return max(sum / abs(e1.u - e0.u), vec4<f32>(0.0));
}
