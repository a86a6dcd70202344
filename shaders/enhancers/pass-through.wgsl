// enhancers/pass-through.wgsl: the default enhancer (G10 §5 "a special
// class, with empty constant and variable data and no operations performed
// in device functions implements the default pass-through behavior").
// `ENH` is replaced by the instance's name, `ENH_INDEX` by its tool slot.

fn ENH_start(ray: ptr<function, Ray>) {
}

fn ENH_sample(smp: ptr<function, Sample>) {
}

fn ENH_end(ray: ptr<function, Ray>, acc: ptr<function, Acc>) {
}
