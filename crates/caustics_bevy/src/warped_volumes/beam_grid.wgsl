// Light shafts at a fixed cost per eye ray: the GPU twin of
// `caustics_core::volumes::BeamGrid`. `deposit` adds every caustic volume's beam to a
// grid over each medium's box (the mean of colour · E_beam · e^{−σt dₛ} per cell, and
// the beams' summed directions); `march` integrates each eye ray through the grid in
// a fixed number of steps (§3.5's single scattering).

#import bevy_render::view::View
#import bevy_core_pipeline::fullscreen_vertex_shader::FullscreenVertexOutput
#import bevy_caustics::receiver::{Medium, clip_medium, exposed, world_at}
#import bevy_caustics::warped_volumes::{CausticVolume, VolumeSettings, load_volume, sample_on_ray}

// One medium's grid (`GpuGrid` in `beam_grid.rs`).
struct Grid {
    size: vec4<u32>,   // xyz: cells, w: the first cell's index in `fixed`
    cell: vec4<f32>,   // x: the smallest world edge of a cell, y: a cell's world volume, z: its first layer in the textures
    blocks: vec4<u32>, // xyz: blocks of 2 × 2 × 2 cells (`direction_blocks`), w: the first one's index in `fixed`
}

struct Grids {
    grids: array<Grid, 4>,
    hue: vec4<f32>,  // xyz: the colour every volume shares up to a factor, w: 1 when they do
    max_steps: u32,
}

// The deposit's three words a cell, colour · E_beam · e^{−σt dₛ} (rgb), and three a
// block of 2 × 2 × 2 cells after every grid's cells, the directions of the samples
// whose lowest corner lies in the block, weighted by their light (xyz): each a signed
// 32-bit fixed-point number (`fixed_units`), so that it adds with one integer atomic
// where a float add needs a compare-exchange loop. `resolve` turns them into the
// march's two half-float 3D textures (`light`, `directions`).
const FIXED_WORDS: u32 = 3u;

// The first word of block `block` of grid `g`.
fn block_word(g: Grid, block: vec3<u32>) -> u32 {
    return (g.blocks.w + (block.z * g.blocks.y + block.y) * g.blocks.x + block.x) * FIXED_WORDS;
}

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

// The half-float textures' units: 2⁻¹⁶ fixed units of source, 2⁻¹⁹ of direction.
const SOURCE_SCALE: f32 = 1.52587890625e-5;
const DIRECTION_SCALE: f32 = 1.9073486328125e-6;

struct GridCorner {
    cell: u32,  // the cell's index in `fixed`, all grids together
    weight: f32,
}

// The eight cells around a point: the lowest one's grid coordinates and the point's
// place between their centres, found once for all eight corners.
struct GridCorners {
    base: vec3<u32>,
    f: vec3<f32>,
}

// `BeamGrid::corners_at`: the eight cells around a point in grid coordinates (cell
// centres at whole numbers; the outer cells' centres clamp).
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

// A cell's grid (the medium's index) and its place in that grid, from its index in
// `fixed`, all grids together.
struct GridCell {
    m: u32,
    at: vec3<u32>,
}

fn grid_cell(cell: u32) -> GridCell {
    var m = 0u;
    while m < 3u && cell >= grids.grids[m + 1u].size.w && grids.grids[m + 1u].size.w != 0u {
        m++;
    }
    let size = grids.grids[m].size;
    let at = cell - size.w;
    return GridCell(m, vec3(at % size.x, (at / size.x) % size.y, at / (size.x * size.y)));
}

#ifdef DEPOSIT
@group(0) @binding(0) var volumes: texture_2d<f32>;
@group(0) @binding(1) var<storage, read> counters: array<u32>;
@group(0) @binding(2) var<uniform> settings: VolumeSettings;
@group(0) @binding(3) var<uniform> grids: Grids;
@group(0) @binding(4) var<storage, read_write> fixed: array<atomic<u32>>;
// The bundles (`BeamBundle`): a hash table of `BUNDLE_WORDS` a slot, keyed by the entry
// cell's index in `fixed` plus one (0: empty), a power of two of them; then how many
// slots are taken, and which, in the order they were.
@group(0) @binding(5) var<storage, read_write> bundles: array<atomic<u32>>;
// Per volume, four words: the slot of the bundle its beam in medium m went to
// (`gather_bundles`), or `NO_BUNDLE`.
@group(0) @binding(6) var<storage, read_write> bundle_of: array<u32>;

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

// `caustic_area`: the area of the caustic triangle at depth `alpha`.
fn caustic_area(v: CausticVolume, alpha: f32) -> f32 {
    let x = v.vertex_x.xyz + alpha * v.ray_x.xyz;
    let z = v.vertex_z.xyz + alpha * v.ray_z.xyz;
    return 0.5 * abs((x.y - x.x) * (z.z - z.x) - (z.y - z.x) * (x.z - x.x));
}

// `grid_ray`: the blend of the volume's rays by `lambda` in a grid's coordinates.
struct GridRay {
    start: vec3<f32>,
    per_alpha: vec3<f32>,
}

fn grid_ray(v: CausticVolume, lambda: vec3<f32>, local_from_world: mat4x4<f32>, cells: vec3<f32>) -> GridRay {
    let origin = v.origin.xyz + v.axis_x.xyz * dot(lambda, v.vertex_x.xyz) + v.axis_z.xyz * dot(lambda, v.vertex_z.xyz);
    let ray = v.axis_x.xyz * dot(lambda, v.ray_x.xyz) + v.axis_y.xyz + v.axis_z.xyz * dot(lambda, v.ray_z.xyz);
    return GridRay(((local_from_world * vec4(origin, 1.0)).xyz + 0.5) * cells - 0.5, (local_from_world * vec4(ray, 0.0)).xyz * cells);
}

// `ThinBeam::new` (`count` 0 for none).
fn thin_beam(v: CausticVolume, g: Grid, local_from_world: mat4x4<f32>, split: u32, k: u32) -> ThinBeam {
    var beam: ThinBeam;
    beam.count = 0u;
    beam.lambda = deposit_barycentric(split, k);
    let cells = vec3<f32>(g.size.xyz);
    let ray = grid_ray(v, beam.lambda, local_from_world, cells);
    beam.start = ray.start;
    beam.per_alpha = ray.per_alpha;
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
// its direction added to the block of the lowest of the eight.
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
    let block = block_word(g, corners.base / 2u);
    for (var k = 0u; k < 3u; k++) {
        add(block + k, direction[k]);
    }
}

// `caustics_core::volumes::{MAX_BUNDLE_BEAMS, MAX_BUNDLED_SPLIT, MAX_BUNDLE_REACH}`.
const MAX_BUNDLE_BEAMS: u32 = 1024u;
const MAX_BUNDLED_SPLIT: u32 = 6u;
const MAX_BUNDLE_REACH: f32 = 4.0;

// A bundle's words: key, flags (atomic or), the beams counted, then `BeamBundle`'s sums
// in fixed point, each `BUNDLE_SCALE` units to one (the beams' start and end, in
// layers, `BUNDLE_LAYER_SCALE`; their source in the grid's units, `fixed_units`).
const BUNDLE_WORDS: u32 = 19u;
const BUNDLE_FLAGS: u32 = 1u;
const BUNDLE_COUNTED: u32 = 2u;
const BUNDLE_ACROSS: u32 = 3u;  // two words, then the slope's two
const BUNDLE_MOMENTS: u32 = 7u;  // across², across·slope, slope²
const BUNDLE_START: u32 = 10u;  // start, end
const BUNDLE_SOURCE: u32 = 12u;  // rgb, or their sum where every volume shares one hue
const BUNDLE_LENGTH: u32 = 15u;  // world length a layer over a cell's edge
const BUNDLE_DIRECTION: u32 = 16u;  // xyz
const BUNDLE_SCALE: f32 = 65536.0;
const BUNDLE_LAYER_SCALE: f32 = 1024.0;
const NO_BUNDLE: u32 = 0xffffffffu;

// The table's slots (`bundle_slots` in `beam_grid.rs`: its words are `BUNDLE_WORDS + 1`
// a slot and one).
fn bundle_slots() -> u32 {
    return (arrayLength(&bundles) - 1u) / (BUNDLE_WORDS + 1u);
}

// The word that counts the slots taken, which the list of them follows.
fn bundle_list() -> u32 {
    return bundle_slots() * BUNDLE_WORDS;
}

// `value` units, rounded, added to the signed number at bundle word `word`.
fn add_to_bundle(word: u32, value: f32) {
    atomicAdd(&bundles[word], bitcast<u32>(i32(floor(clamp(value, -2.1e9, 2.1e9) + 0.5))));
}

fn bundle_word(word: u32) -> f32 {
    return f32(bitcast<i32>(atomicLoad(&bundles[word])));
}

// The slot of the bundle keyed `key`, inserted where `insert` and missing; `NO_BUNDLE`
// where it is missing or the table is full along its probe (then its beams go one by
// one).
fn bundle_slot(key: u32, insert: bool) -> u32 {
    let mask = bundle_slots() - 1u;
    var slot = (key * 2654435761u) & mask;
    for (var probe = 0u; probe < 32u; probe++) {
        var k = atomicLoad(&bundles[slot * BUNDLE_WORDS]);
        if k == 0u && insert {
            let swap = atomicCompareExchangeWeak(&bundles[slot * BUNDLE_WORDS], 0u, key);
            k = select(swap.old_value, key, swap.exchanged);
            if swap.exchanged {
                let list = bundle_list();
                atomicStore(&bundles[list + 1u + atomicAdd(&bundles[list], 1u)], slot);
            }
        }
        if k == key {
            return slot;
        }
        if k == 0u {
            return NO_BUNDLE;
        }
        slot = (slot + 1u) & mask;
    }
    return NO_BUNDLE;
}

// `BundledBeam`: `found` false for none.
struct BundledBeam {
    found: bool,
    key: u32,
    flags: u32,
    across: vec2<f32>,
    slope: vec2<f32>,
    width: vec3<f32>,
    start: f32,
    end: f32,
    source: vec3<f32>,
    length: f32,
    direction: vec3<f32>,
}

// `BeamGrid::bundled_beam`, in grid `g` of medium `medium` (`units` its fixed units).
fn bundled_beam(v: CausticVolume, g: Grid, local_from_world: mat4x4<f32>, units: f32) -> BundledBeam {
    var m: BundledBeam;
    m.found = false;
    if deposit_split(v, g.cell.x) > MAX_BUNDLED_SPLIT {
        return m;
    }
    let beam = thin_beam(v, g, local_from_world, 1u, 0u);
    if beam.count == 0u {
        return m;
    }
    let axis = beam.axis;
    let rate = abs(beam.per_alpha[axis]);
    let forward = beam.per_alpha[axis] > 0.0;
    let sign = select(-1.0, 1.0, forward);
    let entry = select(beam.first + i32(beam.count) - 1, beam.first, forward);
    m.start = (beam.start[axis] - (f32(entry) - 0.5 * sign)) * sign;
    let a = (axis + 1u) % 3u;
    let b = (axis + 2u) % 3u;
    m.slope = vec2(beam.per_alpha[a], beam.per_alpha[b]) / rate;
    let at_start = vec2(beam.start[a], beam.start[b]) - m.start * m.slope;
    let cells = vec3<f32>(g.size.xyz);
    let across = clamp(floor(at_start + 0.5 * m.slope + 0.5), vec2(0.0), vec2(cells[a], cells[b]) - 1.0);
    let alpha = 0.5 * v.origin.w;
    let s = sample_on_ray(v, beam.lambda, alpha, settings.intensity_mode, settings.max_magnification);
    if !s.inside {
        return m;
    }
    let beam_length = length(s.ray);
    // `thin_beam` keeps only rays that move across the grid: `rate` is positive.
    m.source = v.color.rgb * (s.plane_irradiance * beam_length * caustic_area(v, alpha) / (rate * g.cell.y) * units);
    let sum = m.source.x + m.source.y + m.source.z;
    m.end = m.start + v.origin.w * rate;
    let bound = f32(MAX_DEPOSIT_LAYERS);
    if !(sum > 0.0 && sum <= 3.0e38 && abs(m.start) <= bound && abs(m.end) <= bound) {
        return m;
    }
    // The caustic triangle's own spread across the axis (its sides² over 36).
    var corner_at: array<vec2<f32>, 3>;
    var corner_slope: array<vec2<f32>, 3>;
    for (var i = 0u; i < 3u; i++) {
        var lambda = vec3(0.0);
        lambda[i] = 1.0;
        let r = grid_ray(v, lambda, local_from_world, cells);
        corner_slope[i] = vec2(r.per_alpha[a], r.per_alpha[b]) / rate;
        corner_at[i] = vec2(r.start[a], r.start[b]) - m.start * corner_slope[i];
    }
    m.width = vec3(0.0);
    for (var i = 0u; i < 3u; i++) {
        let j = (i + 1u) % 3u;
        let da = corner_at[i] - corner_at[j];
        let db = corner_slope[i] - corner_slope[j];
        m.width += vec3(dot(da, da), dot(da, db), dot(db, db)) / 36.0;
    }
    var cell = vec3(0u);
    cell[axis] = u32(entry);
    cell[a] = u32(across.x);
    cell[b] = u32(across.y);
    let hue = vec3<u32>(v.color.rgb >= vec3(0.5 * max(v.color.r, max(v.color.g, v.color.b))));
    m.key = g.size.w + (cell.z * g.size.y + cell.y) * g.size.x + cell.x + 1u;
    m.flags = (1u << (2u * axis + select(0u, 1u, forward))) | (1u << (6u + hue.x + 2u * hue.y + 4u * hue.z));
    m.across = at_start - across;
    m.length = beam_length / rate / g.cell.x;
    m.direction = s.ray / beam_length;
    m.found = true;
    return m;
}

// `BeamBundle::merges`, from its flags and the beams counted.
fn bundle_merges(slot: u32) -> bool {
    let flags = atomicLoad(&bundles[slot * BUNDLE_WORDS + BUNDLE_FLAGS]);
    let count = atomicLoad(&bundles[slot * BUNDLE_WORDS + BUNDLE_COUNTED]);
    return count >= 2u && count <= MAX_BUNDLE_BEAMS && countOneBits(flags & 0x3fu) == 1u && countOneBits(flags >> 6u) == 1u;
}

// The build's kept flux and medium `m`'s grid's fixed units.
fn medium_units(m: u32) -> f32 {
    let flux = bitcast<vec3<f32>>(vec3(counters[FLUX], counters[FLUX + 1u], counters[FLUX + 2u]));
    return fixed_units(grids.grids[m], flux);
}

// One invocation a volume: each of its beams that could join a bundle inserts the
// bundle, adds itself to it (`BeamBundle::add`) and keeps its slot in `bundle_of`,
// where `deposit` finds whether the bundle merged (`BeamGrid::deposit_all`'s first
// loop).
@compute @workgroup_size(64)
fn gather_bundles(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    for (var index = id.x; index < counters[1]; index += groups.x * 64u) {
        let v = load_volume(volumes, index);
        for (var m = 0u; m < min(settings.medium_count, 4u); m++) {
            var slot = NO_BUNDLE;
            let member = bundled_beam(v, grids.grids[m], settings.media[m].local_from_world, medium_units(m));
            if member.found {
                slot = bundle_slot(member.key, true);
            }
            if slot != NO_BUNDLE {
                add_to_its_bundle(slot, member);
            }
            bundle_of[4u * index + m] = slot;
        }
    }
}

// Adds a member to its bundle (`BeamBundle::add`).
fn add_to_its_bundle(slot: u32, m: BundledBeam) {
    let at = slot * BUNDLE_WORDS;
    atomicOr(&bundles[at + BUNDLE_FLAGS], m.flags);
    atomicAdd(&bundles[at + BUNDLE_COUNTED], 1u);
    add_to_bundle(at + BUNDLE_ACROSS, m.across.x * BUNDLE_SCALE);
    add_to_bundle(at + BUNDLE_ACROSS + 1u, m.across.y * BUNDLE_SCALE);
    add_to_bundle(at + BUNDLE_ACROSS + 2u, m.slope.x * BUNDLE_SCALE);
    add_to_bundle(at + BUNDLE_ACROSS + 3u, m.slope.y * BUNDLE_SCALE);
    add_to_bundle(at + BUNDLE_MOMENTS, (dot(m.across, m.across) + m.width.x) * BUNDLE_SCALE);
    add_to_bundle(at + BUNDLE_MOMENTS + 1u, (dot(m.across, m.slope) + m.width.y) * BUNDLE_SCALE);
    add_to_bundle(at + BUNDLE_MOMENTS + 2u, (dot(m.slope, m.slope) + m.width.z) * BUNDLE_SCALE);
    add_to_bundle(at + BUNDLE_START, m.start * BUNDLE_LAYER_SCALE);
    add_to_bundle(at + BUNDLE_START + 1u, m.end * BUNDLE_LAYER_SCALE);
    // Where every volume shares one hue the deposit adds the channels' sum alone.
    if grids.hue.w > 0.0 {
        add_to_bundle(at + BUNDLE_SOURCE, m.source.x + m.source.y + m.source.z);
    } else {
        for (var k = 0u; k < 3u; k++) {
            add_to_bundle(at + BUNDLE_SOURCE + k, m.source[k]);
        }
    }
    for (var k = 0u; k < 3u; k++) {
        add_to_bundle(at + BUNDLE_DIRECTION + k, m.direction[k] * BUNDLE_SCALE);
    }
    add_to_bundle(at + BUNDLE_LENGTH, m.length * BUNDLE_SCALE);
}

// ∫ tent from −∞ to x.
fn ramp(x: f32) -> f32 {
    if x <= -1.0 {
        return 0.0;
    }
    if x <= 0.0 {
        return 0.5 * (x + 1.0) * (x + 1.0);
    }
    if x <= 1.0 {
        return 1.0 - 0.5 * (1.0 - x) * (1.0 - x);
    }
    return 1.0;
}

// `bundle_weight`: cell `i`'s share along one axis of a bundle's points within
// `reach` of `mean`.
fn bundle_weight(mean: f32, reach: f32, i: i32) -> f32 {
    let x = mean - f32(i);
    if reach > 1.0e-3 {
        return (ramp(x + reach) - ramp(x - reach)) / (2.0 * reach);
    }
    return max(1.0 - abs(x), 0.0);
}

// `bundle_cells`: the first and last cells (past the edges too) they may light.
fn bundle_cells(mean: f32, reach: f32) -> vec2<i32> {
    return vec2(i32(floor(mean - reach)), i32(floor(mean + reach)) + 1);
}

// One invocation a bundle, from the list of slots taken: a bundle that merges adds its
// light layer by layer (`BeamGrid::deposit_bundle`).
@compute @workgroup_size(64)
fn deposit_bundles(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let one_hue = grids.hue.w > 0.0;
    let channels = select(3u, 1u, one_hue);
    let list = bundle_list();
    let taken = atomicLoad(&bundles[list]);
    for (var listed = id.x; listed < taken; listed += groups.x * 64u) {
        let slot = atomicLoad(&bundles[list + 1u + listed]);
        let at = slot * BUNDLE_WORDS;
        let key = atomicLoad(&bundles[at]);
        let n = f32(atomicLoad(&bundles[at + BUNDLE_COUNTED]));
        if key == 0u || n == 0.0 || !bundle_merges(slot) {
            continue;
        }
        let entry = grid_cell(key - 1u);
        let m = entry.m;
        let g = grids.grids[m];
        let size = g.size.xyz;
        let route = firstTrailingBit(atomicLoad(&bundles[at + BUNDLE_FLAGS]) & 0x3fu);
        let axis = route / 2u;
        let forward = route % 2u == 1u;
        let a = (axis + 1u) % 3u;
        let b = (axis + 2u) % 3u;
        let p = vec2(bundle_word(at + BUNDLE_ACROSS), bundle_word(at + BUNDLE_ACROSS + 1u)) / (BUNDLE_SCALE * n);
        let d = vec2(bundle_word(at + BUNDLE_ACROSS + 2u), bundle_word(at + BUNDLE_ACROSS + 3u)) / (BUNDLE_SCALE * n);
        let var_p = bundle_word(at + BUNDLE_MOMENTS) / (BUNDLE_SCALE * n) - dot(p, p);
        let cov = bundle_word(at + BUNDLE_MOMENTS + 1u) / (BUNDLE_SCALE * n) - dot(p, d);
        let var_d = bundle_word(at + BUNDLE_MOMENTS + 2u) / (BUNDLE_SCALE * n) - dot(d, d);
        let start = bundle_word(at + BUNDLE_START) / (BUNDLE_LAYER_SCALE * n);
        let end = bundle_word(at + BUNDLE_START + 1u) / (BUNDLE_LAYER_SCALE * n);
        let path = bundle_word(at + BUNDLE_LENGTH) / (BUNDLE_SCALE * n) * g.cell.x;
        let source = vec3(bundle_word(at + BUNDLE_SOURCE), bundle_word(at + BUNDLE_SOURCE + 1u), bundle_word(at + BUNDLE_SOURCE + 2u));
        let summed = vec3(bundle_word(at + BUNDLE_DIRECTION), bundle_word(at + BUNDLE_DIRECTION + 1u), bundle_word(at + BUNDLE_DIRECTION + 2u));
        let direction = summed / max(length(summed), 1.0e-30);
        let sigma_t = settings.media[m].extinction.xyz;
        let centre = vec2(f32(entry.at[a]), f32(entry.at[b]));
        let first = i32(floor(max(start, 0.0)));
        let last = min(i32(ceil(end)), first + i32(MAX_DEPOSIT_LAYERS));
        for (var k = first; k < last; k++) {
            let layer = i32(entry.at[axis]) + select(-k, k, forward);
            if layer < 0 || layer >= i32(size[axis]) {
                break;
            }
            let lo = max(start, f32(k));
            let hi = min(end, f32(k) + 1.0);
            if !(hi > lo) {
                continue;
            }
            let t = 0.5 * (lo + hi);
            let mean = centre + p + d * t;
            if !(all(mean >= vec2(-0.5)) && all(mean <= vec2(f32(size[a]), f32(size[b])) - 0.5)) {
                continue;
            }
            let reach = min(sqrt(1.5 * max(var_p + 2.0 * t * cov + t * t * var_d, 0.0)), MAX_BUNDLE_REACH);
            let light = source * exp(-sigma_t * (path * (t - start))) * (hi - lo);
            let flat = select(light, vec3(light.x + light.y + light.z, 0.0, 0.0), one_hue);
            var c = vec3(0u);
            c[axis] = u32(layer);
            let edge = vec2(i32(size[a]) - 1, i32(size[b]) - 1);
            let ra = bundle_cells(mean.x, reach);
            let rb = bundle_cells(mean.y, reach);
            for (var i = ra.x; i <= ra.y; i++) {
                let w_i = bundle_weight(mean.x, reach, i);
                if w_i <= 0.0 {
                    continue;
                }
                c[a] = u32(clamp(i, 0, edge.x));
                for (var j = rb.x; j <= rb.y; j++) {
                    c[b] = u32(clamp(j, 0, edge.y));
                    let w = w_i * bundle_weight(mean.y, reach, j);
                    let cell = g.size.w + (c.z * size.y + c.y) * size.x + c.x;
                    for (var ch = 0u; ch < channels; ch++) {
                        add(cell * FIXED_WORDS + ch, w * flat[ch]);
                    }
                }
            }
            // The direction to every other block from the one of the first cell
            // lit, whose eight blocks cover those lit.
            let first_block = clamp(vec2(ra.x, rb.x), vec2(0), edge) / 2;
            let last_block = clamp(vec2(ra.y, rb.y), vec2(0), edge) / 2;
            let blocks = (last_block - first_block) / 2 + 1;
            let share = direction * ((light.x + light.y + light.z) / f32(blocks.x * blocks.y));
            var block = vec3(0u);
            block[axis] = u32(layer) / 2u;
            for (var i = first_block.x; i <= last_block.x; i += 2) {
                block[a] = u32(i);
                for (var j = first_block.y; j <= last_block.y; j += 2) {
                    block[b] = u32(j);
                    let word = block_word(g, block);
                    for (var k3 = 0u; k3 < 3u; k3++) {
                        add(word + k3, share[k3]);
                    }
                }
            }
        }
    }
}

// A volume split into more thin beams than this goes to its workgroup's queue
// (`wide`), whose invocations share out its thin beams, so that no invocation is
// left with a wide beam's thousands of samples. Fewer thin beams than invocations
// would leave most of them idle: on lavapipe, queueing volumes of more than 8 thin
// beams took the deposit of a 33² pool from 64 to 108 ms.
const QUEUED_BEAMS: u32 = 64u;

// The beams of this workgroup's volumes queued for all its invocations to share:
// volume index · 4 + medium.
var<workgroup> wide: array<u32, 256>;
var<workgroup> queued: atomic<u32>;

// Thin beams `first`, `first + stride`, … of volume `v`'s beam in medium `m`, split
// `split`² ways (`deposit_split`), every layer each crosses (`BeamGrid::deposit`).
fn deposit_thin_beams(v: CausticVolume, m: u32, split: u32, first: u32, stride: u32) {
    let medium = settings.media[m];
    let g = grids.grids[m];
    let units = medium_units(m);
    let sigma_t = medium.extinction.xyz;
    let cells = vec3<f32>(g.size.xyz);
    for (var k = first; k < split * split; k += stride) {
        let beam = thin_beam(v, g, medium.local_from_world, split, k);
        for (var j = 0u; j < beam.count; j++) {
            let layer = beam_layer(beam, v.origin.w, j);
            let local = (layer.grid_point + 0.5) / cells - 0.5;
            if !layer.found || !(max(abs(local.x), max(abs(local.y), abs(local.z))) <= 0.5) {
                continue;
            }
            let alpha = layer.alpha;
            let area = caustic_area(v, alpha) / f32(split * split);
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

// One invocation a volume (the build's count in `counters[1]`), each of its beams that
// did not join a bundle laid down layer by layer; a beam split into more than
// `QUEUED_BEAMS` thin ones is queued for the whole workgroup. One invocation walks a
// narrow beam's few tens of layers: on a GPU that runs invocations in lockstep groups
// the layers would keep more of them busy, but the volume's setup (its load, its thin
// beam) would be repeated in every one. Integer adds: the sums do not depend on the
// order the GPU runs them in.
@compute @workgroup_size(64)
fn deposit(@builtin(workgroup_id) group: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    let count = counters[1];
    let media = min(settings.medium_count, 4u);
    for (var base = group.x * 64u; base < count; base += groups.x * 64u) {
        if local == 0u {
            atomicStore(&queued, 0u);
        }
        workgroupBarrier();
        let index = base + local;
        if index < count {
            for (var m = 0u; m < media; m++) {
                // A beam whose bundle merges goes with it (`deposit_bundles`); the
                // volume is loaded only for the others.
                let slot = bundle_of[4u * index + m];
                if slot != NO_BUNDLE && bundle_merges(slot) {
                    continue;
                }
                let v = load_volume(volumes, index);
                let split = deposit_split(v, grids.grids[m].cell.x);
                if split * split > QUEUED_BEAMS {
                    wide[atomicAdd(&queued, 1u)] = index * 4u + m;
                } else {
                    deposit_thin_beams(v, m, split, 0u, 1u);
                }
            }
        }
        workgroupBarrier();
        let n = atomicLoad(&queued);
        for (var q = 0u; q < n; q++) {
            let v = load_volume(volumes, wide[q] / 4u);
            let m = wide[q] % 4u;
            deposit_thin_beams(v, m, deposit_split(v, grids.grids[m].cell.x), local, 64u);
        }
        workgroupBarrier();
    }
}
#endif

// Does nothing: dispatched first under the deposit's or the resolve's bindings while
// timestamps are recorded, so that lavapipe times that pass whole
// (`gpu_work::anchor_first_timestamp`).
@compute @workgroup_size(1)
fn anchor() {}

#ifdef RESOLVE
@group(0) @binding(0) var<uniform> grids: Grids;
@group(0) @binding(1) var<storage, read> fixed: array<u32>;
@group(0) @binding(2) var light: texture_storage_3d<rgba16float, write>;
@group(0) @binding(3) var directions: texture_storage_3d<rgba16float, write>;

// A fixed-point word (`add`) as a float.
fn from_fixed(word: u32) -> f32 {
    return f32(bitcast<i32>(fixed[word]));
}

// The directions deposited in block `block` of grid `g`.
fn deposited_direction(g: Grid, block: vec3<u32>) -> vec3<f32> {
    let word = block_word(g, block);
    return vec3(from_fixed(word), from_fixed(word + 1u), from_fixed(word + 2u));
}

// The directions deposited in the 2 × 2 blocks `(bx − i, by − j)`, `i, j ∈ {0, 1}`, of
// block layer `bz`.
fn block_layer(g: Grid, bx: u32, by: u32, bz: u32) -> vec3<f32> {
    var sum = vec3(0.0);
    for (var corner = 0u; corner < 4u; corner++) {
        let o = vec2(corner & 1u, corner >> 1u);
        if bx >= o.x && by >= o.y && bx - o.x < g.blocks.x && by - o.y < g.blocks.y {
            sum += deposited_direction(g, vec3(bx - o.x, by - o.y, bz));
        }
    }
    return sum;
}

// A workgroup's tile of cells: `RESOLVE_TILE`² across x and y, `RESOLVE_LAYERS` along
// z (`resolve_tiles` in `beam_grid.rs` counts them).
const RESOLVE_TILE: u32 = 8u;
const RESOLVE_LAYERS: u32 = 16u;

struct ResolveTile {
    found: bool,
    m: u32,
    origin: vec3<u32>,
}

// Tile `index` of every grid's tiles, grid by grid.
fn resolve_tile(index: u32) -> ResolveTile {
    var rest = index;
    for (var m = 0u; m < 4u; m++) {
        let size = grids.grids[m].size.xyz;
        let per = vec3(RESOLVE_TILE, RESOLVE_TILE, RESOLVE_LAYERS);
        let tiles = (size + per - 1u) / per;
        let count = tiles.x * tiles.y * tiles.z;
        if rest < count {
            let at = vec3(rest % tiles.x, (rest / tiles.x) % tiles.y, rest / (tiles.x * tiles.y));
            return ResolveTile(true, m, at * per);
        }
        rest -= count;
    }
    return ResolveTile(false, 0u, vec3(0u));
}

// One invocation a column of a tile: each cell's fixed-point words as the march reads
// them, its direction gathered from the eight blocks below its block
// (`BeamGrid::gather_directions`) as the sum of two block layers' 2 × 2 sums, each
// found once for the two layers of cells it serves; each grid at its first layer of
// the textures. Half floats hold the fixed units scaled down (`SOURCE_SCALE`,
// `DIRECTION_SCALE`): a channel stays under 2³¹ units, and the eight blocks'
// directions under 1.4 · 2³⁴. The deposit's words are cleared after this pass, since
// a cell reads its neighbours'.
@compute @workgroup_size(8, 8)
fn resolve(@builtin(workgroup_id) group: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>, @builtin(local_invocation_id) lane: vec3<u32>) {
    for (var index = group.x; ; index += groups.x) {
        let tile = resolve_tile(index);
        if !tile.found {
            break;
        }
        let g = grids.grids[tile.m];
        let size = g.size.xyz;
        let x = tile.origin.x + lane.x;
        let y = tile.origin.y + lane.y;
        let first = tile.origin.z;
        let last = min(first + RESOLVE_LAYERS, size.z);
        // The 2 × 2 sums of the cells' block layer and the one below it (the tile's
        // first layer is even: `RESOLVE_LAYERS` is).
        var below = vec3(0.0);
        var layer = vec3(0.0);
        for (var z = first; z < last; z++) {
            if z % 2u == 0u {
                below = layer;
                if z == first && z > 0u {
                    below = block_layer(g, x / 2u, y / 2u, z / 2u - 1u);
                }
                layer = block_layer(g, x / 2u, y / 2u, z / 2u);
            }
            if x < size.x && y < size.y {
                let direction = layer + below;
                let word = (g.size.w + (z * size.y + y) * size.x + x) * FIXED_WORDS;
                let texel = vec3<i32>(vec3(x, y, z + u32(g.cell.z)));
                // Where every volume shares a hue, one texel a cell: the direction and
                // the source's sum, which `lookup` shares out by the hue.
                if grids.hue.w > 0.0 {
                    textureStore(light, texel, vec4(direction * DIRECTION_SCALE, from_fixed(word) * SOURCE_SCALE));
                } else {
                    textureStore(light, texel, vec4(vec3(from_fixed(word), from_fixed(word + 1u), from_fixed(word + 2u)) * SOURCE_SCALE, 0.0));
                    textureStore(directions, texel, vec4(direction * DIRECTION_SCALE, 0.0));
                }
            }
        }
    }
}
#endif

#ifdef MARCH
@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var<uniform> settings: VolumeSettings;
@group(0) @binding(2) var<uniform> grids: Grids;
@group(0) @binding(3) var<storage, read> counters: array<u32>;
@group(0) @binding(4) var light: texture_3d<f32>;
@group(0) @binding(5) var directions: texture_3d<f32>;
@group(0) @binding(6) var trilinear: sampler;
#ifdef MULTISAMPLED
@group(0) @binding(7) var depth_prepass: texture_depth_multisampled_2d;
#else
@group(0) @binding(7) var depth_prepass: texture_depth_2d;
#endif

const PI: f32 = 3.141592653589793;

// `BeamGrid::lookup`: source (xyz, in fixed units scaled by `SOURCE_SCALE`) and summed
// direction, trilinear between cell centres, clamped to the outer cells' centres so
// that the filter never reads the next grid's layers.
fn lookup(g: Grid, local: vec3<f32>) -> array<vec3<f32>, 2> {
    let size = vec3<f32>(g.size.xyz);
    let texel = clamp((local + 0.5) * size - 0.5, vec3(0.0), size - 1.0) + vec3(0.0, 0.0, g.cell.z);
    let at = (texel + 0.5) / vec3<f32>(textureDimensions(light));
    let packed = textureSampleLevel(light, trilinear, at, 0.0);
    if grids.hue.w > 0.0 {
        // One texel a cell (`resolve`): half the samples.
        return array(grids.hue.xyz * packed.w, packed.xyz);
    }
    return array(packed.xyz, textureSampleLevel(directions, trilinear, at, 0.0).xyz);
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
    let flux = bitcast<vec3<f32>>(vec3(counters[FLUX], counters[FLUX + 1u], counters[FLUX + 2u]));
    var radiance = vec3(0.0);
    for (var m = 0u; m < min(settings.medium_count, 4u); m++) {
        let medium = settings.media[m];
        let unscaled = 1.0 / (SOURCE_SCALE * fixed_units(grids.grids[m], flux));
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
            radiance += cell[0] * exp(-sigma_t * (s - t.x)) * (c.x * phase * dt * unscaled);
        }
    }
    return exposed(radiance, view.exposure);
}
#endif
