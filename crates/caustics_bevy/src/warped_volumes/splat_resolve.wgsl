// The light `splat` (`volumes.wgsl`) added in fixed point, three words a pixel of
// the view's viewport, added to the view's irradiance buffer: at most
// `MAX_EXPOSED_IRRADIANCE`, as each volume's light is (`exposed`), now that a pixel's
// footprint sums the light of every volume it meets.

#import bevy_render::view::View
#import bevy_core_pipeline::fullscreen_vertex_shader::FullscreenVertexOutput
#import bevy_caustics::receiver::MAX_EXPOSED_IRRADIANCE

@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var<storage, read> splatted: array<u32>;

@fragment
fn project(in: FullscreenVertexOutput) -> @location(0) vec4<f32> {
    let pixel = vec2<u32>(in.position.xy - view.viewport.xy);
    let at = 3u * (pixel.y * u32(view.viewport.z) + pixel.x);
    let words = vec3(splatted[at], splatted[at + 1u], splatted[at + 2u]);
    return vec4(min(vec3<f32>(words) / #{SPLAT_SCALE}.0, vec3(MAX_EXPOSED_IRRADIANCE)), 0.0);
}
