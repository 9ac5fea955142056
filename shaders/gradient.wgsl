// Canny on the normal image, first pass: the gradient of the unit-normal field, its
// magnitude (change of normal per pixel) and non-maximum-suppression sector (4 = a tap
// without a normal). The GPU side of src/extract/cpu/gradient.rs (normal_gradient,
// gradient_sector); shaders/classify.wgsl reads what it writes.

// Field by field the Rust struct params::CannyParams (shared with classify.wgsl).
struct CannyParams { width: u32, height: u32, low: f32, high: f32 }

@group(0) @binding(0) var<uniform> p: CannyParams;
@group(0) @binding(1) var<storage, read> normals: array<f32>;
@group(0) @binding(2) var<storage, read_write> magnitude: array<f32>;
@group(0) @binding(3) var<storage, read_write> sector: array<u32>;

fn normal_at(i: u32) -> vec3<f32> {
    return vec3<f32>(normals[3u * i], normals[3u * i + 1u], normals[3u * i + 2u]);
}

@compute @workgroup_size(16, 16)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let u = id.x;
    let v = id.y;
    if (u >= p.width || v >= p.height) { return; }
    let i = v * p.width + u;
    magnitude[i] = 0.0;
    sector[i] = 4u;
    if (u == 0u || v == 0u || u + 1u >= p.width || v + 1u >= p.height) { return; }
    let s = array<f32, 3>(1.0, 2.0, 1.0);
    let d = array<f32, 3>(-1.0, 0.0, 1.0);
    var gx = vec3<f32>(0.0);
    var gy = vec3<f32>(0.0);
    // Row sums first, then the column: the CPU twin's order of sums.
    for (var j = 0u; j < 3u; j++) {
        var row_x = vec3<f32>(0.0);
        var row_y = vec3<f32>(0.0);
        for (var t = 0u; t < 3u; t++) {
            let n = normal_at((v + j - 1u) * p.width + u + t - 1u);
            if (all(n == vec3<f32>(0.0))) { return; }
            row_x += d[t] * n;
            row_y += s[t] * n;
        }
        gx += s[j] * row_x;
        gy += d[j] * row_y;
    }
    let xx = dot(gx, gx) / 64.0;
    let yy = dot(gy, gy) / 64.0;
    let xy = dot(gx, gy) / 64.0;
    magnitude[i] = sqrt(xx + yy);
    let a = xx - yy;
    let b = 2.0 * xy;
    if (a >= abs(b)) { sector[i] = 0u; } else if (b >= abs(a)) { sector[i] = 1u; } else if (-a >= abs(b)) { sector[i] = 2u; } else { sector[i] = 3u; }
}
