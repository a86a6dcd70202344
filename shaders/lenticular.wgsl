// lenticular.wgsl: a Looking Glass panel from its views (the mapping of
// common/src/lenticular.rs). One invocation per panel pixel; each of its
// three sub-pixels takes its channel from the view its lens shows there.
// The views are linear premultiplied RGBA, view k at k·w·h, row 0 at the
// top; the panel likewise (converted to sRGB bytes as a PNG is, on the
// CPU, so the panel file and the screen hold the same bytes).

struct Params {
    size: vec4<u32>,   // panel W, H; view w, h
    views: vec4<u32>,  // N, flip x, flip y, flip sub-pixels
    map: vec4<f32>,    // pitch (lens periods across the panel), tilt, sub-pixel step, center
    inv: vec4<u32>,    // inverted views, 0, 0, 0
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> views: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> panel: array<vec4<f32>>;

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let pw = params.size.x;
    let ph = params.size.y;
    if (id.x >= pw || id.y >= ph) {
        return;
    }
    let vw = params.size.z;
    let vh = params.size.w;
    let n = params.views.x;
    // The pixel's centre, u to the right and v up.
    let u = (f32(id.x) + 0.5) / f32(pw);
    let v = 1.0 - (f32(id.y) + 0.5) / f32(ph);
    // Where the views are sampled: the panel point, flipped as the device
    // says (nearest texel).
    let su = select(u, 1.0 - u, params.views.y != 0u);
    let sv = select(v, 1.0 - v, params.views.z != 0u);
    let tx = min(u32(su * f32(vw)), vw - 1u);
    let ty = min(u32((1.0 - sv) * f32(vh)), vh - 1u);
    var out = vec4<f32>(0.0, 0.0, 0.0, 1.0);
    for (var c = 0u; c < 3u; c = c + 1u) {
        // The lens phase of sub-pixel k; with flipped sub-pixels red shows
        // the phase of the third and blue that of the first.
        var k = c;
        if (params.views.w != 0u && c != 1u) {
            k = 2u - c;
        }
        let a = (u + f32(k) * params.map.z + v * params.map.y) * params.map.x - params.map.w;
        var f = a - floor(a);
        if (params.inv.x != 0u) {
            f = 1.0 - f;
        }
        let view = min(u32(f * f32(n)), n - 1u);
        out[c] = views[(view * vh + ty) * vw + tx][c];
    }
    panel[id.y * pw + id.x] = out;
}
