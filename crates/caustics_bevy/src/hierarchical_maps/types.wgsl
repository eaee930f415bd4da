// What every caustic-map shader shares: the light view (`GpuLightView` in
// `render.rs`, `caustics_core::hierarchical::LightView` and `CausticMapSettings`), the
// pyramid's sentinels and the optics, each the WGSL twin of its core function.

#define_import_path bevy_caustics::caustic_maps

// `light_maps::NO_SURFACE`: the depth a light map holds where it saw nothing.
const NO_SURFACE: f32 = 3.4028235e38;
// `hierarchy::EMPTY` and `hierarchy::DIVERSE`.
const EMPTY: u32 = 0xfffffffeu;
const DIVERSE: u32 = 0xffffffffu;
// A node's texel word carries this bit when two or more photons lie below it
// (`Node::count ≥ 2`); texels are below 2²⁴.
const MANY: u32 = 0x40000000u;
// `caustic_map::FLUX_UNITS` and `MAX_SPLAT_RADIUS`, `hierarchical::MIN_SPLAT_DIAMETER`
// and `SPLAT_LEVEL_THRESHOLD`.
const FLUX_UNITS: f32 = 1048576.0;
const MAX_SPLAT_RADIUS: f32 = 16.0;
const MIN_SPLAT_DIAMETER: f32 = 2.0;
const SPLAT_LEVEL_THRESHOLD: f32 = 5.0;
// `photons::ONE_BELOW`.
const ONE_BELOW: f32 = 0.99999994;

struct LightView {
    clip_from_world: mat4x4<f32>,
    origin: vec4<f32>,        // w: 1 in perspective, 0 orthographic
    right: vec4<f32>,         // w: half the image plane's width
    up: vec4<f32>,            // w: half its height
    forward: vec4<f32>,       // w: near
    // Spot cone: xyz its axis, w cos θₒ; a non-spot has `spot_scale` 0.
    spot: vec4<f32>,
    // Linear RGB colour times the light's intensity (irradiance across the beam, or
    // intensity per steradian).
    color: vec4<f32>,
    far: f32,
    spot_scale: f32,          // 1 / (cos θᵢ − cos θₒ)
    photon_resolution: u32,
    map_resolution: u32,
    photon_levels: u32,       // log₂ of the photon resolution
    start_level: u32,
    clustering: u32,          // 0 off, 1 at level 1, 2 at every level
    variable_splats: u32,
    fixed_diameter: f32,
    top_level: u32,           // the caustic map's top level
    discard_above_top: u32,
    exit_iterations: u32,
    // Word offsets of the pyramid's levels 1..=12 (x of [0] is level 1) and of the
    // caustic map's levels 0..=8 in `levels` (two words a texel).
    pyramid_offsets: array<vec4<u32>, 3>,
    level_offsets: array<vec4<u32>, 3>,
    // Each generator's index of refraction, 0 for a mirror, four to a vector.
    materials: array<vec4<f32>, 16>,
    // Each generator's `DRAWN_HERE` and `ONE_SIDED` bits, four to a vector.
    material_flags: array<vec4<u32>, 16>,
    material_count: u32,
    inverse_range_squared: f32,  // 1/range² of a point or spot light, 0 without
    // Photons traced through the generators' BVH (1) or the image-space pair (0).
    traced_paths: u32,
    // How far a traced ray starts off the surface it leaves (`PathTracer::Traced`).
    path_epsilon: f32,
    // Where the BVH's instances start in `triangle_bvh` (vec4s); 0: no BVH.
    bvh_instances: u32,
    // `LightView::emission`: the central fraction of the image the photons cover.
    emission: f32,
}

// `PhotonMaterial::drawn_here` and `PhotonMaterial::one_sided`.
const DRAWN_HERE: u32 = 1u;
const ONE_SIDED: u32 = 2u;

fn pyramid_offset(view: LightView, level: u32) -> u32 {
    let i = level - 1u;
    return view.pyramid_offsets[i / 4u][i % 4u];
}

fn level_offset(view: LightView, level: u32) -> u32 {
    return view.level_offsets[level / 4u][level % 4u];
}

fn is_perspective(view: LightView) -> bool {
    return view.origin.w > 0.5;
}

fn half_extent(view: LightView) -> vec2<f32> {
    return vec2(view.right.w, view.up.w);
}

// `LightView::to_view`.
fn to_view(view: LightView, p: vec3<f32>) -> vec3<f32> {
    let d = p - view.origin.xyz;
    return vec3(dot(d, view.right.xyz), dot(d, view.up.xyz), dot(d, view.forward.xyz));
}

fn depth_of(view: LightView, p: vec3<f32>) -> f32 {
    return dot(p - view.origin.xyz, view.forward.xyz);
}

// `LightView::uv`: xy the map coordinates, z 1 where defined (0 behind a perspective light).
fn map_uv(view: LightView, p: vec3<f32>) -> vec3<f32> {
    let v = to_view(view, p);
    var q = v.xy;
    if is_perspective(view) {
        if v.z <= 0.0 {
            return vec3(0.0);
        }
        q = v.xy / v.z;
    }
    let h = half_extent(view);
    return vec3(0.5 + 0.5 * q.x / h.x, 0.5 - 0.5 * q.y / h.y, 1.0);
}

fn plane_of_uv(view: LightView, uv: vec2<f32>) -> vec2<f32> {
    let h = half_extent(view);
    return vec2((2.0 * uv.x - 1.0) * h.x, (1.0 - 2.0 * uv.y) * h.y);
}

struct Ray {
    origin: vec3<f32>,
    direction: vec3<f32>,
}

// `LightView::ray`.
fn light_ray(view: LightView, uv: vec2<f32>) -> Ray {
    let q = plane_of_uv(view, uv);
    if is_perspective(view) {
        return Ray(view.origin.xyz, normalize(view.forward.xyz + view.right.xyz * q.x + view.up.xyz * q.y));
    }
    return Ray(view.origin.xyz + view.right.xyz * q.x + view.up.xyz * q.y + view.forward.xyz * view.forward.w, view.forward.xyz);
}

fn texel_center(x: u32, y: u32, resolution: u32) -> vec2<f32> {
    return (vec2(f32(x), f32(y)) + 0.5) / f32(resolution);
}

// `LightView::photon_uv`.
fn photon_texel_center(view: LightView, x: u32, y: u32) -> vec2<f32> {
    return 0.5 + (texel_center(x, y, view.photon_resolution) - 0.5) * view.emission;
}

// `LightView::photon_measure`.
fn photon_measure(view: LightView) -> f32 {
    let h = half_extent(view) * view.emission;
    let n = f32(view.photon_resolution);
    return 4.0 * h.x * h.y / (n * n);
}

// `LightView::map_texels_per_photon`.
fn map_texels_per_photon(view: LightView) -> f32 {
    return f32(view.map_resolution) * view.emission / f32(view.photon_resolution);
}

// `LightView::relative_beam`.
fn relative_beam(view: LightView, uv: vec2<f32>) -> f32 {
    if !is_perspective(view) {
        return 1.0;
    }
    let q = plane_of_uv(view, uv);
    let cos2 = 1.0 / (1.0 + dot(q, q));
    return cos2 * sqrt(cos2);
}

// `Light::cone_attenuation`.
fn cone_attenuation(view: LightView, direction: vec3<f32>) -> f32 {
    if view.spot_scale <= 0.0 {
        return 1.0;
    }
    let s = clamp((dot(direction, view.spot.xyz) - view.spot.w) * view.spot_scale, 0.0, 1.0);
    return s * s;
}

// `Light::range_attenuation` for light that has travelled `distance` from the light.
fn range_attenuation(view: LightView, distance: f32) -> f32 {
    if view.inverse_range_squared <= 0.0 {
        return 1.0;
    }
    let f = distance * distance * view.inverse_range_squared;
    let s = clamp(1.0 - f * f, 0.0, 1.0);
    return s * s;
}

// `LightView::receiver_jacobian`.
fn receiver_jacobian(view: LightView, p: vec3<f32>, n: vec3<f32>) -> f32 {
    if !is_perspective(view) {
        return abs(dot(n, view.forward.xyz));
    }
    let d = p - view.origin.xyz;
    let z = dot(d, view.forward.xyz);
    if z <= 0.0 {
        return 0.0;
    }
    return abs(dot(n, d)) / (z * z * z);
}

// `LightView::texel_size`.
fn texel_size(view: LightView, z: f32, resolution: u32) -> f32 {
    let h = half_extent(view);
    var scale = 1.0;
    if is_perspective(view) {
        scale = max(z, 0.0);
    }
    return 2.0 * max(h.x, h.y) * scale / f32(resolution);
}

// `photons::texel_of`: the texel `uv` falls in, z 1 inside the map.
// `LightView::photon_texel`.
fn photon_texel(view: LightView, uv: vec2<f32>) -> vec3<u32> {
    return texel_of(0.5 + (uv - 0.5) / view.emission, view.photon_resolution);
}

fn texel_of(uv: vec2<f32>, resolution: u32) -> vec3<u32> {
    let t = uv * f32(resolution);
    let n = f32(resolution);
    if t.x >= 0.0 && t.y >= 0.0 && t.x < n && t.y < n {
        return vec3(u32(t.x), u32(t.y), 1u);
    }
    return vec3(0u);
}

// The four texels and weights of `caustic_map::bilinear` at continuous texel
// coordinates `q` (texel centres at integers) in a `width²` grid, clamped to its edges.
struct Bilinear {
    low: vec2<u32>,
    high: vec2<u32>,
    f: vec2<f32>,
}

fn bilinear_taps(q_in: vec2<f32>, width: u32) -> Bilinear {
    let q = clamp(q_in, vec2(0.0), vec2(f32(width - 1u)));
    let base = floor(q);
    let low = vec2<u32>(base);
    return Bilinear(low, min(low + 1u, vec2(width - 1u)), q - base);
}

// The taps' values (low.x low.y, high.x low.y, low.x high.y, high.x high.y) mixed as
// `caustic_map::bilinear` does.
fn bilinear_mix(b: Bilinear, a: f32, c: f32, d: f32, e: f32) -> f32 {
    let top = a + (c - a) * b.f.x;
    let bottom = d + (e - d) * b.f.x;
    return top + (bottom - top) * b.f.y;
}

// Octahedral unit vectors (Cigolle et al. 2014), how the light maps store normals.
fn sign_not_zero(v: vec2<f32>) -> vec2<f32> {
    return select(vec2(-1.0), vec2(1.0), v >= vec2(0.0));
}

fn oct_encode(n: vec3<f32>) -> vec2<f32> {
    let p = n.xy / (abs(n.x) + abs(n.y) + abs(n.z));
    if n.z < 0.0 {
        return (1.0 - abs(p.yx)) * sign_not_zero(p);
    }
    return p;
}

fn oct_decode(e: vec2<f32>) -> vec3<f32> {
    var n = vec3(e, 1.0 - abs(e.x) - abs(e.y));
    if n.z < 0.0 {
        n = vec3((1.0 - abs(n.yx)) * sign_not_zero(n.xy), n.z);
    }
    return normalize(n);
}
