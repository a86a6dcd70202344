// steppers/refraction.wgsl: continuous refraction (G10 §4, Fig. 4): at each
// step the direction turns by Snell's law from the refraction index of the
// previous segment (ν₁) to this one's (ν₂) about the local gradient; where
// Snell's law has no solution the ray is reflected (total internal
// reflection). Unit directions in, unit direction out; never NaN.

fn snell(d: vec3<f32>, g: vec3<f32>, nu1: f32, nu2: f32) -> vec3<f32> {
    let gl = length(g);
    if (gl < 1e-12 || nu1 == nu2) {
        return d;
    }
    var n = g / gl;
    var cosi = -dot(n, d);
    if (cosi < 0.0) {
        n = -n;
        cosi = -cosi;
    }
    let eta = nu1 / nu2;
    let k = 1.0 - eta * eta * (1.0 - cosi * cosi);
    var out: vec3<f32>;
    if (k < 0.0) {
        out = d + 2.0 * cosi * n;
    } else {
        out = eta * d + (eta * cosi - sqrt(k)) * n;
    }
    let l = length(out);
    if (!(l > 1e-12)) {
        return d;
    }
    return out / l;
}

// Snell's law where the refraction index changes from `nu_prev` to `nu`
// (ν_prev ≥ 0: there was a previous segment), about the gradient at the end
// of the segment (ray parameter `tc`): the ray then goes on from there in
// its new direction (`o`, `d` moved). True where it bent.
fn bend_at(leaf: Leaf, o: ptr<function, vec3<f32>>, d: ptr<function, vec3<f32>>, tc: f32,
           nu_prev: f32, nu: f32) -> bool {
    if (nu_prev >= 0.0 && abs(nu - nu_prev) > 1e-6) {
        let p = *o + *d * tc;
        let nd = snell(*d, gradient(leaf, p), nu_prev, nu);
        if (any(nd != *d)) {
            *o = p;
            *d = nd;
            return true;
        }
    }
    return false;
}
