// The sensor's raw depth to metres: the GPU side of extract::depth_metres. The frame is
// uploaded as it comes, 16 bits a pixel, two pixels a word (the first in the low half),
// half the bytes of metres. f32(d) * scale is one correctly rounded product, as on the
// CPU, so both twins start from the same bits.

// Field by field the Rust struct params::MetresParams.
struct MetresParams { width: u32, height: u32, scale: f32, pad: u32 }

@group(0) @binding(0) var<uniform> p: MetresParams;
@group(0) @binding(1) var<storage, read> raw: array<u32>;
@group(0) @binding(2) var<storage, read_write> depth: array<f32>;

@compute @workgroup_size(16, 16)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= p.width || id.y >= p.height) { return; }
    let i = id.y * p.width + id.x;
    let d = (raw[i / 2u] >> (16u * (i % 2u))) & 0xffffu;
    depth[i] = f32(d) * p.scale;
}
