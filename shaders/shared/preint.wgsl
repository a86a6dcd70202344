// shared/preint.wgsl: pre-integrated transfer function lookups.

#import bindings

// Pre-integration (G10 §4 Eq. 2) over the sum pyramid of common/src/tf
// (or, where the table allows, its running integral as an f32 pair):
// the average of four interleaved attributes over the data segment [a, b]:
// (τ, k̃r, k̃g, k̃b) in the table at `base` 0, (ι, ν, 0, 0) at `frame.aux.x`
// (G10 §4: "we employ preintegration for all attributes"). `prefix` is where
// that part's running integral starts, 0 when it has none.

fn tf_offset(k: u32) -> u32 {
    return frame.tf_offsets[k >> 2u][k & 3u];
}

// The average over [j + ta, j + tb] (0 ≤ ta ≤ tb ≤ 1) of bin j's quadratic
// through its nodes a, b and midpoint value m (common/src/tf/preint.rs:
// in a bin without a control point inside, the transfer function exactly):
// f at the centre plus f''·w²/24, exact, no division.
fn bin_average(base: u32, j: u32, ta: f32, tb: f32) -> vec4<f32> {
    let a = table[base + j];
    let b = table[base + j + 1u];
    let m = table[base + frame.tf_mids.x + j];
    let t = 0.5 * (ta + tb);
    let w = tb - ta;
    let f = a * ((1.0 - t) * (1.0 - 2.0 * t)) + m * (4.0 * t * (1.0 - t)) + b * (t * (2.0 * t - 1.0));
    return max(f + (a + b - 2.0 * m) * (w * w / 6.0), vec4<f32>(0.0));
}

fn segment_average(base: u32, prefix: u32, sa: f32, sb: f32) -> vec4<f32> {
    let n = u32(frame.tf.z);
    var ua = clamp((sa - frame.tf.x) / frame.tf.y, 0.0, f32(n));
    var ub = clamp((sb - frame.tf.x) / frame.tf.y, 0.0, f32(n));
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
        sum = sum + (table[b] - table[a]) + (table[b + 1u] - table[a + 1u]);
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
        sum = sum + table[base + tf_offset(k) + (lo >> k)];
        lo = lo + (1u << k);
    }
    if (jb < n) {
        sum = sum + (ub - f32(jb)) * bin_average(base, jb, 0.0, ub - f32(jb));
    }
    return sum / (ub - ua);
}
