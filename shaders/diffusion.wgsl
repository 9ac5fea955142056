// One semi-implicit Perona-Malik pass of depth in metres (0 = invalid) along every line
// of the image (rows, or columns: the line and element strides say which): the GPU half
// of src/extract/cpu/diffusion.rs, whose `solve_line` this mirrors line for line. One
// invocation solves one line's tridiagonal system by the Thomas algorithm; a step is a
// row pass then a column pass. Invalid pixels neither give nor receive.

// Field by field the Rust struct gpu::DiffusionParams.
struct DiffusionParams {
    len: u32,          // pixels along a line
    lines: u32,
    line_stride: u32,  // index of line k's first pixel = k * line_stride
    elem_stride: u32,  // from one pixel of a line to the next
    step: f32,         // the step's time
    inv_kappa: f32,
}

@group(0) @binding(0) var<uniform> p: DiffusionParams;
@group(0) @binding(1) var<storage, read> src: array<f32>;
@group(0) @binding(2) var<storage, read_write> dst: array<f32>;
// The elimination's factors, one per pixel.
@group(0) @binding(3) var<storage, read_write> factor: array<f32>;

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

fn coupling(z: f32, q: f32) -> f32 {
    if (z == 0.0 || q == 0.0) { return 0.0; }
    return p.step * conductance(q - z, p.inv_kappa);
}

// Solves for the change of depth (the right-hand side is the explicit fluxes), then
// adds it: dst holds the changes until the back sweep.
@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= p.lines || p.len == 0u) { return; }
    let first = id.x * p.line_stride;
    var above = 0.0;
    var flux_above = 0.0;
    var e_prev = 0.0;
    var change_prev = 0.0;
    for (var i = 0u; i < p.len; i++) {
        let k = first + i * p.elem_stride;
        let z = src[k];
        var below = 0.0;
        var flux_below = 0.0;
        if (i + 1u < p.len) {
            let q = src[k + p.elem_stride];
            below = coupling(z, q);
            flux_below = below * (q - z);
        }
        let m = 1.0 / (1.0 + above + below - above * e_prev);
        e_prev = below * m;
        change_prev = (flux_below - flux_above + above * change_prev) * m;
        factor[k] = e_prev;
        dst[k] = change_prev;
        above = below;
        flux_above = flux_below;
    }
    var next = change_prev;
    let last = first + (p.len - 1u) * p.elem_stride;
    dst[last] = src[last] + next;
    for (var i = p.len - 1u; i > 0u; i--) {
        let k = first + (i - 1u) * p.elem_stride;
        next = dst[k] + factor[k] * next;
        dst[k] = src[k] + next;
    }
}
