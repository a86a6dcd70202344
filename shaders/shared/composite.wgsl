// shared/composite.wgsl: what one pre-integrated segment adds (docs/design.md
// "What a pixel means"), after the enhancers have had their say.

#import sample

struct Acc {
    color: vec3<f32>,
    alpha: f32,
    // MImDA: the largest importance met so far along the ray (G10 Eq. 3).
    imax: f32,
}

// Premultiplied colour and opacity of a segment: α = 1 − exp(−τ̄·d) and
// colour k̃·α/τ̄ (G10 §4), times the shading factor. Tools scale the opacity
// (and colour with it), may scale the colour alone, and may blend towards
// full opacity, keeping the material's own colour k̃/τ̄.
fn segment_optics(smp: Sample, shade: f32) -> vec4<f32> {
    let x = max(smp.tau, 0.0) * smp.len;
    var a: f32;
    var w: f32;  // α / τ̄, the weight of the emission (→ d as τ̄·d → 0)
    if (x < 1e-4) {
        a = x * (1.0 - 0.5 * x);
        w = smp.len * (1.0 - 0.5 * x);
    } else {
        a = 1.0 - exp(-x);
        w = a / max(smp.tau, 1e-30);
    }
    var c = max(smp.emission, vec3<f32>(0.0)) * w * shade;
    if (MODIFIES_OPTICS) {
        a = a * smp.alpha_scale;
        c = c * (smp.alpha_scale * smp.color_scale);
        if (smp.alpha_mix > 0.0) {
            let chroma = max(smp.emission, vec3<f32>(0.0)) / max(smp.tau, 1e-30);
            a = mix(a, 1.0, smp.alpha_mix);
            c = mix(c, min(chroma, vec3<f32>(1.0)) * shade, smp.alpha_mix);
        }
    }
    return vec4<f32>(c, a);
}

// Front-to-back "over" (plain DVR).
fn over(acc: ptr<function, Acc>, ca: vec4<f32>) {
    let t = 1.0 - (*acc).alpha;
    (*acc).color = (*acc).color + t * ca.xyz;
    (*acc).alpha = (*acc).alpha + t * ca.w;
}

// Two-sided Phong with a headlight: the shade of a surface with gradient `g`
// seen along `d`, material (ka, kd, ks, shininess); 1 where the gradient
// vanishes.
fn phong(g: vec3<f32>, d: vec3<f32>, m: vec4<f32>) -> f32 {
    var shade = 1.0;
    let gl = length(g);
    if (gl > 1e-6) {
        let diff = abs(dot(g / gl, d));
        shade = m.x + m.y * diff + m.z * pow(diff, m.w);
    }
    return shade;
}
