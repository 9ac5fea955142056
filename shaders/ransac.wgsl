// Batched RANSAC scoring for all of a frame's regions in one dispatch: the GPU half of
// src/extract/cpu/ransac.rs (score_hypotheses). Workgroup k scores hypothesis
// k % hypotheses of region k / hypotheses: every invocation draws the same three points
// with the shared hash, then the 64 invocations count the inliers among the region's
// evenly strided scoring points together.

// Field by field the Rust struct gpu::RansacParams.
struct RansacParams { hypotheses: u32, regions: u32, inlier_distance: f32, max_score_points: u32, min_sample_sine: f32 }

@group(0) @binding(0) var<uniform> p: RansacParams;
@group(0) @binding(1) var<storage, read> points: array<f32>;
// (first point, point count) of each region.
@group(0) @binding(2) var<storage, read> ranges: array<vec2<u32>>;
@group(0) @binding(3) var<storage, read_write> scores: array<u32>;

var<workgroup> count: atomic<u32>;

fn hash(x0: u32) -> u32 {
    var x = x0;
    x ^= x >> 16u;
    x *= 0x7feb352du;
    x ^= x >> 15u;
    x *= 0x846ca68bu;
    return x ^ (x >> 16u);
}

fn sample_index(region: u32, hypothesis: u32, j: u32, n: u32) -> u32 {
    return hash((region * 0x9e3779b9u) ^ hash(hypothesis * 3u + j)) % n;
}

fn point(i: u32) -> vec3<f32> {
    return vec3<f32>(points[3u * i], points[3u * i + 1u], points[3u * i + 2u]);
}

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let k = wg.x + wg.y * 65535u;
    if (k >= p.regions * p.hypotheses) { return; }
    let r = k / p.hypotheses;
    let h = k % p.hypotheses;
    let start = ranges[r].x;
    let n = ranges[r].y;
    if (lid == 0u) { atomicStore(&count, 0u); }
    workgroupBarrier();
    if (n >= 3u) {
        let a = point(start + sample_index(r, h, 0u, n));
        let b = point(start + sample_index(r, h, 1u, n));
        let c = point(start + sample_index(r, h, 2u, n));
        let e1 = b - a;
        let e2 = c - a;
        let nv = vec3<f32>(e1.y * e2.z - e1.z * e2.y, e1.z * e2.x - e1.x * e2.z, e1.x * e2.y - e1.y * e2.x);
        let len = sqrt(nv.x * nv.x + nv.y * nv.y + nv.z * nv.z);
        let edges = sqrt((e1.x * e1.x + e1.y * e1.y + e1.z * e1.z) * (e2.x * e2.x + e2.y * e2.y + e2.z * e2.z));
        // Nearly collinear samples give no plane (the CPU twin's plane_through).
        if (len > p.min_sample_sine * edges) {
            let nn = nv / len;
            let d = -(nn.x * a.x + nn.y * a.y + nn.z * a.z);
            let stride = max((n + p.max_score_points - 1u) / p.max_score_points, 1u);
            let scored = (n + stride - 1u) / stride;
            var mine = 0u;
            for (var j = lid; j < scored; j += 64u) {
                let q = point(start + j * stride);
                if (abs(nn.x * q.x + nn.y * q.y + nn.z * q.z + d) < p.inlier_distance) { mine++; }
            }
            atomicAdd(&count, mine);
        }
    }
    workgroupBarrier();
    if (lid == 0u) { scores[k] = atomicLoad(&count); }
}
