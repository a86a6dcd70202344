// steppers/dvr.wgsl: plain front-to-back emission–absorption compositing,
// stopping once the opacity reaches the early-termination threshold.

#import composite

fn accumulate(acc: ptr<function, Acc>, ca: vec4<f32>, smp: Sample) {
    over(acc, ca);
}

fn terminated(acc: Acc) -> bool {
    return acc.alpha >= frame.render.y;
}
