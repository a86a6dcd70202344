// steppers/iso.wgsl: isosurfaces (G08 §5.3, B10). Along the ray the field is
// sampled at the usual steps; where two samples bracket the isovalue the
// crossing is refined by bisection inside the leaf's brick, and the surface
// there is shaded with the gradient (the kernel's ISO branch).

#import sampling
#import composite

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

// The first crossing of the isovalue between the samples at tc and tn
// (values a and b): opaque and shaded, where a tool may cut it away
// (opacity 0) or fade it; `hit_t` keeps the first hit's distance for the
// prediction buffer.
fn iso_hit(acc: ptr<function, Acc>, hit_t: ptr<function, f32>, leaf: Leaf, o: vec3<f32>,
           d: vec3<f32>, tc: f32, tn: f32, a: f32, b: f32) {
    if (!iso_brackets(a, b)) {
        return;
    }
    let th = iso_refine(leaf, o, d, tc, tn, a);
    var smp: Sample;
    smp.pos = o + d * th;
    smp.len = 0.0;
    smp.dir = d;
    smp.scalar = frame.iso.x;
    smp.tau = 1.0;
    smp.emission = frame.iso.yzw;
    smp.alpha_scale = 1.0;
    smp.alpha_mix = 0.0;
    smp.material = frame.light;
    smp.shade = -1.0;
    if (NEEDS_GRADIENT) {
        // The isosurface reads no coarser level: multilevel shading sees
        // the leaf's gradient at every scale.
        smp.gradient = gradient(leaf, smp.pos);
        smp.gradient_up = smp.gradient;
        smp.gradient_up2 = smp.gradient;
    }
    chain_sample(&smp);
    let alpha = clamp(mix(smp.alpha_scale, 1.0, smp.alpha_mix), 0.0, 1.0);
    if (alpha > 0.0) {
        var shade = 1.0;
        if (TOOL_SHADES && smp.shade >= 0.0) {
            shade = smp.shade;
        } else if (SHADING) {
            shade = phong(gradient(leaf, smp.pos), d, smp.material);
        }
        over(acc, vec4<f32>(max(smp.emission, vec3<f32>(0.0)) * shade * alpha, alpha));
        if (*hit_t < 0.0) {
            *hit_t = th;
        }
    }
}

// Where the prediction buffer (B10 §4) starts a ray: one that hit the
// surface last frame starts a window before that distance (local
// traversal, `snap`: from the entry of the octree node that holds that
// point, where the samples fall as a full traversal's would), one that
// missed it steps sparsely (sparse traversal); both step by the voxel size
// / κ, κ from the brick's variance (§4.5). No information: the normal march.
struct Predicted {
    snap: bool,
    sparse: bool,
}

fn predicted_start(out: u32, span: ptr<function, vec2<f32>>) -> Predicted {
    var p = Predicted(false, false);
    let pv = prediction[out];
    if (pv >= 0.0) {
        (*span).x = max((*span).x, pv - frame.predict.y);
        p.snap = true;
        p.sparse = true;
    } else if (pv == PB_MISS_SURFACE || pv == PB_MISS_BOX) {
        p.sparse = true;
    }
    return p;
}
