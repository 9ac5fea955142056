// Exact surface normals from smoothed depth: the GPU half of src/extract/cpu/normals.rs.
// Sobel taps (weights from the CPU side) give Z_u, Z_v; the normal is the
// cross product of the back-projected surface's tangents, facing the camera. A pixel
// with any invalid tap, or within the kernel radius of the border, gets (0, 0, 0).

// Field by field the Rust struct params::NormalsParams.
struct NormalsParams {
    width: u32, height: u32, radius: u32, norm: f32,
    fx: f32, fy: f32, cx: f32, cy: f32,
}

@group(0) @binding(0) var<uniform> p: NormalsParams;
@group(0) @binding(1) var<storage, read> depth: array<f32>;
// smooth[0..7] then deriv[0..7]; only the first 2 * radius + 1 of each are used.
@group(0) @binding(2) var<storage, read> weights: array<f32, 14>;
@group(0) @binding(3) var<storage, read_write> normals: array<f32>;

fn write(i: u32, n: vec3<f32>) {
    normals[3u * i] = n.x;
    normals[3u * i + 1u] = n.y;
    normals[3u * i + 2u] = n.z;
}

@compute @workgroup_size(16, 16)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let u = id.x;
    let v = id.y;
    if (u >= p.width || v >= p.height) { return; }
    let i = v * p.width + u;
    let r = p.radius;
    if (v < r || v + r >= p.height || u < r || u + r >= p.width) { write(i, vec3<f32>(0.0)); return; }
    let z = depth[i];
    if (z == 0.0) { write(i, vec3<f32>(0.0)); return; }
    // Each row's derivative along u and each column's along v as differences either side
    // of the centre (exact on a smooth surface, so fused multiply-adds and the order of
    // sums cannot change them), then smoothed: the CPU twin's order of sums. Row j's
    // differences read every tap off column u, column j's every tap off row v.
    var gu = 0.0;
    var gv = 0.0;
    for (var j = 0u; j < 2u * r + 1u; j++) {
        let row = (v + j - r) * p.width;
        let column = u + j - r;
        var along_u = 0.0;
        var along_v = 0.0;
        for (var k = 1u; k <= r; k++) {
            let right = depth[row + u + k];
            let left = depth[row + u - k];
            let below = depth[(v + k) * p.width + column];
            let above = depth[(v - k) * p.width + column];
            if (right == 0.0 || left == 0.0 || below == 0.0 || above == 0.0) { write(i, vec3<f32>(0.0)); return; }
            let c = weights[7u + r + k];
            along_u += c * (right - left);
            along_v += c * (below - above);
        }
        gu += weights[j] * along_u;
        gv += weights[j] * along_v;
    }
    let zu = gu / p.norm;
    let zv = gv / p.norm;
    let x = (f32(u) - p.cx) / p.fx;
    let y = (f32(v) - p.cy) / p.fy;
    let a = vec3<f32>(zu * x + z / p.fx, zu * y, zu);
    let b = vec3<f32>(zv * x, zv * y + z / p.fy, zv);
    let n = vec3<f32>(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
    let len = sqrt(n.x * n.x + n.y * n.y + n.z * n.z);
    if (!(len > 0.0)) { write(i, vec3<f32>(0.0)); return; }
    var s = 1.0 / len;
    if (n.x * x + n.y * y + n.z > 0.0) { s = -1.0 / len; }
    write(i, n * s);
}
