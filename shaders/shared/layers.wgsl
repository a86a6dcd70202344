// shared/layers.wgsl: registered layers (`[[layer]]`, G10 §4), combined with
// the volume as media.
//
// A scene's layers lie on the volume's octree, so one traversal serves all:
// the pool's texels hold the volume's value (.r) and each layer's (.g, .b,
// .a), interpolated at once, and a slot's mask (the fourth word of its
// range) says which of them hold data there. Where media overlap their
// extinctions add and their extinction-weighted emissions add. A segment's
// optics are the averages of τ and k̃ = τ·c over it (G10 Eq. 2), so the
// summed medium's are the sums of each medium's averages, exactly: two
// layers of one volume with half its extinction each give the volume's
// segment. Each layer's averages come from its own pre-integration table
// (after the volume's in `tf_table`), scaled by the layer's opacity and by
// its view-dependent factor (G10 §4: "controlling a layer's opacity as a
// function of the view direction"). LAYERS (the chain module) is their
// count; without layers none of this is compiled in.
//
// A label layer (a segmentation and its colour table; LABELS, a constant of
// the chain module, has bit k set where layer k is one: without label
// layers none of their code is compiled in) is
// read at the nearest voxel, whole labels, never interpolated into another
// label; its table has a node at each label, holding the label's optics,
// and a segment between two labels takes each end's for half its length
// (`label_average`).

#import bindings
#import preint

// A layer placed by a transform (`[[layer]] transform`, resampled onto the
// volume's bricks: backend/src/loader/resample.rs) has voxels outside its
// box, where it is no medium at all: they hold NO_LAYER (−3e38, f32 pools
// only), and a value interpolated from one is below NO_LAYER_BELOW (any
// weight of 1e-18 or more puts it there), so the layer adds nothing to a
// segment with such an end. Data never comes near these values.
const NO_LAYER_BELOW: f32 = -1.0e20;

// Whether a layer has data at both ends of a segment.
fn layer_at(a: f32, b: f32) -> bool {
    return a > NO_LAYER_BELOW && b > NO_LAYER_BELOW;
}

var<private> layer_p: array<LayerParams, 3>;
// Each layer's share of τ̄ in the last segment (`layered_average`), for
// MImDA's combined importance.
var<private> layer_tau: vec3<f32>;

// The layers' constants, copied once per ray like the frame's.
fn load_layers() {
    if (LAYERS > 0u) {
        layer_p = layer_constants;
    }
}

fn is_label(k: u32) -> bool {
    return (LABELS & (1u << k)) != 0u;
}

// The layers' values at p from the layered pool's texel `v` there and the
// slot's ranges (value = lo + span · stored); a label layer's is the
// nearest voxel's label.
fn layer_values(leaf: Leaf, p: vec3<f32>, v: vec4<f32>, lo: vec3<f32>, span: vec3<f32>) -> vec3<f32> {
    var lay = lo + span * v.yzw;
    if (LABELS != 0u) {
        let near = lo + span * sample_nearest(leaf, p).yzw;
        for (var k = 0u; k < LAYERS; k = k + 1u) {
            if (is_label(k)) {
                lay[k] = round(near[k]);
            }
        }
    }
    return lay;
}

// A label's node in layer `p`'s table (`tf_entry(p.at.x + node)`).
fn label_node(p: LayerParams, label: f32) -> u32 {
    return u32(clamp((label - p.table.x) * p.table.y + 0.5, 0.0, p.table.z));
}

// A label layer's averages over a segment from label `a` to label `b`: the
// boundary between two labels lies somewhere between the samples, and each
// end's label holds for half the segment (G10 Eq. 2 over a medium constant
// on either side), read at the labels' nodes.
fn label_average(p: LayerParams, a: f32, b: f32) -> vec4<f32> {
    return 0.5 * (tf_entry(p.at.x + label_node(p, a)) + tf_entry(p.at.x + label_node(p, b)));
}

// Bin j's average over [j + ta, j + tb] in the part of layer `p`'s table
// at `base` (`bin_average`'s; every part has the layout of its first).
fn layer_bin_average(p: LayerParams, base: u32, j: u32, ta: f32, tb: f32) -> vec4<f32> {
    let mid = base + (p.at.y - p.at.x);
    return quadratic_average(tf_entry(base + j), tf_entry(mid + j),
                             tf_entry(base + j + 1u), ta, tb);
}

// Where pyramid level k of a table of n bins starts (common/src/tf/preint.rs
// `gpu_layout`): after the n + 1 nodes and the levels below it.
fn layer_level_offset(n: u32, k: u32) -> u32 {
    var o = n + 1u;
    for (var i = 0u; i < k; i = i + 1u) {
        o = o + (n >> i);
    }
    return o;
}

// The average of (τ, k̃) over the data segment [sa, sb] in layer `p`'s table.
fn layer_average(p: LayerParams, sa: f32, sb: f32) -> vec4<f32> {
    return layer_part_average(p, p.at.x, p.at.z, sa, sb);
}

// The average over the data segment [sa, sb] in the part of layer `p`'s
// table at `base` (its running integral at `prefix`, 0: none):
// `segment_average`'s sum, whole bins by the running integral where the
// table has one, else by the dyadic pyramid.
fn layer_part_average(p: LayerParams, base: u32, prefix: u32, sa: f32, sb: f32) -> vec4<f32> {
    let n = u32(p.table.z);
    var ua = clamp((sa - p.table.x) * p.table.y, 0.0, f32(n));
    var ub = clamp((sb - p.table.x) * p.table.y, 0.0, f32(n));
    if (ua > ub) {
        let t = ua;
        ua = ub;
        ub = t;
    }
    let ja = min(u32(ua), n - 1u);
    if (ub <= f32(ja + 1u)) {
        return layer_bin_average(p, base, ja, ua - f32(ja), min(ub - f32(ja), 1.0));
    }
    let jb = min(u32(ub), n);
    var sum = (f32(ja + 1u) - ua) * layer_bin_average(p, base, ja, ua - f32(ja), 1.0);
    var lo = ja + 1u;
    if (prefix != 0u) {
        let a = prefix + 2u * lo;
        let b = prefix + 2u * jb;
        sum = sum + (tf_entry(b) - tf_entry(a)) + (tf_entry(b + 1u) - tf_entry(a + 1u));
        lo = jb;
    }
    let top = p.at.w - 1u;
    while (lo < jb) {
        var k = top;
        if (lo != 0u) {
            k = min(countTrailingZeros(lo), top);
        }
        while ((1u << k) > jb - lo) {
            k = k - 1u;
        }
        sum = sum + tf_entry(base + layer_level_offset(n, k) + (lo >> k));
        lo = lo + (1u << k);
    }
    if (jb < n) {
        sum = sum + (ub - f32(jb)) * layer_bin_average(p, base, jb, 0.0, ub - f32(jb));
    }
    return sum / (ub - ua);
}

// A sample's end in layer `p`'s table (`tf_end`'s; LAYER_END, a constant of
// the chain module: every layer's table allows the end path).
fn layer_end(p: LayerParams, s: f32) -> TfEnd {
    return end_in(p.at.x, p.at.y, p.at.z, p.table.x, p.table.y, u32(p.table.z), s);
}

// A sample's ends in every layer's table (LAYER_END; none otherwise).
fn layer_ends(lay: vec3<f32>) -> array<TfEnd, 3> {
    var out: array<TfEnd, 3>;
    if (LAYER_END) {
        for (var k = 0u; k < LAYERS; k = k + 1u) {
            out[k] = layer_end(layer_p[k], lay[k]);
        }
    }
    return out;
}

// Each layer's weight along a ray of direction `d` (volume space): its
// opacity, times the smoothstep of the ray's angle to its axis where it has
// a view-dependent opacity.
fn layer_weights(d: vec3<f32>) -> vec3<f32> {
    var w = vec3<f32>(0.0);
    let u = normalize(d);
    for (var k = 0u; k < LAYERS; k = k + 1u) {
        let p = layer_p[k];
        var f = p.table.w;
        if (p.axis.w > 0.5) {
            let theta = acos(clamp(dot(u, p.axis.xyz), -1.0, 1.0));
            let t = clamp((theta - p.angles.x) * p.angles.y, 0.0, 1.0);
            f = f * t * t * (3.0 - 2.0 * t);
        }
        w[k] = f;
    }
    return w;
}

// What a segment knows of the layers: their values at its two ends (and
// with LAYER_END their table ends), and which media have data at both (bit
// 0 the volume, bit k layer k).
struct LayerSeg {
    a: vec3<f32>,
    b: vec3<f32>,
    ea: array<TfEnd, 3>,
    eb: array<TfEnd, 3>,
    mask: u32,
}

// Layer k's averages over the segment, from the ends or from the table.
fn layer_term(k: u32, a: f32, b: f32, ea: TfEnd, eb: TfEnd) -> vec4<f32> {
    if (is_label(k)) {
        return label_average(layer_p[k], a, b);
    }
    if (LAYER_END) {
        return end_average(ea, eb);
    }
    return layer_average(layer_p[k], a, b);
}

// The summed medium's (τ, k̃) averages over a segment: the volume's `vol`
// and each layer's, weighted by `w` (`layer_weights`), where each has data.
fn layered_average(vol: vec4<f32>, ls: LayerSeg, w: vec3<f32>) -> vec4<f32> {
    var sum = select(vec4<f32>(0.0), vol, (ls.mask & 1u) != 0u);
    if (MIMDA) {
        layer_tau = vec3<f32>(0.0);
    }
    if (LAYERS > 0u && (ls.mask & 2u) != 0u && w.x > 0.0 && layer_at(ls.a.x, ls.b.x)) {
        let t = w.x * layer_term(0u, ls.a.x, ls.b.x, ls.ea[0], ls.eb[0]);
        if (MIMDA) {
            layer_tau.x = t.x;
        }
        sum = sum + t;
    }
    if (LAYERS > 1u && (ls.mask & 4u) != 0u && w.y > 0.0 && layer_at(ls.a.y, ls.b.y)) {
        let t = w.y * layer_term(1u, ls.a.y, ls.b.y, ls.ea[1], ls.eb[1]);
        if (MIMDA) {
            layer_tau.y = t.x;
        }
        sum = sum + t;
    }
    if (LAYERS > 2u && (ls.mask & 8u) != 0u && w.z > 0.0 && layer_at(ls.a.z, ls.b.z)) {
        let t = w.z * layer_term(2u, ls.a.z, ls.b.z, ls.ea[2], ls.eb[2]);
        if (MIMDA) {
            layer_tau.z = t.x;
        }
        sum = sum + t;
    }
    return sum;
}

// The summed medium's importance over a segment (MImDA, G10 Eq. 3): each
// medium's average importance there, weighted by its share of the
// extinction (`vol_tau` the volume's, where it has data; each layer's from
// `layered_average`), as the emissions are. A layer's importance is its own
// function's; a label layer's, each end's label's for half the segment.
fn layered_importance(vol_tau: f32, vol_importance: f32, ls: LayerSeg) -> f32 {
    var num = vol_tau * vol_importance;
    var den = vol_tau;
    for (var k = 0u; k < LAYERS; k = k + 1u) {
        if (layer_tau[k] > 0.0) {
            let p = layer_p[k];
            var imp: f32;
            if (is_label(k)) {
                imp = 0.5 * (tf_entry(p.aux.x + label_node(p, ls.a[k])).x
                             + tf_entry(p.aux.x + label_node(p, ls.b[k])).x);
            } else {
                imp = layer_part_average(p, p.aux.x, p.aux.y, ls.a[k], ls.b[k]).x;
            }
            num = num + layer_tau[k] * imp;
            den = den + layer_tau[k];
        }
    }
    if (den > 0.0) {
        return num / den;
    }
    return vol_importance;
}
