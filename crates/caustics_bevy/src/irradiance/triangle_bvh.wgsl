// Placed meshes in two levels (`caustics_core::triangle_bvh::InstancedBvh`): the top
// level's nodes (two vec4s each) from 0, then from an offset the instances (four vec4s
// each: the rows of local_from_world, then as bits where the mesh's nodes and triangles
// start, its mesh index and flags), then each mesh's BVH in its own space: its nodes,
// then its triangles (six vec4s each: three corners, three normals). The traversal is
// the WGSL twin of `InstancedBvh::intersect`: the same stacks, transforms, slab and
// Möller–Trumbore tests in the same order. A shader that imports it binds the BVH at
// group 0, binding 14.

#define_import_path bevy_caustics::triangle_bvh

@group(0) @binding(14) var<storage, read> triangle_bvh: array<vec4<f32>>;

// `triangle_bvh::STACK_DEPTH`.
const BVH_STACK_DEPTH: u32 = 32u;
// A mesh index no instance has: `intersect_triangles` skips none.
const NO_MESH: u32 = 0xffffffffu;

// `triangle_bvh::slab`.
fn slab(origin: vec3<f32>, inv: vec3<f32>, lo: vec3<f32>, hi: vec3<f32>, t_min: f32, t_max: f32) -> bool {
    let t0 = (lo - origin) * inv;
    let t1 = (hi - origin) * inv;
    let near = max(max(max(min(t0.x, t1.x), min(t0.y, t1.y)), min(t0.z, t1.z)), t_min);
    let far = min(min(min(max(t0.x, t1.x), max(t0.y, t1.y)), max(t0.z, t1.z)), t_max);
    return near <= far;
}

fn bvh_corner(triangles: u32, triangle: u32, i: u32) -> vec4<f32> {
    return triangle_bvh[triangles + 6u * triangle + i];
}

// `triangle_bvh::möller_trumbore`: x t, yz (u, v), w 1 for a hit.
fn moller_trumbore(triangles: u32, triangle: u32, origin: vec3<f32>, dir: vec3<f32>, t_min: f32, t_max: f32) -> vec4<f32> {
    let v0 = bvh_corner(triangles, triangle, 0u).xyz;
    let e1 = bvh_corner(triangles, triangle, 1u).xyz - v0;
    let e2 = bvh_corner(triangles, triangle, 2u).xyz - v0;
    let p = cross(dir, e2);
    let det = dot(e1, p);
    if det == 0.0 {
        return vec4(0.0);
    }
    let inv = 1.0 / det;
    let s = origin - v0;
    let u = dot(s, p) * inv;
    let q = cross(s, e1);
    let v = dot(dir, q) * inv;
    let t = dot(e2, q) * inv;
    if u >= 0.0 && v >= 0.0 && u + v <= 1.0 && t > t_min && t < t_max {
        return vec4(t, u, v, 1.0);
    }
    return vec4(0.0);
}

// `MeshBvh::closest` on the mesh whose nodes start at `nodes` and triangles at
// `triangles`: x t, yz (u, v), w the triangle as bits; t negative for none.
fn closest_triangle(nodes: u32, triangles: u32, origin: vec3<f32>, dir: vec3<f32>, t_min: f32, t_max: f32) -> vec4<f32> {
    let inv = 1.0 / dir;
    var closest = vec4(-1.0, 0.0, 0.0, 0.0);
    var t_far = t_max;
    var stack: array<u32, BVH_STACK_DEPTH>;
    stack[0] = 0u;
    var len = 1u;
    while len > 0u {
        len -= 1u;
        let node = nodes + 2u * stack[len];
        let lo = triangle_bvh[node];
        let hi = triangle_bvh[node + 1u];
        if !slab(origin, inv, lo.xyz, hi.xyz, t_min, t_far) {
            continue;
        }
        let first = bitcast<u32>(lo.w);
        let count = bitcast<u32>(hi.w);
        if count > 0u {
            for (var i = first; i < first + count; i++) {
                let r = moller_trumbore(triangles, i, origin, dir, t_min, t_far);
                if r.w > 0.0 {
                    t_far = r.x;
                    closest = vec4(r.xyz, bitcast<f32>(i));
                }
            }
        } else if len + 2u <= BVH_STACK_DEPTH {
            stack[len] = first;
            stack[len + 1u] = first + 1u;
            len += 2u;
        }
    }
    return closest;
}

struct TriangleHit {
    t: f32,  // negative: no hit
    generator: u32,  // the instance's mesh index, as `GeneratorHit::generator`
    normal: vec3<f32>,
    geometric_normal: vec3<f32>,
}

// `triangle_bvh::MIRRORED`.
const MIRRORED: u32 = 1u;

// `InstancedBvh::intersect` on the BVH whose instances start at `instances` (0: no
// BVH), passing through the instances of mesh `skip` (`NO_MESH`: none).
fn intersect_triangles(instances: u32, skip: u32, origin: vec3<f32>, dir: vec3<f32>, t_min: f32, t_max: f32) -> TriangleHit {
    var none = TriangleHit(-1.0, 0u, vec3(0.0), vec3(0.0));
    if instances == 0u {
        return none;
    }
    let inv = 1.0 / dir;
    var t_far = t_max;
    var best = vec4(0.0);
    var best_instance = 0u;
    var found = false;
    var stack: array<u32, BVH_STACK_DEPTH>;
    stack[0] = 0u;
    var len = 1u;
    while len > 0u {
        len -= 1u;
        let node = stack[len];
        let lo = triangle_bvh[2u * node];
        let hi = triangle_bvh[2u * node + 1u];
        if !slab(origin, inv, lo.xyz, hi.xyz, t_min, t_far) {
            continue;
        }
        let first = bitcast<u32>(lo.w);
        let count = bitcast<u32>(hi.w);
        if count > 0u {
            for (var k = first; k < first + count; k++) {
                let at = instances + 4u * k;
                let ids = bitcast<vec4<u32>>(triangle_bvh[at + 3u]);
                if ids.z == skip {
                    continue;
                }
                let r0 = triangle_bvh[at];
                let r1 = triangle_bvh[at + 1u];
                let r2 = triangle_bvh[at + 2u];
                let o = vec3(dot(r0.xyz, origin) + r0.w, dot(r1.xyz, origin) + r1.w, dot(r2.xyz, origin) + r2.w);
                let d = vec3(dot(r0.xyz, dir), dot(r1.xyz, dir), dot(r2.xyz, dir));
                let r = closest_triangle(ids.x, ids.y, o, d, t_min, t_far);
                if r.x >= 0.0 {
                    t_far = r.x;
                    best = r;
                    best_instance = at;
                    found = true;
                }
            }
        } else if len + 2u <= BVH_STACK_DEPTH {
            stack[len] = first;
            stack[len + 1u] = first + 1u;
            len += 2u;
        }
    }
    if !found {
        return none;
    }
    let ids = bitcast<vec4<u32>>(triangle_bvh[best_instance + 3u]);
    let r0 = triangle_bvh[best_instance].xyz;
    let r1 = triangle_bvh[best_instance + 1u].xyz;
    let r2 = triangle_bvh[best_instance + 2u].xyz;
    let triangle = bitcast<u32>(best.w);
    let uv = best.yz;
    let c0 = bvh_corner(ids.y, triangle, 0u).xyz;
    // Mesh-space normals into the world by the inverse transpose.
    let local_geometric = cross(bvh_corner(ids.y, triangle, 1u).xyz - c0, bvh_corner(ids.y, triangle, 2u).xyz - c0);
    var geometric = r0 * local_geometric.x + r1 * local_geometric.y + r2 * local_geometric.z;
    if (ids.w & MIRRORED) != 0u {
        geometric = -geometric;
    }
    var g = vec3(0.0);
    if dot(geometric, geometric) > 0.0 {
        g = normalize(geometric);
    }
    let local = bvh_corner(ids.y, triangle, 3u).xyz * (1.0 - uv.x - uv.y) + bvh_corner(ids.y, triangle, 4u).xyz * uv.x
        + bvh_corner(ids.y, triangle, 5u).xyz * uv.y;
    let n = r0 * local.x + r1 * local.y + r2 * local.z;
    var normal = g;
    if dot(n, n) > 0.0 {
        normal = normalize(n);
    }
    return TriangleHit(t_far, ids.z, normal, g);
}
