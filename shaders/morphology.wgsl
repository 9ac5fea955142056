// One axis of a binary dilation or erosion by a (2r+1)^2 square: the GPU side of
// cpu::morphology (the oracle `morphology_at` mirrors it). A square is a row pass then
// a column pass; a closing is a dilation then an erosion, four passes.

// Field by field the Rust struct params::MorphologyParams.
struct MorphologyParams {
    width: u32, height: u32, radius: u32,
    // 0: along rows (u), 1: along columns (v).
    axis: u32,
    // 0: any pixel of the window set (dilation), 1: all of them (erosion).
    all: u32,
    // The value of pixels beyond the border.
    outside: u32,
}

@group(0) @binding(0) var<uniform> p: MorphologyParams;
@group(0) @binding(1) var<storage, read> src: array<u32>;
@group(0) @binding(2) var<storage, read_write> dst: array<u32>;

@compute @workgroup_size(16, 16)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= p.width || id.y >= p.height) { return; }
    let i = id.y * p.width + id.x;
    let r = i32(p.radius);
    var at = i32(id.x);
    var len = i32(p.width);
    var stride = 1u;
    if (p.axis == 1u) {
        at = i32(id.y);
        len = i32(p.height);
        stride = p.width;
    }
    var any = 0u;
    var all = 1u;
    for (var k = -r; k <= r; k++) {
        var x = p.outside;
        let j = at + k;
        if (j >= 0 && j < len) { x = u32(src[i + u32(k) * stride] != 0u); }
        any |= x;
        all &= x;
    }
    dst[i] = select(any, all, p.all == 1u);
}
