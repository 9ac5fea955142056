// Where a pixel cannot be inside a planar region: the GPU side of cpu::boundary::boundary
// (the oracle `boundary_oracle` mirrors it). `lines` marks Canny edges and depth steps;
// shaders/morphology.wgsl closes them; `holes` adds the pixels without a normal;
// morphology.wgsl seals those with the small square; `seal` grows each closed line
// pixel into its 4-neighbours (regions are 8-connected, a thin diagonal line would leak)
// and adds the sealed pixels.

// Field by field the Rust struct params::BoundaryParams.
struct BoundaryParams { width: u32, height: u32, depth_edge_ratio: f32, pad: u32 }

@group(0) @binding(0) var<uniform> p: BoundaryParams;
@group(0) @binding(1) var<storage, read> depth: array<f32>;
@group(0) @binding(2) var<storage, read> normals: array<f32>;
@group(0) @binding(3) var<storage, read> edges: array<u32>;
// The closed lines (read by holes and seal).
@group(0) @binding(4) var<storage, read> closed: array<u32>;
@group(0) @binding(5) var<storage, read> sealed: array<u32>;
@group(0) @binding(6) var<storage, read_write> dst: array<u32>;

// 1 where the depth steps to the 4-neighbour j by more than the ratio (both valid).
fn jump(z: f32, j: u32) -> u32 {
    let q = depth[j];
    return u32(z != 0.0 && q != 0.0 && abs(q - z) > p.depth_edge_ratio * z);
}

@compute @workgroup_size(16, 16)
fn lines(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= p.width || id.y >= p.height) { return; }
    let i = id.y * p.width + id.x;
    let z = depth[i];
    var line = u32(edges[i] != 0u);
    if (id.x + 1u < p.width) { line |= jump(z, i + 1u); }
    if (id.x > 0u) { line |= jump(z, i - 1u); }
    if (id.y > 0u) { line |= jump(z, i - p.width); }
    if (id.y + 1u < p.height) { line |= jump(z, i + p.width); }
    dst[i] = line;
}

@compute @workgroup_size(16, 16)
fn holes(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= p.width || id.y >= p.height) { return; }
    let i = id.y * p.width + id.x;
    let no_normal = normals[3u * i] == 0.0 && normals[3u * i + 1u] == 0.0 && normals[3u * i + 2u] == 0.0;
    dst[i] = u32(closed[i] != 0u || no_normal);
}

@compute @workgroup_size(16, 16)
fn seal(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= p.width || id.y >= p.height) { return; }
    let i = id.y * p.width + id.x;
    var out = closed[i] | sealed[i];
    if (id.x > 0u) { out |= closed[i - 1u]; }
    if (id.x + 1u < p.width) { out |= closed[i + 1u]; }
    if (id.y > 0u) { out |= closed[i - p.width]; }
    if (id.y + 1u < p.height) { out |= closed[i + p.width]; }
    dst[i] = u32(out != 0u);
}
