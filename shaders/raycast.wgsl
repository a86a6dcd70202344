// Stackless octree ray casting (G08 §5, G10 §5 "Stackless octree raycaster")
// with pre-integrated emission–absorption (G10 §4 Eq. 2) over the brick pool.
//
// One invocation per pixel; gid.z is the view. The ray of a pixel comes from
// G10 Eq. 1 (DESIGN.md "Which ray a pixel gets"), is moved to volume space
// (data length units) and clipped to the volume's box. Traversal descends
// from the root to the leaf that contains the current point, marches through
// the leaf's brick at a step matched to its level (or skips it when it has no
// data: empty under the transfer function, or dropped at import), leaves it
// through a face, follows that face's neighbour pointer and descends again.
//
// Rust mirrors: `IndexNode` (backend/src/index.rs), `GpuFrame`, `GpuView`
// (backend/src/raycast/params.rs). Keep field order and sizes in step.

override SHADING: bool = false;
// Trilinear filtering by the texture unit (one sample) instead of eight
// loads; off where the pool's format is not filterable on this device.
override HW_FILTER: bool = false;

const NONE16: u32 = 0xFFFFu;
const NO_SLOT: u32 = 0xFFFFFFu;
const OVERLAP: f32 = 2.0;
const MAX_NODES_PER_RAY: u32 = 65536u;

struct IndexNode {
    tree: u32,   // parent (low 16) | first child (high 16)
    data: u32,   // level (high 8) | pool slot (low 24)
    range: u32,  // unorm16 min (low) | max (high) of the dataset range
    nx: u32,     // neighbour −x (low 16) | +x (high 16)
    ny: u32,
    nz: u32,
}

struct GpuView {
    region: vec4<f32>,    // x0, y0, w, h (m) on the screen plane
    eye: vec4<f32>,       // projector / eye E (m); w = η
    observer: vec4<f32>,  // observer V (m)
    size: vec4<u32>,      // W, H, first pixel of this view in `image`, 0
}

struct GpuFrame {
    rt0: vec4<f32>,       // columns of Rᵀ (display → volume rotation)
    rt1: vec4<f32>,
    rt2: vec4<f32>,
    center: vec4<f32>,    // placement centre (m); w = data units per metre
    extent: vec4<f32>,    // N·s: the volume's box (data units)
    domain: vec4<f32>,    // B·2^L·s: the root node's box (data units)
    spacing: vec4<f32>,   // s; w = min(s)
    tf: vec4<f32>,        // table vmin, bin width, bins, 0
    render: vec4<f32>,    // step factor, early-termination opacity, probe offset (root units: 1% of a source voxel), 0
    light: vec4<f32>,     // Phong ka, kd, ks, shininess
    counts: vec4<u32>,    // B, leaf level L, table levels, running-integral offset (0: none)
    pool: vec4<u32>,      // slots per axis x, y, z; stored brick side B + 2·OVERLAP
    tf_offsets: array<vec4<u32>, 8>,  // pyramid level offsets (32)
}

@group(0) @binding(0) var<uniform> frame: GpuFrame;
@group(0) @binding(1) var<storage, read> views: array<GpuView>;
@group(0) @binding(2) var<storage, read> index: array<IndexNode>;
@group(0) @binding(3) var pool: texture_3d<f32>;
@group(0) @binding(4) var<storage, read> slot_range: array<vec2<f32>>;  // (min, max − min) per slot
// (τ, k̃r, k̃g, k̃b) interleaved: node values, then the pyramid levels.
@group(0) @binding(5) var<storage, read> table: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read_write> feedback: array<u32>;
@group(0) @binding(7) var<storage, read_write> image: array<vec4<f32>>;
@group(0) @binding(8) var pool_sampler: sampler;

// ---------------------------------------------------------------------------
// Pre-integration (G10 §4 Eq. 2) over the sum pyramid of common/src/tf
// (or, where the table allows, its running integral as an f32 pair):
// the average of (τ, k̃r, k̃g, k̃b) over the data segment [a, b].

fn tf_offset(k: u32) -> u32 {
    return frame.tf_offsets[k >> 2u][k & 3u];
}

fn node4(j: u32) -> vec4<f32> {
    return table[j];
}

fn lerp4(u: f32) -> vec4<f32> {
    let n = u32(frame.tf.z);
    let j = min(u32(u), n - 1u);
    let t = u - f32(j);
    return (1.0 - t) * node4(j) + t * node4(j + 1u);
}

fn segment_average(sa: f32, sb: f32) -> vec4<f32> {
    let n = u32(frame.tf.z);
    var ua = clamp((sa - frame.tf.x) / frame.tf.y, 0.0, f32(n));
    var ub = clamp((sb - frame.tf.x) / frame.tf.y, 0.0, f32(n));
    if (ua > ub) {
        let t = ua;
        ua = ub;
        ub = t;
    }
    let ja = min(u32(ua), n - 1u);
    if (ub <= f32(ja + 1u)) {
        // Same bin: the exact average of a linear function, no division
        // (this is Eq. 2's "|s_i − s_{i−1}| ≤ ε" branch, made exact).
        return 0.5 * (lerp4(ua) + lerp4(ub));
    }
    let jb = min(u32(ub), n);
    var sum = (f32(ja + 1u) - ua) * 0.5 * (lerp4(ua) + node4(ja + 1u));
    var lo = ja + 1u;
    let prefix = frame.counts.w;
    if (prefix != 0u) {
        // Whole bins [ja+1, jb) by the running integral, an f32 pair per
        // node: (hi_b − hi_a) + (lo_b − lo_a); exact zero for no bins.
        let a = prefix + 2u * lo;
        let b = prefix + 2u * jb;
        sum = sum + (table[b] - table[a]) + (table[b + 1u] - table[a + 1u]);
        lo = jb;
    }
    let top = frame.counts.z - 1u;
    // Whole bins as aligned dyadic blocks: every term ≥ 0, nothing cancels.
    while (lo < jb) {
        var k = top;
        if (lo != 0u) {
            k = min(countTrailingZeros(lo), top);
        }
        while ((1u << k) > jb - lo) {
            k = k - 1u;
        }
        sum = sum + table[tf_offset(k) + (lo >> k)];
        lo = lo + (1u << k);
    }
    if (jb < n) {
        sum = sum + (ub - f32(jb)) * 0.5 * (node4(jb) + lerp4(ub));
    }
    return sum / (ub - ua);
}

// ---------------------------------------------------------------------------
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
    if (HW_FILTER) {
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
    let r = slot_range[leaf.slot];
    return r.x + r.y * v;
}

fn gradient(leaf: Leaf, p: vec3<f32>) -> vec3<f32> {
    let h = frame.spacing.xyz * f32(1u << (frame.counts.y - leaf.level));
    let gx = sample_brick(leaf, p + vec3<f32>(h.x, 0.0, 0.0)) - sample_brick(leaf, p - vec3<f32>(h.x, 0.0, 0.0));
    let gy = sample_brick(leaf, p + vec3<f32>(0.0, h.y, 0.0)) - sample_brick(leaf, p - vec3<f32>(0.0, h.y, 0.0));
    let gz = sample_brick(leaf, p + vec3<f32>(0.0, 0.0, h.z)) - sample_brick(leaf, p - vec3<f32>(0.0, 0.0, h.z));
    return vec3<f32>(gx / h.x, gy / h.y, gz / h.z) * 0.5;
}

// ---------------------------------------------------------------------------
// Octree traversal.

// Descends from `start` to the leaf containing u (root-box units, [0,1)³).
fn descend(start: u32, u: vec3<f32>) -> u32 {
    var i = start;
    loop {
        let n = index[i];
        let first = n.tree >> 16u;
        if (first == NONE16) {
            break;
        }
        let level = (n.data >> 24u) + 1u;
        let c = vec3<u32>(floor(u * f32(1u << level))) & vec3<u32>(1u);
        i = first + (c.x | (c.y << 1u) | (c.z << 2u));
    }
    return i;
}

fn neighbour(n: IndexNode, axis: u32, plus: bool) -> u32 {
    var w = n.nx;
    if (axis == 1u) {
        w = n.ny;
    } else if (axis == 2u) {
        w = n.nz;
    }
    if (plus) {
        return w >> 16u;
    }
    return w & 0xFFFFu;
}

struct Acc {
    color: vec3<f32>,
    alpha: f32,
}

// Front-to-back compositing of one pre-integrated segment of length d.
fn composite(acc: ptr<function, Acc>, avg: vec4<f32>, d: f32, shade: f32) {
    let x = max(avg.x, 0.0) * d;
    var a: f32;
    var w: f32;  // α / τ̄, the weight of the emission (→ d as τ̄·d → 0)
    if (x < 1e-4) {
        a = x * (1.0 - 0.5 * x);
        w = d * (1.0 - 0.5 * x);
    } else {
        a = 1.0 - exp(-x);
        w = a / max(avg.x, 1e-30);
    }
    let c = max(avg.yzw, vec3<f32>(0.0)) * w * shade;
    let t = 1.0 - (*acc).alpha;
    (*acc).color = (*acc).color + t * c;
    (*acc).alpha = (*acc).alpha + t * a;
}

fn clip_box(o: vec3<f32>, d: vec3<f32>, hi: vec3<f32>) -> vec2<f32> {
    let inv = 1.0 / select(d, vec3<f32>(1e-30), abs(d) < vec3<f32>(1e-30));
    let ta = (vec3<f32>(0.0) - o) * inv;
    let tb = (hi - o) * inv;
    let tmin = min(ta, tb);
    let tmax = max(ta, tb);
    let t0 = max(max(max(tmin.x, tmin.y), tmin.z), 0.0);
    let t1 = min(min(tmax.x, tmax.y), tmax.z);
    return vec2<f32>(t0, t1);
}

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let view = views[gid.z];
    if (gid.x >= view.size.x || gid.y >= view.size.y) {
        return;
    }
    let out = view.size.z + gid.y * view.size.x + gid.x;

    // G10 Eq. 1: the ray of screen point Q for projector E and observer V.
    let q = vec3<f32>(
        view.region.x + (f32(gid.x) + 0.5) / f32(view.size.x) * view.region.z,
        view.region.y + view.region.w - (f32(gid.y) + 0.5) / f32(view.size.y) * view.region.w,
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

    // Display → volume space: p = Rᵀ(x − centre)/scale + N·s/2.
    let rt = mat3x3<f32>(frame.rt0.xyz, frame.rt1.xyz, frame.rt2.xyz);
    let o = rt * (origin - frame.center.xyz) * frame.center.w + 0.5 * frame.extent.xyz;
    let d = normalize(rt * dir_display);

    var acc = Acc(vec3<f32>(0.0), 0.0);
    let span = clip_box(o, d, frame.extent.xyz);
    if (span.y <= span.x) {
        image[out] = vec4<f32>(0.0);
        return;
    }

    let step_factor = frame.render.x;
    let opaque = frame.render.y;
    // A point on a face belongs to the node the ray is entering: probe a
    // hundredth of a source voxel further along every axis of travel.
    let nudge = sign(d) * frame.render.z;
    let inv_d = 1.0 / select(d, vec3<f32>(1e-30), abs(d) < vec3<f32>(1e-30));
    var t = span.x;
    var probe = (o + d * t) / frame.domain.xyz + nudge;
    var node = descend(0u, clamp(probe, vec3<f32>(0.0), vec3<f32>(0.99999994)));
    var s_prev = 0.0;
    var have_prev = false;
    for (var visited = 0u; visited < MAX_NODES_PER_RAY; visited = visited + 1u) {
        let n = index[node];
        let level = n.data >> 24u;
        let cells = f32(1u << level);
        let size = frame.domain.xyz / cells;
        let cell = clamp(floor(probe * cells), vec3<f32>(0.0), vec3<f32>(cells - 1.0));
        let lo = cell * size;
        let hi = lo + size;
        let tx = select(select((lo - o) * inv_d, (hi - o) * inv_d, d > vec3<f32>(0.0)),
                        vec3<f32>(3.0e38), abs(d) < vec3<f32>(1e-30));
        var t_exit = min(min(tx.x, tx.y), tx.z);
        var axis = 0u;
        if (tx.y <= tx.x && tx.y <= tx.z) {
            axis = 1u;
        } else if (tx.z <= tx.x && tx.z <= tx.y) {
            axis = 2u;
        }
        let last = t_exit >= span.y;
        t_exit = clamp(t_exit, t, span.y);

        let slot = n.data & NO_SLOT;
        if (slot != NO_SLOT && t_exit > t) {
            let leaf = Leaf(node, level, cell, slot);
            // Sampling rate matched to the leaf's level.
            let h = step_factor * frame.spacing.w * f32(1u << (frame.counts.y - level));
            if (!have_prev) {
                s_prev = sample_brick(leaf, o + d * t);
                have_prev = true;
            }
            var tc = t;
            loop {
                let tn = min(tc + h, t_exit);
                let s = sample_brick(leaf, o + d * tn);
                let avg = segment_average(s_prev, s);
                var shade = 1.0;
                // A transparent segment adds nothing: no gradient needed.
                if (SHADING && avg.x > 0.0) {
                    let g = gradient(leaf, o + d * (0.5 * (tc + tn)));
                    let gl = length(g);
                    if (gl > 1e-6) {
                        // Two-sided Phong with a headlight.
                        let diff = abs(dot(g / gl, d));
                        shade = frame.light.x + frame.light.y * diff + frame.light.z * pow(diff, frame.light.w);
                    }
                }
                composite(&acc, avg, tn - tc, shade);
                s_prev = s;
                tc = tn;
                if (tc >= t_exit || acc.alpha >= opaque) {
                    break;
                }
            }
            // Visibility feedback (G10 §5): this leaf contributed.
            feedback[node] = 1u;
        } else {
            // Nothing to integrate here; the next brick restarts its segment.
            have_prev = false;
        }
        if (last || acc.alpha >= opaque) {
            break;
        }
        // Leave through the exit face and follow its neighbour pointer.
        let next = neighbour(n, axis, d[axis] > 0.0);
        if (next == NONE16) {
            break;
        }
        t = t_exit;
        // Probe just across the exit face, inside this leaf's face on the
        // other axes: a point the neighbour's box is sure to contain.
        let eps = frame.render.z;
        let lo_u = lo / frame.domain.xyz + eps;
        let hi_u = hi / frame.domain.xyz - eps;
        probe = clamp((o + d * t) / frame.domain.xyz, lo_u, hi_u);
        if (d[axis] > 0.0) {
            probe[axis] = hi_u[axis] + 2.0 * eps;
        } else {
            probe[axis] = lo_u[axis] - 2.0 * eps;
        }
        node = descend(next, clamp(probe, vec3<f32>(0.0), vec3<f32>(0.99999994)));
    }
    image[out] = vec4<f32>(acc.color, acc.alpha);
}
