// Canny's hysteresis: the GPU side of cpu::hysteresis::hysteresis. shaders/components.wgsl
// first labels the 8-connected components of the weak-or-strong pixels (classify.wgsl's
// 1 and 2); then `mark_strong` flags each component holding a strong pixel, at its
// root, and `keep` makes an edge of every pixel of a flagged component.

// Field by field the Rust struct params::CannyParams (shared with gradient.wgsl and classify.wgsl).
struct CannyParams { width: u32, height: u32, low: f32, high: f32 }

@group(0) @binding(0) var<uniform> p: CannyParams;
@group(0) @binding(1) var<storage, read> classes: array<u32>;
// Root + 1 of each pixel's component, 0 for pixels in none (components.wgsl's labels).
@group(0) @binding(2) var<storage, read> labels: array<u32>;
// Per root: 1 when its component holds a strong pixel; zeroed before mark_strong.
@group(0) @binding(3) var<storage, read_write> strong: array<atomic<u32>>;
@group(0) @binding(4) var<storage, read_write> edges: array<u32>;

@compute @workgroup_size(16, 16)
fn mark_strong(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= p.width || id.y >= p.height) { return; }
    let i = id.y * p.width + id.x;
    if (classes[i] == 2u) { atomicStore(&strong[labels[i] - 1u], 1u); }
}

@compute @workgroup_size(16, 16)
fn keep(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= p.width || id.y >= p.height) { return; }
    let i = id.y * p.width + id.x;
    let l = labels[i];
    edges[i] = select(0u, atomicLoad(&strong[max(l, 1u) - 1u]), l != 0u);
}
