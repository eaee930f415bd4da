// Light shafts at a fixed cost per eye ray: the GPU twin of
// `caustics_core::volumes::BeamGrid`. `deposit` adds every caustic volume's beam to a
// grid over each medium's box (the mean of colour · E_beam · e^{−σt dₛ} per cell, and
// the beams' summed directions); `march` integrates each eye ray through the grid in
// a fixed number of steps (§3.5's single scattering).

#import bevy_render::view::View
#import bevy_core_pipeline::fullscreen_vertex_shader::FullscreenVertexOutput
#import bevy_caustics::receiver::{Medium, clip_medium, exposed, world_at}
#import bevy_caustics::warped_volumes::{CausticVolume, VolumeSettings, sample_on_ray}

// One medium's grid (`GpuBeamGrid` in `render.rs`).
struct Grid {
    size: vec4<u32>,   // xyz: cells, w: the first cell's index in `cells`
    cell: vec4<f32>,   // x: the smallest world edge of a cell, y: a cell's world volume
}

struct Grids {
    grids: array<Grid, 4>,
    hue: vec4<f32>,  // xyz: the colour every volume shares up to a factor, w: 1 when they do
    max_steps: u32,
}

// The deposit's six words a cell: colour · E_beam · e^{−σt dₛ} (rgb), then the
// directions of the samples whose lowest corner the cell is, weighted by their light
// (xyz), each a signed 32-bit fixed-point number (`fixed_units`), so that it adds with
// one integer atomic where a float add needs a compare-exchange loop. `resolve` turns
// them into the march's two `vec4<f32>` a cell.
const FIXED_WORDS: u32 = 6u;
const DIRECTION_WORD: u32 = 3u;

// `build.wgsl`'s FLUX: the build's kept flux, three words of f32 bits.
const FLUX: u32 = 9u;

// The fixed-point units a cell's value is counted in: 2²⁵ units to Φ · edge / V (Φ the
// build's kept flux, its largest channel, `counters[9..12]`; edge and V a cell's).
// Where every beam meets one cell it holds under 11 Φ · edge / V in a channel (a beam's
// path through the eight cells around a sample is under 2√3 edges, its power under
// 3 Φ), so the three channels' sum, which one hue keeps, and the summed direction stay
// under 33 · 2²⁵ < 2³¹ units. A cell of the mean brightness of a 96² layer that every
// beam crosses counts about 2¹² units.
fn fixed_units(g: Grid, flux: vec3<f32>) -> f32 {
    let unit = max(flux.x, max(flux.y, flux.z)) * g.cell.x / g.cell.y;
    return select(1.0, clamp(33554432.0 / unit, 1.0e-30, 1.0e30), unit > 0.0);
}

struct GridCorner {
    cell: u32,  // the cell's index in `cells`, all grids together
    weight: f32,
}

// The eight cells around a point: the lowest one's grid coordinates and the point's
// place between their centres, found once for all eight corners.
struct GridCorners {
    base: vec3<u32>,
    f: vec3<f32>,
}

// `BeamGrid::corners`: the eight cells around a point of the unit cube.
fn grid_corners(g: Grid, local: vec3<f32>) -> GridCorners {
    return grid_corners_at(g, (local + 0.5) * vec3<f32>(g.size.xyz) - 0.5);
}

// `BeamGrid::corners_at`: the same of a point in grid coordinates (cell centres at
// whole numbers; the outer cells' centres clamp).
fn grid_corners_at(g: Grid, grid_point: vec3<f32>) -> GridCorners {
    let size = vec3<f32>(g.size.xyz);
    let q = clamp(grid_point, vec3(0.0), size - 1.0);
    let base = max(min(floor(q), size - 2.0), vec3(0.0));
    return GridCorners(vec3<u32>(base), q - base);
}

// Corner `corner` (0 to 7) of `corners` and its trilinear weight between cell centres.
fn grid_corner(g: Grid, corners: GridCorners, corner: u32) -> GridCorner {
    let o = vec3(corner & 1u, (corner >> 1u) & 1u, corner >> 2u);
    let c = corners.base + o;
    let w = select(1.0 - corners.f, corners.f, o == vec3(1u));
    return GridCorner(g.size.w + (c.z * g.size.y + c.y) * g.size.x + c.x, w.x * w.y * w.z);
}

#ifdef DEPOSIT
@group(0) @binding(0) var<storage, read> volumes: array<CausticVolume>;
@group(0) @binding(1) var<storage, read> counters: array<u32>;
@group(0) @binding(2) var<uniform> settings: VolumeSettings;
@group(0) @binding(3) var<uniform> grids: Grids;
@group(0) @binding(4) var<storage, read_write> fixed: array<atomic<u32>>;

// `caustics_core::volumes::{MAX_DEPOSIT_LAYERS, MAX_DEPOSIT_SPLIT}`.
const MAX_DEPOSIT_LAYERS: u32 = 1024u;
const MAX_DEPOSIT_SPLIT: u32 = 64u;

// `value` fixed units, rounded, added to the signed number at `word`.
fn add(word: u32, value: f32) {
    atomicAdd(&fixed[word], bitcast<u32>(i32(floor(clamp(value, -2.1e9, 2.1e9) + 0.5))));
}

// `deposit_split`: one split for the whole beam, at its wider end.
fn deposit_split(v: CausticVolume, spacing: f32) -> u32 {
    var longest = 0.0;
    for (var end = 0; end < 2; end++) {
        let alpha = select(0.0, v.origin.w, end == 1);
        let x = v.vertex_x.xyz + alpha * v.ray_x.xyz;
        let z = v.vertex_z.xyz + alpha * v.ray_z.xyz;
        let sides = vec3(length(vec2(x.x - x.y, z.x - z.y)), length(vec2(x.y - x.z, z.y - z.z)), length(vec2(x.z - x.x, z.z - z.x)));
        longest = max(longest, max(sides.x, max(sides.y, sides.z)));
    }
    let split = ceil(longest / spacing);
    return select(1u, u32(clamp(split, 1.0, f32(MAX_DEPOSIT_SPLIT))), split == split);
}

// `deposit_barycentric`: thin beam `k` of `split²`, its sub-triangle's centroid.
fn deposit_barycentric(split: u32, k: u32) -> vec3<f32> {
    let a = k / split;
    let b = k % split;
    let n = f32(split);
    var uw = (vec2(f32(a), f32(b)) + 1.0 / 3.0) / n;
    if a + b >= split {
        uw = (vec2(f32(split - 1u - a), f32(split - 1u - b)) + 2.0 / 3.0) / n;
    }
    return vec3(1.0 - uw.x - uw.y, uw.x, uw.y);
}

// `ThinBeam`: the blend of the volume's rays that is a thin beam's central ray, that
// ray in grid coordinates, `start + α · per_alpha`, the axis it runs most along and the
// layers across it that it passes.
struct ThinBeam {
    lambda: vec3<f32>,
    start: vec3<f32>,
    per_alpha: vec3<f32>,
    axis: u32,
    first: i32,
    count: u32,
}

// `ThinBeam::new` (`count` 0 for none).
fn thin_beam(v: CausticVolume, g: Grid, local_from_world: mat4x4<f32>, split: u32, k: u32) -> ThinBeam {
    var beam: ThinBeam;
    beam.count = 0u;
    beam.lambda = deposit_barycentric(split, k);
    let lambda = beam.lambda;
    let origin = v.origin.xyz + v.axis_x.xyz * dot(lambda, v.vertex_x.xyz) + v.axis_z.xyz * dot(lambda, v.vertex_z.xyz);
    let ray = v.axis_x.xyz * dot(lambda, v.ray_x.xyz) + v.axis_y.xyz + v.axis_z.xyz * dot(lambda, v.ray_z.xyz);
    let cells = vec3<f32>(g.size.xyz);
    beam.start = ((local_from_world * vec4(origin, 1.0)).xyz + 0.5) * cells - 0.5;
    beam.per_alpha = (local_from_world * vec4(ray, 0.0)).xyz * cells;
    let along = abs(beam.per_alpha);
    beam.axis = select(select(2u, 1u, along.y >= along.z), 0u, along.x >= along.y && along.x >= along.z);
    let a = beam.start[beam.axis];
    let b = a + v.origin.w * beam.per_alpha[beam.axis];
    let lo = min(a, b);
    let hi = max(a, b);
    let finite = all(abs(beam.start) <= vec3(3.0e38)) && all(abs(beam.per_alpha) <= vec3(3.0e38));
    if !(finite && hi > lo) {
        return beam;
    }
    let first = max(floor(lo + 0.5), 0.0);
    let last = min(floor(hi + 0.5), cells[beam.axis] - 1.0);
    beam.first = i32(first);
    beam.count = u32(clamp(last - first + 1.0, 0.0, f32(MAX_DEPOSIT_LAYERS)));
    return beam;
}

struct BeamLayer {
    found: bool,
    alpha: f32,
    d_alpha: f32,
    grid_point: vec3<f32>,
}

// `ThinBeam::layer`.
fn beam_layer(beam: ThinBeam, depth: f32, j: u32) -> BeamLayer {
    var out: BeamLayer;
    out.found = false;
    let layer = f32(beam.first + i32(j));
    let a0 = (layer - 0.5 - beam.start[beam.axis]) / beam.per_alpha[beam.axis];
    let a1 = (layer + 0.5 - beam.start[beam.axis]) / beam.per_alpha[beam.axis];
    let whole_lo = min(a0, a1);
    let whole_hi = max(a0, a1);
    let lo = max(whole_lo, 0.0);
    let hi = min(whole_hi, depth);
    if !(hi > lo) {
        return out;
    }
    out.found = true;
    out.alpha = 0.5 * (lo + hi);
    out.d_alpha = hi - lo;
    out.grid_point = beam.start + out.alpha * beam.per_alpha;
    out.grid_point[beam.axis] = layer;
    return out;
}

// The deposit's spread (`BeamGrid::deposit`) over the cells around a grid point on a
// layer's middle plane across `axis`: the four of its layer, since the other four weigh
// nothing (one atomic add a channel each, in fixed-point units; where every volume
// shares one hue, only the source's sum, which `resolve` shares out by the hue), and
// its direction added to the lowest of the eight.
fn spread(g: Grid, grid_point: vec3<f32>, axis: u32, source: vec3<f32>, direction: vec3<f32>) {
    let one_hue = grids.hue.w > 0.0;
    let channels = select(3u, 1u, one_hue);
    let light = select(source, vec3(source.x + source.y + source.z, 0.0, 0.0), one_hue);
    let corners = grid_corners_at(g, grid_point);
    // The layer's side of the eight along `axis` (its weight there is 0 or 1), and the
    // two axes across it.
    let side = select(0u, 1u, corners.f[axis] > 0.5) << axis;
    let across = vec2((axis + 1u) % 3u, (axis + 2u) % 3u);
    for (var j = 0u; j < 4u; j++) {
        let c = grid_corner(g, corners, side | ((j & 1u) << across.x) | ((j >> 1u) << across.y));
        if c.weight == 0.0 {
            continue;
        }
        for (var k = 0u; k < channels; k++) {
            add(c.cell * FIXED_WORDS + k, c.weight * light[k]);
        }
    }
    let lowest = grid_corner(g, corners, 0u).cell * FIXED_WORDS + DIRECTION_WORD;
    for (var k = 0u; k < 3u; k++) {
        add(lowest + k, direction[k]);
    }
}

// Invocations that share one volume's samples: a beam finer than a cell has one a
// layer it crosses, a few tens, so a workgroup takes four volumes at a time.
const VOLUME_LANES: u32 = 16u;

// Four volumes a workgroup at a time (the build's count in `counters[1]`), sixteen
// invocations sharing each thin beam's layers; `BeamGrid::deposit` per medium.
// Integer adds: the sums do not depend on the order the GPU runs them in.
@compute @workgroup_size(64)
fn deposit(@builtin(workgroup_id) group: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    let count = counters[1];
    let flux = bitcast<vec3<f32>>(vec3(counters[FLUX], counters[FLUX + 1u], counters[FLUX + 2u]));
    let per_group = 64u / VOLUME_LANES;
    let lane = local % VOLUME_LANES;
    for (var index = group.x * per_group + local / VOLUME_LANES; index < count; index += groups.x * per_group) {
        let v = volumes[index];
        for (var m = 0u; m < min(settings.medium_count, 4u); m++) {
            let medium = settings.media[m];
            let g = grids.grids[m];
            let units = fixed_units(g, flux);
            let sigma_t = medium.extinction.xyz;
            let split = deposit_split(v, g.cell.x);
            let cells = vec3<f32>(g.size.xyz);
            for (var k = 0u; k < split * split; k++) {
                let beam = thin_beam(v, g, medium.local_from_world, split, k);
                for (var j = lane; j < beam.count; j += VOLUME_LANES) {
                    let layer = beam_layer(beam, v.origin.w, j);
                    let local = (layer.grid_point + 0.5) / cells - 0.5;
                    if !layer.found || !(max(abs(local.x), max(abs(local.y), abs(local.z))) <= 0.5) {
                        continue;
                    }
                    let alpha = layer.alpha;
                    let x = v.vertex_x.xyz + alpha * v.ray_x.xyz;
                    let z = v.vertex_z.xyz + alpha * v.ray_z.xyz;
                    let area = 0.5 * abs((x.y - x.x) * (z.z - z.x) - (z.y - z.x) * (x.z - x.x)) / f32(split * split);
                    let s = sample_on_ray(v, beam.lambda, alpha, settings.intensity_mode, settings.max_magnification);
                    if !s.inside {
                        continue;
                    }
                    let beam_length = length(s.ray);
                    let source = v.color.rgb * exp(-sigma_t * (s.depth * beam_length)) * (s.plane_irradiance * beam_length * area * layer.d_alpha / g.cell.y * units);
                    if any(source != source) || any(abs(source) > vec3(3.0e38)) {
                        continue;
                    }
                    spread(g, layer.grid_point, beam.axis, source, s.ray / beam_length * (source.x + source.y + source.z));
                }
            }
        }
    }
}
#endif

// Does nothing: dispatched first under the deposit's or the resolve's bindings while
// timestamps are recorded, so that lavapipe times that pass whole
// (`gpu_work::anchor_first_timestamp`).
@compute @workgroup_size(1)
fn anchor() {}

#ifdef RESOLVE
@group(0) @binding(0) var<storage, read> counters: array<u32>;
@group(0) @binding(1) var<uniform> grids: Grids;
@group(0) @binding(2) var<storage, read> fixed: array<u32>;
@group(0) @binding(3) var<storage, read_write> cells: array<vec4<f32>>;

// A fixed-point word (`add`) as a float.
fn from_fixed(word: u32) -> f32 {
    return f32(bitcast<i32>(fixed[word]));
}

// The directions deposited at a cell's word `DIRECTION_WORD`.
fn deposited_direction(cell: u32) -> vec3<f32> {
    let word = cell * FIXED_WORDS + DIRECTION_WORD;
    return vec3(from_fixed(word), from_fixed(word + 1u), from_fixed(word + 2u));
}

// One invocation a cell of every grid: its fixed-point words as the march reads them,
// its direction gathered from the eight cells below it (`BeamGrid::gather_directions`).
// The deposit's words are cleared after this pass, since a cell reads its neighbours'.
@compute @workgroup_size(64)
fn resolve(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let flux = bitcast<vec3<f32>>(vec3(counters[FLUX], counters[FLUX + 1u], counters[FLUX + 2u]));
    let total = arrayLength(&cells) / 2u;
    for (var cell = id.x; cell < total; cell += groups.x * 64u) {
        var m = 0u;
        while m < 3u && cell >= grids.grids[m + 1u].size.w && grids.grids[m + 1u].size.w != 0u {
            m++;
        }
        let g = grids.grids[m];
        let units = fixed_units(g, flux);
        let word = cell * FIXED_WORDS;
        let first = g.size.w;
        let at = cell - first;
        let c = vec3(at % g.size.x, (at / g.size.x) % g.size.y, at / (g.size.x * g.size.y));
        var direction = vec3(0.0);
        for (var corner = 0u; corner < 8u; corner++) {
            let o = vec3(corner & 1u, (corner >> 1u) & 1u, corner >> 2u);
            if all(c >= o) {
                let b = c - o;
                direction += deposited_direction(first + (b.z * g.size.y + b.y) * g.size.x + b.x);
            }
        }
        // Where every volume shares a hue, one vec4 a cell: the direction and the
        // source's sum, which `lookup` shares out by the hue.
        if grids.hue.w > 0.0 {
            cells[2u * cell] = vec4(direction, from_fixed(word)) / units;
            continue;
        }
        cells[2u * cell] = vec4(from_fixed(word), from_fixed(word + 1u), from_fixed(word + 2u), 0.0) / units;
        cells[2u * cell + 1u] = vec4(direction / units, 0.0);
    }
}
#endif

#ifdef MARCH
@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var<uniform> settings: VolumeSettings;
@group(0) @binding(2) var<uniform> grids: Grids;
@group(0) @binding(3) var<storage, read> cells: array<vec4<f32>>;
#ifdef MULTISAMPLED
@group(0) @binding(4) var depth_prepass: texture_depth_multisampled_2d;
#else
@group(0) @binding(4) var depth_prepass: texture_depth_2d;
#endif

const PI: f32 = 3.141592653589793;

// `BeamGrid::lookup`: source (xyz) and summed direction, trilinear between cell centres.
fn lookup(g: Grid, local: vec3<f32>) -> array<vec3<f32>, 2> {
    let corners = grid_corners(g, local);
    if grids.hue.w > 0.0 {
        // One vec4 a cell (`resolve`): half the loads.
        var packed = vec4(0.0);
        for (var corner = 0u; corner < 8u; corner++) {
            let c = grid_corner(g, corners, corner);
            packed += c.weight * cells[c.cell * 2u];
        }
        return array(grids.hue.xyz * packed.w, packed.xyz);
    }
    var source = vec3(0.0);
    var direction = vec3(0.0);
    for (var corner = 0u; corner < 8u; corner++) {
        let c = grid_corner(g, corners, corner);
        source += c.weight * cells[c.cell * 2u].xyz;
        direction += c.weight * cells[c.cell * 2u + 1u].xyz;
    }
    return array(source, direction);
}

// `BeamGrid::in_scattered_radiance` at the view's pixel this fragment stands for
// (`shaft_pixel` in `volumes.wgsl`).
@fragment
fn march(in: FullscreenVertexOutput) -> @location(0) vec4<f32> {
#ifdef SHAFT_SCALE
    let at = (floor(in.position.xy) + 0.5) * f32(#{SHAFT_SCALE});
#else
    let at = in.position.xy;
#endif
    let depth = textureLoad(depth_prepass, vec2<i32>(at), 0);
    let eye = world_at(view, at, 1.0);
    let dir = normalize(world_at(view, at, 0.5) - eye);
    var len = 1.0e5;
    if depth > 0.0 {
        len = distance(world_at(view, at, depth), eye);
    }
    var radiance = vec3(0.0);
    for (var m = 0u; m < min(settings.medium_count, 4u); m++) {
        let medium = settings.media[m];
        let t = clip_medium(medium, eye, dir, len);
        if !(t.x < t.y) {
            continue;
        }
        let c = medium.coefficients;
        let sigma_t = medium.extinction.xyz;
        // `march_steps`: one a cell.
        let steps = u32(clamp(ceil((t.y - t.x) / grids.grids[m].cell.x), 1.0, f32(max(grids.max_steps, 1u))));
        let dt = (t.y - t.x) / f32(steps);
        for (var i = 0u; i < steps; i++) {
            let s = t.x + (f32(i) + 0.5) * dt;
            let local = (medium.local_from_world * vec4(eye + s * dir, 1.0)).xyz;
            let cell = lookup(grids.grids[m], local);
            let direction = cell[1];
            let along = length(direction);
            var phase = 1.0 / (4.0 * PI);
            if along > 0.0 {
                let g = clamp(c.y, -0.999, 0.999);
                let denom = max(1.0 + g * g - 2.0 * g * dot(direction / along, -dir), 1e-12);
                phase = (1.0 - g * g) / (4.0 * PI * denom * sqrt(denom));
            }
            radiance += cell[0] * exp(-sigma_t * (s - t.x)) * (c.x * phase * dt);
        }
    }
    return exposed(radiance, view.exposure);
}
#endif
