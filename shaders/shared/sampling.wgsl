// shared/sampling.wgsl: brick sampling and gradients.

#import bindings

// Trilinear filtering by the texture unit (one sample) instead of eight
// loads; off where the pool's format is not filterable on this device.
override HW_FILTER: bool = false;
// Tricubic B-spline filtering instead of trilinear (L12 §5.1).
override TRICUBIC: bool = false;

// The volume has no-data voxels (NaN at import, `--nan empty`): they are
// left out of the interpolation, the other taps' weights renormalised; a
// sample whose eight taps all lack data is NO_SAMPLE. Off, this costs
// nothing. A tap at or above NO_DATA_TAP is a no-data voxel.
override NO_DATA: bool = false;
override NO_DATA_TAP: f32 = 3.0e38;
const NO_SAMPLE: f32 = -3.0e38;

fn has_data(s: f32) -> bool {
    return s > -1.0e38;
}

// Brick sampling: trilinear interpolation of the stored (B+4)³ brick, by the
// texture unit or by eight loads with exact f32 weights (the overlap keeps
// every tap inside the slot).

struct Leaf {
    node: u32,
    level: u32,
    cell: vec3<f32>,   // brick coordinates at its level
    slot: u32,
    voxel: vec3<f32>,  // its voxel's edges (data units): spacing · level_scale(level)
    origin: vec3<i32>, // its slot's first texel in the pool
    range: vec2<f32>,  // its data range: value = range.x + range.y · stored
    to_local: vec3<f32>,  // 1 / voxel: data units → texels
    shift: vec3<f32>,     // the leaf's first texel centre, −cell·B + OVERLAP − ½
}

// The leaf `node` of `level` at brick coordinates `cell`, its data in `slot`
// (where it has data: the slot's place and range are read once per leaf,
// not per sample).
fn make_leaf(node: u32, level: u32, cell: vec3<f32>, slot: u32, values: vec2<f32>) -> Leaf {
    let voxel = frame.spacing.xyz * level_scale(level);
    var leaf = Leaf(node, level, cell, slot, voxel, vec3<i32>(0), vec2<f32>(0.0), 1.0 / voxel,
                    vec3<f32>(OVERLAP - 0.5) - cell * f32(frame.counts.x));
    if (slot != NO_SLOT) {
        leaf.origin = slot_origin(slot);
        leaf.range = values;
    }
    return leaf;
}

// The slot's place in the pool, by f32 arithmetic (exact below 2²⁴ slots):
// integer division by a non-constant has no SIMD instruction on a CPU.
fn slot_origin(slot: u32) -> vec3<i32> {
    let p = vec3<f32>(frame.pool.xyz);
    let i = f32(slot);
    let row = floor((i + 0.5) / p.x);
    let layer = floor((row + 0.5) / p.y);
    let s = vec3<f32>(i - row * p.x, row - layer * p.y, layer);
    return vec3<i32>(s) * i32(frame.pool.w);
}

fn tap(o: vec3<i32>, i: vec3<i32>) -> f32 {
    return textureLoad(pool, o + i, 0).r;
}

// Trilinear interpolation at `local` (tap units: tap i at i) in the slot at
// `o`: by the texture unit, or by eight loads with exact f32 weights.
fn trilinear(o: vec3<i32>, local: vec3<f32>) -> f32 {
    if (HW_FILTER) {
        return textureSampleLevel(pool, pool_sampler, (vec3<f32>(o) + local + 0.5) * frame.recip.xyz, 0.0).r;
    }
    let f0 = floor(local);
    let w = local - f0;
    let i0 = vec3<i32>(f0);
    let i1 = min(i0 + vec3<i32>(1), vec3<i32>(i32(frame.pool.w) - 1));
    let c00 = mix(tap(o, i0), tap(o, vec3<i32>(i1.x, i0.y, i0.z)), w.x);
    let c10 = mix(tap(o, vec3<i32>(i0.x, i1.y, i0.z)), tap(o, vec3<i32>(i1.x, i1.y, i0.z)), w.x);
    let c01 = mix(tap(o, vec3<i32>(i0.x, i0.y, i1.z)), tap(o, vec3<i32>(i1.x, i0.y, i1.z)), w.x);
    let c11 = mix(tap(o, vec3<i32>(i0.x, i1.y, i1.z)), tap(o, i1), w.x);
    return mix(mix(c00, c10, w.y), mix(c01, c11, w.y), w.z);
}

// Tricubic B-spline filtering (L12 §5.1, after Sigg and Hadwiger, "Fast
// third-order texture filtering", GPU Gems 2 ch. 20): the 4³ taps around
// `local` weighted by the cubic B-spline, gathered as eight trilinear
// lookups at h0 = i − 1 + w1/(w0 + w1) and h1 = i + 1 + w3/(w2 + w3) per
// axis. The brick's overlap of 2 keeps every tap inside the slot.
fn tricubic(o: vec3<i32>, x: vec3<f32>) -> f32 {
    let local = clamp(x, vec3<f32>(1.0), vec3<f32>(f32(frame.pool.w) - 2.0));
    let i = floor(local);
    let f = local - i;
    let f2 = f * f;
    let f3 = f2 * f;
    let w0 = (1.0 - 3.0 * f + 3.0 * f2 - f3) / 6.0;
    let w1 = (4.0 - 6.0 * f2 + 3.0 * f3) / 6.0;
    let w2 = (1.0 + 3.0 * f + 3.0 * f2 - 3.0 * f3) / 6.0;
    let w3 = f3 / 6.0;
    let g0 = w0 + w1;
    let g1 = w2 + w3;
    let h0 = i - 1.0 + w1 / g0;
    let h1 = i + 1.0 + w3 / g1;
    let a = mix(trilinear(o, h1), trilinear(o, vec3<f32>(h0.x, h1.y, h1.z)), g0.x);
    let b = mix(trilinear(o, vec3<f32>(h1.x, h0.y, h1.z)), trilinear(o, vec3<f32>(h0.x, h0.y, h1.z)), g0.x);
    let c = mix(trilinear(o, vec3<f32>(h1.x, h1.y, h0.z)), trilinear(o, vec3<f32>(h0.x, h1.y, h0.z)), g0.x);
    let e = mix(trilinear(o, vec3<f32>(h1.x, h0.y, h0.z)), trilinear(o, h0), g0.x);
    return mix(mix(a, b, g0.y), mix(c, e, g0.y), g0.z);
}

fn sample_brick(leaf: Leaf, p: vec3<f32>) -> f32 {
    let side = f32(frame.pool.w);
    let local = clamp(p * leaf.to_local + leaf.shift, vec3<f32>(0.0), vec3<f32>(side - 1.0));
    let o = leaf.origin;
    var v: f32;
    if (NO_DATA) {
        let f0 = floor(local);
        let w = local - f0;
        let i0 = vec3<i32>(f0);
        let i1 = min(i0 + vec3<i32>(1), vec3<i32>(i32(frame.pool.w) - 1));
        var sum = 0.0;
        var wsum = 0.0;
        for (var c = 0u; c < 8u; c = c + 1u) {
            let hi = vec3<bool>((c & 1u) != 0u, (c & 2u) != 0u, (c & 4u) != 0u);
            let t = tap(o, select(i0, i1, hi));
            let wc = select(1.0 - w, w, hi);
            let wt = wc.x * wc.y * wc.z;
            if (t < NO_DATA_TAP) {
                sum = sum + wt * t;
                wsum = wsum + wt;
            }
        }
        if (wsum <= 0.0) {
            return NO_SAMPLE;
        }
        v = sum / wsum;
    } else if (TRICUBIC) {
        v = tricubic(o, local);
    } else {
        v = trilinear(o, local);
    }
    return leaf.range.x + leaf.range.y * v;
}

// The volume's and its registered layers' stored values at p (LAYERS > 0: a
// pool of two or four channels, f32 or 8-bit codes, no no-data voxels),
// every channel of a texel interpolated at once, by the texture unit or by
// eight loads; each channel's range turns them into data values.
fn sample_layered(leaf: Leaf, p: vec3<f32>) -> vec4<f32> {
    let side = f32(frame.pool.w);
    let local = clamp(p * leaf.to_local + leaf.shift, vec3<f32>(0.0), vec3<f32>(side - 1.0));
    let o = leaf.origin;
    if (HW_FILTER) {
        return textureSampleLevel(pool, pool_sampler, (vec3<f32>(o) + local + 0.5) * frame.recip.xyz, 0.0);
    }
    let f0 = floor(local);
    let w = local - f0;
    let i0 = vec3<i32>(f0);
    let i1 = min(i0 + vec3<i32>(1), vec3<i32>(i32(frame.pool.w) - 1));
    let c00 = mix(textureLoad(pool, o + i0, 0), textureLoad(pool, o + vec3<i32>(i1.x, i0.y, i0.z), 0), w.x);
    let c10 = mix(textureLoad(pool, o + vec3<i32>(i0.x, i1.y, i0.z), 0), textureLoad(pool, o + vec3<i32>(i1.x, i1.y, i0.z), 0), w.x);
    let c01 = mix(textureLoad(pool, o + vec3<i32>(i0.x, i0.y, i1.z), 0), textureLoad(pool, o + vec3<i32>(i1.x, i0.y, i1.z), 0), w.x);
    let c11 = mix(textureLoad(pool, o + vec3<i32>(i0.x, i1.y, i1.z), 0), textureLoad(pool, o + i1, 0), w.x);
    return mix(mix(c00, c10, w.y), mix(c01, c11, w.y), w.z);
}

// The stored values of the voxel nearest p (a label layer's whole labels,
// `layer_values`).
fn sample_nearest(leaf: Leaf, p: vec3<f32>) -> vec4<f32> {
    let side = f32(frame.pool.w);
    let local = clamp(p * leaf.to_local + leaf.shift, vec3<f32>(0.0), vec3<f32>(side - 1.0));
    return textureLoad(pool, leaf.origin + vec3<i32>(round(local)), 0);
}

// One axis of the gradient where samples may lack data: central where both
// neighbours have data, one-sided against the centre where one has, 0 else.
fn partial(a: f32, b: f32, c: f32, h: f32) -> f32 {
    if (has_data(a) && has_data(b)) {
        return (a - b) / (2.0 * h);
    }
    if (has_data(c)) {
        if (has_data(a)) {
            return (a - c) / h;
        }
        if (has_data(b)) {
            return (c - b) / h;
        }
    }
    return 0.0;
}

fn gradient(leaf: Leaf, p: vec3<f32>) -> vec3<f32> {
    let h = leaf.voxel;
    if (NO_DATA) {
        let c = sample_brick(leaf, p);
        let ex = vec3<f32>(h.x, 0.0, 0.0);
        let ey = vec3<f32>(0.0, h.y, 0.0);
        let ez = vec3<f32>(0.0, 0.0, h.z);
        return vec3<f32>(
            partial(sample_brick(leaf, p + ex), sample_brick(leaf, p - ex), c, h.x),
            partial(sample_brick(leaf, p + ey), sample_brick(leaf, p - ey), c, h.y),
            partial(sample_brick(leaf, p + ez), sample_brick(leaf, p - ez), c, h.z));
    }
    let gx = sample_brick(leaf, p + vec3<f32>(h.x, 0.0, 0.0)) - sample_brick(leaf, p - vec3<f32>(h.x, 0.0, 0.0));
    let gy = sample_brick(leaf, p + vec3<f32>(0.0, h.y, 0.0)) - sample_brick(leaf, p - vec3<f32>(0.0, h.y, 0.0));
    let gz = sample_brick(leaf, p + vec3<f32>(0.0, 0.0, h.z)) - sample_brick(leaf, p - vec3<f32>(0.0, 0.0, h.z));
    return vec3<f32>(gx / h.x, gy / h.y, gz / h.z) * 0.5;
}

// Multilevel sampling (G10 §4 and Fig. 5; GigaVoxels' quadrilinear
// filtering): a leaf's samples blend its data with its parent's and its
// grandparent's by how much coarser than the leaf the view needs the point
// to be, so that where the cut changes level between bricks both sides
// sample the same blend of levels and the image has no seam.
override MULTILEVEL: bool = false;

// The levels a leaf's samples may read: the leaf, its parent and its
// grandparent (`slot` NO_SLOT where absent or without data).
struct Levels {
    leaf: Leaf,
    up: Leaf,
    up2: Leaf,
}

// Per ray: accuracy × the view's pixel angle (pixel width / |V_z|), the
// observer in volume space, and whether the view's detail follows the light
// field display's s(z).
var<private> lod_k: f32;
var<private> lod_observer: vec3<f32>;
var<private> lod_lf: bool;

fn levels_of(leaf: Leaf, n: IndexNode) -> Levels {
    var lv = Levels(leaf, leaf, leaf);
    lv.up.slot = NO_SLOT;
    lv.up2.slot = NO_SLOT;
    let pi = n.tree & 0xFFFFu;
    if (pi == NONE16) {
        return lv;
    }
    let pn = node_at(pi);
    lv.up = make_leaf(pi, leaf.level - 1u, floor(leaf.cell / vec3<f32>(level_split(leaf.level) + 1u)),
                 pn.data & NO_SLOT, node_values(pi));
    let gi = pn.tree & 0xFFFFu;
    if (lv.up.slot == NO_SLOT || gi == NONE16) {
        return lv;
    }
    lv.up2 = make_leaf(gi, leaf.level - 2u, floor(lv.up.cell / vec3<f32>(level_split(leaf.level - 1u) + 1u)),
                  node_at(gi).data & NO_SLOT, node_values(gi));
    return lv;
}

// The voxel length refinement sizes a level by (backend/src/geometry.rs
// `voxel_len`): the finest edge at the leaves; above, the longest of the
// edges its children halve.
fn level_voxel(level: u32) -> f32 {
    if (level >= frame.counts.y) {
        return frame.spacing.w;
    }
    let e = frame.spacing.xyz * level_scale(level);
    let h = e * vec3<f32>(level_split(level + 1u));
    let refined = max(max(h.x, h.y), h.z);
    return select(max(max(e.x, e.y), e.z), refined, refined > 0.0);
}

// How many levels coarser than `level` the view needs the point p: log2 of
// accuracy × footprint / voxel. The footprint is a pixel's back-projection
// to p, pixel·Δz²/(D·|VP|) (L12 §4.2.1 for a small sphere: the distance
// and the magnification 1/cos²β off the axis; D = |V_z|, Δz the depth of p
// from the observer), or the display's s(z) = s0 + 2|z|·tan(Φ/2) at p's
// depth for light field views (G10 §4). A leaf is adequate where this is
// ≥ 0; refinement keeps every leaf adequate at its corners and closest
// point (backend/src/loader/geometry.rs `point_pixels`), so on a face
// between a coarse and a finer leaf the value is ≤ 0 for the coarse one and
// both sides blend the same levels.
fn lod_offset(level: u32, p: vec3<f32>) -> f32 {
    let voxel = level_voxel(level);
    if (lod_lf) {
        let z = dot(frame.rt2.xyz, p - 0.5 * frame.extent.xyz) / frame.center.w + frame.center.z;
        let s = frame.lod.y + 2.0 * abs(z) * frame.lod.z;
        return log2(frame.lod.x * s * frame.center.w / voxel);
    }
    let rel = p - lod_observer;
    let dz = abs(dot(rel, frame.rt2.xyz));
    return log2(lod_k * dz * dz / (max(length(rel), 1e-30) * voxel));
}

// lod_offset clamped to the levels at hand: 0 to 1 blends leaf to parent,
// 1 to 2 parent to grandparent.
fn level_blend(lv: Levels, p: vec3<f32>) -> f32 {
    let top = select(1.0, 2.0, lv.up2.slot != NO_SLOT);
    return clamp(lod_offset(lv.leaf.level, p), 0.0, top);
}

// The sample at p: the leaf's alone, or blended with the coarser levels.
fn sample_levels(lv: Levels, blend: bool, p: vec3<f32>) -> f32 {
    let s0 = sample_brick(lv.leaf, p);
    if (!MULTILEVEL || !blend) {
        return s0;
    }
    let c = level_blend(lv, p);
    if (c <= 0.0) {
        return s0;
    }
    let s1 = sample_brick(lv.up, p);
    if (!has_data(s0) || !has_data(s1)) {
        return s0;
    }
    if (c <= 1.0) {
        return mix(s0, s1, c);
    }
    let s2 = sample_brick(lv.up2, p);
    if (!has_data(s2)) {
        return s1;
    }
    return mix(s1, s2, c - 1.0);
}

// The gradient at p, blended across levels like the samples (G10 §4).
fn gradient_levels(lv: Levels, blend: bool, p: vec3<f32>) -> vec3<f32> {
    let g0 = gradient(lv.leaf, p);
    if (!MULTILEVEL || !blend) {
        return g0;
    }
    let c = level_blend(lv, p);
    if (c <= 0.0) {
        return g0;
    }
    let g1 = gradient(lv.up, p);
    if (c <= 1.0) {
        return mix(g0, g1, c);
    }
    return mix(g1, gradient(lv.up2, p), c - 1.0);
}
