// Hierarchical caustic maps (Wyman 2008) in compute: the GPU twin of
// `caustics_core::hierarchical`, entry point by entry point.
//
// - `trace_photons`: one photon per photon buffer texel, through the generator in
//   image space or along a path traced through the generators' BVH, and onto the
//   receivers (`photons::trace_photon`);
// - `build_pyramid`: one pyramid level from the one below (`Node::parent`);
// - `write_args`: the indirect dispatch of the next step from a list's length, which
//   it records as the nodes processed at that level;
// - `traverse`: one level of the breadth-first traversal (§3.1), clustering where
//   photons converge (§3.2), and at the photon buffer's own level every valid photon of
//   its list (`hierarchy::gather`);
// - `splat`: every gathered photon or cluster into its caustic map level (§3.3,
//   `CausticMap::splat`), in 64-bit fixed point with integer atomics;
// - `resolve`: the levels summed into the full-resolution map (eq. 3).

#import bevy_caustics::caustic_maps::{
    LightView, NO_SURFACE, EMPTY, DRAWN_HERE, ONE_SIDED, DIVERSE, MANY, FLUX_UNITS, MAX_SPLAT_RADIUS, MIN_SPLAT_DIAMETER,
    SPLAT_LEVEL_THRESHOLD, ONE_BELOW, pyramid_offset, level_offset, is_perspective, half_extent, to_view,
    map_uv, light_ray, photon_texel_center, photon_measure, photon_texel, relative_beam, cone_attenuation, range_attenuation, texel_of,
    oct_decode, bilinear_taps, bilinear_mix,
}
#import bevy_caustics::optics::{reflect_about, refract_through, fresnel_transmittance}
#import bevy_caustics::triangle_bvh::{NO_MESH, TriangleHit, intersect_triangles}

// One step of the traversal (`GpuStep` in `render.rs`).
struct Step {
    level: u32,
    // The list a step reads: 0 or 1 (the traversal's two), 2 (the gathered list), or 3
    // (every node of `level`, `fixed_count` of them).
    source: u32,
    // The list `traverse` appends children to.
    destination: u32,
    // Which three words of `args` `write_args` fills.
    args_slot: u32,
    fixed_count: u32,
    // This view's first counter.
    counter_base: u32,
    // The photon buffer `trace_photons` traces: 0 the transmitted light, k ≥ 1 the
    // Fresnel branch that reflects at a photon's k-th refraction.
    branch: u32,
}

// Counters, from `Step::counter_base`: the lengths of lists 0, 1 and 2, the clusters
// gathered, then the nodes processed at each level.
const COUNT_CLUSTERS: u32 = 3u;
const COUNT_PROCESSED: u32 = 4u;
const ALL_NODES: u32 = 3u;
const WORKGROUP: u32 = 64u;

@group(0) @binding(0) var<uniform> view: LightView;
@group(0) @binding(1) var<uniform> step: Step;
@group(0) @binding(2) var front_map: texture_2d<f32>;
@group(0) @binding(3) var back_map: texture_2d<f32>;
@group(0) @binding(4) var receiver_map: texture_2d<f32>;
// The photon buffer in two halves (each within a binding's size limit at 4096²): where
// each photon lands, and its flux and solid angle.
@group(0) @binding(5) var<storage, read_write> photon_uv: array<vec2<f32>>;
@group(0) @binding(6) var<storage, read_write> photon_flux: array<vec2<f32>>;
@group(0) @binding(7) var<storage, read_write> pyramid: array<vec4<u32>>; // flux, Σ flux·uv (f32 bits), texel word
// The traversal's two lists and the gathered list, photon-count capacity each.
@group(0) @binding(8) var<storage, read_write> list0: array<u32>;
@group(0) @binding(9) var<storage, read_write> list1: array<u32>;
@group(0) @binding(10) var<storage, read_write> gathered: array<u32>;
@group(0) @binding(11) var<storage, read_write> counters: array<atomic<u32>>;
@group(0) @binding(12) var<storage, read_write> levels: array<atomic<u32>>; // two words a texel, low first
@group(0) @binding(13) var<storage, read_write> resolved: array<f32>;
// Binding 14: the generators' `InstancedBvh` (`bevy_caustics::triangle_bvh`).
// Only `write_args` binds the indirect arguments: a dispatch may not read the buffer it
// is dispatched from as storage.
@group(1) @binding(0) var<storage, read_write> args: array<u32>;

struct PhotonTexel {
    uv: vec2<f32>,
    flux: f32,
}

fn photon_at(index: u32) -> PhotonTexel {
    return PhotonTexel(photon_uv[index], photon_flux[index].x);
}

fn list_entry(source: u32, i: u32) -> u32 {
    switch source {
        case 0u: {
            return list0[i];
        }
        case 1u: {
            return list1[i];
        }
        default: {
            return gathered[i];
        }
    }
}

fn set_list_entry(destination: u32, i: u32, value: u32) {
    if destination == 0u {
        list0[i] = value;
    } else {
        list1[i] = value;
    }
}

// ---------------------------------------------------------------- photon buffer

struct Sample {
    depth: f32,
    normal: vec3<f32>,
    material: u32,
}

fn front_at(x: u32, y: u32) -> Sample {
    let t = textureLoad(front_map, vec2<i32>(i32(x), i32(y)), 0);
    return Sample(t.x, oct_decode(t.yz), u32(t.w));
}

fn back_at(x: u32, y: u32) -> Sample {
    let t = textureLoad(back_map, vec2<i32>(i32(x), i32(y)), 0);
    return Sample(t.x, oct_decode(t.yz), 0u);
}

fn receiver_at(x: u32, y: u32) -> f32 {
    return textureLoad(receiver_map, vec2<i32>(i32(x), i32(y)), 0).x;
}

// `photons::exit_distance`: xyz the far side's normal, w the distance along `t`.
fn exit_distance(p1: vec3<f32>, z1: f32, t: vec3<f32>, back: Sample) -> vec4<f32> {
    let dz = dot(t, view.forward.xyz);
    if dz < 1.0e-3 {
        return vec4(back.normal, max(back.depth - z1, 0.0));
    }
    var normal = back.normal;
    var d = (back.depth - z1) / dz;
    for (var i = 0u; i < view.exit_iterations; i++) {
        let uv = map_uv(view, p1 + t * d);
        if uv.z == 0.0 {
            break;
        }
        let texel = photon_texel(view, uv.xy);
        if texel.z == 0u {
            break;
        }
        let next = back_at(texel.x, texel.y);
        if next.depth >= NO_SURFACE || next.depth <= z1 {
            break;
        }
        normal = next.normal;
        d = (next.depth - z1) / dz;
    }
    return vec4(normal, d);
}

// `photons::crossing`.
fn crossing(o: vec3<f32>, v: vec3<f32>, axis: u32, boundary: f32) -> f32 {
    let h = half_extent(view);
    var c = (1.0 - 2.0 * boundary) * h.y;
    var oc = o.y;
    var vc = v.y;
    if axis == 0u {
        c = (2.0 * boundary - 1.0) * h.x;
        oc = o.x;
        vc = v.x;
    }
    var num = c - oc;
    var den = vc;
    if is_perspective(view) {
        num = c * o.z - oc;
        den = vc - c * v.z;
    }
    let d = num / den;
    if abs(den) < 1.0e-20 || d < 0.0 {
        return 3.4028235e38;
    }
    return d;
}

fn direction_step(s: f32) -> i32 {
    if s > 0.0 {
        return 1;
    }
    if s < 0.0 {
        return -1;
    }
    return 0;
}

fn boundary(i: u32, s: i32, m: f32) -> f32 {
    if s > 0 {
        return f32(i + 1u) / m;
    }
    return f32(i) / m;
}

// `photons::march_receivers`: xyz where the ray lands, w 1 if it does by `reach`.
fn march_receivers(origin: vec3<f32>, dir: vec3<f32>, reach: f32) -> vec4<f32> {
    let m = view.map_resolution;
    let mf = f32(m);
    let o = to_view(view, origin);
    let v = vec3(dot(dir, view.right.xyz), dot(dir, view.up.xyz), dot(dir, view.forward.xyz));
    let start = map_uv(view, origin);
    if start.z == 0.0 {
        return vec4(0.0);
    }
    let first = texel_of(start.xy, m);
    if first.z == 0u {
        return vec4(0.0);
    }
    var ix = first.x;
    var iy = first.y;
    var su = v.x;
    var sv = -v.y;
    if is_perspective(view) {
        su = v.x * o.z - o.x * v.z;
        sv = -(v.y * o.z - o.y * v.z);
    }
    let step_u = direction_step(su);
    let step_v = direction_step(sv);
    let infinity = 3.4028235e38;
    var d_enter = 0.0;
    for (var i = 0u; i < 2u * m + 4u; i++) {
        if d_enter > reach {
            return vec4(0.0);
        }
        var du = infinity;
        if step_u != 0 {
            du = max(crossing(o, v, 0u, boundary(ix, step_u, mf)), d_enter);
        }
        var dv = infinity;
        if step_v != 0 {
            dv = max(crossing(o, v, 1u, boundary(iy, step_v, mf)), d_enter);
        }
        let d_exit = min(du, dv);
        let z_receiver = receiver_at(ix, iy);
        if z_receiver < NO_SURFACE {
            if o.z + d_enter * v.z >= z_receiver {
                return vec4(origin + dir * d_enter, 1.0);
            }
            if v.z > 0.0 {
                let d_hit = (z_receiver - o.z) / v.z;
                if d_hit <= d_exit {
                    return vec4(origin + dir * d_hit, f32(d_hit <= reach));
                }
            }
        }
        if d_exit >= infinity {
            return vec4(0.0);
        }
        let z_exit = o.z + d_exit * v.z;
        if z_exit > view.far || (is_perspective(view) && z_exit <= 0.0) {
            return vec4(0.0);
        }
        var nx = i32(ix);
        var ny = i32(iy);
        if du <= dv {
            nx += step_u;
        } else {
            ny += step_v;
        }
        if nx < 0 || ny < 0 || nx >= i32(m) || ny >= i32(m) {
            return vec4(0.0);
        }
        ix = u32(nx);
        iy = u32(ny);
        d_enter = d_exit;
    }
    return vec4(0.0);
}

// ---------------------------------------------------------------- traced paths

// `photons::MAX_PATH_EVENTS`.
const MAX_PATH_EVENTS: u32 = 8u;

fn material_ior(m: u32) -> f32 {
    return view.materials[m / 4u][m % 4u];
}

fn material_flags(m: u32) -> u32 {
    return view.material_flags[m / 4u][m % 4u];
}

// Where a photon lands (`photons::Landing`): the receiver point, the last generator
// point it left, its flux and its path length between its first surface and there.
struct Landing {
    hit: vec3<f32>,
    last: vec3<f32>,
    flux: f32,
    travelled: f32,
    landed: bool,
}

// `photons::traced_path`.
fn traced_path(p1: vec3<f32>, first_material: u32, first_normal: vec3<f32>, dir_in: vec3<f32>, flux_in: f32) -> Landing {
    var lost = Landing(vec3(0.0), vec3(0.0), 0.0, 0.0, false);
    var refractions = 0u;
    var p = p1;
    var dir = dir_in;
    var flux = flux_in;
    var travelled = 0.0;
    var material = first_material;
    var ns = first_normal;
    var ng = first_normal;
    for (var event = 0u; event < MAX_PATH_EVENTS; event++) {
        if material >= view.material_count {
            return lost;
        }
        if (material_flags(material) & ONE_SIDED) != 0u && dot(dir, ng) > 0.0 {
            return lost;
        }
        var n = ns;
        if dot(ns, dir) > 0.0 {
            n = -ns;
        }
        let ior = material_ior(material);
        if ior > 0.0 {
            var eta = ior;
            if dot(dir, ng) < 0.0 {
                eta = 1.0 / ior;
            }
            let t = refract_through(dir, n, eta);
            if t.w == 0.0 {
                dir = reflect_about(dir, n);
            } else {
                refractions += 1u;
                let transmitted = fresnel_transmittance(dot(dir, n), eta);
                if refractions == step.branch {
                    flux *= 1.0 - transmitted;
                    dir = reflect_about(dir, n);
                } else {
                    flux *= transmitted;
                    dir = t.xyz;
                }
            }
        } else {
            dir = reflect_about(dir, n);
        }
        var side = -ng;
        if dot(dir, ng) >= 0.0 {
            side = ng;
        }
        let origin = p + side * view.path_epsilon;
        let next = intersect_triangles(view.bvh_instances, NO_MESH, origin, dir, 0.0, 3.4028235e38);
        var reach = 3.4028235e38;
        if next.t >= 0.0 {
            reach = next.t;
        }
        let hit = march_receivers(origin, dir, reach);
        // A Fresnel branch whose path ends before its refraction: branch 0 has it.
        if refractions < step.branch && (hit.w != 0.0 || next.t < 0.0) {
            return lost;
        }
        if hit.w != 0.0 {
            return Landing(hit.xyz, origin, flux, travelled, true);
        }
        if next.t < 0.0 {
            return lost;
        }
        p = origin + dir * next.t;
        travelled += next.t;
        material = next.generator;
        ns = next.normal;
        ng = next.geometric_normal;
    }
    return lost;
}

// `photons::image_space_path`.
fn image_space_path(id: vec2<u32>, front: Sample, p1: vec3<f32>, dir: vec3<f32>, weight: f32) -> Landing {
    var lost = Landing(vec3(0.0), vec3(0.0), 0.0, 0.0, false);
    var n1 = front.normal;
    if dot(n1, dir) > 0.0 {
        n1 = -n1;
    }
    let ior = material_ior(front.material);
    var origin = p1;
    var out = reflect_about(dir, n1);
    var flux = weight;
    if ior > 0.0 {
        let t1 = refract_through(dir, n1, 1.0 / ior);
        if t1.w == 0.0 {
            return lost;
        }
        flux = weight * fresnel_transmittance(dot(dir, n1), 1.0 / ior);
        out = t1.xyz;
        let back = back_at(id.x, id.y);
        if back.depth < NO_SURFACE && back.depth > front.depth {
            let exit = exit_distance(p1, front.depth, t1.xyz, back);
            let t2 = refract_through(t1.xyz, exit.xyz, ior);
            if t2.w == 0.0 {
                return lost;
            }
            flux *= fresnel_transmittance(dot(t1.xyz, exit.xyz), ior);
            origin = p1 + t1.xyz * exit.w;
            out = t2.xyz;
        }
    }
    let hit = march_receivers(origin, out, 3.4028235e38);
    return Landing(hit.xyz, origin, flux, length(origin - p1), hit.w != 0.0);
}

@compute @workgroup_size(8, 8, 1)
fn trace_photons(@builtin(global_invocation_id) id: vec3<u32>) {
    let n = view.photon_resolution;
    if id.x >= n || id.y >= n {
        return;
    }
    let index = id.y * n + id.x;
    photon_uv[index] = vec2(0.0);
    photon_flux[index] = vec2(0.0);
    let front = front_at(id.x, id.y);
    if front.depth >= NO_SURFACE || front.material >= view.material_count {
        return;
    }
    // Light another technique draws.
    if (material_flags(front.material) & DRAWN_HERE) == 0u {
        return;
    }
    let uv0 = photon_texel_center(view, id.x, id.y);
    // `photons::trace_photon`: a surface nearer the light than the generator hides it.
    let m = view.map_resolution;
    let shadow_texel = min(vec2<u32>(uv0 * f32(m)), vec2(m - 1u));
    if receiver_at(shadow_texel.x, shadow_texel.y) < front.depth - (1e-3 * abs(front.depth) + 1e-4) {
        return;
    }
    let ray = light_ray(view, uv0);
    let beam = relative_beam(view, uv0);
    let weight = beam * cone_attenuation(view, ray.direction);
    if weight <= 0.0 {
        return;
    }
    let forward = view.forward.xyz;
    let dir = ray.direction;
    let p1 = ray.origin + dir * ((front.depth - dot(ray.origin - view.origin.xyz, forward)) / dot(dir, forward));
    var landing: Landing;
    if view.traced_paths != 0u {
        landing = traced_path(p1, front.material, front.normal, dir, weight);
    } else {
        landing = image_space_path(id.xy, front, p1, dir, weight);
    }
    if !landing.landed {
        return;
    }
    let uv = map_uv(view, landing.hit);
    if uv.z == 0.0 || uv.x < 0.0 || uv.y < 0.0 || uv.x > 1.0 || uv.y > 1.0 {
        return;
    }
    // A point or spot light's range fades the photon by its whole path (the light sits
    // at a perspective view's origin).
    let path = length(p1 - view.origin.xyz) + landing.travelled + length(landing.hit - landing.last);
    photon_uv[index] = min(uv.xy, vec2(ONE_BELOW));
    photon_flux[index] = vec2(landing.flux * range_attenuation(view, path), beam * photon_measure(view));
}

// ---------------------------------------------------------------- pyramid

struct Node {
    texel: u32,   // with `MANY`
    flux: f32,
    moment: vec2<f32>,
}

// `Node::of_photon`.
fn photon_node(index: u32) -> Node {
    let p = photon_at(index);
    if p.flux <= 0.0 {
        return Node(EMPTY, 0.0, vec2(0.0));
    }
    let m = view.map_resolution;
    let t = min(vec2<u32>(p.uv * f32(m)), vec2(m - 1u));
    return Node(t.y * m + t.x, p.flux, p.uv * p.flux);
}

fn pyramid_node(level: u32, index: u32) -> Node {
    if level == 0u {
        return photon_node(index);
    }
    let w = pyramid[pyramid_offset(view, level) + index];
    return Node(w.w, bitcast<f32>(w.x), vec2(bitcast<f32>(w.y), bitcast<f32>(w.z)));
}

fn texel_part(word: u32) -> u32 {
    if word >= EMPTY {
        return word;
    }
    return word & ~MANY;
}

@compute @workgroup_size(8, 8, 1)
fn build_pyramid(@builtin(global_invocation_id) id: vec3<u32>) {
    let width = view.photon_resolution >> step.level;
    if id.x >= width || id.y >= width {
        return;
    }
    let below = 2u * width;
    let x = 2u * id.x;
    let y = 2u * id.y;
    var children = array<u32, 4>(y * below + x, y * below + x + 1u, (y + 1u) * below + x, (y + 1u) * below + x + 1u);
    var texel = EMPTY;
    var occupied = 0u;
    var many = false;
    var flux = 0.0;
    var moment = vec2(0.0);
    for (var i = 0u; i < 4u; i++) {
        let c = pyramid_node(step.level - 1u, children[i]);
        flux = flux + c.flux;
        moment = moment + c.moment;
        let t = texel_part(c.texel);
        if t == EMPTY {
            continue;
        }
        occupied += 1u;
        many = many || (c.texel < EMPTY && (c.texel & MANY) != 0u);
        if texel == EMPTY {
            texel = t;
        } else if texel != t {
            texel = DIVERSE;
        }
    }
    var word = texel;
    if texel < EMPTY && (many || occupied >= 2u) {
        word = texel | MANY;
    }
    pyramid[pyramid_offset(view, step.level) + id.y * width + id.x] =
        vec4(bitcast<u32>(flux), bitcast<u32>(moment.x), bitcast<u32>(moment.y), word);
}

// ---------------------------------------------------------------- traversal

fn list_length(source: u32) -> u32 {
    if source == ALL_NODES {
        return step.fixed_count;
    }
    return atomicLoad(&counters[step.counter_base + source]);
}

@compute @workgroup_size(1, 1, 1)
fn write_args() {
    let n = list_length(step.source);
    let groups = (n + WORKGROUP - 1u) / WORKGROUP;
    let x = min(groups, 65535u);
    let slot = 3u * step.args_slot;
    args[slot] = x;
    args[slot + 1u] = select(1u, (groups + 65534u) / 65535u, groups > 0u);
    args[slot + 2u] = 1u;
    // Every photon buffer's gather counts into the view's totals, and each starts a
    // gathered list of its own.
    if step.source != 2u {
        atomicAdd(&counters[step.counter_base + COUNT_PROCESSED + step.level], n);
    }
    if step.source == ALL_NODES {
        atomicStore(&counters[step.counter_base + 2u], 0u);
    }
    if step.destination < 2u {
        atomicStore(&counters[step.counter_base + step.destination], 0u);
    }
}

fn thread_index(workgroup: vec3<u32>, groups: vec3<u32>, local: u32) -> u32 {
    return (workgroup.y * groups.x + workgroup.x) * WORKGROUP + local;
}

const NO_NODE: u32 = 0xffffffffu;

// The node thread `t` of a step handles: entry `t` of the step's list, or node `t`
// itself; `NO_NODE` past the list's end.
fn source_node(t: u32) -> u32 {
    if t >= list_length(step.source) {
        return NO_NODE;
    }
    if step.source == ALL_NODES {
        return t;
    }
    return list_entry(step.source, t);
}

fn gather(entry: u32) {
    let i = atomicAdd(&counters[step.counter_base + 2u], 1u);
    gathered[i] = entry;
}

@compute @workgroup_size(64, 1, 1)
fn traverse(
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) local: u32,
) {
    let index = source_node(thread_index(workgroup, groups, local));
    if index == NO_NODE {
        return;
    }
    // The photon buffer's own level: every valid photon is gathered.
    if step.level == 0u {
        if photon_flux[index].x > 0.0 {
            gather(index);
        }
        return;
    }
    let node = pyramid_node(step.level, index);
    if node.texel == EMPTY {
        return;
    }
    let clusters_here = view.clustering == 2u || (view.clustering == 1u && step.level == 1u);
    if clusters_here && node.texel < EMPTY && (node.texel & MANY) != 0u {
        gather((step.level << 24u) | index);
        atomicAdd(&counters[step.counter_base + COUNT_CLUSTERS], 1u);
        return;
    }
    let width = view.photon_resolution >> step.level;
    let x = 2u * (index % width);
    let y = 2u * (index / width);
    let below = 2u * width;
    let first = atomicAdd(&counters[step.counter_base + step.destination], 4u);
    set_list_entry(step.destination, first, y * below + x);
    set_list_entry(step.destination, first + 1u, y * below + x + 1u);
    set_list_entry(step.destination, first + 2u, (y + 1u) * below + x);
    set_list_entry(step.destination, first + 3u, (y + 1u) * below + x + 1u);
}

// ---------------------------------------------------------------- splats

// `caustic_map::divergence_diameter`.
fn divergence_diameter(index: u32) -> f32 {
    let n = view.photon_resolution;
    let x = index % n;
    let y = index / n;
    let here = photon_uv[index];
    var largest = -1.0;
    let m = f32(view.map_resolution);
    var neighbours = array<vec2<i32>, 4>(vec2(-1, 0), vec2(1, 0), vec2(0, -1), vec2(0, 1));
    for (var k = 0u; k < 4u; k++) {
        let q = vec2<i32>(i32(x), i32(y)) + neighbours[k];
        if q.x < 0 || q.y < 0 || q.x >= i32(n) || q.y >= i32(n) {
            continue;
        }
        let p = photon_at(u32(q.y) * n + u32(q.x));
        if p.flux > 0.0 {
            largest = max(largest, length((p.uv - here) * m));
        }
    }
    var spacing = largest;
    if largest < 0.0 {
        spacing = m / f32(n);
    }
    return max(2.0 * spacing, MIN_SPLAT_DIAMETER);
}

// Photon (x, y)'s offset from `here` in caustic-map texels, w = 1 where it is a valid
// photon, 0 where it is not (or lies outside the buffer).
fn neighbour_offset(x: i32, y: i32, here: vec2<f32>) -> vec3<f32> {
    let n = i32(view.photon_resolution);
    if x < 0 || y < 0 || x >= n || y >= n {
        return vec3(0.0);
    }
    let p = photon_at(u32(y * n + x));
    if p.flux <= 0.0 {
        return vec3(0.0);
    }
    return vec3((p.uv - here) * f32(view.map_resolution), 1.0);
}

// The spacing from the neighbours before and after (`divergence_axes`' central
// difference, or the one valid); w = 0 where neither is.
fn spacing(before: vec3<f32>, after: vec3<f32>) -> vec3<f32> {
    if before.z > 0.0 && after.z > 0.0 {
        return vec3(0.5 * (after.xy - before.xy), 1.0);
    }
    if after.z > 0.0 {
        return after;
    }
    return vec3(-before.xy, before.z);
}

// `caustic_map::divergence_axes`.
fn divergence_axes(index: u32) -> mat2x2<f32> {
    let n = view.photon_resolution;
    let x = i32(index % n);
    let y = i32(index / n);
    let here = photon_uv[index];
    let row = spacing(neighbour_offset(x - 1, y, here), neighbour_offset(x + 1, y, here));
    let column = spacing(neighbour_offset(x, y - 1, here), neighbour_offset(x, y + 1, here));
    if row.z > 0.0 && column.z > 0.0 {
        let j = mat2x2(row.xy, column.xy);
        return spd_sqrt(j * transpose(j));
    }
    return round_axes(divergence_diameter(index));
}

// `caustic_map::round_axes`.
fn round_axes(diameter: f32) -> mat2x2<f32> {
    return mat2x2(0.5 * diameter, 0.0, 0.0, 0.5 * diameter);
}

// `caustic_map::spd_sqrt`.
fn spd_sqrt(m: mat2x2<f32>) -> mat2x2<f32> {
    let s = sqrt(max(determinant(m), 0.0));
    let t = sqrt(m[0].x + m[1].y + 2.0 * s);
    if t > 0.0 {
        return (m + mat2x2(s, 0.0, 0.0, s)) * (1.0 / t);
    }
    return mat2x2(0.0, 0.0, 0.0, 0.0);
}

// `caustic_map::eigen_spread`: half the trace and half the eigenvalues' difference.
fn eigen_spread(a: mat2x2<f32>) -> vec2<f32> {
    let half_difference = 0.5 * (a[0].x - a[1].y);
    return vec2(0.5 * (a[0].x + a[1].y), sqrt(half_difference * half_difference + a[1].x * a[1].x));
}

// `caustic_map::clamp_half_axes`.
fn clamp_half_axes(a: mat2x2<f32>, low: f32, high: f32) -> mat2x2<f32> {
    let e = eigen_spread(a);
    let longer = clamp(e.x + e.y, low, high);
    let shorter = clamp(e.x - e.y, low, high);
    let p = a[0].x;
    let b = a[1].x;
    let r = a[1].y;
    var v = vec2(b, e.x + e.y - p);
    if p >= r {
        v = vec2(e.x + e.y - r, b);
    }
    let l = length(v);
    if !(l > 0.0) {
        return mat2x2(shorter, 0.0, 0.0, shorter);
    }
    v = v / l;
    let d = longer - shorter;
    return mat2x2(shorter + d * v.x * v.x, d * v.x * v.y, d * v.x * v.y, shorter + d * v.y * v.y);
}

// `caustic_map::splat_level`.
fn splat_level(diameter: f32) -> u32 {
    var level = 0u;
    while level < 31u && diameter >= SPLAT_LEVEL_THRESHOLD * f32(2u << level) {
        level += 1u;
    }
    return level;
}

// `caustic_map::splat_level_of`.
fn splat_level_of(axes: mat2x2<f32>, top: u32) -> u32 {
    var level = splat_level(2.0 * sqrt(abs(determinant(axes))));
    let e = eigen_spread(axes);
    while level < top && e.x + e.y > MAX_SPLAT_RADIUS * f32(1u << level) {
        level += 1u;
    }
    return level;
}

// `caustic_map::row_span`.
fn row_span(to_footprint: mat2x2<f32>, p: vec2<f32>, y: f32, columns: vec2<f32>) -> vec2<f32> {
    let dy = y - p.y;
    var low = columns.x - p.x;
    var high = columns.y - p.x;
    // The rows (a, b) of s and t: |a·dx + b·dy| ≤ 1.
    var rows = array<vec2<f32>, 2>(vec2(to_footprint[0].x, to_footprint[1].x), vec2(to_footprint[0].y, to_footprint[1].y));
    for (var k = 0u; k < 2u; k++) {
        let a = rows[k].x;
        let c = rows[k].y * dy;
        if a != 0.0 {
            let u = (-1.0 - c) / a;
            let v = (1.0 - c) / a;
            low = max(low, min(u, v));
            high = min(high, max(u, v));
        } else if abs(c) > 1.0 {
            return vec2(1.0, 0.0);
        }
    }
    return vec2(max(ceil(p.x + low - 0.01), columns.x), min(floor(p.x + high + 0.01), columns.y));
}

fn tent(t: f32) -> f32 {
    return max(1.0 - abs(t), 0.0);
}

// `caustic_map::fixed_point`, added to a texel's two words with the carry.
fn add_fixed_point(texel: u32, value: f32) {
    let x = value + 0.5;
    let high = floor(x * (1.0 / 4294967296.0));
    let low = u32(x - high * 4294967296.0);
    let old = atomicAdd(&levels[2u * texel], low);
    let carry = select(0u, 1u, low > 0xffffffffu - old);
    let up = u32(high) + carry;
    if up > 0u {
        atomicAdd(&levels[2u * texel + 1u], up);
    }
}

@compute @workgroup_size(64, 1, 1)
fn splat(
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) local: u32,
) {
    let t = thread_index(workgroup, groups, local);
    if t >= list_length(2u) {
        return;
    }
    let entry = gathered[t];
    let entry_level = entry >> 24u;
    let index = entry & 0x00ffffffu;
    var uv: vec2<f32>;
    var flux: f32;
    var axes = round_axes(max(view.fixed_diameter, MIN_SPLAT_DIAMETER));
    if entry_level == 0u {
        let p = photon_at(index);
        uv = p.uv;
        flux = p.flux;
        if view.variable_splats != 0u {
            axes = divergence_axes(index);
        }
    } else {
        let node = pyramid_node(entry_level, index);
        uv = node.moment / node.flux;
        flux = node.flux;
        if view.variable_splats != 0u {
            axes = round_axes(MIN_SPLAT_DIAMETER);
        }
    }
    var level = 0u;
    if view.variable_splats != 0u {
        level = splat_level_of(axes, view.top_level);
        if level > view.top_level {
            if view.discard_above_top != 0u {
                return;
            }
            level = view.top_level;
        }
    }
    let width = max(view.map_resolution >> level, 1u);
    let here = clamp_half_axes(axes * (1.0 / f32(1u << level)), 1.0, MAX_SPLAT_RADIUS);
    // `Mat2::inverse`.
    let to_footprint = mat2x2(here[1].y, -here[0].y, -here[1].x, here[0].x) * (1.0 / determinant(here));
    let p = uv * f32(width) - 0.5;
    // The footprint's box: the parallelogram p + A[-1, 1]².
    let reach = abs(here[0]) + abs(here[1]);
    let x0 = i32(floor(p.x - reach.x));
    let x1 = i32(ceil(p.x + reach.x));
    let y0 = i32(floor(p.y - reach.y));
    let y1 = i32(ceil(p.y + reach.y));
    let columns = vec2(f32(x0), f32(x1));
    var sum = 0.0;
    for (var y = y0; y <= y1; y++) {
        let span = row_span(to_footprint, p, f32(y), columns);
        for (var x = i32(span.x); x <= i32(span.y); x++) {
            let st = to_footprint * (vec2(f32(x), f32(y)) - p);
            sum = sum + tent(st.x) * tent(st.y);
        }
    }
    let scale = flux * FLUX_UNITS / sum;
    let offset = level_offset(view, level);
    for (var y = max(y0, 0); y <= min(y1, i32(width) - 1); y++) {
        let span = row_span(to_footprint, p, f32(y), columns);
        for (var x = max(i32(span.x), 0); x <= min(i32(span.y), i32(width) - 1); x++) {
            let st = to_footprint * (vec2(f32(x), f32(y)) - p);
            let w = tent(st.x) * tent(st.y);
            if w > 0.0 {
                add_fixed_point(offset + u32(y) * width + u32(x), scale * w);
            }
        }
    }
}

// ---------------------------------------------------------------- resolve

// `caustic_map::from_fixed_point`.
fn level_value(texel: u32) -> f32 {
    let low = atomicLoad(&levels[2u * texel]);
    let high = atomicLoad(&levels[2u * texel + 1u]);
    return (f32(high) * 4294967296.0 + f32(low)) / FLUX_UNITS;
}

fn level_texel(level: u32, width: u32, x: u32, y: u32) -> f32 {
    return level_value(level_offset(view, level) + y * width + x);
}

// `caustic_map::bilinear` of one level.
fn level_bilinear(level: u32, q: vec2<f32>) -> f32 {
    let width = max(view.map_resolution >> level, 1u);
    let b = bilinear_taps(q, width);
    let a = level_texel(level, width, b.low.x, b.low.y);
    let c = level_texel(level, width, b.high.x, b.low.y);
    let d = level_texel(level, width, b.low.x, b.high.y);
    let e = level_texel(level, width, b.high.x, b.high.y);
    return bilinear_mix(b, a, c, d, e);
}

// `CausticMap::resolve`: C = Σᵢ Cᵢ / 4ⁱ (eq. 3).
@compute @workgroup_size(8, 8, 1)
fn resolve(@builtin(global_invocation_id) id: vec3<u32>) {
    let m = view.map_resolution;
    if id.x >= m || id.y >= m {
        return;
    }
    var c = 0.0;
    for (var level = 0u; level <= view.top_level; level++) {
        let q = (vec2(f32(id.x), f32(id.y)) + 0.5) / f32(1u << level) - 0.5;
        c = c + level_bilinear(level, q) / f32(1u << (2u * level));
    }
    resolved[id.y * m + id.x] = c;
}

// Does nothing: dispatched first under the caustic maps' bindings while timestamps are recorded,
// so that lavapipe times the pass whole (`gpu_work::anchor_first_timestamp`).
@compute @workgroup_size(1)
fn anchor() {}
