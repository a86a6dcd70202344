// enhancers/exit-direction.wgsl: a diagnostic enhancer whose ray-end stage
// writes the ray's final direction (volume space, x/y/z as r/g/b, mapped
// from [−1, 1] to [0, 1]) with full opacity: how refraction is checked
// against Snell's law in closed form.

fn ENH_start(ray: ptr<function, Ray>) {
}

fn ENH_sample(smp: ptr<function, Sample>) {
}

fn ENH_end(ray: ptr<function, Ray>, acc: ptr<function, Acc>) {
    (*acc).color = (*ray).dir * 0.5 + vec3<f32>(0.5);
    (*acc).alpha = 1.0;
}
