// steppers/iso.wgsl: isosurfaces (G08 §5.3, B10). Along the ray the field is
// sampled at the usual steps; where two samples bracket the isovalue the
// crossing is refined by bisection inside the leaf's brick, and the surface
// there is shaded with the gradient (the kernel's ISO branch).

#import sampling

// Prediction buffer values besides a hit distance (B10 §4.1).
const PB_MISS_SURFACE: f32 = -1.0;
const PB_MISS_BOX: f32 = -2.0;

// Bisections of a bracket: the hit is within step / 2^ISO_BISECTIONS.
const ISO_BISECTIONS: u32 = 12u;

// Whether the field crosses the isovalue between two samples with data.
fn iso_brackets(a: f32, b: f32) -> bool {
    return has_data(a) && has_data(b) && ((a - frame.iso.x < 0.0) != (b - frame.iso.x < 0.0));
}

// The ray parameter of the crossing in [ta, tb], where the sample at ta is
// a (on the other side of the isovalue than the one at tb).
fn iso_refine(leaf: Leaf, o: vec3<f32>, d: vec3<f32>, ta: f32, tb: f32, a: f32) -> f32 {
    var lo = ta;
    var hi = tb;
    let below = a - frame.iso.x < 0.0;
    for (var k = 0u; k < ISO_BISECTIONS; k = k + 1u) {
        let m = 0.5 * (lo + hi);
        let v = sample_brick(leaf, o + d * m);
        if (has_data(v) && (v - frame.iso.x < 0.0) == below) {
            lo = m;
        } else {
            hi = m;
        }
    }
    return 0.5 * (lo + hi);
}
