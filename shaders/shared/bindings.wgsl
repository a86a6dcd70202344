// shared/bindings.wgsl: the structs every ray-casting kernel reads and their bindings.
//
// Rust mirrors: `IndexNode` (backend/src/index.rs), `GpuFrame`, `GpuView`
// (backend/src/raycast/params.rs); a test checks them against naga's layout.

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
    size: vec4<u32>,      // W, H, first pixel of this view in `image`, sub-frame (0: all pixels, 1 + k: quincunx sub-frame k)
}

struct GpuFrame {
    rt0: vec4<f32>,       // columns of Rᵀ (display → volume rotation)
    rt1: vec4<f32>,
    rt2: vec4<f32>,
    center: vec4<f32>,    // placement centre (m); w = data units per metre
    extent: vec4<f32>,    // N·s: the volume's box (data units); w = sub-pixel accuracy (< 1; 0: off, leaf_step)
    domain: vec4<f32>,    // B·2^L·s: the root node's box (data units)
    spacing: vec4<f32>,   // s; w = min(s)
    tf: vec4<f32>,        // table vmin, bin width, bins, nodes per axis of the 2D table (0: none)
    render: vec4<f32>,    // step factor, early-termination opacity, probe offset (root units: 1% of a source voxel), adaptive step (1: L12 Eq. 3)
    light: vec4<f32>,     // Phong ka, kd, ks, shininess
    counts: vec4<u32>,    // B, leaf level L, table levels, running-integral offset (0: none)
    pool: vec4<u32>,      // slots per axis x, y, z; stored brick side B + 2·OVERLAP
    optics: vec4<f32>,    // MImDA γ, the transfer function's largest importance, record depth (1: the overlay's depth combination), the refinement's parts
    aux: vec4<u32>,       // (ι, ν, 0, 0) table: first entry, running-integral offset (0: none); macrocells per brick axis C, voxels per cell side M
    iso: vec4<f32>,       // isovalue, the surface's linear RGB colour (mode "iso")
    predict: vec4<f32>,   // prediction buffer: mode (0 off, 1 full traversal, 2 predicted), local window (data units), κ low, κ high
    tf_offsets: array<vec4<u32>, 8>,  // pyramid level offsets (32)
    tf_mids: vec4<u32>,   // offset of the bin midpoint values in a table part, 0, 0, 0
    lod: vec4<f32>,       // multilevel sampling: accuracy (pixels per voxel), light field s0 (m), tan(Φ/2), light field (1) or not (0)
    splits: vec4<u32>,    // per axis, the levels that halve it (bit l: level l against l − 1), 0
    dispatch: vec4<u32>,  // tiles listed; first texel of the index, of the tiles in `frame_table`; tiles that meet a tool's region (listed first)
    recip: vec4<f32>,     // 1 / the pool's texels along x, y, z; 1 / the table's bin width
    grid: vec4<f32>,      // 2D table: nodes per data unit, n − 1, 1 / n, 0 (products, not quotients, per sample)
}

// A tool's constant parameters (their meaning is the enhancer's: see
// shaders/enhancers/).
struct ToolParams {
    a: vec4<f32>,
    b: vec4<f32>,
    c: vec4<f32>,
    d: vec4<f32>,
}

// The frame's and the tools' constants are read from private copies that
// `main` makes at its start (`load_constants`): lavapipe reads a buffer
// through a per-lane, bounds-checked gather wherever it cannot prove the
// offset uniform, and it did so for every use of these fields inside the
// sample loop; a copy is read once per ray and then lives in registers or
// on the stack. On the Colin27 brain it took 14–21 % off the frame
// (docs/performance.md, "Kernel changes on a CPU device"). On a GPU the copy
// is one read per ray of the fields the kernel uses.
//
// The constants are read-only storage, not uniform buffers: lavapipe
// compiles a new variant of a kernel for each set of values of the uniform
// words its branches test ("inlined uniforms") and keeps every variant, so
// constants that change each frame (the view, the tiles listed) made it
// compile the kernel again each frame and keep it: about 0.6 MiB and a
// compilation a frame in the live soak (docs/performance.md, "Constants in
// storage").
@group(0) @binding(0) var<storage, read> frame_constants: GpuFrame;
var<private> frame: GpuFrame;
// The frame's views, spatial index and tiles, in texels of four words
// (backend/src/raycast/texels.rs: a CPU device reads a storage buffer one
// lane and word at a time, a texture by gathers): `view_at`, `node_at`,
// `tile_at`.
@group(0) @binding(1) var frame_table: texture_2d<u32>;
@group(0) @binding(3) var pool: texture_3d<f32>;
// Per pool slot, in SLOT_TEXELS (7) texels (backend/src/raycast/pool.rs):
// its value range (min, max − min, variance on [0, 1] among bricks, and in
// a layered pool the mask of the media with data; f32 bits), then its
// empty macrocells (L12 §4.1): 16 words of bits, one per cell of the brick
// (C³ ≤ 512 cells of M³ voxels), set where the transfer function is τ ≡ 0
// over every value interpolation there can give (in a layered pool, every
// medium's), then the registered layers' ranges (`layer_ranges`).
@group(0) @binding(4) var slot_table: texture_2d<u32>;
// (τ, k̃r, k̃g, k̃b) interleaved: node values, then the pyramid levels.
@group(0) @binding(5) var tf_table: texture_2d<u32>;
@group(0) @binding(6) var<storage, read_write> feedback: array<u32>;
@group(0) @binding(7) var<storage, read_write> image: array<vec4<f32>>;
@group(0) @binding(8) var pool_sampler: sampler;
@group(0) @binding(9) var<storage, read> tool_constants: array<ToolParams, 3>;
var<private> tools: array<ToolParams, 3>;
// Isosurfaces: each pixel's last hit distance along its ray (volume units),
// or PB_MISS_SURFACE / PB_MISS_BOX (B10 §4.1). Read and written per pixel.
@group(0) @binding(10) var<storage, read_write> prediction: array<f32>;
// Samples taken this frame (COUNT_SAMPLES), a 64-bit count: low, high.
@group(0) @binding(11) var<storage, read_write> counters: array<atomic<u32>, 4>;
// The 2D pre-integration table (`preintegration = "2d"`; a 1×1 stand-in
// otherwise) and its bilinear sampler.
@group(0) @binding(12) var preint_grid: texture_2d<f32>;
@group(0) @binding(13) var grid_sampler: sampler;

// The transfer function's DVR channels in closed form (`preintegration =
// "analytic"`, common/src/tf/closed.rs `ClosedForm::gpu`): per piece
// [start, start + width] of the data range, f(x) = q0 + 2·q1·x + 3·q2·x² of
// (τ, k̃r, k̃g, k̃b) in x = s − start.
struct TfPiece {
    span: vec4<f32>,  // start, width, 0, 0
    q0: vec4<f32>,
    q1: vec4<f32>,
    q2: vec4<f32>,
}

// Whether segments are pre-integrated in closed form, and over how many
// pieces (a constant, so that a scene pays for the pieces it has).
override ANALYTIC_PREINT: bool = false;
override TF_PIECES: u32 = 0u;

struct TfPieces {
    range: vec4<f32>,  // data vmin, vmax (sample values are clamped to them), segment widening ε, pieces
    piece: array<TfPiece, 16>,
}

// Read from a private copy, as the frame's constants are (see below): read
// from the buffer itself, even at constant indices, the brain's frame of
// docs/performance.md ("Kernel changes on a CPU device") took 81 ms against 41.
@group(0) @binding(14) var<storage, read> tf_pieces_constants: TfPieces;
var<private> tf_pieces: TfPieces;

// Registered layers (shared/layers.wgsl): each layer's table in `tf_table`,
// opacity and view-dependent opacity (Rust mirror: `LayerParams`,
// backend/src/raycast/params.rs).
struct LayerParams {
    table: vec4<f32>,   // vmin, 1 / bin width, bins, opacity
    at: vec4<u32>,      // first entry, the bin midpoints' first entry, the running integral's first entry (0: none), pyramid levels
    axis: vec4<f32>,    // view-dependent opacity: its axis (volume space, unit); w: 1 where it has one
    angles: vec4<f32>,  // its angles (radians): from, 1 / (to − from), 0, 0
    aux: vec4<u32>,     // its (ι, ν) part: first entry, the running integral's first entry (0: none)
}
@group(0) @binding(15) var<storage, read> layer_constants: array<LayerParams, 3>;

fn load_constants() {
    frame = frame_constants;
    tools = tool_constants;
    if (ANALYTIC_PREINT) {
        tf_pieces = tf_pieces_constants;
    }
}

// Texel `i` of a table, 256 texels a row (texels::ROW).
fn texel_at(table: texture_2d<u32>, i: u32) -> vec4<u32> {
    return textureLoad(table, vec2<u32>(i & 255u, i >> 8u), 0);
}

fn view_at(i: u32) -> GpuView {
    let t = 4u * i;
    return GpuView(bitcast<vec4<f32>>(texel_at(frame_table, t)),
                   bitcast<vec4<f32>>(texel_at(frame_table, t + 1u)),
                   bitcast<vec4<f32>>(texel_at(frame_table, t + 2u)),
                   texel_at(frame_table, t + 3u));
}

// Node `i` of the spatial index is two texels from `node_texel(i)`:
// (tree, data, range, nx) and (ny, nz, and the value range of its pool
// slot: min, max − min as f32 bits). A texel whose fields are not used is
// not read (the compiler drops it).
fn node_texel(i: u32) -> u32 {
    return frame.dispatch.y + 2u * i;
}

fn node_of(a: vec4<u32>, b: vec4<u32>) -> IndexNode {
    return IndexNode(a.x, a.y, a.z, a.w, b.x, b.y);
}

fn node_at(i: u32) -> IndexNode {
    let t = node_texel(i);
    return node_of(texel_at(frame_table, t), texel_at(frame_table, t + 1u));
}

// The data values of node `i`'s brick: min, max − min (the slot's range,
// copied into the node so that entering a leaf reads no slot texel).
fn node_values(i: u32) -> vec2<f32> {
    return bitcast<vec2<f32>>(texel_at(frame_table, node_texel(i) + 1u).zw);
}

// The 8×8 tile workgroup `w` runs: (view, tile x | tile y << 16)
// (backend/src/raycast/tiles.rs), two a texel.
// The pipeline for the tiles that can meet a tool's region: the first
// frame.dispatch.w listed tiles (backend/src/raycast/tiles.rs
// `flag_regions`); the other pipeline runs the rest, with everything the
// enhancers read there compiled out (a CPU device runs the body of every
// branch for all lanes, taken or not).
override TOOL_TILES: bool = false;

fn tile_at(w: u32) -> vec2<u32> {
    let t = texel_at(frame_table, frame.dispatch.z + (w >> 1u));
    return select(t.xy, t.zw, (w & 1u) == 1u);
}

// Entry `i` of the pre-integration table.
fn tf_entry(i: u32) -> vec4<f32> {
    return bitcast<vec4<f32>>(texel_at(tf_table, i));
}

// Texels of a pool slot's entry (backend/src/raycast/pool.rs SLOT_TEXELS):
// its range, its macrocells' bits, the registered layers' ranges.
const SLOT_TEXELS: u32 = 7u;

// A pool slot's value range (min, max − min, variance, and in a layered
// pool the mask of the media with data as bits).
fn slot_range(slot: u32) -> vec4<f32> {
    return bitcast<vec4<f32>>(texel_at(slot_table, SLOT_TEXELS * slot));
}

// A layered slot's layers' ranges: (min, max − min) of layers 1 and 2,
// then of layer 3 (value = min + (max − min) · stored).
fn layer_ranges(slot: u32) -> array<vec4<f32>, 2> {
    let t = SLOT_TEXELS * slot + SLOT_TEXELS - 2u;
    return array<vec4<f32>, 2>(bitcast<vec4<f32>>(texel_at(slot_table, t)),
                               bitcast<vec4<f32>>(texel_at(slot_table, t + 1u)));
}

// Whether macrocell `k` of a pool slot is empty.
fn cell_empty(slot: u32, k: u32) -> bool {
    let t = texel_at(slot_table, SLOT_TEXELS * slot + 1u + k / 128u);
    let w = (k / 32u) % 4u;
    let word = select(select(t.x, t.y, w == 1u), select(t.z, t.w, w == 3u), w >= 2u);
    return ((word >> (k % 32u)) & 1u) != 0u;
}

// The octree's levels (backend/src/store/layout.rs): level l halves axis a
// against level l − 1 where bit l of frame.splits[a] is set (all three in
// an isotropic octree; over thick slices the finer axes first).

// Which axes `level` halves against level − 1 (1: halved).
fn level_split(level: u32) -> vec3<u32> {
    return (frame.splits.xyz >> vec3<u32>(level)) & vec3<u32>(1u);
}

// Halvings of each axis from the root down to `level`.
fn level_halvings(level: u32) -> vec3<u32> {
    let upto = (2u << level) - 1u;
    return countOneBits(frame.splits.xyz & vec3<u32>(upto));
}

// Nodes along each axis of the root's domain at `level`.
fn level_cells(level: u32) -> vec3<f32> {
    return vec3<f32>(vec3<u32>(1u) << level_halvings(level));
}

// Source voxels per level-`level` voxel along each axis.
fn level_scale(level: u32) -> vec3<f32> {
    return vec3<f32>(vec3<u32>(1u) << (countOneBits(frame.splits.xyz) - level_halvings(level)));
}
