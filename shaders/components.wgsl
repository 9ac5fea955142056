// 8-connected components of a mask: the GPU side of src/extract/cpu/components.rs
// (the oracle `components_oracle` mirrors these three passes line for line).
//
// Union-find with lock-free unions (Playne & Hawick, "A new algorithm for parallel
// connected-component labelling on GPUs", IEEE TPDS 2018): every pixel starts as its
// own root; each pixel unites with its inside neighbours above and to the left, the
// larger root always hung under the smaller with atomicMin, so a component's root ends
// as its first pixel in scan order; flattening then labels each pixel root + 1. The
// label is the same whatever order the unions run in.

// Field by field the Rust struct params::ComponentsParams.
struct ComponentsParams { width: u32, height: u32, inside_nonzero: u32, pad: u32 }

@group(0) @binding(0) var<uniform> p: ComponentsParams;
@group(0) @binding(1) var<storage, read> mask: array<u32>;
@group(0) @binding(2) var<storage, read_write> parent: array<atomic<u32>>;
@group(0) @binding(3) var<storage, read_write> labels: array<u32>;

// Inside: the mask is nonzero (inside_nonzero = 1) or zero (inside_nonzero = 0).
fn inside(i: u32) -> bool {
    return (mask[i] != 0u) == (p.inside_nonzero != 0u);
}

// The root of `start`, halving the path on the way (each pixel passed is hung under its
// grandparent): a find walks the chain a merge left, and on a large region that chain
// is long. Hanging a pixel higher in its own tree changes no root, and atomicMin never
// undoes a union that ran meanwhile.
fn find(start: u32) -> u32 {
    var r = start;
    var q = atomicLoad(&parent[r]);
    while (q != r) {
        let g = atomicLoad(&parent[q]);
        if (g != q) { atomicMin(&parent[r], g); }
        r = g;
        q = atomicLoad(&parent[r]);
    }
    return r;
}

fn unite(first: u32, second: u32) {
    var a = first;
    var b = second;
    loop {
        a = find(a);
        b = find(b);
        if (a == b) { return; }
        if (a < b) {
            // Hang b under a; if b was no longer a root, go on from where it now points.
            let old = atomicMin(&parent[b], a);
            if (old == b) { return; }
            b = old;
        } else {
            let old = atomicMin(&parent[a], b);
            if (old == a) { return; }
            a = old;
        }
    }
}

@compute @workgroup_size(16, 16)
fn init(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= p.width || id.y >= p.height) { return; }
    let i = id.y * p.width + id.x;
    atomicStore(&parent[i], i);
}

@compute @workgroup_size(16, 16)
fn merge(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= p.width || id.y >= p.height) { return; }
    let i = id.y * p.width + id.x;
    if (!inside(i)) { return; }
    // Left, then the three above: each pair of neighbours is united from one side only.
    if (id.x > 0u && inside(i - 1u)) { unite(i, i - 1u); }
    if (id.y > 0u) {
        let up = i - p.width;
        if (id.x > 0u && inside(up - 1u)) { unite(i, up - 1u); }
        if (inside(up)) { unite(i, up); }
        if (id.x + 1u < p.width && inside(up + 1u)) { unite(i, up + 1u); }
    }
}

@compute @workgroup_size(16, 16)
fn flatten(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= p.width || id.y >= p.height) { return; }
    let i = id.y * p.width + id.x;
    if (inside(i)) { labels[i] = find(i) + 1u; } else { labels[i] = 0u; }
}
