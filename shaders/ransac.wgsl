// Batched RANSAC scoring for all of a frame's regions in one dispatch: the GPU half of
// src/extract/cpu/ransac.rs (score_hypotheses). The CPU gathers what both twins score
// (`ScoringBatch`): each region's evenly strided scoring points, and each hypothesis's
// plane through its three samples drawn with the shared hash. Workgroup k scores
// hypothesis k % hypotheses of region k / hypotheses: its 64 invocations count the
// region's scoring points within the inlier distance of the plane together.

// Field by field the Rust struct params::RansacParams.
struct RansacParams { hypotheses: u32, regions: u32, inlier_distance: f32, points: u32 }

@group(0) @binding(0) var<uniform> p: RansacParams;
// x of every scoring point, then y, then z (p.points of each).
@group(0) @binding(1) var<storage, read> coords: array<f32>;
// (first point, point count) of each region.
@group(0) @binding(2) var<storage, read> ranges: array<vec2<u32>>;
// (normal, offset) of each hypothesis, region-major; all zero for none.
@group(0) @binding(3) var<storage, read> planes: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read_write> scores: array<u32>;

var<workgroup> count: atomic<u32>;

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let k = wg.x + wg.y * 65535u;
    if (k >= p.regions * p.hypotheses) { return; }
    let start = ranges[k / p.hypotheses].x;
    let n = ranges[k / p.hypotheses].y;
    let plane = planes[k];
    if (lid == 0u) { atomicStore(&count, 0u); }
    workgroupBarrier();
    if (any(plane.xyz != vec3<f32>(0.0))) {
        var mine = 0u;
        for (var j = lid; j < n; j += 64u) {
            let i = start + j;
            let q = vec3<f32>(coords[i], coords[p.points + i], coords[2u * p.points + i]);
            if (abs(plane.x * q.x + plane.y * q.y + plane.z * q.z + plane.w) < p.inlier_distance) { mine++; }
        }
        atomicAdd(&count, mine);
    }
    workgroupBarrier();
    if (lid == 0u) { scores[k] = atomicLoad(&count); }
}
