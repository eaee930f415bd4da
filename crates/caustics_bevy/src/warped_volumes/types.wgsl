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
    corners: array<vec4<f32>, 8>,  // the bounding shape (§4.3) the in-scattering pass draws
    surface_corners: array<vec4<f32>, 8>, // the one the surface pass draws: the slice crossing the slab, or none, or `corners`
}

struct VolumeSettings {
    intensity_mode: u32,        // 0 conserving, 1 the paper's interpolation, 2 constant
    max_magnification: f32,
    medium_count: u32,
    splat_pixels: u32,          // `splat` lights the volumes whose box holds at most this many pixels
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

// Normalised barycentric coordinates in .xyz; .w = 1 inside the volume, 0 outside.
fn barycentric(v: CausticVolume, p: vec3<f32>) -> vec4<f32> {
    if !(p.y >= 0.0 && p.y <= v.origin.w) {
        return vec4(0.0);
    }
    let n = v.surface_normal.xyz;
    let height = p.x * dot(v.axis_x.xyz, n) + p.y * dot(v.axis_y.xyz, n) + p.z * dot(v.axis_z.xyz, n);
    if height < 0.0 {
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

// `CausticVolume::sample` (`VolumeSettings`' mode and cap): irradiance on the slicing plane and the interpolated ray.
fn sample_volume(v: CausticVolume, world: vec3<f32>, intensity_mode: u32, max_magnification: f32) -> VolumeSample {
    var s: VolumeSample;
    s.inside = false;
    let p = to_local(v, world);
    let bary = barycentric(v, p);
    if bary.w == 0.0 {
        return s;
    }
    let lambda = bary.xyz;
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
