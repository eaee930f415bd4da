// Triangles in a binary BVH (`caustics_core::hierarchical::GeneratorBvh`): its nodes
// (two vec4s each), then from an offset its triangles (six vec4s each: three corners,
// w the mesh's index as bits, three normals). The traversal is the WGSL twin of
// `GeneratorBvh::intersect`: the same stack, the same slab and Möller–Trumbore tests in
// the same order. A shader that imports it binds the BVH at group 0, binding 14.

#define_import_path bevy_caustics::triangle_bvh

@group(0) @binding(14) var<storage, read> triangle_bvh: array<vec4<f32>>;

// `generator_bvh::STACK_DEPTH`.
const BVH_STACK_DEPTH: u32 = 32u;
// A mesh index no triangle has: `intersect_triangles` skips none.
const NO_MESH: u32 = 0xffffffffu;

// `generator_bvh::slab`.
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

// `generator_bvh::möller_trumbore`: x t, yz (u, v), w 1 for a hit.
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

struct TriangleHit {
    t: f32,  // negative: no hit
    generator: u32,  // the triangle's mesh, as `BvhTriangle::generator`
    normal: vec3<f32>,
    geometric_normal: vec3<f32>,
}

// `GeneratorBvh::intersect` on the BVH whose triangles start at `triangles` (0: no BVH),
// passing through the triangles of mesh `skip` (`NO_MESH`: none).
fn intersect_triangles(triangles: u32, skip: u32, origin: vec3<f32>, dir: vec3<f32>, t_min: f32, t_max: f32) -> TriangleHit {
    var none = TriangleHit(-1.0, 0u, vec3(0.0), vec3(0.0));
    if triangles == 0u {
        return none;
    }
    let inv = 1.0 / dir;
    var t_far = t_max;
    var best = 0u;
    var best_uv = vec2(0.0);
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
            for (var i = first; i < first + count; i++) {
                if bitcast<u32>(bvh_corner(triangles, i, 0u).w) == skip {
                    continue;
                }
                let r = moller_trumbore(triangles, i, origin, dir, t_min, t_far);
                if r.w > 0.0 {
                    t_far = r.x;
                    best = i;
                    best_uv = r.yz;
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
    let c0 = bvh_corner(triangles, best, 0u);
    let geometric = cross(bvh_corner(triangles, best, 1u).xyz - c0.xyz, bvh_corner(triangles, best, 2u).xyz - c0.xyz);
    var g = vec3(0.0);
    if dot(geometric, geometric) > 0.0 {
        g = normalize(geometric);
    }
    let n = bvh_corner(triangles, best, 3u).xyz * (1.0 - best_uv.x - best_uv.y) + bvh_corner(triangles, best, 4u).xyz * best_uv.x
        + bvh_corner(triangles, best, 5u).xyz * best_uv.y;
    var normal = g;
    if dot(n, n) > 0.0 {
        normal = normalize(n);
    }
    return TriangleHit(t_far, bitcast<u32>(c0.w), normal, g);
}
