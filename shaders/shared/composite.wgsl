// shared/composite.wgsl: front-to-back emission–absorption compositing (DESIGN.md "What a pixel means").

struct Acc {
    color: vec3<f32>,
    alpha: f32,
}

// Front-to-back compositing of one pre-integrated segment of length d.
fn composite(acc: ptr<function, Acc>, avg: vec4<f32>, d: f32, shade: f32) {
    let x = max(avg.x, 0.0) * d;
    var a: f32;
    var w: f32;  // α / τ̄, the weight of the emission (→ d as τ̄·d → 0)
    if (x < 1e-4) {
        a = x * (1.0 - 0.5 * x);
        w = d * (1.0 - 0.5 * x);
    } else {
        a = 1.0 - exp(-x);
        w = a / max(avg.x, 1e-30);
    }
    let c = max(avg.yzw, vec3<f32>(0.0)) * w * shade;
    let t = 1.0 - (*acc).alpha;
    (*acc).color = (*acc).color + t * c;
    (*acc).alpha = (*acc).alpha + t * a;
}
