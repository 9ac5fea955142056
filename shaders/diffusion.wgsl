// One semi-implicit Perona-Malik pass of depth in metres (0 = invalid) along every line
// of the image (rows, or columns: the line and element strides say which): the GPU half
// of src/extract/cpu/diffusion.rs, solving the system its `solve_line` solves. A
// workgroup takes one line. Its invocations write the line's tridiagonal system into
// workgroup memory, solve it by cyclic reduction (Hockney: each level folds every other
// row into its neighbours, so 2 log2(n) levels of parallel work replace the Thomas
// algorithm's chain of n dependent steps; `cyclic_reduction` is this solve one
// invocation at a time), and write the line back. A step is a row pass then a column
// pass. Invalid pixels neither give nor receive.

// Field by field the Rust struct params::DiffusionParams.
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

// Rows 1..SLOTS - 1 of a system (row 0 is the zero outside the line), so lines of up to
// SLOTS - 1 pixels: gpu::DIFFUSION_MAX_LINE. Four arrays of it are 32 KiB of workgroup
// memory.
const SLOTS: u32 = 2048u;
const MAX_LINE: u32 = SLOTS - 1u;
const THREADS: u32 = 256u;
// Row r's coefficients of x[r - s], x[r] and x[r + s] at the current level (s = 1 at the
// start), and its right-hand side, which becomes x[r] once solved.
var<workgroup> sub: array<f32, SLOTS>;
var<workgroup> diag: array<f32, SLOTS>;
var<workgroup> sup: array<f32, SLOTS>;
var<workgroup> rhs: array<f32, SLOTS>;

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
// adds it.
@compute @workgroup_size(THREADS)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let n = p.len;
    if (wg.x >= p.lines || n == 0u || n > MAX_LINE) { return; }
    let first = wg.x * p.line_stride;
    // 2^m - 1 rows, the fewest of that form that hold the line; those past it are x = 0.
    let rows = (1u << (32u - countLeadingZeros(n))) - 1u;
    for (var r = lid + 1u; r <= rows; r += THREADS) {
        var above = 0.0;
        var below = 0.0;
        var flux = 0.0;
        if (r <= n) {
            let k = first + (r - 1u) * p.elem_stride;
            let z = src[k];
            var flux_above = 0.0;
            var flux_below = 0.0;
            if (r > 1u) {
                let o = src[k - p.elem_stride];
                above = coupling(o, z);
                flux_above = above * (z - o);
            }
            if (r < n) {
                let q = src[k + p.elem_stride];
                below = coupling(z, q);
                flux_below = below * (q - z);
            }
            flux = flux_below - flux_above;
        }
        sub[r] = -above;
        diag[r] = 1.0 + above + below;
        sup[r] = -below;
        rhs[r] = flux;
    }
    workgroupBarrier();
    // Reduction: at stride s, every row at a multiple of 2s takes in rows r - s and r + s.
    var s = 1u;
    while (2u * s <= rows) {
        for (var j = lid + 1u; j * 2u * s <= rows; j += THREADS) {
            let r = j * 2u * s;
            let alpha = -sub[r] / diag[r - s];
            let gamma = -sup[r] / diag[r + s];
            diag[r] = diag[r] + alpha * sup[r - s] + gamma * sub[r + s];
            rhs[r] = rhs[r] + alpha * rhs[r - s] + gamma * rhs[r + s];
            sub[r] = alpha * sub[r - s];
            sup[r] = gamma * sup[r + s];
        }
        workgroupBarrier();
        s *= 2u;
    }
    // Back substitution: at stride s, the rows at odd multiples of s, from the solved
    // rows either side (none past the ends).
    s = (rows + 1u) / 2u;
    loop {
        for (var j = lid; (2u * j + 1u) * s <= rows; j += THREADS) {
            let r = (2u * j + 1u) * s;
            var x = rhs[r];
            if (r > s) { x -= sub[r] * rhs[r - s]; }
            if (r + s <= rows) { x -= sup[r] * rhs[r + s]; }
            rhs[r] = x / diag[r];
        }
        workgroupBarrier();
        if (s == 1u) { break; }
        s /= 2u;
    }
    for (var r = lid + 1u; r <= n; r += THREADS) {
        let k = first + (r - 1u) * p.elem_stride;
        dst[k] = src[k] + rhs[r];
    }
}
