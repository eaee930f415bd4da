// A caustic volume as the passes read it and the GPU build writes it
// (`GpuCausticVolume` in `render.rs`, `caustics_core::volumes::CausticVolume`).

#define_import_path bevy_caustics::warped_volumes

#import bevy_caustics::receiver::Medium

struct CausticVolume {
    origin: vec4<f32>,          // xyz: origin (a generator vertex), w: depth
    axis_x: vec4<f32>,
    axis_y: vec4<f32>,          // slicing axis: the caustic triangle lies at y = α
    axis_z: vec4<f32>,
    surface_normal: vec4<f32>,  // the generator triangle's normal, rays' side; w: owned sides (bits)
    vertex_x: vec4<f32>,        // §4.1 vertical layout: x of the three vertices
    vertex_z: vec4<f32>,
    ray_x: vec4<f32>,           // rays scaled to r_y = 1
    ray_z: vec4<f32>,
    fan_a: vec4<f32>,           // per-vertex fan area coefficients ā, b̄, c̄ (Fig. 5)
    fan_b: vec4<f32>,
    fan_c: vec4<f32>,
    triangle_abc: vec4<f32>,    // the triangle's own a, b, c
    flux: vec4<f32>,            // per-vertex irradiance on the slicing plane
    color: vec4<f32>,
    light_distance: vec4<f32>,  // the light's path to each vertex (in y = 0), w: 1/range² or 0
    slab: vec4<f32>,           // the slab near ≤ n·p ≤ far around the surface the rays land on (world): xyz n (zero: none), w near
    slab_far: vec4<f32>,       // x: far
    hit_planes: array<vec4<f32>, 3>, // per vertex ray: the first surface it meets, n·p + w < 0 behind
    corners: array<vec4<f32>, 8>,  // the bounding shape (§4.3) the in-scattering pass draws (`ShaftIntegral::Exact`; else maybe `surface_corners`)
    surface_corners: array<vec4<f32>, 8>, // the one the surface pass draws: the slice crossing the slab, or none, or `corners`
}

// The volumes live in a texture (`render::VolumeTexture`): one rgba32float texel a vec4
// of `CausticVolume`, in field order, whole volumes to a row. The passes read a
// volume's fields at scattered places, and lavapipe reads a texel there about five
// times faster than the same four words of a storage buffer, whose loads it makes
// lane by lane; a GPU reads either through its caches.
const VOLUME_TEXELS: u32 = 37u;
// The first texel of `CausticVolume::hit_planes`, of `corners` and of `surface_corners`.
const HIT_PLANES_TEXEL: u32 = 18u;
const CORNERS_TEXEL: u32 = 21u;
const SURFACE_CORNERS_TEXEL: u32 = 29u;

// Where record `index` of `texels` texels (a volume, the build's vertex ray) begins in
// a texture `width` texels wide that holds whole records to a row.
fn record_at(width: u32, texels: u32, index: u32) -> vec2<u32> {
    let per_row = width / texels;
    return vec2(index % per_row * texels, index / per_row);
}

// Where volume `index`'s first texel lies in a texture `width` texels wide.
fn volume_at(width: u32, index: u32) -> vec2<u32> {
    return record_at(width, VOLUME_TEXELS, index);
}

// The volumes a texture of `size` texels holds.
fn volume_capacity(size: vec2<u32>) -> u32 {
    return size.x / VOLUME_TEXELS * size.y;
}

// Texel `k` of the record that begins at `at`.
fn texel(records: texture_2d<f32>, at: vec2<u32>, k: u32) -> vec4<f32> {
    return textureLoad(records, vec2(at.x + k, at.y), 0);
}

// Texel `k` of volume `index`: one field, or one of its corners.
fn volume_texel(volumes: texture_2d<f32>, index: u32, k: u32) -> vec4<f32> {
    return texel(volumes, volume_at(textureDimensions(volumes).x, index), k);
}

// Volume `index`; a pass loads only the fields it reads.
fn load_volume(volumes: texture_2d<f32>, index: u32) -> CausticVolume {
    let at = volume_at(textureDimensions(volumes).x, index);
    return CausticVolume(
        texel(volumes, at, 0u), texel(volumes, at, 1u), texel(volumes, at, 2u), texel(volumes, at, 3u), texel(volumes, at, 4u), texel(volumes, at, 5u),
        texel(volumes, at, 6u), texel(volumes, at, 7u), texel(volumes, at, 8u), texel(volumes, at, 9u), texel(volumes, at, 10u), texel(volumes, at, 11u),
        texel(volumes, at, 12u), texel(volumes, at, 13u), texel(volumes, at, 14u), texel(volumes, at, 15u), texel(volumes, at, 16u), texel(volumes, at, 17u),
        array(texel(volumes, at, 18u), texel(volumes, at, 19u), texel(volumes, at, 20u)),
        array(texel(volumes, at, 21u), texel(volumes, at, 22u), texel(volumes, at, 23u), texel(volumes, at, 24u),
            texel(volumes, at, 25u), texel(volumes, at, 26u), texel(volumes, at, 27u), texel(volumes, at, 28u)),
        array(texel(volumes, at, 29u), texel(volumes, at, 30u), texel(volumes, at, 31u), texel(volumes, at, 32u),
            texel(volumes, at, 33u), texel(volumes, at, 34u), texel(volumes, at, 35u), texel(volumes, at, 36u)),
    );
}

struct VolumeSettings {
    intensity_mode: u32,        // 0 conserving, 1 the paper's interpolation, 2 constant
    max_magnification: f32,
    medium_count: u32,
    splat_pixels: u32,          // `splat` lights the volumes whose shape covers at most this many pixels
    footprint_filter: u32,      // 1: `splat` gives each pixel the mean over its footprint, 0: the point sample
    hue: vec4<f32>,             // xyz: the colour every volume shares up to a factor, largest channel 1; w: 1 when they do
    media: array<Medium, 4>,
}

// `caustics_core::volumes::EDGE_EPSILON`.
const EDGE_EPSILON: f32 = 1.0e-4;

fn to_local(v: CausticVolume, p: vec3<f32>) -> vec3<f32> {
    let d = p - v.origin.xyz;
    return vec3(dot(d, v.axis_x.xyz), dot(d, v.axis_y.xyz), dot(d, v.axis_z.xyz));
}

// Unnormalised barycentric coordinates βᵢ in the caustic triangle at depth α = y
// (§3.3, §4.1), from the edge vectors p − cⁱ (see `CausticVolume::beta`).
fn beta(v: CausticVolume, p: vec3<f32>) -> vec3<f32> {
    let ex = p.x - (v.vertex_x.xyz + p.y * v.ray_x.xyz);
    let ez = p.z - (v.vertex_z.xyz + p.y * v.ray_z.xyz);
    return ez.yzx * ex.zxy - ex.yzx * ez.zxy;
}

// A local point's height above the generator triangle, on the side the rays leave to.
fn height(v: CausticVolume, p: vec3<f32>) -> f32 {
    let n = v.surface_normal.xyz;
    return p.x * dot(v.axis_x.xyz, n) + p.y * dot(v.axis_y.xyz, n) + p.z * dot(v.axis_z.xyz, n);
}

// Normalised barycentric coordinates in .xyz; .w = 1 inside the volume, 0 outside.
fn barycentric(v: CausticVolume, p: vec3<f32>) -> vec4<f32> {
    if !(p.y >= 0.0 && p.y <= v.origin.w) {
        return vec4(0.0);
    }
    if height(v, p) < 0.0 {
        return vec4(0.0);
    }
    let b = beta(v, p);
    let sum = b.x + b.y + b.z;
    if sum == 0.0 {
        return vec4(0.0);
    }
    let lambda = b / sum;
    // A side shared with a neighbour belongs to one of the two (`owned_edges`).
    let owned = u32(v.surface_normal.w);
    var inside = true;
    for (var i = 0u; i < 3u; i++) {
        if (owned & (1u << i)) != 0u {
            inside = inside && lambda[i] >= -EDGE_EPSILON;
        } else {
            inside = inside && lambda[i] > EDGE_EPSILON;
        }
    }
    return vec4(lambda, select(0.0, 1.0, inside));
}

// `CausticVolume::occluded`: behind the hit planes of vertices weighing past one half.
fn occluded(v: CausticVolume, p: vec3<f32>, lambda: vec3<f32>) -> bool {
    var behind = 0.0;
    for (var i = 0; i < 3; i++) {
        if dot(v.hit_planes[i].xyz, p) + v.hit_planes[i].w < 0.0 {
            behind += lambda[i];
        }
    }
    return behind > 0.5;
}

struct VolumeSample {
    inside: bool,
    plane_irradiance: f32,
    ray: vec3<f32>,  // world, unit height along the slicing axis
    depth: f32,
}

// No light: a point outside the volume, or in its shadow.
fn unlit() -> VolumeSample {
    var s: VolumeSample;
    s.inside = false;
    return s;
}

// `CausticVolume::sample` (`VolumeSettings`' mode and cap): irradiance on the slicing plane and the interpolated ray.
fn sample_volume(v: CausticVolume, world: vec3<f32>, intensity_mode: u32, max_magnification: f32) -> VolumeSample {
    let p = to_local(v, world);
    let bary = barycentric(v, p);
    if bary.w == 0.0 {
        return unlit();
    }
    return sample_inside(v, p, bary.xyz, intensity_mode, max_magnification);
}

// `CausticVolume::sample_on_ray`: `sample_volume` at barycentric `lambda` (each above
// the fill rule's margin) in the caustic triangle at depth `alpha`, which lies inside
// wherever 0 ≤ α ≤ depth and it is above the generator triangle.
fn sample_on_ray(v: CausticVolume, lambda: vec3<f32>, alpha: f32, intensity_mode: u32, max_magnification: f32) -> VolumeSample {
    let p = vec3(dot(lambda, v.vertex_x.xyz + alpha * v.ray_x.xyz), alpha, dot(lambda, v.vertex_z.xyz + alpha * v.ray_z.xyz));
    if !(alpha >= 0.0 && alpha <= v.origin.w && height(v, p) >= 0.0) {
        return unlit();
    }
    return sample_inside(v, p, lambda, intensity_mode, max_magnification);
}

// `sample_volume` at a local point `p` found inside, with barycentric coordinates `lambda`.
fn sample_inside(v: CausticVolume, p: vec3<f32>, lambda: vec3<f32>, intensity_mode: u32, max_magnification: f32) -> VolumeSample {
    var s: VolumeSample;
    s.inside = false;
    if occluded(v, p, lambda) {
        return s;
    }
    let alpha = p.y;
    let max_mag = max(max_magnification, 1.0);
    let abc = v.triangle_abc.xyz;
    let triangle_area = abs(abc.x + alpha * abc.y + alpha * alpha * abc.z);
    if triangle_area < abc.x / max_mag {
        return s;
    }
    let flux = v.flux.xyz;
    let constant = (flux.x + flux.y + flux.z) / 3.0 * abc.x / triangle_area;
    let fan_area = v.fan_a.xyz + alpha * v.fan_b.xyz + alpha * alpha * v.fan_c.xyz;
    var e = constant;
    if intensity_mode == 1u {
        let a = dot(lambda, v.fan_a.xyz);
        e = dot(lambda, flux * v.fan_a.xyz) / max(abs(dot(lambda, fan_area)), a / max_mag);
    } else if intensity_mode == 0u {
        let vertex = flux * v.fan_a.xyz / max(abs(fan_area), v.fan_a.xyz / max_mag);
        let mean = (vertex.x + vertex.y + vertex.z) / 3.0;
        if mean > 0.0 {
            e = constant * dot(lambda, vertex) / mean;
        }
    }
    s.inside = true;
    s.ray = v.axis_x.xyz * dot(lambda, v.ray_x.xyz) + v.axis_y.xyz + v.axis_z.xyz * dot(lambda, v.ray_z.xyz);
    // `range_window` on the light's whole path to the point.
    var window = 1.0;
    if v.light_distance.w > 0.0 {
        let path = dot(lambda, v.light_distance.xyz) + alpha * length(s.ray);
        let f = path * path * v.light_distance.w;
        window = clamp(1.0 - f * f, 0.0, 1.0);
        window *= window;
    }
    s.plane_irradiance = e * window;
    s.depth = alpha;
    return s;
}

// Whether every component is a finite number (NaN fails every comparison).
fn finite3(x: vec3<f32>) -> bool {
    return all(abs(x) <= vec3(3.4e38));
}

// Normalised barycentric coordinates of a local point, inside the volume or not.
fn lambda_at(v: CausticVolume, p: vec3<f32>) -> vec3<f32> {
    let b = beta(v, p);
    return b / (b.x + b.y + b.z);
}

// `caustics_core::volumes::footprint_coverage`: .x the area of the part of the unit
// square u, v ∈ [−½, ½] where the three λᵢ + u ∂uᵢ + v ∂vᵢ are non-negative, .yz its
// centroid: each of the seven half-planes a + b·q ≥ 0 that cut it adds the stretch
// of its line inside the other six, counter-clockwise, to the shoelace sums.
fn footprint_coverage(lambda: vec3<f32>, du: vec3<f32>, dv: vec3<f32>) -> vec3<f32> {
    // Each λᵢ's least and greatest over the square: wholly outside, or wholly inside.
    let reach = 0.5 * (abs(du) + abs(dv));
    if any(lambda + reach < vec3(0.0)) {
        return vec3(0.0);
    }
    if all(lambda - reach >= vec3(0.0)) {
        return vec3(1.0, 0.0, 0.0);
    }
    // (a, b.x, b.y) of each half-plane: the square's sides, then λᵢ ≥ 0.
    var planes = array<vec3<f32>, 7>(
        vec3(0.5, 1.0, 0.0),
        vec3(0.5, -1.0, 0.0),
        vec3(0.5, 0.0, 1.0),
        vec3(0.5, 0.0, -1.0),
        vec3(lambda.x, du.x, dv.x),
        vec3(lambda.y, du.y, dv.y),
        vec3(lambda.z, du.z, dv.z),
    );
    var twice_area = 0.0;
    var moment = vec2(0.0);
    for (var k = 0; k < 7; k++) {
        let b = planes[k].yz;
        let length_squared = dot(b, b);
        if length_squared == 0.0 {
            continue;
        }
        // The line a + b·q = 0, run with the inside (b) on its left.
        let origin = -planes[k].x * b / length_squared;
        let along = vec2(b.y, -b.x);
        var enter = -3.4e38;
        var leave = 3.4e38;
        for (var j = 0; j < 7; j++) {
            let at = planes[j].x + dot(planes[j].yz, origin);
            let rate = dot(planes[j].yz, along);
            if j == k {
                continue;
            } else if rate > 0.0 {
                enter = max(enter, -at / rate);
            } else if rate < 0.0 {
                leave = min(leave, -at / rate);
            } else if at < 0.0 || (at == 0.0 && j < k) {
                // Outside a parallel side, or on the same line as an earlier one.
                leave = -3.4e38;
            }
        }
        if enter < leave {
            let p = origin + enter * along;
            let q = origin + leave * along;
            let cross = p.x * q.y - p.y * q.x;
            twice_area += cross;
            moment += (p + q) * cross;
        }
    }
    if !(twice_area > 1.1920929e-7) {
        return vec3(0.0);
    }
    return vec3(0.5 * twice_area, moment / (3.0 * twice_area));
}

// `CausticVolume::irradiance_over` without the slab and the colour: the mean over a
// pixel's footprint `world + u du + v dv` (u, v ∈ [−½, ½]) of the plane irradiance
// times the cosine on `n`: the part of the footprint inside the caustic triangle times
// the irradiance at that part's centroid.
fn footprint_irradiance(v: CausticVolume, world: vec3<f32>, n: vec3<f32>, du_world: vec3<f32>, dv_world: vec3<f32>, intensity_mode: u32, max_magnification: f32) -> f32 {
    let p = to_local(v, world);
    let du = vec3(dot(du_world, v.axis_x.xyz), dot(du_world, v.axis_y.xyz), dot(du_world, v.axis_z.xyz));
    let dv = vec3(dot(dv_world, v.axis_x.xyz), dot(dv_world, v.axis_y.xyz), dot(dv_world, v.axis_z.xyz));
    let centre = lambda_at(v, p);
    let along_u = lambda_at(v, p + 0.5 * du) - lambda_at(v, p - 0.5 * du);
    let along_v = lambda_at(v, p + 0.5 * dv) - lambda_at(v, p - 0.5 * dv);
    if !(finite3(centre) && finite3(along_u) && finite3(along_v)) {
        return 0.0;
    }
    let cover = footprint_coverage(centre, along_u, along_v);
    if cover.x <= 0.0 {
        return 0.0;
    }
    let at = p + cover.y * du + cover.z * dv;
    if !(at.y >= 0.0 && at.y <= v.origin.w) || height(v, at) < 0.0 {
        return 0.0;
    }
    let clamped = max(lambda_at(v, at), vec3(0.0));
    let inside = clamped / (clamped.x + clamped.y + clamped.z);
    if !finite3(inside) {
        return 0.0;
    }
    let s = sample_inside(v, at, inside, intensity_mode, max_magnification);
    if !s.inside {
        return 0.0;
    }
    return cover.x * s.plane_irradiance * max(0.0, -dot(s.ray, n));
}
