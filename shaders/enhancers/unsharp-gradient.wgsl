// enhancers/unsharp-gradient.wgsl: multilevel shading by unsharp masking
// of the gradient (G10 §3 and Fig. 5, "normal unsharp masking"). Where a
// segment has extinction its gradient g becomes g + λ·(g − g_c), g_c the
// gradient of the leaf's parent (level 1) or grandparent (level 2) at the
// same point: the gradient of the unsharp-masked volume s + λ·(s − s_c),
// since the gradient is linear in the data. Shading and the later
// enhancers see the masked gradient; λ = 0 changes no bit.
//
// Constant state, tools[ENH_INDEX]: a = (λ, level, 0, 0).

fn ENH_start(ray: ptr<function, Ray>) {
}

// Where the gradient is masked (and the coarse gradients are computed):
// segments with extinction, the only ones shading sees.
fn ENH_active(smp: ptr<function, Sample>) -> bool {
    return (*smp).tau > 0.0;
}

fn ENH_sample(smp: ptr<function, Sample>) {
    if (!TOOL_TILES) {
        return;
    }
    if (!ENH_active(smp)) {
        return;
    }
    let tp = tools[ENH_INDEX];
    let g = (*smp).gradient;
    let gc = select((*smp).gradient_up, (*smp).gradient_up2, tp.a.y > 1.5);
    (*smp).gradient = g + tp.a.x * (g - gc);
}

fn ENH_end(ray: ptr<function, Ray>, acc: ptr<function, Acc>) {
}
