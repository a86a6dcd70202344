// steppers/mimda.wgsl: maximum importance difference accumulation (G10 §4
// Eq. 3): δᵢ = max(ιᵢ − ι_maxᵢ, 0), βᵢ = 1 − γ·δᵢ,
//   [c*ᵢ α*ᵢ] = [c*ᵢ₋₁ α*ᵢ₋₁]·βᵢ + (1 − βᵢ·α*ᵢ₋₁)·[cᵢ αᵢ].
// γ = frame.optics.x, the transfer function's largest importance
// frame.optics.y. Segments with τ̄ = 0 take no part (β = 1, ι_max unchanged).

#import composite

fn accumulate(acc: ptr<function, Acc>, ca: vec4<f32>, smp: Sample) {
    // Only material that is there takes part: a segment with no extinction
    // (air, or a band the transfer function leaves transparent) neither
    // raises the largest importance nor lets it fade what lies in front
    // (δ = 0), as the empty bricks and macrocells the traversal steps over
    // do neither; so MImDA skips empty space as DVR does.
    var delta = 0.0;
    if (smp.tau > 0.0) {
        delta = max(smp.importance - (*acc).imax, 0.0);
        (*acc).imax = max((*acc).imax, smp.importance);
    }
    let beta = 1.0 - frame.optics.x * delta;
    if (beta == 1.0) {
        // Eq. 3 with β = 1 is plain "over"; the same operations keep γ = 0
        // equal to DVR bit for bit.
        over(acc, ca);
    } else {
        let keep = 1.0 - beta * (*acc).alpha;
        (*acc).color = (*acc).color * beta + keep * ca.xyz;
        (*acc).alpha = (*acc).alpha * beta + keep * ca.w;
    }
}

// Eq. 3 does not make opacity grow monotonically: G10 stops when the largest
// future change Δα* = 1 − (1 − γ·(ι_max^tf − ι_max))·α* is below ε = 1 − the
// early-termination opacity, i.e. when (1 − γ·(ι_max^tf − ι_max))·α* reaches
// that opacity (for γ = 0 exactly the DVR test).
fn terminated(acc: Acc) -> bool {
    // A tool that sets importances (the band picker) may set them up to 1.
    var imax_tf = frame.optics.y;
    if (TOOL_IMPORTANCE) {
        imax_tf = max(imax_tf, 1.0);
    }
    let factor = 1.0 - frame.optics.x * max(imax_tf - acc.imax, 0.0);
    return factor * acc.alpha >= frame.render.y;
}
