// shared/sample.wgsl: the state enhancers read and modify (G10 §4 "Flexible
// ray traversal and compositing": "all the computed attributes, the current
// ray position and direction, and the material and light properties … are
// then made available to enhancer objects").

// One integration step: the segment from the previous sample to this one.
struct Sample {
    pos: vec3<f32>,       // segment midpoint, volume space (data units)
    len: f32,             // segment length d (data units)
    dir: vec3<f32>,       // ray direction, volume space, unit
    scalar: f32,          // s at the segment's end
    scalar_prev: f32,     // s at its start
    gradient: vec3<f32>,  // ∇s at the midpoint (computed when an enhancer reads it)
    gradient_up: vec3<f32>,  // ∇s of the leaf's parent there (idem, COARSE_GRADIENTS; else ∇s)
    gradient_up2: vec3<f32>, // ∇s of its grandparent (idem; else gradient_up)
    shade: f32,           // shading factor set by tools (< 0: none, the kernel's own)
    tau: f32,             // pre-integrated extinction τ̄
    emission: vec3<f32>,  // pre-integrated extinction-weighted colour k̃
    importance: f32,      // pre-integrated importance ι (MImDA, refraction kernels)
    refraction: f32,      // pre-integrated refraction index ν (idem)
    alpha_scale: f32,     // opacity multiplier set by tools (1: none)
    alpha_mix: f32,       // blend towards full opacity set by tools (0: none; only where τ̄ > 0)
    color_scale: f32,     // colour multiplier set by tools (1: none; G10 Eq. 5's μ(i))
    material: vec4<f32>,  // Phong ka, kd, ks, shininess
}

// Breaks of a ray: three per enhancer at most (the probe's sphere and its
// centre plane).
const MAX_BREAKS: u32 = 9u;
// The ray: where it starts and goes since its last change of direction.
struct Ray {
    origin: vec3<f32>,    // volume space
    t_end: f32,           // where it leaves the volume's box
    dir: vec3<f32>,       // unit
    n_breaks: u32,
    // Parameters along the ray where a segment must end (a tool's plane):
    // no segment straddles them, so a tool acts exactly on its side.
    breaks: array<f32, 9>,
}

fn add_break(ray: ptr<function, Ray>, t: f32) {
    if (t > 0.0 && t < (*ray).t_end && (*ray).n_breaks < MAX_BREAKS) {
        (*ray).breaks[(*ray).n_breaks] = t;
        (*ray).n_breaks = (*ray).n_breaks + 1u;
    }
}

// The first break after t (3e38 when none).
fn next_break(ray: ptr<function, Ray>, t: f32) -> f32 {
    var b = 3.0e38;
    for (var i = 0u; i < (*ray).n_breaks; i = i + 1u) {
        let x = (*ray).breaks[i];
        if (x > t) {
            b = min(b, x);
        }
    }
    return b;
}
