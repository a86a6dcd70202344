// overlay.wgsl: tool geometry over the volume images (G10 §5, "overlaying
// rasterised images"; backend/src/overlay.rs). Each vertex belongs to a
// line segment a–b drawn `width` pixels wide, or to a quad of pixel
// offsets about one point (a dot, a glyph's pixel). The vertex stage
// projects display points into the view of its instance by G10 Eq. 1's
// rays (common/src/overlay.rs `project`): in a light field view a point
// lands where the projector's ray through it leaves the projector, so
// every eye sees the geometry at the same place in space. A straight edge
// bends under that projection; the CPU cuts it into short segments.
//
// Depth combination (`pixels.y`): a fragment farther along its pixel's ray
// than where the volume's opacity reached ½ (`depth`, recorded by the ray
// caster in volume units from the ray's origin; ≤ 0: no such point) is
// hidden. Rays are straight there: refraction refuses it.

struct OverlayView {
    region: vec4<f32>,    // x0, y0, w, h of the screen region (m)
    eye: vec4<f32>,       // projector E, η
    observer: vec4<f32>,  // observer V
    size: vec4<f32>,      // width, height (pixels), line width (pixels), volume units per metre
    pixels: vec4<u32>,    // first pixel of the view in `depth`, depth combination (1) or not (0)
}

@group(0) @binding(0) var<storage, read> views: array<OverlayView>;
@group(0) @binding(1) var<storage, read> depth: array<f32>;

struct VertexIn {
    @location(0) a: vec4<f32>,       // xyz: one end (display, m); w: along (0 at a, 1 at b)
    @location(1) b: vec4<f32>,       // xyz: the other end; w: side (−1, 1; 0 for quads)
    @location(2) offset: vec4<f32>,  // xy: pixel offset (quads)
    @location(3) color: vec4<f32>,   // straight alpha
}

struct VertexOut {
    @builtin(position) pos: vec4<f32>,
    @location(0) color: vec4<f32>,
    @location(1) world: vec3<f32>,   // the display point drawn
    @location(2) @interpolate(flat) view: u32,
}

// Pixel coordinates (x right, y down) of display point x in view v, and 1
// in z where a ray of the view reaches it (0 behind the observer).
fn project(v: OverlayView, x: vec3<f32>) -> vec3<f32> {
    let vz = v.observer.z;
    let t = 1.0 - x.z / vz;
    if (!(t > 1e-6)) {
        return vec3<f32>(0.0);
    }
    var c = 0.0;
    if (abs(v.eye.z) > 1e-9) {
        c = (v.eye.z - vz) / v.eye.z;
    }
    let eta = v.eye.w;
    let a = (1.0 - eta) * v.observer.x + eta * v.eye.x * (1.0 - c);
    let b = eta * c;
    let den = b * (1.0 - t) + t;
    if (abs(den) < 1e-9) {
        return vec3<f32>(0.0);
    }
    let qx = (x.x - a * (1.0 - t)) / den;
    let qy = v.observer.y + (x.y - v.observer.y) / t;
    return vec3<f32>((qx - v.region.x) / v.region.z * v.size.x,
                     (v.region.y + v.region.w - qy) / v.region.w * v.size.y, 1.0);
}

@vertex
fn vs(vin: VertexIn, @builtin(instance_index) view: u32) -> VertexOut {
    let v = views[view];
    var out: VertexOut;
    out.color = vin.color;
    out.view = view;
    out.world = mix(vin.a.xyz, vin.b.xyz, vin.a.w);
    let pa = project(v, vin.a.xyz);
    let pb = project(v, vin.b.xyz);
    if (pa.z < 0.5 || pb.z < 0.5) {
        // Behind the observer: outside the clip volume.
        out.pos = vec4<f32>(0.0, 0.0, 2.0, 1.0);
        return out;
    }
    let along = vin.a.w;
    let side = vin.b.w;
    var p = mix(pa.xy, pb.xy, along);
    let d = pb.xy - pa.xy;
    let l = length(d);
    if (l > 1e-6) {
        // Widen the segment across, and by half a width at each end so
        // that consecutive segments join.
        let u = d / l;
        let n = vec2<f32>(-u.y, u.x);
        let hw = 0.5 * v.size.z;
        p = p + n * (side * hw) + u * ((along * 2.0 - 1.0) * hw);
    }
    p = p + vin.offset.xy;
    out.pos = vec4<f32>(p.x / v.size.x * 2.0 - 1.0, 1.0 - p.y / v.size.y * 2.0, 0.0, 1.0);
    return out;
}

// The origin of the ray of the pixel whose centre is at `px` (G10 Eq. 1,
// as the ray caster's `pixel_ray`).
fn ray_origin(v: OverlayView, px: vec2<f32>) -> vec3<f32> {
    let qx = v.region.x + px.x / v.size.x * v.region.z;
    let e = v.eye.xyz;
    let o = v.observer.xyz;
    var mcop_x = o.x;
    if (abs(e.z) > 1e-12) {
        mcop_x = e.x + (qx - e.x) / (-e.z) * (o.z - e.z);
    }
    return vec3<f32>((1.0 - v.eye.w) * o.x + v.eye.w * mcop_x, o.y, o.z);
}

@fragment
fn fs(vin: VertexOut) -> @location(0) vec4<f32> {
    let v = views[vin.view];
    if (v.pixels.y != 0u) {
        let px = vec2<u32>(vin.pos.xy);
        let d = depth[v.pixels.x + px.y * u32(v.size.x) + px.x];
        if (d > 0.0) {
            let t = length(vin.world - ray_origin(v, vin.pos.xy)) * v.size.w;
            if (t > d) {
                discard;
            }
        }
    }
    return vec4<f32>(vin.color.rgb * vin.color.a, vin.color.a);
}
