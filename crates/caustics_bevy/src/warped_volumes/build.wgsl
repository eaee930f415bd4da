// Caustic volumes built on the GPU: the WGSL twin of `build_generator_volumes` in
// `caustics_core::volumes`, one job (a generator under one light, in one colour
// channel) at a time, in five dispatches:
//
// - `vertex_rays`: each vertex placed in the world, its ray reflected or refracted with
//   its Fresnel weight, whether an occluder hides it from the light, and where its ray
//   first meets an occluder (the scene's other surfaces, `bevy_caustics::triangle_bvh`);
// - `slicing_axis`: the rays' sum, the axis shared by the triangles it fits (one
//   workgroup);
// - `triangle_areas`: each triangle's area coefficients in a frame along that axis;
// - `vertex_fans`: each vertex's fan coefficients in a frame along that axis, summed
//   from its triangles', which the triangles that slice along it share;
// - `triangle_volumes`: each triangle's caustic volume (frame, flattening, area and fan
//   coefficients of §3.4, hit planes, the bounding prism of §4.3), appended to the
//   volumes the passes draw; a dropped triangle (unlit, shadowed, TIR, grazing,
//   degenerate) is counted, with its flux, and leaves no gap.
//
// `counters` starts with the passes' indirect draw (36 vertices, the volumes kept as
// instances), then the counts and fluxes of `BuildStats` (`GpuBuildStats` in
// `compute.rs`).

#import bevy_caustics::optics::{reflect_about, refract_through, fresnel_transmittance}
#import bevy_caustics::triangle_bvh::intersect_triangles
#import bevy_caustics::warped_volumes::{CORNERS_TEXEL, CausticVolume, HIT_PLANES_TEXEL, SURFACE_CORNERS_TEXEL, record_at, texel, volume_at, volume_capacity}

struct BuildJob {
    world_from_local: mat4x4<f32>,
    normal_from_local: mat4x4<f32>,  // the inverse transpose of its 3 × 3 part
    light: vec4<f32>,       // w 0: directional, xyz its unit travel direction; w 1: xyz the position
    spot: vec4<f32>,        // a spot's unit axis, w cos θₒ
    light_power: vec4<f32>, // x irradiance (directional) or intensity, y the spot's 1/(cos θᵢ − cos θₒ) (0: no cone), z 1/range² (0: none), w 1: the beams are drawn
    color: vec4<f32>,       // the channel's flux colour; w the index of refraction (0: a mirror)
    bounds_lo: vec4<f32>,   // the receivers' bounds; w the smallest ray cosine
    bounds_hi: vec4<f32>,   // w 1: lit from behind too
    counts: vec4<u32>,      // vertices, triangles, the occluders' BVH instance offset (0: none), the generator's own mesh there
    vertex: vec4<u32>,      // in `vertices`: the first vertex's word, the vertex stride, the position's and the normal's word in a vertex
}

// One vertex's ray (`VertexRay` with its shadow and first hit).
struct VertexRay {
    position: vec4<f32>,   // world; w 1 when the mesh's data there is finite
    normal: vec4<f32>,     // world, unit
    direction: vec4<f32>,  // unit; w the Fresnel weight; zero under total internal reflection
    incident: vec4<f32>,   // the light's travel direction; w the irradiance (0 in shadow)
    hit: vec4<f32>,        // where the ray first meets an occluder; w 1 when it does
    hit_normal: vec4<f32>, // that surface's geometric normal; w 1 when an occluder hides the vertex
    fan: vec4<f32>,        // `vertex_fans`, where there is a shared axis: the fan's coefficients along it; w 0 where it cannot be flattened
}

// `compute::RAY_TEXELS`.
const RAY_TEXELS: u32 = 7u;

@group(0) @binding(0) var<uniform> job: BuildJob;
// The generator's vertices where Bevy draws them from (or a copy, for a mesh without
// normals), read through `job.vertex`.
@group(0) @binding(1) var<storage, read> vertices: array<f32>;
@group(0) @binding(3) var<storage, read> triangles: array<u32>;
// Each vertex's first entry in the fans' list (one more than the vertices), then that
// list: the triangles around each vertex.
@group(0) @binding(4) var<storage, read> fans: array<u32>;
// `triangle_areas`: each triangle's area coefficients along the shared slicing axis,
// in the frame at its first vertex; w 0 where it cannot be flattened.
@group(0) @binding(5) var<storage, read_write> areas: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read> owned_sides: array<u32>;
// One per vertex, then the slicing axis (w 1 when there is one).
@group(0) @binding(7) var<storage, read_write> rays: array<VertexRay>;
@group(0) @binding(8) var volumes: texture_storage_2d<rgba32float, write>;
@group(0) @binding(9) var<storage, read_write> counters: array<atomic<u32>>;
// `rays` as `triangle_volumes` reads them, copied into a texture once the fans are in
// (`compute::build_volumes`): one rgba32float texel a field, whole rays to a row
// (`build::rays_per_row`). Lavapipe loads a texel about five times faster than a
// storage buffer's four words at scattered places (`types.wgsl`).
@group(0) @binding(10) var ray_texels: texture_2d<f32>;

// `build::SHARED_AXIS_MIN_COS`, `volumes::OCCLUSION_SLACK`.
const SHARED_AXIS_MIN_COS: f32 = 0.25;
const OCCLUSION_SLACK: f32 = 1.0e-2;
const INFINITY: f32 = 3.4028235e38;
// Where the counts of `GpuBuildStats` start in `counters`, and the fluxes.
const INSTANCES: u32 = 1u;
const UNLIT: u32 = 4u;
const SHADOWED: u32 = 5u;
const TOTAL_INTERNAL_REFLECTION: u32 = 6u;
const GRAZING: u32 = 7u;
const DEGENERATE: u32 = 8u;
const FLUX: u32 = 9u;
const DROPPED_FLUX: u32 = 12u;
const SURFACE_SLABS: u32 = 15u;
const ESCAPING: u32 = 16u;

fn is_finite3(v: vec3<f32>) -> bool {
    return all(abs(v) <= vec3(INFINITY));
}

// `Vec3::try_normalize`: zero when `v` has no finite, non-zero length.
fn try_normalize(v: vec3<f32>) -> vec3<f32> {
    let l = length(v);
    if l > 0.0 && l <= INFINITY {
        return v / l;
    }
    return vec3(0.0);
}

// An f32 added to a counter word holding f32 bits.
fn add_float(word: u32, value: f32) {
    var old = atomicLoad(&counters[word]);
    loop {
        let swap = atomicCompareExchangeWeak(&counters[word], old, bitcast<u32>(bitcast<f32>(old) + value));
        if swap.exchanged {
            break;
        }
        old = swap.old_value;
    }
}

fn add_flux(word: u32, flux: vec3<f32>) {
    add_float(word, flux.x);
    add_float(word + 1u, flux.y);
    add_float(word + 2u, flux.z);
}

fn vertex_vec3(i: u32, word: u32) -> vec3<f32> {
    let at = job.vertex.x + i * job.vertex.y + word;
    return vec3(vertices[at], vertices[at + 1u], vertices[at + 2u]);
}

fn position_at(i: u32) -> vec3<f32> {
    return vertex_vec3(i, job.vertex.z);
}

fn normal_at(i: u32) -> vec3<f32> {
    return vertex_vec3(i, job.vertex.w);
}

// `Light::incident`: the light's travel direction at `p` and the irradiance there on a
// plane across it.
fn incident(p: vec3<f32>) -> vec4<f32> {
    if job.light.w == 0.0 {
        return vec4(job.light.xyz, job.light_power.x);
    }
    let d = p - job.light.xyz;
    let r2 = max(dot(d, d), 1.0e-12);
    let dir = d / sqrt(r2);
    var cone = 1.0;
    if job.light_power.y > 0.0 {
        let s = clamp((dot(dir, job.spot.xyz) - job.spot.w) * job.light_power.y, 0.0, 1.0);
        cone = s * s;
    }
    return vec4(dir, job.light_power.x / r2 * cone);
}

@compute @workgroup_size(64)
fn vertex_rays(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= job.counts.x {
        return;
    }
    // `TriMesh::new` normalises the normals, `TriMesh::transformed` places both.
    let local_normal = try_normalize(normal_at(i));
    let p = (job.world_from_local * vec4(position_at(i), 1.0)).xyz;
    var n = try_normalize((job.normal_from_local * vec4(local_normal, 0.0)).xyz);
    if all(n == vec3(0.0)) {
        n = local_normal;
    }
    var ray: VertexRay;
    ray.position = vec4(p, select(0.0, 1.0, is_finite3(p) && any(local_normal != vec3(0.0))));
    ray.normal = vec4(n, 0.0);
    let l = incident(p);
    ray.incident = l;
    // `vertex_ray`.
    if job.color.w == 0.0 {
        var r = try_normalize(reflect_about(l.xyz, n));
        if all(r == vec3(0.0)) {
            r = l.xyz;
        }
        ray.direction = vec4(r, 1.0);
    } else {
        // The inside (index `ior`) is opposite the normal.
        let ior = job.color.w;
        let eta = select(ior, 1.0 / ior, dot(l.xyz, n) < 0.0);
        let t = refract_through(l.xyz, n, eta);
        if t.w > 0.0 {
            ray.direction = vec4(t.xyz, fresnel_transmittance(dot(l.xyz, n), eta));
        }
    }
    // `SceneBvh::hides` and `first_hit`.
    let occluders = job.counts.z;
    let hair = 1.0e-5 * (1.0 + max(max(abs(p.x), abs(p.y)), abs(p.z)));
    if occluders != 0u {
        var to_light = -job.light.xyz;
        var distance = INFINITY;
        if job.light.w != 0.0 {
            to_light = try_normalize(job.light.xyz - p);
            distance = length(job.light.xyz - p);
        }
        if intersect_triangles(occluders, job.counts.w, p, to_light, hair, distance).t >= 0.0 {
            ray.incident.w = 0.0;
            ray.hit_normal.w = 1.0;
        }
        if any(ray.direction.xyz != vec3(0.0)) {
            let hit = intersect_triangles(occluders, job.counts.w, p, ray.direction.xyz, hair, INFINITY);
            if hit.t >= 0.0 {
                ray.hit = vec4(p + hit.t * ray.direction.xyz, 1.0);
                ray.hit_normal = vec4(hit.geometric_normal, ray.hit_normal.w);
            }
        }
    }
    rays[i] = ray;
}

var<workgroup> partial: array<vec3<f32>, 256>;

// The sum of every ray's direction, normalised: the slicing axis the triangles share
// where it fits them.
@compute @workgroup_size(256)
fn slicing_axis(@builtin(local_invocation_index) lane: u32) {
    var sum = vec3(0.0);
    for (var i = lane; i < job.counts.x; i += 256u) {
        sum += rays[i].direction.xyz;
    }
    partial[lane] = sum;
    workgroupBarrier();
    for (var width = 128u; width > 0u; width /= 2u) {
        if lane < width {
            partial[lane] += partial[lane + width];
        }
        workgroupBarrier();
    }
    if lane == 0u {
        let axis = try_normalize(partial[0]);
        rays[job.counts.x].direction = vec4(axis, select(0.0, 1.0, any(axis != vec3(0.0))));
    }
}

// A triangle's local frame (`Frame`): origin and axes.
struct Frame {
    origin: vec3<f32>,
    x: vec3<f32>,
    y: vec3<f32>,
    z: vec3<f32>,
}

fn local(f: Frame, p: vec3<f32>) -> vec3<f32> {
    let d = p - f.origin;
    return vec3(dot(d, f.x), dot(d, f.y), dot(d, f.z));
}

fn local_dir(f: Frame, d: vec3<f32>) -> vec3<f32> {
    return vec3(dot(d, f.x), dot(d, f.y), dot(d, f.z));
}

fn world(f: Frame, p: vec3<f32>) -> vec3<f32> {
    return f.origin + world_dir(f, p);
}

fn world_dir(f: Frame, d: vec3<f32>) -> vec3<f32> {
    return f.x * d.x + f.y * d.y + f.z * d.z;
}

// `flattened`: the vertex moved along its ray into y = 0 and the ray scaled to r_y = 1;
// w 0 when the ray does not leave the plane steeply enough.
struct Flat {
    v: vec3<f32>,
    r: vec3<f32>,
    ok: bool,
}

fn flattened(f: Frame, p: vec3<f32>, ray: vec3<f32>) -> Flat {
    var r = local_dir(f, ray);
    if !(r.y >= job.bounds_lo.w) {
        return Flat(vec3(0.0), vec3(0.0), false);
    }
    r = r / r.y;
    let v = local(f, p);
    return Flat(v - v.y * r, r, true);
}

// `area_coefficients`: (a, b, c) of A(α) = a + bα + cα² (§3.4).
fn area_coefficients(v0: vec3<f32>, v1: vec3<f32>, v2: vec3<f32>, r0: vec3<f32>, r1: vec3<f32>, r2: vec3<f32>) -> vec3<f32> {
    let k1 = v1 - v0;
    let k2 = v2 - v0;
    let l1 = r1 - r0;
    let l2 = r2 - r0;
    return vec3(
        k1.z * k2.x - k1.x * k2.z,
        k1.z * l2.x - k1.x * l2.z + l1.z * k2.x - l1.x * k2.z,
        l1.z * l2.x - l1.x * l2.z,
    );
}

// `Frame::hit_plane`.
fn hit_plane(f: Frame, point: vec3<f32>, normal: vec3<f32>, r: vec3<f32>, depth: f32) -> vec4<f32> {
    var n = local_dir(f, normal);
    if dot(n, r) > 0.0 {
        n = -n;
    }
    let q = local(f, point);
    let slack = max(OCCLUSION_SLACK * q.y, 1.0e-4 * depth);
    let plane = vec4(n, slack - dot(n, q));
    if is_finite3(plane.xyz) && abs(plane.w) <= INFINITY {
        return plane;
    }
    return vec4(0.0, 0.0, 0.0, 1.0);
}

// `occluded_beyond`: the depth past which every point is behind hit planes weighing
// more than one half (x), found when y is 1.
fn occluded_beyond(v: array<vec3<f32>, 3>, r: array<vec3<f32>, 3>, planes: array<vec4<f32>, 3>) -> vec2<f32> {
    var end = 0.0;
    for (var i = 0u; i < 3u; i++) {
        let plane = planes[i];
        if all(plane == vec4(0.0, 0.0, 0.0, 1.0)) {
            return vec2(0.0);
        }
        for (var j = 0u; j < 3u; j++) {
            var at = v[i];
            var ray = r[i];
            if j != i {
                at = 0.25 * v[i] + 0.75 * v[j];
                ray = 0.25 * r[i] + 0.75 * r[j];
            }
            let start = dot(plane.xyz, at) + plane.w;
            let slope = dot(plane.xyz, ray);
            if !(slope < 0.0) {
                return vec2(0.0);
            }
            end = max(end, -start / slope);
        }
    }
    end *= 1.0 + 1.0e-3;
    if !(end <= INFINITY) {
        return vec2(0.0);
    }
    return vec2(end, 1.0);
}

// `build::ONE_SURFACE`, `build::ONE_SURFACE_COS`, `build::SLAB_MARGIN`.
const ONE_SURFACE: f32 = 0.02;
const ONE_SURFACE_COS: f32 = 0.99;
const SLAB_MARGIN: f32 = 1.0e-3;

// `SurfaceSlab` in the local frame (found when the rays land on one surface), and
// the depths between which the volume crosses it.
struct Slab {
    normal: vec3<f32>,
    near: f32,
    far: f32,
    first: f32,
    last: f32,
    found: bool,
}

// Where a ray (vertex v, scaled ray r) crosses the plane n·p = offset going deeper (x);
// y 0 where it does not.
fn crossing(n: vec3<f32>, offset: f32, v: vec3<f32>, r: vec3<f32>) -> vec2<f32> {
    let towards = dot(n, r);
    let at = (offset - dot(n, v)) / select(1.0, towards, towards != 0.0);
    if !(towards > 0.0) || !(at > 0.0 && at <= INFINITY) {
        return vec2(0.0);
    }
    return vec2(at, 1.0);
}

// `local_slab`: the slab around the one surface the rays that `hit` land on (at
// `points` with `normals`, local), which the others hold to.
fn local_slab(v: array<vec3<f32>, 3>, r: array<vec3<f32>, 3>, hit: vec3<bool>, points: array<vec3<f32>, 3>, hit_normals: array<vec3<f32>, 3>) -> Slab {
    var slab = Slab(vec3(0.0), 0.0, 0.0, 0.0, 0.0, false);
    let sum = r[0] + r[1] + r[2];
    var normals = hit_normals;
    var total = vec3(0.0);
    // The first ray that hits: a ray that meets nothing holds to its plane.
    var first_hit = 3u;
    for (var i = 0u; i < 3u; i++) {
        if dot(normals[i], sum) < 0.0 {
            normals[i] = -normals[i];
        }
        if hit[i] {
            total += normals[i];
            first_hit = min(first_hit, i);
        }
    }
    let normal = try_normalize(total);
    if all(normal == vec3(0.0)) || first_hit == 3u {
        return slab;
    }
    for (var i = 0u; i < 3u; i++) {
        if hit[i] && !(dot(normals[i], normal) >= ONE_SURFACE_COS) {
            return slab;
        }
    }
    var deepest = 0.0;
    var near = INFINITY;
    var far = -INFINITY;
    for (var j = 0u; j < 3u; j++) {
        let mine = select(first_hit, j, hit[j]);
        let own = crossing(normals[mine], dot(normals[mine], points[mine]), v[j], r[j]);
        if own.y == 0.0 {
            return slab;
        }
        for (var i = 0u; i < 3u; i++) {
            if !hit[i] {
                continue;
            }
            let at = crossing(normals[i], dot(normals[i], points[i]), v[j], r[j]);
            if at.y == 0.0 || !(abs(at.x - own.x) <= ONE_SURFACE * own.x) {
                return slab;
            }
            deepest = max(deepest, at.x);
        }
        if hit[j] {
            near = min(near, dot(normal, points[j]));
            far = max(far, dot(normal, points[j]));
        }
    }
    let margin = SLAB_MARGIN * deepest;
    slab.normal = normal;
    slab.near = near - margin;
    slab.far = far + margin;
    var first = INFINITY;
    var last = 0.0;
    for (var j = 0u; j < 3u; j++) {
        let near = crossing(normal, slab.near, v[j], r[j]);
        let far = crossing(normal, slab.far, v[j], r[j]);
        if near.y == 0.0 || far.y == 0.0 {
            return slab;
        }
        first = min(first, near.x);
        last = max(last, far.x);
    }
    slab.first = (1.0 - SLAB_MARGIN) * first;
    slab.last = (1.0 + SLAB_MARGIN) * last;
    slab.found = true;
    return slab;
}

fn signed_area_xz(a: vec3<f32>, b: vec3<f32>, c: vec3<f32>) -> f32 {
    let e1 = b - a;
    let e2 = c - a;
    return e1.z * e2.x - e1.x * e2.z;
}

// `cut_to_slab`: each side line of a local shape from where it crosses the slab's near
// plane to where it crosses the far one; the shape as it is where one does not.
fn cut_to_slab(shape: array<vec3<f32>, 8>, slab: Slab) -> array<vec3<f32>, 8> {
    var cut = shape;
    for (var k = 0u; k < 4u; k++) {
        let top = shape[k];
        let bottom = shape[k + 4u];
        let a = dot(slab.normal, top);
        let b = dot(slab.normal, bottom);
        if !(a < slab.near && slab.far < b) {
            return shape;
        }
        cut[k] = mix(top, bottom, (slab.near - a) / (b - a));
        cut[k + 4u] = mix(top, bottom, (slab.far - a) / (b - a));
    }
    return cut;
}

// `BoundingShape::to_world`: local corners in the world, ordered to face outwards
// (`orient_outwards`).
fn to_world_outwards(f: Frame, local_corners: array<vec3<f32>, 8>) -> array<vec3<f32>, 8> {
    var corners = local_corners;
    var centre = vec3(0.0);
    for (var c = 0u; c < 8u; c++) {
        corners[c] = world(f, corners[c]);
        centre += corners[c];
    }
    centre /= 8.0;
    if dot(cross(corners[1] - corners[0], corners[2] - corners[0]), corners[0] - centre) < 0.0 {
        let c1 = corners[1];
        let c5 = corners[5];
        corners[1] = corners[3];
        corners[3] = c1;
        corners[5] = corners[7];
        corners[7] = c5;
    }
    return corners;
}

// `BoundingShape::new`, in the local frame: the tight prism of §4.3 when it exists and
// is smaller than the box, else the box.
fn bounding_shape(top: array<vec3<f32>, 3>, rays: array<vec3<f32>, 3>, depth: f32) -> array<vec3<f32>, 8> {
    var v = top;
    var b = array(v[0] + depth * rays[0], v[1] + depth * rays[1], v[2] + depth * rays[2]);
    // `local_box`.
    var lo = min(min(v[0], v[1]), v[2]);
    var hi = max(max(v[0], v[1]), v[2]);
    lo = min(lo, min(min(b[0], b[1]), b[2]));
    hi = max(hi, max(max(b[0], b[1]), b[2]));
    // From the top's y (0 for the whole beam, deeper for a slice of it) down by `depth`.
    let y = v[0].y;
    let box = array(
        vec3(lo.x, y, lo.z), vec3(hi.x, y, lo.z), vec3(hi.x, y, hi.z), vec3(lo.x, y, hi.z),
        vec3(lo.x, y + depth, lo.z), vec3(hi.x, y + depth, lo.z), vec3(hi.x, y + depth, hi.z), vec3(lo.x, y + depth, hi.z),
    );
    // `tight_prism`: per edge, the plane through it and one bottom vertex that keeps
    // all three bottom vertices inside.
    var planes: array<vec4<f32>, 3>;
    var tight = true;
    let tolerance = 1.0e-5 * (1.0 + depth);
    for (var e = 0u; e < 3u; e++) {
        let v0 = v[e];
        let edge = v[(e + 1u) % 3u] - v0;
        let v2 = v[(e + 2u) % 3u];
        var found = false;
        for (var k = 0u; k < 3u && !found; k++) {
            let to_bottom = b[k] - v0;
            var n = cross(edge, to_bottom);
            if dot(n, n) <= 1.0e-20 * dot(edge, edge) * dot(to_bottom, to_bottom) {
                continue;
            }
            n = normalize(n);
            var d = -dot(n, v0);
            if dot(n, v2) + d > 0.0 {
                n = -n;
                d = -d;
            }
            if dot(n, b[0]) + d <= tolerance && dot(n, b[1]) + d <= tolerance && dot(n, b[2]) + d <= tolerance {
                planes[e] = vec4(n, d);
                found = true;
            }
        }
        tight = tight && found;
    }
    var bottom: array<vec3<f32>, 3>;
    for (var i = 0u; i < 3u && tight; i++) {
        let dir = cross(planes[(i + 2u) % 3u].xyz, planes[i].xyz);
        if abs(dir.y) < 1.0e-6 * length(dir) || dot(dir, dir) == 0.0 {
            tight = false;
        } else {
            bottom[i] = v[i] + dir * (depth / dir.y);
        }
    }
    if tight {
        let top_area = signed_area_xz(v[0], v[1], v[2]);
        let bottom_area = signed_area_xz(bottom[0], bottom[1], bottom[2]);
        tight = top_area * bottom_area > 0.0 && is_finite3(bottom[0]) && is_finite3(bottom[1]) && is_finite3(bottom[2]);
    }
    if tight {
        // `prism_volume` (Simpson's rule) against `box_volume`.
        let mid = array(0.5 * (v[0] + bottom[0]), 0.5 * (v[1] + bottom[1]), 0.5 * (v[2] + bottom[2]));
        let prism_depth = bottom[0].y - v[0].y;
        let areas = 0.5 * abs(signed_area_xz(v[0], v[1], v[2])) + 4.0 * 0.5 * abs(signed_area_xz(mid[0], mid[1], mid[2]))
            + 0.5 * abs(signed_area_xz(bottom[0], bottom[1], bottom[2]));
        let box_volume = length(box[1] - box[0]) * length(box[3] - box[0]) * length(box[4] - box[0]);
        if prism_depth / 6.0 * areas <= box_volume {
            return array(v[0], v[1], v[2], v[2], bottom[0], bottom[1], bottom[2], bottom[2]);
        }
    }
    return box;
}

// `tracer::orthonormal_basis(y).0`: a unit vector perpendicular to the unit `y`.
fn perpendicular(y: vec3<f32>) -> vec3<f32> {
    let sign = select(1.0, -1.0, (bitcast<u32>(y.z) >> 31u) != 0u);
    let a = -1.0 / (sign + y.z);
    return vec3(1.0 + sign * y.x * y.x * a, sign * y.x * y.y * a, -sign * y.x);
}

// Entry `k` of the fans' list: a triangle.
fn fan_triangle(k: u32) -> u32 {
    return fans[job.counts.x + 1u + k];
}

// Triangle `t`'s area coefficients, its vertices' rays flattened into frame `f`
// (§3.4); w 0 where one cannot be flattened.
fn flattened_area(f: Frame, t: u32) -> vec4<f32> {
    var fv: array<vec3<f32>, 3>;
    var fr: array<vec3<f32>, 3>;
    for (var j = 0u; j < 3u; j++) {
        let corner = triangles[3u * t + j];
        let flat = flattened(f, rays[corner].position.xyz, rays[corner].direction.xyz);
        if !flat.ok {
            return vec4(0.0);
        }
        fv[j] = flat.v;
        fr[j] = flat.r;
    }
    return vec4(area_coefficients(fv[0], fv[1], fv[2], fr[0], fr[1], fr[2]), 1.0);
}

// The area coefficients of the fan around `vertex`, flattened into frame `f` and
// summed (§3.4, Fig. 5); w 0 where a triangle of it cannot be flattened.
fn fan_sum(f: Frame, vertex: u32) -> vec4<f32> {
    var sum = vec3(0.0);
    for (var k = fans[vertex]; k < fans[vertex + 1u]; k++) {
        let area = flattened_area(f, fan_triangle(k));
        if area.w == 0.0 {
            return vec4(0.0);
        }
        sum += area.xyz;
    }
    return vec4(sum, 1.0);
}

// `fan_sum` at a vertex in the frame of a triangle that slices along the shared axis
// `y` (origin `origin`, its z mirrored or not), from the vertex's own (`vertex_fans`):
// the two frames differ by a turn about y, which keeps areas across it, a height h,
// which shifts the depth (A(α + h)), and perhaps a mirror, which negates the areas.
fn shifted_fan(ray: VertexRay, origin: vec3<f32>, y: vec3<f32>, mirrored: bool) -> vec4<f32> {
    let s = shifted(ray.fan.xyz, dot(origin - ray.position.xyz, y));
    return vec4(select(s, -s, mirrored), ray.fan.w);
}

// `shifted_fan`'s shift: area coefficients found in a frame along the shared axis, in
// the frame whose origin lies `h` deeper along it (A(α + h)).
fn shifted(s: vec3<f32>, h: f32) -> vec3<f32> {
    return vec3(s.x + h * (s.y + h * s.z), s.y + 2.0 * h * s.z, s.z);
}

// The frame at `origin` along the shared slicing axis `y` (`perpendicular` its x).
fn axis_frame(origin: vec3<f32>, y: vec3<f32>) -> Frame {
    let x = perpendicular(y);
    return Frame(origin, x, y, cross(x, y));
}

// Each triangle's area coefficients in the frame along the shared slicing axis at its
// first vertex, flattened once here rather than once in each of its vertices' fans.
@compute @workgroup_size(64)
fn triangle_areas(@builtin(global_invocation_id) id: vec3<u32>) {
    let t = id.x;
    let axis = rays[job.counts.x].direction;
    // Without a shared axis no fan reads them.
    if t >= job.counts.y || axis.w == 0.0 {
        return;
    }
    areas[t] = flattened_area(axis_frame(rays[triangles[3u * t]].position.xyz, axis.xyz), t);
}

// Each vertex's fan sum in the frame at the vertex along the shared slicing axis
// (`axis_frame`), once a vertex rather than once for each of the triangles around it
// that slice along the axis (`shifted_fan`): its triangles' `areas`, each shifted from
// its first vertex's frame, which differs from the vertex's only along the axis.
@compute @workgroup_size(64)
fn vertex_fans(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    let axis = rays[job.counts.x].direction;
    // Without a shared axis no triangle reads the fans.
    if i >= job.counts.x || axis.w == 0.0 {
        return;
    }
    let position = rays[i].position.xyz;
    var sum = vec3(0.0);
    for (var k = fans[i]; k < fans[i + 1u]; k++) {
        let t = fan_triangle(k);
        let area = areas[t];
        if area.w == 0.0 {
            rays[i].fan = vec4(0.0);
            return;
        }
        sum += shifted(area.xyz, dot(position - rays[triangles[3u * t]].position.xyz, axis.xyz));
    }
    rays[i].fan = vec4(sum, 1.0);
}

// The flux a triangle's volume keeps and the flux it drops, per channel.
struct TriangleFlux {
    kept: vec3<f32>,
    dropped: vec3<f32>,
}

// Vertex `v`'s ray from `ray_texels`; a kernel loads only the fields it reads.
fn vertex_ray(v: u32) -> VertexRay {
    let at = record_at(textureDimensions(ray_texels).x, RAY_TEXELS, v);
    return VertexRay(
        texel(ray_texels, at, 0u), texel(ray_texels, at, 1u), texel(ray_texels, at, 2u), texel(ray_texels, at, 3u),
        texel(ray_texels, at, 4u), texel(ray_texels, at, 5u), texel(ray_texels, at, 6u),
    );
}

// A dropped triangle's flux: its vertices' mean weight over its area (half the length
// of its edges' cross product).
fn dropped(colour: vec3<f32>, weight: vec3<f32>, cross_length: f32) -> TriangleFlux {
    return TriangleFlux(vec3(0.0), colour * ((weight.x + weight.y + weight.z) / 3.0 * 0.5 * cross_length));
}

// Triangle `t`'s caustic volume, appended to `volumes` where it is kept, and its flux,
// which `triangle_volumes` adds up.
fn triangle_volume(t: u32) -> TriangleFlux {
    let none = TriangleFlux(vec3(0.0), vec3(0.0));
    if t >= job.counts.y {
        return none;
    }
    let tri = vec3(triangles[3u * t], triangles[3u * t + 1u], triangles[3u * t + 2u]);
    var p: array<vec3<f32>, 3>;
    var valid = true;
    for (var i = 0u; i < 3u; i++) {
        let position = vertex_ray(tri[i]).position;
        p[i] = position.xyz;
        valid = valid && position.w > 0.0;
    }
    let edge_cross = cross(p[1] - p[0], p[2] - p[0]);
    let longest = max(max(dot(p[1] - p[0], p[1] - p[0]), dot(p[2] - p[0], p[2] - p[0])), dot(p[2] - p[1], p[2] - p[1]));
    if !valid || dot(edge_cross, edge_cross) <= (1.0e-12 * longest) * longest || !is_finite3(edge_cross) {
        atomicAdd(&counters[DEGENERATE], 1u);
        return none;
    }
    let cross_length = length(edge_cross);
    let geometric = edge_cross / cross_length;
    // The front is the side the vertex normals face.
    let front = vertex_ray(tri.x).normal.xyz + vertex_ray(tri.y).normal.xyz + vertex_ray(tri.z).normal.xyz;
    var unit: array<vec3<f32>, 3>;
    var weight = vec3(0.0);
    var lit = false;
    var tir = false;
    var all_shadowed = true;
    for (var i = 0u; i < 3u; i++) {
        let ray = vertex_ray(tri[i]);
        unit[i] = ray.direction.xyz;
        var fresnel = ray.direction.w;
        if all(ray.direction.xyz == vec3(0.0)) {
            tir = true;
            fresnel = 1.0;
        }
        // Irradiance on the triangle's plane at the vertex, after Fresnel.
        let cos = abs(dot(ray.incident.xyz, geometric));
        weight[i] = ray.incident.w * cos * fresnel;
        lit = lit || (ray.incident.w * cos > 0.0 && (job.bounds_hi.w > 0.0 || dot(ray.incident.xyz, front) < 0.0));
        all_shadowed = all_shadowed && ray.hit_normal.w > 0.0;
    }
    let colour = job.color.xyz;
    if !lit {
        if job.counts.z != 0u && all_shadowed {
            atomicAdd(&counters[SHADOWED], 1u);
        } else {
            atomicAdd(&counters[UNLIT], 1u);
        }
        return none;
    }
    if tir {
        atomicAdd(&counters[TOTAL_INTERNAL_REFLECTION], 1u);
        return dropped(colour, weight, cross_length);
    }
    var normal = geometric;
    if dot(unit[0] + unit[1] + unit[2], normal) < 0.0 {
        normal = -normal;
    }
    // The generator's shared slicing axis where it fits this triangle, else its normal.
    let axis = rays[job.counts.x].direction;
    let along_axis = axis.w > 0.0 && dot(unit[0], axis.xyz) >= SHARED_AXIS_MIN_COS && dot(unit[1], axis.xyz) >= SHARED_AXIS_MIN_COS
        && dot(unit[2], axis.xyz) >= SHARED_AXIS_MIN_COS && dot(normal, axis.xyz) >= SHARED_AXIS_MIN_COS;
    let y = select(normal, axis.xyz, along_axis);
    // The origin is the vertex lowest along y.
    var lowest = 0u;
    for (var i = 1u; i < 3u; i++) {
        if dot(p[i], y) < dot(p[lowest], y) {
            lowest = i;
        }
    }
    let to_next = p[(lowest + 1u) % 3u] - p[lowest];
    var x = try_normalize(to_next - y * dot(to_next, y));
    if all(x == vec3(0.0)) {
        x = perpendicular(y);
    }
    var frame = Frame(p[lowest], x, y, cross(x, y));
    var v: array<vec3<f32>, 3>;
    var r: array<vec3<f32>, 3>;
    for (var i = 0u; i < 3u; i++) {
        let f = flattened(frame, p[i], unit[i]);
        if !f.ok {
            atomicAdd(&counters[GRAZING], 1u);
            return dropped(colour, weight, cross_length);
        }
        v[i] = f.v;
        r[i] = f.r;
    }
    var abc = area_coefficients(v[0], v[1], v[2], r[0], r[1], r[2]);
    let mirrored = abc.x < 0.0;
    if mirrored {
        // Mirroring z keeps every ray's height.
        frame.z = -frame.z;
        for (var i = 0u; i < 3u; i++) {
            v[i].z = -v[i].z;
            r[i].z = -r[i].z;
        }
        abc = area_coefficients(v[0], v[1], v[2], r[0], r[1], r[2]);
    }
    // The flux crossing the triangle crosses its flattened image too.
    weight *= cross_length / abc.x;
    let lo = job.bounds_lo.xyz;
    let hi = job.bounds_hi.xyz;
    var depth = -INFINITY;
    for (var c = 0u; c < 8u; c++) {
        let corner = vec3(select(lo.x, hi.x, (c & 1u) != 0u), select(lo.y, hi.y, (c & 2u) != 0u), select(lo.z, hi.z, (c & 4u) != 0u));
        depth = max(depth, local(frame, corner).y);
    }
    depth *= 1.0 + 1.0e-3;
    if !(depth > 0.0) || !(abc.x > 0.0) || !is_finite3(abc) {
        atomicAdd(&counters[DEGENERATE], 1u);
        return dropped(colour, weight, cross_length);
    }
    // Per-vertex coefficients from the fan around each vertex, flattened into this
    // frame and summed (§3.4, Fig. 5; the CPU twin flattens every fan in the triangle's
    // frame, as `fan_sum` does off the shared axis); the triangle's own where it
    // cannot be flattened.
    var fan = array(abc, abc, abc);
    for (var i = 0u; i < 3u; i++) {
        var sum: vec4<f32>;
        if along_axis {
            sum = shifted_fan(vertex_ray(tri[i]), frame.origin, y, mirrored);
        } else {
            sum = fan_sum(frame, tri[i]);
        }
        if sum.w > 0.0 && sum.x > 0.0 && is_finite3(sum.xyz) {
            fan[i] = sum.xyz;
        }
    }
    var out: CausticVolume;
    out.origin = vec4(frame.origin, depth);
    out.axis_x = vec4(frame.x, 0.0);
    out.axis_y = vec4(frame.y, 0.0);
    out.axis_z = vec4(frame.z, 0.0);
    out.surface_normal = vec4(normal, f32(owned_sides[t]));
    out.vertex_x = vec4(v[0].x, v[1].x, v[2].x, 0.0);
    out.vertex_z = vec4(v[0].z, v[1].z, v[2].z, 0.0);
    out.ray_x = vec4(r[0].x, r[1].x, r[2].x, 0.0);
    out.ray_z = vec4(r[0].z, r[1].z, r[2].z, 0.0);
    out.fan_a = vec4(fan[0].x, fan[1].x, fan[2].x, 0.0);
    out.fan_b = vec4(fan[0].y, fan[1].y, fan[2].y, 0.0);
    out.fan_c = vec4(fan[0].z, fan[1].z, fan[2].z, 0.0);
    out.triangle_abc = vec4(abc, 0.0);
    out.flux = vec4(weight, 0.0);
    out.color = vec4(colour, 0.0);
    var light_distance = vec3(0.0);
    for (var i = 0u; i < 3u; i++) {
        var to_vertex = 0.0;
        if job.light.w != 0.0 {
            to_vertex = length(p[i] - job.light.xyz);
        }
        light_distance[i] = to_vertex - local(frame, p[i]).y * length(r[i]);
        let ray = vertex_ray(tri[i]);
        out.hit_planes[i] = vec4(0.0, 0.0, 0.0, 1.0);
        if ray.hit.w > 0.0 {
            out.hit_planes[i] = hit_plane(frame, ray.hit.xyz, ray.hit_normal.xyz, r[i], depth);
        }
    }
    out.light_distance = vec4(light_distance, job.light_power.z);
    // The volume ends where its rays have met the surfaces they hit; where they land
    // on one surface, the surface pass draws only the slab around it.
    var points: array<vec3<f32>, 3>;
    var normals: array<vec3<f32>, 3>;
    // Which of the three rays meet a surface, and how many.
    var hit = vec3(false);
    var hits = 0u;
    for (var i = 0u; i < 3u; i++) {
        let ray = vertex_ray(tri[i]);
        hit[i] = ray.hit.w > 0.0;
        hits += select(0u, 1u, hit[i]);
        points[i] = local(frame, ray.hit.xyz);
        normals[i] = local_dir(frame, ray.hit_normal.xyz);
    }
    var slab = Slab(vec3(0.0), 0.0, 0.0, 0.0, 0.0, false);
    if hits > 0u {
        slab = local_slab(v, r, hit, points, normals);
    }
    var corners: array<vec3<f32>, 8>;
    var surface: array<vec3<f32>, 8>;
    out.slab = vec4(0.0);
    out.slab_far = vec4(0.0);
    let on_slab = slab.found && slab.last <= depth;
    if on_slab {
        // A beam partly past the surface's edge goes on in a medium.
        if hits == 3u {
            out.origin.w = slab.last;
        }
        let normal = world_dir(frame, slab.normal);
        out.slab = vec4(normal, slab.near + dot(normal, frame.origin));
        out.slab_far = vec4(slab.far + dot(normal, frame.origin), 0.0, 0.0, 0.0);
        // The slice of the beam that crosses the slab, bounded on its own and cut to
        // the slab where its sides cross it.
        let top = array(v[0] + slab.first * r[0], v[1] + slab.first * r[1], v[2] + slab.first * r[2]);
        surface = to_world_outwards(frame, cut_to_slab(bounding_shape(top, r, slab.last - slab.first), slab));
        // The whole beam only where the in-scattering pass draws it; else no pass
        // reads `corners`.
        corners = surface;
        if job.light_power.w > 0.0 {
            corners = to_world_outwards(frame, bounding_shape(v, r, slab.last));
        }
    } else {
        let end = occluded_beyond(v, r, out.hit_planes);
        if end.y > 0.0 {
            out.origin.w = clamp(end.x, 1.0e-3 * depth, depth);
        }
        corners = to_world_outwards(frame, bounding_shape(v, r, out.origin.w));
        surface = corners;
        // `SurfaceSlab::EMPTY`, `BoundingShape::EMPTY`: rays that all meet nothing
        // light no surface.
        if job.counts.z != 0u && hits == 0u {
            out.slab = vec4(0.0, 1.0, 0.0, 1.0);
            surface = array<vec3<f32>, 8>();
        }
    }
    for (var c = 0u; c < 8u; c++) {
        out.corners[c] = vec4(corners[c], 1.0);
        out.surface_corners[c] = vec4(surface[c], 1.0);
    }
    let flux = colour * ((weight.x + weight.y + weight.z) / 3.0 * 0.5 * abc.x);
    // Past the volumes the texture holds (`prepare_build` warns), the slot is given
    // back and the volume's flux counted as dropped: the instance count never passes it.
    let slot = atomicAdd(&counters[INSTANCES], 1u);
    if slot >= volume_capacity(textureDimensions(volumes)) {
        atomicSub(&counters[INSTANCES], 1u);
        return TriangleFlux(vec3(0.0), flux);
    }
    if on_slab {
        atomicAdd(&counters[SURFACE_SLABS], 1u);
    } else if out.slab.y == 1.0 {
        atomicAdd(&counters[ESCAPING], 1u);
    }
    store_volume(slot, out);
    return TriangleFlux(flux, vec3(0.0));
}

// Writes volume `v` at `index` of `volumes`, as `load_volume` reads it.
fn store_volume(index: u32, v: CausticVolume) {
    let at = volume_at(textureDimensions(volumes).x, index);
    // The fields before `hit_planes`, in order.
    let fields = array(
        v.origin, v.axis_x, v.axis_y, v.axis_z, v.surface_normal, v.vertex_x, v.vertex_z, v.ray_x, v.ray_z,
        v.fan_a, v.fan_b, v.fan_c, v.triangle_abc, v.flux, v.color, v.light_distance, v.slab, v.slab_far,
    );
    for (var k = 0u; k < HIT_PLANES_TEXEL; k++) {
        textureStore(volumes, vec2(at.x + k, at.y), fields[k]);
    }
    for (var k = 0u; k < 3u; k++) {
        textureStore(volumes, vec2(at.x + HIT_PLANES_TEXEL + k, at.y), v.hit_planes[k]);
    }
    for (var k = 0u; k < 8u; k++) {
        textureStore(volumes, vec2(at.x + CORNERS_TEXEL + k, at.y), v.corners[k]);
        textureStore(volumes, vec2(at.x + SURFACE_CORNERS_TEXEL + k, at.y), v.surface_corners[k]);
    }
}

// The workgroup's kept and dropped fluxes, summed in halves.
var<workgroup> fluxes: array<TriangleFlux, 64>;

// One invocation a triangle (`triangle_volume`); each workgroup adds its triangles'
// kept and dropped flux to `counters` once, not once a triangle on the same words.
@compute @workgroup_size(64)
fn triangle_volumes(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_index) lane: u32) {
    fluxes[lane] = triangle_volume(id.x);
    workgroupBarrier();
    for (var half = 32u; half > 0u; half >>= 1u) {
        if lane < half {
            fluxes[lane].kept += fluxes[lane + half].kept;
            fluxes[lane].dropped += fluxes[lane + half].dropped;
        }
        workgroupBarrier();
    }
    if lane == 0u {
        if any(fluxes[0].kept != vec3(0.0)) {
            add_flux(FLUX, fluxes[0].kept);
        }
        if any(fluxes[0].dropped != vec3(0.0)) {
            add_flux(DROPPED_FLUX, fluxes[0].dropped);
        }
    }
}

// Does nothing, under the build's bindings: dispatched first while timestamps are
// recorded, so that lavapipe times the first job's vertex rays
// (`gpu_work::anchor_first_timestamp`).
@compute @workgroup_size(1)
fn anchor() {}
