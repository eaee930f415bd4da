// The media's transmittance multiplied into a view's image (`caustics_bevy::medium_fog`):
// `surface_depth` draws the nearest transmissive surface's depth; `dim_behind_transmission`
// multiplies the opaque image behind that surface by exp(−σt ℓ) over the eye ray's stretch
// from the surface to the opaque point; `tint` multiplies the whole image by the part of
// the transmittance to the view's depth that Bevy's grey fog leaves out, exp(−(σt − σt,min) ℓ).

#import bevy_pbr::mesh_functions::{get_world_from_local, mesh_position_local_to_clip}
#import bevy_core_pipeline::fullscreen_vertex_shader::FullscreenVertexOutput
#import bevy_render::view::View
#import bevy_caustics::receiver::{Medium, medium_optical_depth, world_at}

struct Media {
    count: u32,
    media: array<Medium, 4>,
}

// Far enough to leave any medium box behind, for pixels that see the sky.
const FAR: f32 = 1.0e6;

@vertex
fn surface_depth(@builtin(instance_index) instance_index: u32, @location(0) position: vec3<f32>) -> @builtin(position) vec4<f32> {
    return mesh_position_local_to_clip(get_world_from_local(instance_index), vec4(position, 1.0));
}

@group(0) @binding(0) var<uniform> view: View;
#ifdef MULTISAMPLED
@group(0) @binding(1) var view_depth: texture_depth_multisampled_2d;
#else
@group(0) @binding(1) var view_depth: texture_depth_2d;
#endif
@group(0) @binding(2) var<uniform> media: Media;
// Only `dim_behind_transmission`'s layout has it.
@group(0) @binding(3) var surface_depth_texture: texture_depth_2d;

// Where the eye ray through `frag` that passes `start` ends at the view's depth `depth`:
// for the sky (depth 0) far along the ray (parallel to the view's axis when orthographic).
fn ray_end(frag: vec2<f32>, depth: f32, start: vec3<f32>) -> vec3<f32> {
    if depth > 0.0 {
        return world_at(view, frag, depth);
    }
    let orthographic = view.clip_from_view[3].w == 1.0;
    let along = select(start - view.world_position, -view.world_from_view[2].xyz, orthographic);
    return start + normalize(along) * FAR;
}

// Σ σt ℓ over the view's media along the segment from `start` to `end`
// (`medium_optical_depth`).
fn optical_depth(start: vec3<f32>, end: vec3<f32>, tint: bool) -> vec3<f32> {
    var sum = vec3(0.0);
    for (var i = 0u; i < min(media.count, 4u); i++) {
        sum += medium_optical_depth(media.media[i], start, end, tint);
    }
    return sum;
}

@fragment
fn dim_behind_transmission(in: FullscreenVertexOutput) -> @location(0) vec4<f32> {
    let pixel = vec2<i32>(in.position.xy);
    let surface = textureLoad(surface_depth_texture, pixel, 0);
    let opaque = textureLoad(view_depth, pixel, 0);
    // Reverse Z: nothing transmissive in front of the opaque point.
    if surface <= opaque {
        discard;
    }
    let start = world_at(view, in.position.xy, surface);
    return vec4(exp(-optical_depth(start, ray_end(in.position.xy, opaque, start), false)), 1.0);
}

@fragment
fn tint(in: FullscreenVertexOutput) -> @location(0) vec4<f32> {
    // From the near plane: a point on the eye ray for any projection.
    let start = world_at(view, in.position.xy, 1.0);
    let depth = textureLoad(view_depth, vec2<i32>(in.position.xy), 0);
    return vec4(exp(-optical_depth(start, ray_end(in.position.xy, depth, start), true)), 1.0);
}
