// The media's transmittance behind Bevy's transmissive surfaces
// (`caustics_bevy::medium_fog::behind_transmission`): `surface_depth` draws the nearest
// transmissive surface's depth, `dim` multiplies the opaque image behind it by
// exp(−σt ℓ) over the eye ray's stretch from that surface to the opaque point.

#import bevy_pbr::mesh_functions::{get_world_from_local, mesh_position_local_to_clip}
#import bevy_core_pipeline::fullscreen_vertex_shader::FullscreenVertexOutput
#import bevy_render::view::View
#import bevy_caustics::receiver::{Medium, transmittance, world_at}

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
@group(0) @binding(1) var opaque_depth: texture_depth_multisampled_2d;
#else
@group(0) @binding(1) var opaque_depth: texture_depth_2d;
#endif
@group(0) @binding(2) var surface_depth_texture: texture_depth_2d;
@group(0) @binding(3) var<uniform> media: Media;

@fragment
fn dim(in: FullscreenVertexOutput) -> @location(0) vec4<f32> {
    let pixel = vec2<i32>(in.position.xy);
    let surface = textureLoad(surface_depth_texture, pixel, 0);
    let opaque = textureLoad(opaque_depth, pixel, 0);
    // Reverse Z: nothing transmissive in front of the opaque point.
    if surface <= opaque {
        discard;
    }
    let start = world_at(view, in.position.xy, surface);
    var end: vec3<f32>;
    if opaque > 0.0 {
        end = world_at(view, in.position.xy, opaque);
    } else {
        // The sky: on along the eye ray (parallel to the view's axis when orthographic).
        let orthographic = view.clip_from_view[3].w == 1.0;
        let along = select(start - view.world_position, -view.world_from_view[2].xyz, orthographic);
        end = start + normalize(along) * FAR;
    }
    return vec4(vec3(transmittance(media.media, media.count, start, end)), 1.0);
}
