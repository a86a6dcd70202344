// enhancers/exaggerated-shading.wgsl: multilevel shading by exaggerated
// shading (G10 §3, after Rusinkiewicz, Burns and DeCarlo 2006, Eq. 2). With
// n₀, n₁, n₂ the outward normals −∇s/‖∇s‖ of the leaf, its parent and its
// grandparent at the sample, l the light and l_i = l − (l·n_i)·n_i
// normalised (the light turned into the tangent plane of scale i),
//   E = ½ + ½·(k₀·clamp(a·n₀·l₁) + k₁·clamp(a·n₁·l₂) + k_b·clamp(n₂·l)),
// each detail term lighting a scale relative to the next coarser one, the
// base term the coarse shape. The shade is ka + kd·E of the material,
// blended from the plain shade (Phong, or 1 unshaded; or what an earlier
// tool set) by the strength; strength 0 leaves the shade alone.
//
// Constant state, tools[ENH_INDEX]: a = (l in volume space, unit;
// strength), b = (k₀, k₁, k_b summing to 1; a).

fn ENH_start(ray: ptr<function, Ray>) {
}

// Segments with extinction, the only ones shading sees.
fn ENH_active(smp: ptr<function, Sample>) -> bool {
    return (*smp).tau > 0.0;
}

// The outward unit normal of gradient g, or `fallback` where g vanishes.
fn ENH_normal(g: vec3<f32>, fallback: vec3<f32>) -> vec3<f32> {
    let l = length(g);
    if (l > 1e-30) {
        return -g / l;
    }
    return fallback;
}

// l turned into the plane normal to n (0 where l is along n).
fn ENH_tangent(l: vec3<f32>, n: vec3<f32>) -> vec3<f32> {
    let t = l - dot(l, n) * n;
    let tl = length(t);
    if (tl > 1e-6) {
        return t / tl;
    }
    return vec3<f32>(0.0);
}

fn ENH_sample(smp: ptr<function, Sample>) {
    if (!TOOL_TILES) {
        return;
    }
    if (!ENH_active(smp)) {
        return;
    }
    let tp = tools[ENH_INDEX];
    let strength = tp.a.w;
    if (strength <= 0.0) {
        return;
    }
    let m = (*smp).material;
    var plain = 1.0;
    if ((*smp).shade >= 0.0) {
        plain = (*smp).shade;
    } else if (SHADING) {
        plain = phong((*smp).gradient, (*smp).dir, m);
    }
    let l = tp.a.xyz;
    let a = tp.b.w;
    let n0 = ENH_normal((*smp).gradient, vec3<f32>(0.0));
    let n1 = ENH_normal((*smp).gradient_up, n0);
    let n2 = ENH_normal((*smp).gradient_up2, n1);
    let c0 = clamp(a * dot(n0, ENH_tangent(l, n1)), -1.0, 1.0);
    let c1 = clamp(a * dot(n1, ENH_tangent(l, n2)), -1.0, 1.0);
    let cb = clamp(dot(n2, l), -1.0, 1.0);
    let e = 0.5 + 0.5 * (tp.b.x * c0 + tp.b.y * c1 + tp.b.z * cb);
    (*smp).shade = mix(plain, m.x + m.y * e, strength);
}

fn ENH_end(ray: ptr<function, Ray>, acc: ptr<function, Acc>) {
}
