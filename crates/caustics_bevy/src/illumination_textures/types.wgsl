// What the illumination texture shaders share: a light's frame (`GpuIlluminationFrame`
// in `render.rs`, `caustics_core::illumination_textures::IlluminationTextures`), its
// illumination volumes, and the virtual camera's depth map and the depths it saw
// (`seen.wgsl`).

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
    size: u32,
    planes: u32,
    // 0: `Cosine::Receiver`, 1: `Cosine::VirtualCamera`.
    cosine: u32,
    shadow_slack: f32,
    max_magnification: f32,
    // Where the virtual camera's rays start, in depth along the axis.
    start: f32,
    // Where the receivers' instances start in `triangle_bvh` (vec4s); 0: none.
    receivers: u32,
}

// `IlluminationVolume`: flux.x the flux, flux.y the cross-section `S cos θ`.
struct IlluminationVolume {
    exits: array<vec4<f32>, 3>,
    directions: array<vec4<f32>, 3>,
    flux: vec4<f32>,
}

// A depth as a u32 that orders as the depth does, for `atomicMax`.
fn ordered(depth: f32) -> u32 {
    let bits = bitcast<u32>(depth);
    return select(bits | 0x80000000u, ~bits, (bits & 0x80000000u) != 0u);
}

// The nearest and farthest depth the virtual camera saw, from `seen.wgsl`'s two words:
// the largest `~ordered` and `ordered` depth. x > y where it saw none.
fn seen_depths(words: vec2<u32>) -> vec2<f32> {
    if words.y == 0u {
        return vec2(1.0, 0.0);
    }
    let near = ~words.x;
    let far = words.y;
    return vec2(
        bitcast<f32>(select(~near, near & 0x7fffffffu, (near & 0x80000000u) != 0u)),
        bitcast<f32>(select(~far, far & 0x7fffffffu, (far & 0x80000000u) != 0u)),
    );
}

// `planes::plane_depth`: plane `k` evenly across the depths `seen` the camera saw.
fn plane_depth(frame: IlluminationFrame, seen: vec2<f32>, k: u32) -> f32 {
    if frame.planes == 1u {
        return 0.5 * (seen.x + seen.y);
    }
    return seen.x + (seen.y - seen.x) * f32(k) / f32(frame.planes - 1u);
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
