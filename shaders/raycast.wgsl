// Stackless octree ray casting (G08 §5, G10 §5 "Stackless octree raycaster")
// with pre-integrated emission–absorption (G10 §4 Eq. 2) over the brick pool.
//
// One invocation per pixel, one workgroup per listed 8×8 tile of a view
// (only tiles whose rays can meet data are listed). The ray of a pixel comes from
// G10 Eq. 1 (docs/design.md "Which ray a pixel gets"), is moved to volume space
// (data length units) and clipped to the volume's box. Traversal descends
// from the root to the leaf that contains the current point, marches through
// the leaf's brick at a step matched to its level (or skips it when it has no
// data: empty under the transfer function, or dropped at import), leaves it
// through a face, follows that face's neighbour pointer and descends again.
// With MULTILEVEL, a leaf's samples blend in its parent's and grandparent's
// data as far as the view's footprint allows (G10 §4, Fig. 5), so that a
// cut that mixes levels shows no seams; TRICUBIC filters bricks with the
// cubic B-spline (L12 §5.1).
//
// The shared modules in shaders/shared/ are pulled in by `#import` lines,
// resolved by backend/src/raycast/shader.rs (each module once, in order).
// `#import chain` is the part made for each pipeline (G10 §5 "Custom
// compositing behavior": one kernel per combination of stepper and
// enhancers): the stepper (steppers/dvr or mimda: `accumulate`,
// `terminated`), refraction or none, up to three enhancers chained
// (`chain_start`, `chain_sample`, `chain_end`) and the constants that leave
// out what the combination does not need.

#import bindings
#import sample
#import preint
#import sampling
#import traversal
#import layers
#import chain

// Phong shading from central-difference gradients.
override SHADING: bool = false;
// Step over empty macrocells inside bricks (L12 §4.1; `cells`). Set only for
// kernels where τ = 0 means no effect at all (plain DVR).
override MACROCELLS: bool = false;
// Count the samples taken (`counters`): benches and tests.
override COUNT_SAMPLES: bool = false;
// Fetch each sample one pass ahead of its segment (the sample loop in
// `main`). Set for pools of float voxels read with the 2D table or the
// closed form: on a CPU device a float pool's fetch waits for memory, and
// the wait then overlaps the segment's table fetch or arithmetic (Colin27
// brain 3–13 % less time with the 2D table, docs/performance.md "Kernel
// changes on a CPU device"). With the exact table, or an 8-bit pool, it
// saved nothing measurable, and it adds a fetch at each leaf's end: those
// kernels keep the plain loop.
override LOOKAHEAD: bool = false;
// Opaque-segment refinement (`RenderConfig::refinement`): a segment whose
// own optical depth τ̄·h exceeds REFINE_DEPTH, met while the ray's opacity
// is below REFINE_ALPHA, is not composited but marched again in
// ⌈τ̄·h / REFINE_DEPTH⌉ equal parts, at most `frame.optics.w`, so that the
// parts' step shrinks steadily with the segment's, never jumping back up.
// Pre-integration is exact for a scalar linear between samples; the
// field's departure from its chord, O(h²), sets the pixel where one
// segment is optically thick (where inside it the opacity accrues), and P
// parts cut it by P². Set by the CPU only where the transfer function and
// the cut's longest step allow such a segment (backend/src/raycast/mod.rs
// `can_be_opaque`); not for isosurfaces, refraction (a bend per sample) or
// registered layers.
override REFINE: bool = false;
// Set by the CPU from the one definition (backend/src/raycast/mod.rs
// `REFINE_DEPTH`), which the loader's opaque detail shares.
override REFINE_DEPTH: f32;
fn refines() -> bool {
    return REFINE && !ISO && LAYERS == 0u && !REFRACTION;
}
// Once the ray's transmittance is below 1/256, a segment can change the
// pixel by less than that: no refinement (with early termination off, the
// segments behind a surface would otherwise all be refined).
const REFINE_ALPHA: f32 = 1.0 - 1.0 / 256.0;

// The distance from `p` along `d` (unit, 1/d in `inv_d`) to where the ray
// enters the first non-empty macrocell of `leaf` within `len`, or 3e38 when
// it crosses none: a 3D DDA over the brick's C³ cells (Amanatides and Woo)
// that stops at the first non-empty cell.
fn first_cell(leaf: Leaf, p: vec3<f32>, d: vec3<f32>, inv_d: vec3<f32>, len: f32) -> f32 {
    let voxel = leaf.voxel;
    let n = frame.aux.z;
    let cell = voxel * f32(frame.aux.w);
    let base = leaf.cell * f32(frame.counts.x) * voxel;
    // The cell of the point a little past p (a point on a face belongs to
    // the cell the ray enters).
    let tm = 1e-4 * min(len, min(min(cell.x, cell.y), cell.z));
    var c = vec3<i32>(clamp(floor((p + d * tm - base) / cell), vec3<f32>(0.0),
                            vec3<f32>(f32(n) - 1.0)));
    let step = vec3<i32>(sign(d));
    let big = vec3<f32>(3.0e38);
    let flat = abs(d) < vec3<f32>(1e-30);
    let t_delta = select(abs(cell * inv_d), big, flat);
    let next_face = base + (vec3<f32>(c) + select(vec3<f32>(0.0), vec3<f32>(1.0), d > vec3<f32>(0.0))) * cell;
    var t_max = select((next_face - p) * inv_d, big, flat);
    var t_in = 0.0;
    let words = leaf.slot;
    for (var i = 0u; i < 3u * n; i = i + 1u) {
        let k = u32(c.x) + n * (u32(c.y) + n * u32(c.z));
        if (!cell_empty(words, k)) {
            return t_in;
        }
        let t_out = min(min(t_max.x, t_max.y), t_max.z);
        if (t_out >= len) {
            break;
        }
        t_in = t_out;
        if (t_max.x <= t_max.y && t_max.x <= t_max.z) {
            c.x = c.x + step.x;
            t_max.x = t_max.x + t_delta.x;
        } else if (t_max.y <= t_max.z) {
            c.y = c.y + step.y;
            t_max.y = t_max.y + t_delta.y;
        } else {
            c.z = c.z + step.z;
            t_max.z = t_max.z + t_delta.z;
        }
        if (any(c < vec3<i32>(0)) || any(c >= vec3<i32>(i32(n)))) {
            break;
        }
    }
    return 3.0e38;
}

// Where the ray, entering `leaf` at t0, meets its first non-empty
// macrocell before t1 (less a thousandth of a cell against rounding: a
// segment in empty cells adds exactly nothing, so an earlier start changes
// no pixel), or 3e38 when every cell it crosses is empty. Done once as the
// ray enters the leaf, so the sample loop carries no per-sample test (on
// SIMD hardware a rare branch taken by one lane is paid by all of them).
// Only the empty cells before the first non-empty one are stepped over: a
// second walk back from the leaf's exit to its last non-empty cell cost
// more than the samples it saved on every view measured (5 % more kernel
// instructions on the Colin27 skin and brain and a CT, docs/performance.md "Tried and dropped");
// an opaque ray ends before the trailing cells, a translucent one finds
// few of them empty.
fn cells_start(leaf: Leaf, o: vec3<f32>, d: vec3<f32>, inv_d: vec3<f32>, t0: f32, t1: f32) -> f32 {
    let r0 = first_cell(leaf, o + d * t0, d, inv_d, t1 - t0);
    if (r0 > 1.0e38) {
        return 3.0e38;
    }
    let cell = leaf.voxel * f32(frame.aux.w);
    let margin = 1e-3 * min(min(cell.x, cell.y), cell.z);
    return max(t0 + r0 - margin, t0);
}

// The place of a leaf's next sample on its grid t + k·h, cut short at the
// leaf's exit and at a tool's break (`tc`: the last sample's); k moves on
// when the grid point itself is taken.
fn next_sample(ray: ptr<function, Ray>, t: f32, h: f32, k: ptr<function, u32>, tc: f32,
               t_exit: f32) -> f32 {
    return grid_next(ray, t, h, k, tc, t_exit, true);
}

// `next_sample`, moving k on only where `moving` (a refined segment's
// passes leave the leaf's grid where it was).
fn grid_next(ray: ptr<function, Ray>, t: f32, h: f32, k: ptr<function, u32>, tc: f32,
             t_exit: f32, moving: bool) -> f32 {
    let tk = t + f32(*k) * h;
    var tn = min(tk, t_exit);
    if (HAS_BREAKS) {
        tn = min(tn, next_break(ray, tc));
    }
    *k = *k + select(0u, 1u, moving && tn >= tk);
    return tn;
}

// The next sample of a refined segment from t0 to t1 (`parts` equal parts,
// t0 + k·(t1 − t0)/parts) where `moving`, moving k on only there.
fn fine_next(ray: ptr<function, Ray>, t0: f32, t1: f32, parts: f32, k: ptr<function, u32>,
             tc: f32, moving: bool) -> f32 {
    let tk = select(mix(t0, t1, f32(*k) / parts), t1, f32(*k) >= parts);
    var tn = tk;
    if (HAS_BREAKS) {
        tn = min(tn, next_break(ray, tc));
    }
    *k = *k + select(0u, 1u, moving && tn >= tk);
    return tn;
}

// The pixel a lane of tile `gid` renders: every pixel (size.w = 0), or only
// quincunx sub-frame k (size.w = 1 + k: frame reconstruction, G10 §5), one
// pixel of each 2×2 quad at its offset.
fn pixel_of(view: GpuView, gid: vec2<u32>) -> vec2<u32> {
    var px = gid;
    if (view.size.w != 0u) {
        let k = view.size.w - 1u;
        let off = vec2<u32>(select(0u, 1u, k == 1u || k == 2u), select(0u, 1u, k == 1u || k == 3u));
        px = gid * 2u + off;
    }
    return px;
}

// A pixel's ray in volume space (data length units), and sin(θ/2) of the
// angle θ the pixel subtends from the ray's origin (the larger of its width
// and height), for L12's adaptive step (Eq. 3).
struct PixelRay {
    o: vec3<f32>,
    d: vec3<f32>,
    sin_half: f32,
}

// G10 Eq. 1: the ray of screen point Q for projector E and observer V,
// moved from display to volume space, p = Rᵀ(x − centre)/scale + N·s/2.
// With MULTILEVEL it also sets the view's footprint constants (`lod_k`,
// `lod_observer`, `lod_lf`).
fn pixel_ray(view: GpuView, px: vec2<u32>) -> PixelRay {
    let q = vec3<f32>(
        view.region.x + (f32(px.x) + 0.5) / f32(view.size.x) * view.region.z,
        view.region.y + view.region.w - (f32(px.y) + 0.5) / f32(view.size.y) * view.region.w,
        0.0);
    let e = view.eye.xyz;
    let v = view.observer.xyz;
    let eta = view.eye.w;
    let dz = q.z - e.z;
    var mcop_x = v.x;
    if (abs(dz) > 1e-12) {
        mcop_x = e.x + (q.x - e.x) / dz * (v.z - e.z);
    }
    let origin = vec3<f32>((1.0 - eta) * v.x + eta * mcop_x, v.y, v.z);
    let dir_display = normalize(q - origin);
    let half_px = 0.5 * vec2<f32>(view.region.z / f32(view.size.x), view.region.w / f32(view.size.y));
    let chord = max(length(normalize(q + vec3<f32>(half_px.x, 0.0, 0.0) - origin)
                           - normalize(q - vec3<f32>(half_px.x, 0.0, 0.0) - origin)),
                    length(normalize(q + vec3<f32>(0.0, half_px.y, 0.0) - origin)
                           - normalize(q - vec3<f32>(0.0, half_px.y, 0.0) - origin)));
    let rt = mat3x3<f32>(frame.rt0.xyz, frame.rt1.xyz, frame.rt2.xyz);
    var ray: PixelRay;
    ray.o = rt * (origin - frame.center.xyz) * frame.center.w + 0.5 * frame.extent.xyz;
    ray.d = normalize(rt * dir_display);
    ray.sin_half = 0.5 * chord;
    if (MULTILEVEL) {
        lod_k = frame.lod.x * view.region.z / f32(view.size.x) / max(abs(v.z), 1e-9);
        lod_observer = rt * (v - frame.center.xyz) * frame.center.w + 0.5 * frame.extent.xyz;
        lod_lf = frame.lod.w > 0.5 && eta != 0.0;
    }
    return ray;
}

// Where the march is in the octree: the ray parameter `t` and the probe
// point it descends to, the node found and its box (`lo`, `hi`, the cell
// of its level), where and through which face the ray leaves it, whether
// that is the ray's end (`last`), its pool slot and data values;
// `advance`: leave the node first (it has been integrated).
struct Walk {
    t: f32,
    probe: vec3<f32>,
    node: u32,
    n: IndexNode,
    level: u32,
    cell: vec3<f32>,
    lo: vec3<f32>,
    hi: vec3<f32>,
    t_exit: f32,
    axis: u32,
    last: bool,
    slot: u32,
    values: vec2<f32>,
    advance: bool,
    visited: u32,
}

// Through the nodes with nothing to integrate by traversal alone, to the
// next leaf with data along the ray (o, d) before `t_end`: false at the
// ray's end. A CPU device runs the leaf's whole body in `main` for all its
// lanes on every pass of the outer loop, taken or not, so passes through
// empty space must not include it. Entering an empty node restarts the
// next brick's segment (`have_prev`); `snap` (the prediction buffer's
// local traversal) moves t back to the found node's entry, not before
// `entry`.
fn next_leaf(w: ptr<function, Walk>, o: vec3<f32>, d: vec3<f32>, inv_d: vec3<f32>, t_end: f32,
             entry: f32, acc: Acc, snap: ptr<function, bool>,
             have_prev: ptr<function, bool>) -> bool {
    var found_leaf = false;
    loop {
        // The first descent starts at the root, a later one at the
        // neighbour across the exit face: one descent in the kernel's
        // code (a CPU device runs every copy of it on every pass).
        var start = 0u;
        if ((*w).advance) {
            if ((*w).last || terminated(acc)) {
                break;
            }
            // Leave through the exit face and follow its neighbour pointer.
            let axis = (*w).axis;
            let next = neighbour((*w).n, axis, d[axis] > 0.0);
            if (next == NONE16) {
                break;
            }
            (*w).t = (*w).t_exit;
            // Probe just across the exit face, inside this leaf's face on the
            // other axes: a point the neighbour's box is sure to contain.
            let eps = frame.render.z;
            let lo_u = (*w).lo / frame.domain.xyz + eps;
            let hi_u = (*w).hi / frame.domain.xyz - eps;
            (*w).probe = clamp((o + d * (*w).t) / frame.domain.xyz, lo_u, hi_u);
            if (d[axis] > 0.0) {
                (*w).probe[axis] = hi_u[axis] + 2.0 * eps;
            } else {
                (*w).probe[axis] = lo_u[axis] - 2.0 * eps;
            }
            start = next;
        }
        let probe = (*w).probe;
        let found = descend(start, clamp(probe, vec3<f32>(0.0), vec3<f32>(0.99999994)));
        (*w).node = found.node;
        (*w).advance = true;
        (*w).visited = (*w).visited + 1u;
        if ((*w).visited > MAX_NODES_PER_RAY) {
            break;
        }
        // `descend` has read the node's first texel.
        let b = texel_at(frame_table, node_texel(found.node) + 1u);
        let n = node_of(found.a, b);
        (*w).n = n;
        (*w).values = bitcast<vec2<f32>>(b.zw);
        let level = n.data >> 24u;
        (*w).level = level;
        let cells = level_cells(level);
        let size = frame.domain.xyz / cells;
        let cell = clamp(floor(probe * cells), vec3<f32>(0.0), vec3<f32>(cells - 1.0));
        let lo = cell * size;
        let hi = lo + size;
        (*w).cell = cell;
        (*w).lo = lo;
        (*w).hi = hi;
        let tx = select(select((lo - o) * inv_d, (hi - o) * inv_d, d > vec3<f32>(0.0)),
                        vec3<f32>(3.0e38), abs(d) < vec3<f32>(1e-30));
        var t_exit = min(min(tx.x, tx.y), tx.z);
        var axis = 0u;
        if (tx.y <= tx.x && tx.y <= tx.z) {
            axis = 1u;
        } else if (tx.z <= tx.x && tx.z <= tx.y) {
            axis = 2u;
        }
        (*w).axis = axis;
        if (ISO && *snap) {
            let te = select((hi - o) * inv_d, (lo - o) * inv_d, d > vec3<f32>(0.0));
            let te_m = select(te, vec3<f32>(-3.0e38), abs(d) < vec3<f32>(1e-30));
            (*w).t = clamp(max(max(te_m.x, te_m.y), te_m.z), entry, (*w).t);
            *snap = false;
        }
        (*w).last = t_exit >= t_end;
        t_exit = clamp(t_exit, (*w).t, t_end);
        (*w).t_exit = t_exit;

        let slot = n.data & NO_SLOT;
        (*w).slot = slot;
        if (slot != NO_SLOT && t_exit > (*w).t) {
            found_leaf = true;
            break;
        }
        // Nothing to integrate here; the next brick restarts its segment.
        *have_prev = false;
    }
    return found_leaf;
}

// A voxel of edges `e` measured along the unit direction `d`: the radius
// along d of the ellipsoid whose semi-axes are the edges, 1 / |d ⊘ e|. A
// cubic voxel's edge whatever the direction (returned as is, so that
// isotropic volumes step exactly as before); over thick slices the thin
// edge for rays across the slices, the thick one for rays along z, and in
// between what the ray crosses (issue 40: the step follows the voxel in
// the ray's direction, not its smallest or largest side).
fn voxel_along(e: vec3<f32>, d: vec3<f32>) -> f32 {
    if (e.x == e.y && e.y == e.z) {
        return e.x;
    }
    let q = d / e;
    return inverseSqrt(dot(q, q));
}

// The step through a leaf: `step_factor` × its voxel along the ray
// (`voxel_along`), or with the adaptive
// step L12 §4.4 Eq. 3, λ = t·sin(θ/2), the radius of the pixel's cone at
// distance `t_eye` from the eye (data units, as the ray's parameter), taken
// at the leaf's entry so that the samples of a leaf stay evenly spaced
// (step_factor 0.5 is λ itself). The prediction buffer's sparse traversal
// steps by the voxel size / κ, κ from the brick's variance (B10 §4.5).
// Sub-pixel accuracy a < 1 (issue 40, `frame.extent.w`): a leaf of the
// finest level whose voxel covers p > a pixels cannot be refined, so its
// step shrinks by a / min(p, 1), to a quarter at most; p is the voxel's
// smallest edge over the pixel's cone 2·t·sin(θ/2) at the leaf's entry.
// Continuous in a, and off (bit for bit the voxel step) from a = 1 up.
fn leaf_step(leaf: Leaf, d: vec3<f32>, t_eye: f32, sin_half: f32, sparse: bool) -> f32 {
    let step_factor = frame.render.x;
    let voxel = voxel_along(leaf.voxel, d);
    var h = step_factor * voxel;
    if (frame.render.w > 0.5) {
        h = max(2.0 * step_factor * t_eye * sin_half, voxel / 64.0);
    } else if (!ISO && frame.extent.w > 0.0 && leaf.level == frame.counts.y) {
        let p = frame.spacing.w / max(2.0 * t_eye * sin_half, 1e-30);
        h = h * clamp(frame.extent.w / min(p, 1.0), 0.25, 1.0);
    }
    if (ISO && sparse) {
        h = max(h, voxel / mix(frame.predict.z, frame.predict.w, slot_range(leaf.slot).z));
    }
    return h;
}

// Macrocells: segments inside empty macrocells add exactly nothing, so the
// march starts only from the last sample before the first non-empty cell,
// on the same grid t + k·h (the samples computed by the same expressions,
// so the image is bit for bit the one without macrocells). Sets k and
// returns whether that first sample only starts the march; an all-empty
// leaf needs only the value at its exit, for the next leaf's first segment.
fn cells_skip(leaf: Leaf, o: vec3<f32>, d: vec3<f32>, inv_d: vec3<f32>, t: f32, t_exit: f32,
              h: f32, k: ptr<function, u32>) -> bool {
    let start = cells_start(leaf, o, d, inv_d, t, t_exit);
    if (start > 1.0e38) {
        *k = 0xFFFFFFFFu;
        return true;
    }
    var k0 = floor((start - t) / h);
    if (k0 >= 1.0 && t + k0 * h > start) {
        k0 = k0 - 1.0;
    }
    if (k0 >= 1.0) {
        *k = u32(k0);
        return true;
    }
    return false;
}

// The volume's pre-integrated average (τ̄, τ̄·c̄) over the data segment from
// s_prev to s: the closed form, the 2D table, the table from the segment's
// ends, or the table's segment integral.
fn preintegrated(s_prev: f32, s: f32, e_prev: TfEnd, e: TfEnd) -> vec4<f32> {
    if (ANALYTIC_PREINT) {
        return analytic_average(s_prev, s);
    } else if (GRID_PREINT) {
        return grid_average(s_prev, s);
    } else if (END_PREINT) {
        return end_average(e_prev, e);
    }
    return segment_average(0u, frame.counts.w, s_prev, s);
}

// What the segment from (tc, s_prev) to (tn, s) adds: its pre-integrated
// average `avg_in` (`preintegrated`, which the march also reads to decide
// on refinement), the enhancers' say, Phong shading where it is not
// transparent, composited by the stepper.
fn composite_average(acc: ptr<function, Acc>, lv: Levels, blend: bool, o: vec3<f32>,
                     d: vec3<f32>, tc: f32, tn: f32, s_prev: f32, s: f32, avg_in: vec4<f32>,
                     ls: LayerSeg, layer_w: vec3<f32>) -> Sample {
    var avg = avg_in;
    let vol_tau = select(0.0, avg.x, (ls.mask & 1u) != 0u);
    if (LAYERS > 0u) {
        // The summed medium of the volume and its registered layers.
        avg = layered_average(avg, ls, layer_w);
    }
    var smp: Sample;
    smp.pos = o + d * (0.5 * (tc + tn));
    smp.len = tn - tc;
    smp.dir = d;
    smp.scalar = s;
    smp.scalar_prev = s_prev;
    smp.tau = avg.x;
    smp.emission = avg.yzw;
    smp.alpha_scale = 1.0;
    smp.alpha_mix = 0.0;
    smp.color_scale = 1.0;
    smp.shade = -1.0;
    smp.material = frame.light;
    // What the enhancers read, computed only where one that reads it acts
    // (`chain_active`: a probe's sphere), so that a tool costs its inputs
    // only where it has an effect.
    // MImDA reads the importance only of segments with extinction (the
    // others take no part), refraction reads ν everywhere.
    // In tiles that meet no tool's region (the pipeline without
    // TOOL_TILES) none of this is compiled in.
    var inputs = false;
    let tools_here = (NEEDS_GRADIENT || TOOL_AUX) && TOOL_TILES;
    if (tools_here) {
        inputs = chain_active(&smp);
    }
    if ((NEEDS_AUX && (REFRACTION || smp.tau > 0.0)) || (TOOL_AUX && inputs)) {
        let aux = segment_average(frame.aux.x, frame.aux.y, s_prev, s);
        smp.importance = aux.x;
        smp.refraction = aux.y;
        if (LAYERS > 0u && MIMDA) {
            smp.importance = layered_importance(vol_tau, aux.x, ls);
        }
    }
    // The gradient (six fetches): for the enhancers where they act, and for
    // shading where the segment has extinction — a transparent segment adds
    // nothing, and tools blend towards opacity only where τ̄ > 0. Computed
    // before the enhancers, in one place per kind of tile: a CPU device
    // runs a divergent branch's body for all lanes.
    let shaded = SHADING && smp.tau > 0.0;
    if (tools_here) {
        if (inputs || shaded) {
            smp.gradient = gradient_levels(lv, blend, smp.pos);
        }
    } else if (shaded) {
        smp.gradient = gradient_levels(lv, blend, smp.pos);
    }
    // The coarser levels' gradients (multilevel shading, G10 §3): the
    // leaf's parent's and grandparent's, each the finer one's where that
    // level is not resident.
    if (COARSE_GRADIENTS && tools_here && inputs) {
        smp.gradient_up = smp.gradient;
        if (lv.up.slot != NO_SLOT) {
            smp.gradient_up = gradient(lv.up, smp.pos);
        }
        smp.gradient_up2 = smp.gradient_up;
        if (lv.up2.slot != NO_SLOT) {
            smp.gradient_up2 = gradient(lv.up2, smp.pos);
        }
    }
    chain_sample(&smp);
    var shade = 1.0;
    if (TOOL_SHADES && smp.shade >= 0.0) {
        shade = smp.shade;
    } else if (shaded) {
        shade = phong(smp.gradient, d, smp.material);
    }
    accumulate(acc, segment_optics(smp, shade), smp);
    return smp;
}

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(local_invocation_id) lid: vec3<u32>, @builtin(workgroup_id) wg: vec3<u32>,
        @builtin(num_workgroups) groups: vec3<u32>) {
    // One workgroup per listed 8×8 tile (`tiles`: the tiles whose rays can
    // meet data, backend/src/raycast/tiles.rs): its view and place, read
    // at the workgroup's index, a value a compiler can know to be uniform
    // across the workgroup.
    load_constants();
    load_layers();
    let first = select(frame.dispatch.w, 0u, TOOL_TILES);
    let end = select(frame.dispatch.x, frame.dispatch.w, TOOL_TILES);
    let w = first + wg.x + wg.y * groups.x;
    if (w >= end) {
        return;
    }
    let tile = tile_at(w);
    let view = view_at(tile.x);
    let px = pixel_of(view, vec2<u32>(tile.y & 0xFFFFu, tile.y >> 16u) * 8u + lid.xy);
    if (px.x >= view.size.x || px.y >= view.size.y) {
        return;
    }
    let out = view.size.z + px.y * view.size.x + px.x;
    let pray = pixel_ray(view, px);
    var o = pray.o;
    var d = pray.d;
    // Registered layers: each one's weight along this ray, the values of
    // the last sample and the media that had data there.
    var layer_w = vec3<f32>(0.0);
    if (LAYERS > 0u) {
        layer_w = layer_weights(d);
    }
    var lay_prev = vec3<f32>(0.0);
    var le_prev: array<TfEnd, 3>;
    var mask_prev = 0u;

    var acc = Acc(vec3<f32>(0.0), 0.0, 0.0);
    var span = clip_box(o, d, frame.extent.xyz);
    let predicting = ISO && frame.predict.x > 0.0;
    // The overlay's depth combination (G10 §5): where the ray's opacity
    // first reaches ½, in the prediction buffer (−1: nowhere).
    let record_depth = frame.optics.z > 0.5;
    if (span.y <= span.x) {
        image[out] = vec4<f32>(0.0);
        if (predicting) {
            prediction[out] = PB_MISS_BOX;
        } else if (record_depth) {
            prediction[out] = -1.0;
        }
        return;
    }
    let entry = span.x;
    var pb = Predicted(false, false);
    if (predicting && frame.predict.x > 1.5) {
        pb = predicted_start(out, &span);
    }
    var snap = pb.snap;
    var hit_t = -1.0;
    var ray: Ray;
    ray.origin = o;
    ray.dir = d;
    ray.t_end = span.y;
    ray.n_breaks = 0u;
    chain_start(&ray);

    // A point on a face belongs to the node the ray is entering: probe a
    // hundredth of a source voxel further along every axis of travel.
    var nudge = sign(d) * frame.render.z;
    var inv_d = 1.0 / select(d, vec3<f32>(1e-30), abs(d) < vec3<f32>(1e-30));
    var walk: Walk;
    walk.t = span.x;
    walk.probe = (o + d * walk.t) / frame.domain.xyz + nudge;
    walk.slot = NO_SLOT;
    var s_prev = 0.0;
    var e_prev: TfEnd;
    var have_prev = false;
    var nu_prev = -1.0;
    var n_samples = 0u;
    // Distance travelled before the last refraction bend (the adaptive
    // step's t counts from the eye, not from the bend).
    var t_base = 0.0;
    var depth_t = -1.0;
    loop {
        if (!next_leaf(&walk, o, d, inv_d, span.y, entry, acc, &snap, &have_prev)) {
            break;
        }
        let t = walk.t;
        let t_exit = walk.t_exit;
        var bent = false;
        let leaf = make_leaf(walk.node, walk.level, walk.cell, walk.slot, walk.values);
        // Which media have data in this leaf (the slot's mask), and the
        // layers' ranges (value = lo + span · stored).
        var mask = 0u;
        var lay_lo = vec3<f32>(0.0);
        var lay_span = vec3<f32>(1.0);
        if (LAYERS > 0u) {
            mask = bitcast<u32>(slot_range(walk.slot).w);
            let r = layer_ranges(walk.slot);
            lay_lo = vec3<f32>(r[0].x, r[0].z, r[1].x);
            lay_span = vec3<f32>(r[0].y, r[0].w, r[1].y);
        }
        // Multilevel sampling blends in coarser levels only in leaves
        // that the view needs coarser somewhere along the ray (the
        // footprint grows monotonically along a ray from the observer;
        // s(|z|) is convex along it): the others sample as usual and
        // may skip their empty macrocells.
        var lv = Levels(leaf, leaf, leaf);
        var blend = false;
        // Multilevel shading reads the coarser levels too, without blending.
        if ((MULTILEVEL || COARSE_GRADIENTS) && !ISO) {
            lv = levels_of(leaf, walk.n);
        }
        if (MULTILEVEL && !ISO) {
            blend = lv.up.slot != NO_SLOT
                && max(lod_offset(walk.level, o + d * t), lod_offset(walk.level, o + d * t_exit)) > 0.0;
        }
        let h = leaf_step(leaf, d, t_base + t, pray.sin_half, pb.sparse);
        // Samples fall at t + k·h (and where the leaf ends or a tool's
        // boundary lies).
        var tc = t;
        var k = 1u;
        // Whether the first sample taken only starts the march.
        var skip_first = false;
        if (MACROCELLS && !blend) {
            skip_first = cells_skip(leaf, o, d, inv_d, t, t_exit, h, &k);
        }
        if (!have_prev && !skip_first) {
            // The leaf's entry value starts the march, at t + 0·h.
            k = 0u;
            skip_first = true;
        }
        if (skip_first) {
            // The sample that only starts the march (the leaf's entry, or
            // the last one before its non-empty cells, or its exit), taken
            // before the loop: a CPU device runs the loop's whole body,
            // the segment's table lookup and compositing included, for
            // every pass of any of its lanes; as a pass of the loop this
            // sample cost a full pass, here it costs a sample.
            let tn = next_sample(&ray, t, h, &k, tc, t_exit);
            if (LAYERS > 0u) {
                let v = sample_layered(leaf, o + d * tn);
                s_prev = leaf.range.x + leaf.range.y * v.x;
                lay_prev = layer_values(leaf, o + d * tn, v, lay_lo, lay_span);
                le_prev = layer_ends(lay_prev);
                mask_prev = mask;
            } else {
                s_prev = sample_levels(lv, blend, o + d * tn);
            }
            n_samples = n_samples + 1u;
            if (!ISO) {
                e_prev = tf_end(s_prev);
            }
            have_prev = true;
            tc = tn;
        }
        // LOOKAHEAD: each pass fetches the value of the next pass's sample
        // before it composites its own segment, so that the fetch overlaps
        // the segment's table lookup and compositing, which do not depend
        // on it. The samples, their order and the image are the same; a
        // leaf's march fetches one value more than it uses. Nothing a pass
        // does moves a later sample: tools add their breaks at the ray's
        // start, and a bent ray leaves the loop.
        var tn_next = tc;
        var s_next = s_prev;
        if (LOOKAHEAD && tc < t_exit) {
            tn_next = next_sample(&ray, t, h, &k, tc, t_exit);
            s_next = sample_levels(lv, blend, o + d * tn_next);
        }
        var fine = false;
        var t_fine = 0.0;
        var fine_end = 0.0;
        var k_fine = 0u;
        var parts_fine = 1.0;
        loop {
            // An all-empty leaf ends with its starting sample, at its exit.
            if (tc >= t_exit) {
                break;
            }
            var tn: f32;
            var s: f32;
            var lay = vec3<f32>(0.0);
            if (LOOKAHEAD && refines()) {
                // Inside a refined segment each pass fetches its own
                // sample; the leaf's next one, fetched ahead, waits in
                // (tn_next, s_next). One fetch, placed by selects.
                let ahead = !fine && tn_next < t_exit;
                let tg = grid_next(&ray, t, h, &k, tn_next, t_exit, ahead);
                let tf = fine_next(&ray, t_fine, fine_end, parts_fine, &k_fine, tc, fine);
                let v = sample_levels(lv, blend, o + d * select(tg, tf, fine));
                tn = select(tn_next, tf, fine);
                s = select(s_next, v, fine);
                tn_next = select(tn_next, tg, ahead);
                s_next = select(s_next, v, ahead);
            } else if (LOOKAHEAD) {
                tn = tn_next;
                s = s_next;
                if (tn < t_exit) {
                    tn_next = next_sample(&ray, t, h, &k, tn, t_exit);
                    s_next = sample_levels(lv, blend, o + d * tn_next);
                }
            } else {
                if (refines()) {
                    let tg = grid_next(&ray, t, h, &k, tc, t_exit, !fine);
                    let tf = fine_next(&ray, t_fine, fine_end, parts_fine, &k_fine, tc, fine);
                    tn = select(tg, tf, fine);
                } else {
                    tn = next_sample(&ray, t, h, &k, tc, t_exit);
                }
                if (LAYERS > 0u) {
                    let v = sample_layered(leaf, o + d * tn);
                    s = leaf.range.x + leaf.range.y * v.x;
                    lay = layer_values(leaf, o + d * tn, v, lay_lo, lay_span);
                } else {
                    s = sample_levels(lv, blend, o + d * tn);
                }
            }
            n_samples = n_samples + 1u;
            var e: TfEnd;
            if (!ISO) {
                e = tf_end(s);
            }
            var le: array<TfEnd, 3>;
            if (LAYERS > 0u) {
                le = layer_ends(lay);
            }
            // A segment with an end that lacks data adds nothing.
            if (NO_DATA && !ISO && !(has_data(s) && has_data(s_prev))) {
                have_prev = true;
                s_prev = s;
                e_prev = e;
                tc = tn;
                if (tc >= t_exit) {
                    break;
                }
                continue;
            }
            if (ISO) {
                iso_hit(&acc, &hit_t, leaf, o, d, tc, tn, s_prev, s);
                s_prev = s;
                tc = tn;
                if (tc >= t_exit || terminated(acc)) {
                    break;
                }
                continue;
            }
            let segment = LayerSeg(lay_prev, lay, le_prev, le, mask & mask_prev);
            let avg = preintegrated(s_prev, s, e_prev, e);
            let depth = avg.x * (tn - tc);
            if (refines() && !fine && depth > REFINE_DEPTH && acc.alpha < REFINE_ALPHA) {
                fine = true;
                parts_fine = min(frame.optics.w, ceil(depth / REFINE_DEPTH));
                t_fine = tc;
                k_fine = 1u;
                fine_end = tn;
                continue;
            }
            let smp = composite_average(&acc, lv, blend, o, d, tc, tn, s_prev, s, avg, segment,
                                        layer_w);
            s_prev = s;
            e_prev = e;
            lay_prev = lay;
            le_prev = le;
            mask_prev = mask;
            tc = tn;
            if (refines() && fine && tc >= fine_end) {
                fine = false;
            }
            if (record_depth && depth_t < 0.0 && acc.alpha >= 0.5) {
                depth_t = t_base + tc;
            }
            if (REFRACTION) {
                bent = bend_at(leaf, &o, &d, tc, nu_prev, smp.refraction);
                if (bent) {
                    t_base = t_base + tc;
                }
                nu_prev = smp.refraction;
            }
            if (bent || tc >= t_exit || terminated(acc)) {
                break;
            }
        }
        // Visibility feedback (G10 §5): this leaf contributed.
        feedback[walk.node] = 1u;
        if (REFRACTION && bent) {
            // Start again from the bend: a new straight ray inside the same
            // leaf (rays that leave the volume go on straight).
            inv_d = 1.0 / select(d, vec3<f32>(1e-30), abs(d) < vec3<f32>(1e-30));
            nudge = sign(d) * frame.render.z;
            span = clip_box(o, d, frame.extent.xyz);
            if (span.y <= 0.0 || terminated(acc)) {
                break;
            }
            walk.t = 0.0;
            ray.origin = o;
            ray.dir = d;
            ray.t_end = span.y;
            ray.n_breaks = 0u;
            chain_start(&ray);
            walk.probe = o / frame.domain.xyz + nudge;
            walk.advance = false;
            continue;
        }
        // Ended here: leave the loop now, not at the top of another pass.
        // A CPU device runs a loop's whole body, masked, until no lane is
        // left in it; with the test at the top of the next pass, every
        // group of rays paid one such pass after its last ray had ended.
        if (walk.last || terminated(acc)) {
            break;
        }
    }
    ray.dir = d;
    chain_end(&ray, &acc);
    image[out] = vec4<f32>(acc.color, acc.alpha);
    if (COUNT_SAMPLES) {
        atomicAdd(&counters[0], n_samples);
    }
    if (predicting) {
        prediction[out] = select(PB_MISS_SURFACE, hit_t, hit_t >= 0.0);
    } else if (record_depth) {
        if (ISO) {
            depth_t = hit_t;
        }
        prediction[out] = select(-1.0, max(depth_t, 1e-30), depth_t >= 0.0);
    }
}
