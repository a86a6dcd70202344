// Frame reconstruction's filter (G10 §5) on the GPU, over the frame's image
// buffer after the sub-frame's rays: the filter of backend/src/reconstruct.rs
// (its header says what it computes and why), pixel for pixel, in three
// dispatches: PHASE 0 takes the rendered sub-frame into each pixel's
// history, PHASE 1 fills the pixels diagonal to it from their four diagonal
// neighbours, PHASE 2 the others from their four axis neighbours. No pixel
// of a phase reads another pixel of the same phase.
//
// One invocation per 2×2 quad of every view (the views lie one after the
// other in the image, as the ray caster writes them).

struct Params {
    // The sub-frame's quad offset (x, y), the number of views, all quads.
    sub: vec4<u32>,
    // Colour change below which a pixel keeps its last rendering, above
    // which it takes the spatial estimate (DELTA_LOW, DELTA_HIGH).
    delta: vec4<f32>,
}

@group(0) @binding(0) var<uniform> params: Params;
// Per view: width, height, first pixel, end of its quads (exclusive).
@group(0) @binding(1) var<storage, read> views: array<vec4<u32>>;
@group(0) @binding(2) var<storage, read_write> image: array<vec4<f32>>;
// Each pixel's most recent rendering, the colour change from the one before
// (valid once it was rendered twice), and its renderings since the history
// was last reset (saturating at 2).
@group(0) @binding(3) var<storage, read_write> last: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read_write> change: array<f32>;
@group(0) @binding(5) var<storage, read_write> renders: array<u32>;

override PHASE: u32 = 0u;

// "No neighbour on this side": a pair with one neighbour never wins over a
// pair with two (the CPU filter's infinity).
const ONE_SIDED: f32 = 3.4028235e38;

fn diff(a: vec4<f32>, b: vec4<f32>) -> f32 {
    let d = abs(a - b);
    return max(max(max(max(0.0, d.x), d.y), d.z), d.w);
}

fn smoothstep01(x: f32) -> f32 {
    let t = clamp((x - params.delta.x) / (params.delta.y - params.delta.x), 0.0, 1.0);
    return t * t * (3.0 - 2.0 * t);
}

// Pixel (x, y) of view v, or -1 outside it.
fn pixel(v: vec4<u32>, x: i32, y: i32) -> i32 {
    if (x < 0 || y < 0 || x >= i32(v.x) || y >= i32(v.y)) {
        return -1;
    }
    return i32(v.z) + y * i32(v.x) + x;
}

fn change_of(j: i32) -> f32 {
    if (renders[j] >= 2u) {
        return change[j];
    }
    return 0.0;
}

// One opposite pair's mean and colour difference; w = 0 where it has no
// pixel.
struct Pair {
    mean: vec4<f32>,
    diff: f32,
    w: u32,
}

fn pair(a: i32, b: i32) -> Pair {
    var p: Pair;
    if (a >= 0 && b >= 0) {
        p.mean = 0.5 * (image[a] + image[b]);
        p.diff = diff(image[a], image[b]);
        p.w = 2u;
    } else if (a >= 0 || b >= 0) {
        p.mean = image[max(a, b)];
        p.diff = ONE_SIDED;
        p.w = 1u;
    }
    return p;
}

// Pixel (x, y) of view v, not rendered this frame, from its neighbours at
// offsets d0…d3 (opposite pairs d0–d1 and d2–d3) and its own history.
fn filtered(v: vec4<u32>, x: i32, y: i32, d: array<vec2<i32>, 4>) {
    let i = pixel(v, x, y);
    if (i < 0) {
        return;
    }
    var n: array<i32, 4>;
    for (var k = 0; k < 4; k = k + 1) {
        n[k] = pixel(v, x + d[k].x, y + d[k].y);
    }
    let p = pair(n[0], n[1]);
    let q = pair(n[2], n[3]);
    var spatial = last[i];
    if (p.w > 0u && q.w > 0u) {
        spatial = select(p.mean, q.mean, q.diff < p.diff);
    } else if (p.w > 0u) {
        spatial = p.mean;
    } else if (q.w > 0u) {
        spatial = q.mean;
    }
    if (renders[i] == 0u) {
        image[i] = spatial;
        return;
    }
    var dq = 0.0;
    for (var k = 0; k < 4; k = k + 1) {
        if (n[k] >= 0) {
            dq = max(dq, change_of(n[k]));
        }
    }
    let s = smoothstep01(dq);
    let own = last[i];
    if (s == 0.0) {
        image[i] = own;
    } else {
        image[i] = own + s * (spatial - own);
    }
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>,
        @builtin(num_workgroups) groups: vec3<u32>) {
    let quad = gid.x + gid.y * groups.x * 64u;
    if (quad >= params.sub.w) {
        return;
    }
    var first = 0u;
    var v = views[0];
    for (var k = 0u; k < params.sub.z; k = k + 1u) {
        v = views[k];
        if (quad < v.w) {
            break;
        }
        first = v.w;
    }
    let per_row = (v.x + 1u) / 2u;
    let qx = i32(2u * ((quad - first) % per_row));
    let qy = i32(2u * ((quad - first) / per_row));
    let ox = i32(params.sub.x);
    let oy = i32(params.sub.y);
    if (PHASE == 0u) {
        let i = pixel(v, qx + ox, qy + oy);
        if (i >= 0) {
            let now = image[i];
            if (renders[i] > 0u) {
                change[i] = diff(now, last[i]);
            }
            last[i] = now;
            renders[i] = min(renders[i] + 1u, 2u);
        }
    } else if (PHASE == 1u) {
        filtered(v, qx + (ox ^ 1), qy + (oy ^ 1),
                 array<vec2<i32>, 4>(vec2<i32>(-1, -1), vec2<i32>(1, 1), vec2<i32>(1, -1), vec2<i32>(-1, 1)));
    } else {
        let axis = array<vec2<i32>, 4>(vec2<i32>(-1, 0), vec2<i32>(1, 0), vec2<i32>(0, -1), vec2<i32>(0, 1));
        filtered(v, qx + (ox ^ 1), qy + oy, axis);
        filtered(v, qx + ox, qy + (oy ^ 1), axis);
    }
}
