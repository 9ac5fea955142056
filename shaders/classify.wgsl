// Canny on the normal image, second pass: non-maximum suppression along the gradient's
// sector and the double threshold (0 none, 1 weak, 2 strong), from shaders/gradient.wgsl's
// magnitude and sector. The GPU side of src/extract/cpu/classify.rs (suppressed_class).
// Hysteresis follows in shaders/hysteresis.wgsl.

// Field by field the Rust struct params::CannyParams (shared with gradient.wgsl).
struct CannyParams { width: u32, height: u32, low: f32, high: f32 }

@group(0) @binding(0) var<uniform> p: CannyParams;
@group(0) @binding(1) var<storage, read> magnitude: array<f32>;
@group(0) @binding(2) var<storage, read> sector: array<u32>;
@group(0) @binding(3) var<storage, read_write> classes: array<u32>;

fn magnitude_at(u: i32, v: i32) -> f32 {
    if (u < 0 || v < 0 || u >= i32(p.width) || v >= i32(p.height)) { return 0.0; }
    return magnitude[u32(v) * p.width + u32(u)];
}

@compute @workgroup_size(16, 16)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= p.width || id.y >= p.height) { return; }
    let i = id.y * p.width + id.x;
    let m = magnitude[i];
    let sec = sector[i];
    classes[i] = 0u;
    if (sec == 4u || m < p.low) { return; }
    let steps = array<vec2<i32>, 4>(vec2<i32>(1, 0), vec2<i32>(1, 1), vec2<i32>(0, 1), vec2<i32>(-1, 1));
    let st = steps[sec];
    let u = i32(id.x);
    let v = i32(id.y);
    if (m > magnitude_at(u - st.x, v - st.y) && m >= magnitude_at(u + st.x, v + st.y)) {
        if (m >= p.high) { classes[i] = 2u; } else { classes[i] = 1u; }
    }
}
