// One Perona-Malik diffusion step of depth in metres (0 = invalid): the GPU half of
// src/extract/cpu/diffusion.rs, with the same conductance. The CPU twin computes each
// pixel pair's flux once and gives it to both sides; the values and sums are the same.
// Invalid pixels and pixels outside the image neither give nor receive flux.

struct Params { width: u32, height: u32, inv_kappa: f32, gamma: f32 }

@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var<storage, read> src: array<f32>;
@group(0) @binding(2) var<storage, read_write> dst: array<f32>;

const LOG2_E: f32 = 1.4426950408889634;

// exp(-(d * inv_kappa)^2) as 2^-t: integer part by the exponent bits, fraction by a
// degree-4 minimax polynomial of 2^-f (relative error under 3e-6); the CPU twin's
// conductance(), with its coefficients EXP2_NEG.
fn conductance(d: f32, inv_kappa: f32) -> f32 {
    let s = d * inv_kappa;
    let t = min(s * s * LOG2_E, 100.0);
    let n = i32(t);
    let f = t - f32(n);
    let q = 0.9999974 + f * (-0.6930302 + f * (0.23934102 + f * (-0.05307402 + f * 0.0067670685)));
    return bitcast<f32>(u32(127 - n) << 23u) * q;
}

fn flux(z: f32, q: f32) -> f32 {
    if (q == 0.0) { return 0.0; }
    let d = q - z;
    return conductance(d, p.inv_kappa) * d;
}

fn depth_at(u: i32, v: i32) -> f32 {
    if (u < 0 || v < 0 || u >= i32(p.width) || v >= i32(p.height)) { return 0.0; }
    return src[u32(v) * p.width + u32(u)];
}

@compute @workgroup_size(16, 16)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= p.width || id.y >= p.height) { return; }
    let i = id.y * p.width + id.x;
    let z = src[i];
    if (z == 0.0) { dst[i] = 0.0; return; }
    let u = i32(id.x);
    let v = i32(id.y);
    // Right and left, then below, then above: the CPU twin's order of sums.
    let sum = flux(z, depth_at(u + 1, v)) + flux(z, depth_at(u - 1, v)) + flux(z, depth_at(u, v + 1)) + flux(z, depth_at(u, v - 1));
    dst[i] = z + p.gamma * sum;
}
