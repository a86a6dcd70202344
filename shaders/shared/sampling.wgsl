// shared/sampling.wgsl: brick sampling and gradients.

#import bindings

// Trilinear filtering by the texture unit (one sample) instead of eight
// loads; off where the pool's format is not filterable on this device.
override HW_FILTER: bool = false;

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
}

fn slot_origin(slot: u32) -> vec3<i32> {
    let p = frame.pool;
    let s = vec3<u32>(slot % p.x, (slot / p.x) % p.y, slot / (p.x * p.y));
    return vec3<i32>(s * p.w);
}

fn tap(o: vec3<i32>, i: vec3<i32>) -> f32 {
    return textureLoad(pool, o + i, 0).r;
}

fn sample_brick(leaf: Leaf, p: vec3<f32>) -> f32 {
    let scale = f32(1u << (frame.counts.y - leaf.level));
    let voxel = frame.spacing.xyz * scale;
    let side = f32(frame.pool.w);
    let local = clamp(p / voxel - leaf.cell * f32(frame.counts.x) + vec3<f32>(OVERLAP - 0.5),
                      vec3<f32>(0.0), vec3<f32>(side - 1.0));
    let o = slot_origin(leaf.slot);
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
    } else if (HW_FILTER) {
        let size = vec3<f32>(frame.pool.xyz * frame.pool.w);
        v = textureSampleLevel(pool, pool_sampler, (vec3<f32>(o) + local + 0.5) / size, 0.0).r;
    } else {
        let f0 = floor(local);
        let w = local - f0;
        let i0 = vec3<i32>(f0);
        let i1 = min(i0 + vec3<i32>(1), vec3<i32>(i32(frame.pool.w) - 1));
        let c00 = mix(tap(o, i0), tap(o, vec3<i32>(i1.x, i0.y, i0.z)), w.x);
        let c10 = mix(tap(o, vec3<i32>(i0.x, i1.y, i0.z)), tap(o, vec3<i32>(i1.x, i1.y, i0.z)), w.x);
        let c01 = mix(tap(o, vec3<i32>(i0.x, i0.y, i1.z)), tap(o, vec3<i32>(i1.x, i0.y, i1.z)), w.x);
        let c11 = mix(tap(o, vec3<i32>(i0.x, i1.y, i1.z)), tap(o, i1), w.x);
        v = mix(mix(c00, c10, w.y), mix(c01, c11, w.y), w.z);
    }
    let r = slots[leaf.slot].range;
    return r.x + r.y * v;
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
    let h = frame.spacing.xyz * f32(1u << (frame.counts.y - leaf.level));
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
