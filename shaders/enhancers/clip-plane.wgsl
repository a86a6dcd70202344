// enhancers/clip-plane.wgsl: clip plane with view-dependent context (G10 §4).
// δ = n·x + p (display metres). On the positive side a sample's opacity is
// multiplied by μ = smoothstep(f_l, f_h, 1 − max(0, −n·v)); in the band
// −thickness < δ < 0 opacity and shading go from the sample's own at
// δ = −thickness to full opacity and ambient-plus-emission shading at δ = 0.
//
// Constant state, tools[ENH_INDEX]: a = (n in volume space scaled so that
// δ = a.xyz·q + a.w is in metres), b = (unit normal in volume space,
// thickness in metres), c = (f_l, f_h, 0, 0). Variable state: μ of the ray.

var<private> ENH_mu: f32;

// At ray start (and after a change of direction): μ depends only on the
// ray's direction; the plane and the band's far side become breaks, so no
// segment straddles them. A ray for which the plane changes nothing (μ = 1
// and no band) gets no break: its samples, and its pixel, are those of no
// plane.
fn ENH_start(ray: ptr<function, Ray>) {
    let tp = tools[ENH_INDEX];
    ENH_mu = smoothstep(tp.c.x, tp.c.y, 1.0 - max(0.0, -dot(tp.b.xyz, (*ray).dir)));
    let nd = dot(tp.a.xyz, (*ray).dir);
    if (abs(nd) > 1e-30 && (ENH_mu < 1.0 || tp.b.w > 0.0)) {
        let d0 = dot(tp.a.xyz, (*ray).origin) + tp.a.w;
        add_break(ray, -d0 / nd);
        if (tp.b.w > 0.0) {
            add_break(ray, (-tp.b.w - d0) / nd);
        }
    }
}

fn ENH_sample(smp: ptr<function, Sample>) {
    let tp = tools[ENH_INDEX];
    let delta = dot(tp.a.xyz, (*smp).pos) + tp.a.w;
    if (delta > 0.0) {
        (*smp).alpha_scale = (*smp).alpha_scale * ENH_mu;
    } else if (tp.b.w > 0.0 && delta > -tp.b.w && (*smp).tau > 0.0) {
        // Emphasis of the tissue the plane slices.
        let w = smoothstep(-tp.b.w, 0.0, delta);
        (*smp).alpha_mix = 1.0 - (1.0 - (*smp).alpha_mix) * (1.0 - w);
        (*smp).material = mix((*smp).material, vec4<f32>(1.0, 0.0, 0.0, (*smp).material.w), w);
    }
}

fn ENH_end(ray: ptr<function, Ray>, acc: ptr<function, Acc>) {
}
