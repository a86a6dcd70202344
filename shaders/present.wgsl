// present.wgsl: a projector's image, straight from the ray caster's image
// buffer on the device, into its viewport of an output's window (no
// read-back). One full-screen triangle per projector, clipped to its
// viewport by the scissor rect. The colour is the PNG's: the 8-bit sRGB
// code of each linear channel, found among the codes' thresholds (the
// least linear value of each code, backend/src/output.rs), so the screen
// and the files hold the same bytes.

struct Tile {
    // First pixel of the projector's image in `image`, its width, and the
    // viewport's top left in the window.
    offset: u32,
    width: u32,
    x0: u32,
    y0: u32,
}

@group(0) @binding(0) var<uniform> tile: Tile;
@group(0) @binding(1) var<storage, read> image: array<vec4<f32>>;
// threshold[k] (k = 0…255, as 64 vec4s): the least linear value of code k.
@group(0) @binding(2) var<uniform> thresholds: array<vec4<f32>, 64>;

@vertex
fn vs(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    let x = f32(i & 1u) * 4.0 - 1.0;
    let y = f32(i >> 1u) * 4.0 - 1.0;
    return vec4<f32>(x, y, 0.0, 1.0);
}

fn threshold(k: u32) -> f32 {
    return thresholds[k >> 2u][k & 3u];
}

// The sRGB code of a linear value (clamped to [0, 1]), as a unorm value.
fn code(v: f32) -> f32 {
    let x = clamp(v, 0.0, 1.0);
    var k = 0u;
    for (var step = 128u; step > 0u; step = step >> 1u) {
        if (x >= threshold(k + step)) {
            k = k + step;
        }
    }
    return f32(k) / 255.0;
}

@fragment
fn fs(@builtin(position) p: vec4<f32>) -> @location(0) vec4<f32> {
    let x = u32(p.x) - tile.x0;
    let y = u32(p.y) - tile.y0;
    let c = image[tile.offset + y * tile.width + x];
    return vec4<f32>(code(c.r), code(c.g), code(c.b), 1.0);
}
