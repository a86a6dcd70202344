// enhancers/gradient-direction.wgsl: a diagnostic enhancer that shows, for
// each ray, the gradient of its first sample with extinction as the
// earlier enhancers leave it (volume space; its direction's x/y/z as r/g/b,
// mapped from [−1, 1] to [0, 1]), opaque; rays that meet no extinction stay
// transparent. How the unsharp-masked gradient is checked against an
// analytic volume's.

var<private> ENH_g: vec3<f32>;
var<private> ENH_seen: bool;

fn ENH_start(ray: ptr<function, Ray>) {
    ENH_g = vec3<f32>(0.0);
    ENH_seen = false;
}

fn ENH_active(smp: ptr<function, Sample>) -> bool {
    return !ENH_seen && (*smp).tau > 0.0;
}

fn ENH_sample(smp: ptr<function, Sample>) {
    if (ENH_active(smp)) {
        ENH_g = (*smp).gradient;
        ENH_seen = true;
    }
}

fn ENH_end(ray: ptr<function, Ray>, acc: ptr<function, Acc>) {
    if (ENH_seen) {
        let l = length(ENH_g);
        var n = vec3<f32>(0.0);
        if (l > 1e-30) {
            n = ENH_g / l;
        }
        (*acc).color = n * 0.5 + vec3<f32>(0.5);
        (*acc).alpha = 1.0;
    } else {
        (*acc).color = vec3<f32>(0.0);
        (*acc).alpha = 0.0;
    }
}
