// enhancers/probe.wgsl: context-preserving probe (G10 §4, Eqs. 4–5). A
// sphere of centre c and radius r; for a sample inside it at distance
// s = (x − c)·v along the ray from the plane through c facing the ray
// (s < 0 in front), ω_d = 1 − (s/r)², and
//   η = ω_a · smoothstep(g_l, g_h, ι·‖∇s‖/∇_max) · (1 − |∇s·v|/‖∇s‖)⁴,
//   in front:  μ(α) = lerp(0, η, ω_d),       μ(i) = 1 − η,
//   behind:    μ(α) = lerp(η, 1, 1 − ω_d),   μ(i) = lerp(1 − η, 1, 1 − ω_d),
// opacity times μ(α), colour times μ(i) (silhouette darkening). Samples
// outside the sphere are untouched; the sphere's surface and the centre
// plane are breaks of the ray, so no segment straddles them.
//
// Constant state, tools[ENH_INDEX]: a = (c in volume space, r in data
// units), b = (the axis in volume space, unit; ∇_max), c = (a_l, a_h, g_l,
// g_h). Variable state: ω_a = smoothstep(a_l, a_h, max(0, −axis·v)) of the
// ray.

var<private> ENH_wa: f32;

fn ENH_start(ray: ptr<function, Ray>) {
    let tp = tools[ENH_INDEX];
    let d = (*ray).dir;
    ENH_wa = smoothstep(tp.c.x, tp.c.y, max(0.0, -dot(tp.b.xyz, d)));
    let oc = (*ray).origin - tp.a.xyz;
    let b = dot(oc, d);
    let disc = b * b - (dot(oc, oc) - tp.a.w * tp.a.w);
    if (disc > 0.0) {
        let q = sqrt(disc);
        add_break(ray, -b - q);
        add_break(ray, -b);
        add_break(ray, -b + q);
    }
}

// Inside the sphere: where the gradient and the importance are needed.
fn ENH_active(smp: ptr<function, Sample>) -> bool {
    let tp = tools[ENH_INDEX];
    let rel = (*smp).pos - tp.a.xyz;
    return dot(rel, rel) < tp.a.w * tp.a.w;
}

fn ENH_sample(smp: ptr<function, Sample>) {
    // Outside the tiles that can meet a tool's region (the pipeline
    // without TOOL_TILES), and outside the sphere, nothing changes.
    if (!TOOL_TILES) {
        return;
    }
    if (!ENH_active(smp)) {
        return;
    }
    let tp = tools[ENH_INDEX];
    let r2 = tp.a.w * tp.a.w;
    let s = dot((*smp).pos - tp.a.xyz, (*smp).dir);
    let wd = max(1.0 - s * s / r2, 0.0);
    let g = (*smp).gradient;
    let gl = length(g);
    var eta = 0.0;
    if (gl > 1e-30 && ENH_wa > 0.0) {
        let edge = smoothstep(tp.c.z, tp.c.w, (*smp).importance * gl / tp.b.w);
        let across = 1.0 - min(abs(dot(g, (*smp).dir)) / gl, 1.0);
        let a2 = across * across;
        eta = ENH_wa * edge * a2 * a2;
    }
    var mu_a: f32;
    var mu_i: f32;
    if (s < 0.0) {
        mu_a = mix(0.0, eta, wd);
        mu_i = 1.0 - eta;
    } else {
        mu_a = mix(eta, 1.0, 1.0 - wd);
        mu_i = mix(1.0 - eta, 1.0, 1.0 - wd);
    }
    (*smp).alpha_scale = (*smp).alpha_scale * mu_a;
    (*smp).color_scale = (*smp).color_scale * mu_i;
}

fn ENH_end(ray: ptr<function, Ray>, acc: ptr<function, Acc>) {
}
