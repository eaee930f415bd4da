// Warped caustic volumes (Ernst, Akenine-Möller & Jensen 2005): the GPU twin of
// `caustics_core::volumes`. The surface pass (`SURFACE`) lights each pixel's receiver
// point with the exact point-in-volume test (§3.3) and the interpolated intensity
// (§3.4) of every volume whose bounding shape covers the pixel, or with the footprint
// filter the mean over the pixel's footprint: `splat` (`SPLAT`, one invocation a
// volume) does it for shapes that cover a few pixels, looping over them, and hands the
// larger ones to the rasteriser, which draws their outlines on the view into
// `surface` (the back faces of their bounding prisms, §4.3, where they reach behind
// the eye).
// The volumetric pass draws every prism into `volumetric`, the eye ray's single
// scattering in media (§3.5). Both surface
// paths read each pixel's receiver depth from `receiver_centre`, which the view's
// depth copy (`receiver_depth.wgsl`) computes once a frame, not once a volume.

#import bevy_render::view::View
#import bevy_caustics::receiver::{Medium, clip_medium, exposed, world_at}
#import bevy_caustics::warped_volumes::{CORNERS_TEXEL, CausticVolume, SURFACE_CORNERS_TEXEL, VolumeSettings, beta, footprint_irradiance, load_volume, sample_volume, to_local, volume_texel}


@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var volumes: texture_2d<f32>;
@group(0) @binding(2) var<uniform> settings: VolumeSettings;
#ifdef RECEIVER_CENTRE
// The depth of the receiver point at each pixel's centre (`centre_depth`), 0 where the
// view sees no surface.
@group(0) @binding(3) var receiver_centre: texture_2d<f32>;
#else
#ifdef MULTISAMPLED
@group(0) @binding(3) var depth_prepass: texture_depth_multisampled_2d;
#else
@group(0) @binding(3) var depth_prepass: texture_depth_2d;
#endif

fn load_depth(pixel: vec2<i32>) -> f32 {
    return textureLoad(depth_prepass, pixel, 0);
}
#endif
#ifdef MULTISAMPLED
@group(0) @binding(4) var normal_prepass: texture_multisampled_2d<f32>;
#else
@group(0) @binding(4) var normal_prepass: texture_2d<f32>;
#endif
#ifdef SPLAT
// The build's counters: [1] is the number of volumes it kept.
@group(0) @binding(5) var<storage, read> counters: array<u32>;
// The light `splat` adds, fixed point, three words a pixel of the view's viewport
// (the first alone where every volume shares `settings.hue`).
@group(0) @binding(6) var<storage, read_write> splatted: array<atomic<u32>>;
// The rasteriser's indirect draw ([0] vertices, [1] instances), the volumes `splat`
// lit and the pixels it shaded for them, then from `FIRST_LARGE` on the volumes the
// rasteriser draws.
@group(0) @binding(7) var<storage, read_write> large: array<atomic<u32>>;
#else
#ifdef SURFACE
@group(0) @binding(5) var<storage, read> large: array<u32>;
#endif
#endif

// `render.rs`: the words of `large`, and the fixed-point scale of `splatted`.
const SPLATTED_VOLUMES: u32 = 4u;
const SPLATTED_PIXELS: u32 = 5u;
const FIRST_LARGE: u32 = 8u;
const SPLAT_SCALE: f32 = #{SPLAT_SCALE}.0;

const PI: f32 = 3.141592653589793;

struct VertexOutput {
    @builtin(position) position: vec4<f32>,
    @location(0) @interpolate(flat) volume: u32,
#ifdef SURFACE
    // The shape's eight corners in pixels, two a vector, where it lies in front of
    // the eye (`outlined` 1).
    @location(1) @interpolate(flat) corners_01: vec4<f32>,
    @location(2) @interpolate(flat) corners_23: vec4<f32>,
    @location(3) @interpolate(flat) corners_45: vec4<f32>,
    @location(4) @interpolate(flat) corners_67: vec4<f32>,
    @location(5) @interpolate(flat) outlined: u32,
#endif
}

#ifdef SURFACE
// The convex hull of thirty-two points, in order around it (gift wrapping): `count`
// of `points`.
struct Outline {
    points: array<vec2<f32>, 32>,
    count: u32,
}

fn outline(p: array<vec2<f32>, 32>) -> Outline {
    var start = 0u;
    for (var k = 1u; k < 32u; k++) {
        if p[k].x < p[start].x || (p[k].x == p[start].x && p[k].y < p[start].y) {
            start = k;
        }
    }
    var out: Outline;
    out.count = 0u;
    var current = start;
    loop {
        out.points[out.count] = p[current];
        out.count++;
        // The point that leaves every other on one side, the farthest where in line.
        var next = (current + 1u) % 32u;
        for (var k = 0u; k < 32u; k++) {
            let a = p[next] - p[current];
            let b = p[k] - p[current];
            let turn = a.x * b.y - a.y * b.x;
            if turn < 0.0 || (turn == 0.0 && dot(b, b) > dot(a, a)) {
                next = k;
            }
        }
        current = next;
        if current == start || out.count == 32u {
            break;
        }
    }
    return out;
}
#endif

@vertex
fn vertex(@builtin(vertex_index) vertex_index: u32, @builtin(instance_index) instance: u32) -> VertexOutput {
    var out: VertexOutput;
#ifdef SURFACE
    // The volumes too large for `splat`; where the rays land on one surface, the
    // slice of the beam crossing the slab around it. Drawn as its outline on the view
    // grown by a pixel (the convex hull of its corners moved a pixel each way, a fan
    // of at most ten triangles, each drawn both ways so that one survives the
    // culling), at the depth of its farthest corner; `surface` keeps the pixels
    // `splat` would light, by its arithmetic (`row_span`): each pixel the shape
    // touches once, where the hexahedron's faces, bilinear patches split in two, may
    // fold.
    let volume = large[FIRST_LARGE + instance];
    out.volume = volume;
    let origin = view.viewport.xy;
    let size = view.viewport.zw;
    var corners: array<vec2<f32>, 8>;
    var grown: array<vec2<f32>, 32>;
    var farthest = 1.0;
    var projected = true;
    for (var k = 0; k < 8; k++) {
        let seen = view_pixel(volume_texel(volumes, volume, SURFACE_CORNERS_TEXEL + u32(k)).xyz);
        corners[k] = seen.xy;
        for (var j = 0; j < 4; j++) {
            grown[4 * k + j] = corners[k] + vec2(f32(j & 1), f32(j >> 1u)) * 2.0 - 1.0;
        }
        farthest = min(farthest, seen.z);
        projected = projected && seen.w != 0.0;
    }
    if projected {
        let hull = outline(grown);
        let t = (vertex_index / 3u) % 10u;
        let i = vertex_index % 3u;
        let flip = vertex_index >= 30u;
        let k = select(t + select(1u, 2u, (i == 2u) != flip), 0u, i == 0u);
        let p = (hull.points[min(k, hull.count - 1u)] - origin) / size;
        // A hair farther (reversed z), so that the depth test keeps the receiver
        // points at that corner's depth to rounding.
        out.position = vec4(p.x * 2.0 - 1.0, 1.0 - p.y * 2.0, farthest * (1.0 - 1.0e-4), 1.0);
        if t + 2u >= hull.count {
            out.position = vec4(0.0, 0.0, 0.0, 1.0);
        }
        out.corners_01 = vec4(corners[0], corners[1]);
        out.corners_23 = vec4(corners[2], corners[3]);
        out.corners_45 = vec4(corners[4], corners[5]);
        out.corners_67 = vec4(corners[6], corners[7]);
        out.outlined = 1u;
        return out;
    }
    // Partly behind the eye: the back faces of the hexahedron, clipped.
    if vertex_index >= 36u {
        out.position = vec4(0.0, 0.0, 0.0, 1.0);
        return out;
    }
    out.outlined = 0u;
#endif
    // `HEXAHEDRON_TRIANGLES` of caustics_core: outward, counter-clockwise.
    var triangles = array<u32, 36>(
        0u, 1u, 2u, 0u, 2u, 3u, 4u, 6u, 5u, 4u, 7u, 6u, 0u, 4u, 5u, 0u, 5u, 1u,
        1u, 5u, 6u, 1u, 6u, 2u, 2u, 6u, 7u, 2u, 7u, 3u, 3u, 7u, 4u, 3u, 4u, 0u,
    );
    let k = triangles[vertex_index];
#ifdef SURFACE
    let corner = volume_texel(volumes, volume, SURFACE_CORNERS_TEXEL + u32(k));
#else
    let volume = instance;
    out.volume = volume;
    let corner = volume_texel(volumes, instance, CORNERS_TEXEL + u32(k));
#endif
    out.position = view.clip_from_world * vec4(corner.xyz, 1.0);
    // A hair farther (reversed z), so that the surface pass's depth test keeps the
    // back faces through a receiver point to rounding.
    out.position.z *= 1.0 - 1.0e-4;
    return out;
}

#ifdef RECEIVER_CENTRE
// The least and greatest x of a convex shape's twelve edges (`corner`, the hexahedron's
// corners in pixels) over the rows `y0 ≤ y ≤ y1`.
fn row_span(corner: array<vec2<f32>, 8>, y0: f32, y1: f32) -> vec2<f32> {
    // The hexahedron's edges: around the top, around the bottom, top to bottom.
    var start = array(0, 1, 2, 3, 4, 5, 6, 7, 0, 1, 2, 3);
    var end = array(1, 2, 3, 0, 5, 6, 7, 4, 4, 5, 6, 7);
    var span = vec2(3.0e38, -3.0e38);
    for (var e = 0; e < 12; e++) {
        let a = corner[start[e]];
        let b = corner[end[e]];
        let low = min(a.y, b.y);
        let high = max(a.y, b.y);
        if low <= y1 && y0 <= high {
            var x0 = a.x;
            var x1 = b.x;
            if a.y != b.y {
                x0 = mix(a.x, b.x, clamp((clamp(y0, low, high) - a.y) / (b.y - a.y), 0.0, 1.0));
                x1 = mix(a.x, b.x, clamp((clamp(y1, low, high) - a.y) / (b.y - a.y), 0.0, 1.0));
            }
            span = vec2(min(span.x, min(x0, x1)), max(span.y, max(x0, x1)));
        }
    }
    return span;
}

// The columns `first ≤ x ≤ last` of the pixels in a row whose centres lie in `span`
// (`reach` 0) or whose squares meet it (`reach` ½); empty where `span` is.
fn columns(span: vec2<f32>, first: i32, last: i32, reach: f32) -> vec2<i32> {
    if !(span.x <= span.y) {
        return vec2(1, 0);
    }
    let from_x = i32(ceil(clamp(span.x, f32(first) - 1.0, f32(last) + 1.0) - 0.5 - reach));
    let to_x = i32(floor(clamp(span.y, f32(first) - 1.0, f32(last) + 1.0) - 0.5 + reach));
    return vec2(max(from_x, first), min(to_x, last));
}

// The columns `first ≤ x ≤ last` of row `y` that a volume's shape (`corner`, in
// pixels) lights: with `settings.footprint_filter` the pixels it touches, else those
// whose centres it covers. `splat` and the rasteriser's `surface` both ask it, so
// that they light the same pixels.
fn lit_columns(corner: array<vec2<f32>, 8>, y: i32, first: i32, last: i32) -> vec2<i32> {
    let reach = select(0.0, 0.5, settings.footprint_filter != 0u);
    let row = f32(y) + 0.5;
    return columns(row_span(corner, row - reach, row + reach), first, last, reach);
}

// A point of the view in pixels of its target (`xy`) and its depth (`z`, reversed);
// `w` 0 behind the eye, or so near its plane that the point leaves every float, else 1.
fn view_pixel(p: vec3<f32>) -> vec4<f32> {
    let clip = view.clip_from_world * vec4(p, 1.0);
    let ndc = clip.xyz / clip.w;
    let projected = clip.w > 0.0 && all(abs(ndc.xy) < vec2(1.0e30));
    let pixel = view.viewport.xy + vec2(ndc.x * 0.5 + 0.5, 0.5 - ndc.y * 0.5) * view.viewport.zw;
    return vec4(pixel, ndc.z, select(0.0, 1.0, projected));
}

// `caustics_core::volumes::MAX_FOOTPRINT_STRETCH`.
const MAX_FOOTPRINT_STRETCH: f32 = 8.0;

// `Footprint::seen`: a step of one pixel between neighbouring eye rays at the receiver
// point's depth, carried along the eye ray (`eye`, unit) onto the tangent plane of
// normal `n`, at most `MAX_FOOTPRINT_STRETCH` times its length.
fn onto_receiver(step: vec3<f32>, eye: vec3<f32>, n: vec3<f32>) -> vec3<f32> {
    let cosine = dot(eye, n);
    let limit = MAX_FOOTPRINT_STRETCH * length(step);
    let along = select(0.0, -dot(step, n) / cosine, cosine != 0.0);
    return step + eye * clamp(along, -limit, limit);
}

// What volume `v` adds to the irradiance buffer at `pixel`, exposed: with `filtered`,
// the mean of its light over the pixel's footprint on the receiver
// (`CausticVolume::irradiance_over`), else its light at the receiver point on the ray
// through the pixel's centre; zero where it lights nothing.
fn surface_light(v: CausticVolume, pixel: vec2<i32>, filtered: bool) -> vec3<f32> {
    let depth = textureLoad(receiver_centre, pixel, 0).x;
    if depth <= 0.0 {
        return vec3(0.0);
    }
    let n = normalize(textureLoad(normal_prepass, pixel, 0).xyz * 2.0 - 1.0);
    // `world_at`, keeping the homogeneous point for the footprint's derivatives.
    let uv = (vec2<f32>(pixel) + 0.5 - view.viewport.xy) / view.viewport.zw;
    let h = view.world_from_clip * vec4(uv.x * 2.0 - 1.0, 1.0 - uv.y * 2.0, depth, 1.0);
    let p = h.xyz / h.w;
    // `CausticVolume::irradiance`: surfaces in the volume's slab, where it has one.
    let d = dot(v.slab.xyz, p);
    if any(v.slab.xyz != vec3(0.0)) && !(d >= v.slab.w && d <= v.slab_far.x) {
        return vec3(0.0);
    }
    if filtered {
        // The unprojection's derivatives at p: along the NDC depth (the eye ray), and
        // one pixel right and down at p's depth.
        let m = view.world_from_clip;
        let eye = normalize(m[2].xyz - p * m[2].w);
        let du = onto_receiver((m[0].xyz - p * m[0].w) * (2.0 / (view.viewport.z * h.w)), eye, n);
        let dv = onto_receiver((m[1].xyz - p * m[1].w) * (-2.0 / (view.viewport.w * h.w)), eye, n);
        let e = footprint_irradiance(v, p, n, du, dv, settings.intensity_mode, settings.max_magnification);
        return exposed(v.color.rgb * e, view.exposure).rgb;
    }
    let s = sample_volume(v, p, settings.intensity_mode, settings.max_magnification);
    if !s.inside {
        return vec3(0.0);
    }
    let e = s.plane_irradiance * max(0.0, -dot(s.ray, n));
    return exposed(v.color.rgb * e, view.exposure).rgb;
}

#ifdef SURFACE
@fragment
fn surface(in: VertexOutput) -> @location(0) vec4<f32> {
    // The large volumes, at the pixels `splat` would light (`add_light`).
    let pixel = vec2<i32>(in.position.xy);
    if in.outlined != 0u {
        let corners = array(in.corners_01.xy, in.corners_01.zw, in.corners_23.xy, in.corners_23.zw, in.corners_45.xy, in.corners_45.zw, in.corners_67.xy, in.corners_67.zw);
        let lit = lit_columns(corners, pixel.y, pixel.x - 2, pixel.x + 2);
        if pixel.x < lit.x || pixel.x > lit.y {
            discard;
        }
    }
    return vec4(surface_light(load_volume(volumes, in.volume), pixel, settings.footprint_filter != 0u), 0.0);
}
#endif
#endif

#ifdef SPLAT
// Adds volume `v`'s light to `splatted` at the pixels of row `y` of the box
// `first`..`last` that its convex shape (`corner`, in pixels) may light: with
// `settings.footprint_filter` every pixel it touches, with the mean over the pixel's
// footprint, else those whose centres it covers, with the point sample. Returns the
// number of pixels shaded.
fn add_light(v: CausticVolume, corner: array<vec2<f32>, 8>, y: i32, first: i32, last: i32) -> u32 {
    let filtered = settings.footprint_filter != 0u;
    let origin = vec2<i32>(view.viewport.xy);
    let width = i32(view.viewport.z);
    let lit = lit_columns(corner, y, first, last);
    for (var x = lit.x; x <= lit.y; x++) {
        let light = surface_light(v, vec2(x, y), filtered);
        let pixel = 3u * u32((y - origin.y) * width + x - origin.x);
        if settings.hue.w > 0.0 {
            // One hue: its largest channel, which `splat_resolve` turns back into
            // the colour (at the cap, the clamp keeps the hue).
            let word = u32(max(light.r, max(light.g, light.b)) * SPLAT_SCALE + 0.5);
            if word != 0u {
                atomicAdd(&splatted[pixel], word);
            }
            continue;
        }
        let words = vec3<u32>(light * SPLAT_SCALE + 0.5);
        for (var c = 0u; c < 3u; c++) {
            if words[c] != 0u {
                atomicAdd(&splatted[pixel + c], words[c]);
            }
        }
    }
    return u32(max(lit.y - lit.x + 1, 0));
}

// A volume's shape as `splat` lights it: its corners in pixels and the box of pixels
// it may light (`rows` 0 where it lights none here).
struct SplatShape {
    corner: array<vec2<f32>, 8>,
    first: vec2<i32>,
    last: vec2<i32>,
    rows: u32,
}

// Volume `index`'s shape: where its surface bounding shape projects onto at most
// `settings.splat_pixels` pixels, the rows of pixels it may light; a larger or clipped
// shape goes to the rasteriser's list, and one off the viewport lights nothing.
fn splat_shape(index: u32) -> SplatShape {
    var shape: SplatShape;
    shape.rows = 0u;
    if index >= counters[1] {
        return shape;
    }
    let v = load_volume(volumes, index);
    // A volume whose rays meet no surface lights none (`SurfaceSlab::EMPTY`).
    if any(v.slab.xyz != vec3(0.0)) && v.slab.w > v.slab_far.x {
        return shape;
    }
    // The corners in pixels of the view's target.
    let origin = view.viewport.xy;
    let size = view.viewport.zw;
    var lo = vec2(3.0e38);
    var hi = vec2(-3.0e38);
    var behind = 0;
    for (var k = 0; k < 8; k++) {
        let seen = view_pixel(v.surface_corners[k].xyz);
        behind += select(1, 0, seen.w != 0.0);
        shape.corner[k] = seen.xy;
        lo = min(lo, seen.xy);
        hi = max(hi, seen.xy);
    }
    // Wholly behind the eye: nothing to light. Partly: the rasteriser clips it.
    if behind == 8 {
        return shape;
    }
    let clipped = behind > 0;
    // The pixels whose centres (point samples) or squares (footprints) meet the
    // shape's box, within the viewport (clamped first, so that every conversion to an
    // integer is in range).
    let reach = select(0.0, 0.5, settings.footprint_filter != 0u);
    shape.first = max(vec2<i32>(ceil(clamp(lo, origin - 1.0, origin + size + 1.0) - 0.5 - reach)), vec2<i32>(origin));
    shape.last = min(vec2<i32>(floor(clamp(hi, origin - 1.0, origin + size + 1.0) - 0.5 + reach)), vec2<i32>(origin + size) - 1);
    if !clipped && any(shape.last < shape.first) {
        return shape;
    }
    // The shape's area in pixels: every point of a convex solid's outline is covered
    // by the projections of exactly two of its faces. A thin sliver across the view
    // (a cardioid's) has a large box and few pixels, and stays here.
    var triangles = array<u32, 36>(
        0u, 1u, 2u, 0u, 2u, 3u, 4u, 6u, 5u, 4u, 7u, 6u, 0u, 4u, 5u, 0u, 5u, 1u,
        1u, 5u, 6u, 1u, 6u, 2u, 2u, 6u, 7u, 2u, 7u, 3u, 3u, 7u, 4u, 3u, 4u, 0u,
    );
    var faces = 0.0;
    for (var t = 0; t < 36; t += 3) {
        let a = shape.corner[triangles[t]];
        let ab = shape.corner[triangles[t + 1]] - a;
        let ac = shape.corner[triangles[t + 2]] - a;
        faces += abs(ab.x * ac.y - ab.y * ac.x);
    }
    if clipped || 0.25 * faces > f32(settings.splat_pixels) {
        let slot = atomicAdd(&large[1], 1u);
        atomicStore(&large[FIRST_LARGE + slot], index);
        return shape;
    }
    shape.rows = u32(shape.last.y - shape.first.y + 1);
    return shape;
}

// A shape of at most this many rows is lit by the invocation that found it, which
// loads its volume once; taller ones share out their rows (`splat`).
const OWN_ROWS: u32 = 16u;

// The workgroup's tall shapes, and how many of their rows come before each's.
var<workgroup> shapes: array<SplatShape, 64>;
var<workgroup> rows_before: array<u32, 65>;

// The surface pass's small volumes, 64 a workgroup: each invocation finds one volume's
// shape (`splat_shape`) and lights it if it is at most `OWN_ROWS` rows tall; the
// workgroup then lights the rows of the taller ones, every 64th row from each
// invocation's, so that a large shape beside small ones keeps no lanes waiting (the
// shape's convexity lets a row of pixels meet it between the outermost points of its
// twelve edges over the row).
@compute @workgroup_size(64)
fn splat(@builtin(workgroup_id) group: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>, @builtin(local_invocation_index) lane: u32) {
    // Workgroups in turn take volumes from the two halves of the list (a bijection on
    // the workgroups): lavapipe runs neighbouring workgroups at once on its threads,
    // and near volumes light near pixels, so that from far apart their atomic adds
    // seldom meet in one cache line.
    let g = group.x + group.y * groups.x;
    let first_volume = (g % 2u * ((groups.x * groups.y + 1u) / 2u) + g / 2u) * 64u;
    if first_volume + lane == 0u {
        atomicStore(&large[0], 60u);
    }
    let shape = splat_shape(first_volume + lane);
    let own = shape.rows <= OWN_ROWS;
    shapes[lane] = shape;
    if own {
        shapes[lane].rows = 0u;
    }
    workgroupBarrier();
    if lane == 0u {
        var rows = 0u;
        for (var k = 0u; k < 64u; k++) {
            rows_before[k] = rows;
            rows += shapes[k].rows;
        }
        rows_before[64] = rows;
    }
    workgroupBarrier();
    var shaded = 0u;
    if own && shape.rows > 0u {
        let v = load_volume(volumes, first_volume + lane);
        for (var row = 0u; row < shape.rows; row++) {
            shaded += add_light(v, shape.corner, shape.first.y + i32(row), shape.first.x, shape.last.x);
        }
    }
    let total = rows_before[64];
    var k = 0u;
    for (var row = lane; row < total; row += 64u) {
        // The shape the row belongs to (rows go up, so the search goes on from the last).
        while rows_before[k + 1u] <= row {
            k++;
        }
        let s = shapes[k];
        shaded += add_light(load_volume(volumes, first_volume + k), s.corner, s.first.y + i32(row - rows_before[k]), s.first.x, s.last.x);
    }
    atomicAdd(&large[SPLATTED_PIXELS], shaded);
    if shape.rows > 0u {
        atomicAdd(&large[SPLATTED_VOLUMES], 1u);
    }
}
#endif

#ifndef RECEIVER_CENTRE
// `caustics_core::volumes::mean_attenuation`: the mean of e^{−σt d} over σt d ∈ [m − x, m + x],
// per channel.
fn mean_attenuation(m: vec3<f32>, x: vec3<f32>) -> vec3<f32> {
    let h = abs(x);
    let short = exp(-m) * (1.0 + h * h / 6.0);
    let long = (exp(h - m) - exp(-h - m)) / (2.0 * max(h, vec3(1.0e-3)));
    return select(long, short, h < vec3(1.0e-3));
}

// Real roots of a s² + b s + c (NaN-free: a missing root is returned as 2, outside [−1, 1]).
fn quadratic_roots(a: f32, b: f32, c: f32) -> vec2<f32> {
    let scale = max(abs(a), max(abs(b), abs(c)));
    if scale == 0.0 {
        return vec2(2.0);
    }
    if abs(a) <= 1e-7 * scale {
        return vec2(select(2.0, -c / b, b != 0.0), 2.0);
    }
    let disc = b * b - 4.0 * a * c;
    if disc < 0.0 {
        return vec2(2.0);
    }
    let q = -0.5 * (b + select(-1.0, 1.0, b >= 0.0) * sqrt(disc));
    if q == 0.0 {
        return vec2(0.0, 2.0);
    }
    return vec2(q / a, c / q);
}

// `in_scattered_radiance` for one volume and one medium: the eye ray's pieces inside
// the warped volume (roots of the βᵢ quadratics, the slab 0 ≤ α ≤ depth and the
// hit planes: `ray_pieces`), each
// scattering e^{−σt dₑ} e^{−σt dₛ} Δx σs p(cos θ) E_beam at its midpoint (§3.5).
fn scatter(v: CausticVolume, m: Medium, eye: vec3<f32>, dir: vec3<f32>, enter: f32, exit: f32) -> vec3<f32> {
    let o = to_local(v, eye);
    let d = vec3(dot(dir, v.axis_x.xyz), dot(dir, v.axis_y.xyz), dot(dir, v.axis_z.xyz));
    var cuts: array<f32, 13>;
    var n = 0;
    cuts[n] = enter;
    n++;
    if abs(d.y) > 1e-12 {
        for (var k = 0; k < 2; k++) {
            let t = (select(0.0, v.origin.w, k == 1) - o.y) / d.y;
            if t > enter && t < exit {
                cuts[n] = t;
                n++;
            }
        }
    }
    let mid = 0.5 * (enter + exit);
    let h = 0.5 * (exit - enter);
    let b0 = beta(v, o + enter * d);
    let b1 = beta(v, o + mid * d);
    let b2 = beta(v, o + exit * d);
    for (var i = 0; i < 3; i++) {
        let roots = quadratic_roots(0.5 * (b2[i] + b0[i]) - b1[i], 0.5 * (b2[i] - b0[i]), b1[i]);
        for (var r = 0; r < 2; r++) {
            let s = roots[r];
            let t = mid + s * h;
            if s > -1.0 && s < 1.0 && t > enter && t < exit {
                cuts[n] = t;
                n++;
            }
        }
    }
    for (var i = 0; i < 3; i++) {
        let plane = v.hit_planes[i];
        let along = dot(plane.xyz, d);
        let t = -(dot(plane.xyz, o) + plane.w) / select(1.0, along, along != 0.0);
        if along != 0.0 && t > enter && t < exit {
            cuts[n] = t;
            n++;
        }
    }
    cuts[n] = exit;
    n++;
    // Insertion sort: at most thirteen cuts.
    for (var i = 1; i < n; i++) {
        let x = cuts[i];
        var j = i - 1;
        while j >= 0 && cuts[j] > x {
            cuts[j + 1] = cuts[j];
            j--;
        }
        cuts[j + 1] = x;
    }
    let c = m.coefficients;
    let sigma_t = m.extinction.xyz;
    var radiance = vec3(0.0);
    for (var i = 0; i + 1 < n; i++) {
        let a = cuts[i];
        let b = cuts[i + 1];
        if b <= a {
            continue;
        }
        let t = 0.5 * (a + b);
        let s = sample_volume(v, eye + t * dir, settings.intensity_mode, settings.max_magnification);
        if !s.inside {
            continue;
        }
        let beam_length = length(s.ray);
        let beam = s.ray / beam_length;
        let g = clamp(c.y, -0.999, 0.999);
        let denom = max(1.0 + g * g - 2.0 * g * dot(beam, -dir), 1e-12);
        let phase = (1.0 - g * g) / (4.0 * PI * denom * sqrt(denom));
        // `mean_attenuation`: the path grows along the piece by (1 + d_α |r|) per unit.
        let attenuation = mean_attenuation(sigma_t * ((t - enter) + s.depth * beam_length), 0.5 * sigma_t * (b - a) * (1.0 + d.y * beam_length));
        radiance += v.color.rgb * attenuation * ((b - a) * c.x * phase * s.plane_irradiance * beam_length);
    }
    return radiance;
}

// The view's pixel a volumetric fragment integrates: itself, or with SHAFT_SCALE the
// centre of the block its texel of the smaller shaft texture stands for.
fn shaft_pixel(position: vec2<f32>) -> vec2<f32> {
#ifdef SHAFT_SCALE
    return (floor(position) + 0.5) * f32(#{SHAFT_SCALE});
#else
    return position;
#endif
}

@fragment
fn volumetric(in: VertexOutput) -> @location(0) vec4<f32> {
    let at = shaft_pixel(in.position.xy);
    let depth = load_depth(vec2<i32>(at));
    // The eye ray starts on the near plane (any projection) and ends at the surface,
    // or far away where the pixel sees the sky.
    let eye = world_at(view, at, 1.0);
    let dir = normalize(world_at(view, at, 0.5) - eye);
    var len = 1.0e5;
    if depth > 0.0 {
        len = distance(world_at(view, at, depth), eye);
    }
    let v = load_volume(volumes, in.volume);
    var radiance = vec3(0.0);
    for (var i = 0u; i < min(settings.medium_count, 4u); i++) {
        let m = settings.media[i];
        let t = clip_medium(m, eye, dir, len);
        if t.x < t.y {
            radiance += scatter(v, m, eye, dir, t.x, t.y);
        }
    }
    return exposed(radiance, view.exposure);
}
#endif
