// shared/traversal.wgsl: stackless octree traversal over the spatial index (G08 §5, G10 §5).

#import bindings

// A leaf `descend` found, and the first of its texels (it has read it).
struct Found {
    node: u32,
    a: vec4<u32>,
}

// Descends from `start` to the leaf containing u (root-box units, [0,1)³).
fn descend(start: u32, u: vec3<f32>) -> Found {
    var i = start;
    var a: vec4<u32>;
    loop {
        a = texel_at(frame_table, node_texel(i));
        let n = node_of(a, vec4<u32>(0u));
        let first = n.tree >> 16u;
        if (first == NONE16) {
            break;
        }
        // The child's offset along each axis its level halves, packed x
        // first (backend/src/index.rs).
        let level = (n.data >> 24u) + 1u;
        let s = level_split(level);
        let c = vec3<u32>(floor(u * level_cells(level))) & s;
        i = first + (c.x | (c.y << s.x) | (c.z << (s.x + s.y)));
    }
    return Found(i, a);
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
