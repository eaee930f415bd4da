// A mesh's BVH in an `InstancedBvh` buffer (`triangle_bvh.wgsl`) refit to the mesh's
// vertices as this frame moved them on the GPU (an ocean's waves, a pool's ripples):
// the WGSL twin of `MeshBvh::refit`. `refit_triangles` reads each triangle's corners
// and normals again from Bevy's vertex buffer; `refit_nodes`, dispatched once a level
// from the deepest, makes each node's box from its triangles' or its children's. The
// tree's shape and the nodes' links stay: the buffer is written as words, so the links
// kept in the nodes' `w` are never read as floats.

struct RefitJob {
    at: vec4<u32>,     // where the mesh's nodes and triangles start (vec4s), its triangles
    level: vec4<u32>,  // the level's first node in `levels`, its nodes
    vertex: vec4<u32>, // in `vertices`: the first vertex's word, the stride, the position's and the normal's word
}

@group(0) @binding(0) var<uniform> job: RefitJob;
@group(0) @binding(1) var<storage, read> vertices: array<f32>;
// Each triangle's three vertices, in BVH order (`MeshBvh::corners`).
@group(0) @binding(2) var<storage, read> corners: array<u32>;
// The nodes, level by level (`MeshBvh::levels`).
@group(0) @binding(3) var<storage, read> levels: array<u32>;
@group(0) @binding(4) var<storage, read_write> bvh: array<u32>;

const INFINITY: f32 = 3.4028235e38;

fn vertex_vec3(i: u32, word: u32) -> vec3<f32> {
    let at = job.vertex.x + i * job.vertex.y + word;
    return vec3(vertices[at], vertices[at + 1u], vertices[at + 2u]);
}

// The `vec3` at word `at` of the BVH.
fn read3(at: u32) -> vec3<f32> {
    return bitcast<vec3<f32>>(vec3(bvh[at], bvh[at + 1u], bvh[at + 2u]));
}

fn write3(at: u32, v: vec3<f32>) {
    let bits = bitcast<vec3<u32>>(v);
    bvh[at] = bits.x;
    bvh[at + 1u] = bits.y;
    bvh[at + 2u] = bits.z;
}

@compute @workgroup_size(64)
fn refit_triangles(@builtin(global_invocation_id) id: vec3<u32>) {
    let t = id.x;
    if t >= job.at.z {
        return;
    }
    let at = 4u * (job.at.y + 6u * t);
    for (var k = 0u; k < 3u; k++) {
        let v = corners[3u * t + k];
        write3(at + 4u * k, vertex_vec3(v, job.vertex.z));
        write3(at + 4u * (3u + k), vertex_vec3(v, job.vertex.w));
    }
}

@compute @workgroup_size(64)
fn refit_nodes(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= job.level.y {
        return;
    }
    let at = 4u * (job.at.x + 2u * levels[job.level.x + id.x]);
    let first = bvh[at + 3u];
    let count = bvh[at + 7u];
    var lo = vec3(INFINITY);
    var hi = vec3(-INFINITY);
    if count > 0u {
        for (var t = first; t < first + count; t++) {
            for (var k = 0u; k < 3u; k++) {
                let p = read3(4u * (job.at.y + 6u * t + k));
                lo = min(lo, p);
                hi = max(hi, p);
            }
        }
    } else {
        let left = 4u * (job.at.x + 2u * first);
        lo = min(read3(left), read3(left + 8u));
        hi = max(read3(left + 4u), read3(left + 12u));
    }
    write3(at, lo);
    write3(at + 4u, hi);
}

// Does nothing: dispatched first under the refit's bindings while timestamps are recorded,
// so that lavapipe times the pass whole (`gpu_work::anchor_first_timestamp`).
@compute @workgroup_size(1)
fn anchor() {}
