// What the illumination texture shaders share: a light's frame (`GpuIlluminationFrame`
// in `render.rs`, `caustics_core::illumination_textures::IlluminationTextures`), its
// illumination volumes, and the virtual camera's depth map.

#define_import_path bevy_caustics::illumination_textures

// `render::FAR`: no receiver in a texel, or an unused solid span.
const FAR: f32 = 1.0e30;

struct IlluminationFrame {
    axis: vec4<f32>,
    u: vec4<f32>,
    v: vec4<f32>,
    // The texture rectangle: corner (xy) and extent (zw) in (u, v) metres.
    rectangle: vec4<f32>,
    light_color: vec4<f32>,
    // Up to 16 plane depths, four to a vector.
    depths: array<vec4<f32>, 4>,
    size: u32,
    planes: u32,
    // 0: `Cosine::Receiver`, 1: `Cosine::VirtualCamera`.
    cosine: u32,
    shadow_slack: f32,
    max_magnification: f32,
}

// `IlluminationVolume`: flux.x the flux, flux.y the cross-section `S cos θ`.
struct IlluminationVolume {
    exits: array<vec4<f32>, 3>,
    directions: array<vec4<f32>, 3>,
    flux: vec4<f32>,
}

fn plane_depth(frame: IlluminationFrame, k: u32) -> f32 {
    return frame.depths[k / 4u][k % 4u];
}

// The texels' side in metres.
fn texel_size(frame: IlluminationFrame) -> vec2<f32> {
    return frame.rectangle.zw / f32(frame.size);
}

// `IlluminationTextures::texel_coords`.
fn texel_coords(frame: IlluminationFrame, p: vec3<f32>) -> vec2<f32> {
    return (vec2(dot(p, frame.u.xyz), dot(p, frame.v.xyz)) - frame.rectangle.xy) / frame.rectangle.zw * f32(frame.size);
}

// A texel of the depth map takes three vec4s: (normal, depth), then the solid spans'
// (in, out) pairs (`SeenSurface`, `render::surface_texel`).
fn surface_index(index: u32) -> u32 {
    return 3u * index;
}
