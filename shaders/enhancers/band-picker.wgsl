// enhancers/band-picker.wgsl: view-dependent band picker (G10 §4, Fig. 9).
// The band is the trapezoid of four ordered data values (0 below b0 and
// above b3, 1 on [b1, b2]); w is its largest value over the segment's span
// of values [min(s0, s1), max(s0, s1)], so a segment that passes through
// the band counts whatever its ends. With ω_a = smoothstep(a_l, a_h,
// max(0, −axis·v)) of the ray:
//   importance ← lerp(ι, w, ω_a): 1 in the band and 0 outside where the
//                eye looks along the axis (MImDA lets the band through),
//   opacity    × 1 − ω_a·(1 − w): the other bands vanish looking along the
//                axis and return looking across it.
//
// Constant state, tools[ENH_INDEX]: a = (b0, b1, b2, b3), b = (the axis in
// volume space, unit; 0), c = (a_l, a_h, 0, 0). Variable state: ω_a.

var<private> ENH_wa: f32;

fn ENH_start(ray: ptr<function, Ray>) {
    let tp = tools[ENH_INDEX];
    ENH_wa = smoothstep(tp.c.x, tp.c.y, max(0.0, -dot(tp.b.xyz, (*ray).dir)));
}

// The trapezoid's largest value over [lo, hi].
fn ENH_weight(lo: f32, hi: f32) -> f32 {
    let b = tools[ENH_INDEX].a;
    // The plateau first: with b0 = b1 (or b2 = b3) its edge value is 1.
    if (hi >= b.y && lo <= b.z) {
        return 1.0;
    }
    if (hi <= b.x || lo >= b.w) {
        return 0.0;
    }
    // Wholly on one ramp: its value at the end nearer the plateau.
    if (hi < b.y) {
        return (hi - b.x) / max(b.y - b.x, 1e-30);
    }
    return (b.w - lo) / max(b.w - b.z, 1e-30);
}

fn ENH_sample(smp: ptr<function, Sample>) {
    let w = ENH_weight(min((*smp).scalar_prev, (*smp).scalar), max((*smp).scalar_prev, (*smp).scalar));
    (*smp).importance = mix((*smp).importance, w, ENH_wa);
    (*smp).alpha_scale = (*smp).alpha_scale * (1.0 - ENH_wa * (1.0 - w));
}

fn ENH_end(ray: ptr<function, Ray>, acc: ptr<function, Acc>) {
}
