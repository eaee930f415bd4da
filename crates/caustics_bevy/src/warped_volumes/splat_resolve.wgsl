// The light `splat` (`volumes.wgsl`) added in fixed point, three words a pixel of
// the view's viewport (one, times the hue, where every volume shares
// `settings.hue`), added to the view's irradiance buffer: at most
// `MAX_EXPOSED_IRRADIANCE`, as each volume's light is (`exposed`), now that a pixel's
// footprint sums the light of every volume it meets.

#import bevy_render::view::View
#import bevy_core_pipeline::fullscreen_vertex_shader::FullscreenVertexOutput
#import bevy_caustics::receiver::MAX_EXPOSED_IRRADIANCE
#import bevy_caustics::warped_volumes::VolumeSettings

@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var<storage, read> splatted: array<u32>;
@group(0) @binding(2) var<uniform> settings: VolumeSettings;

@fragment
fn project(in: FullscreenVertexOutput) -> @location(0) vec4<f32> {
    let pixel = vec2<u32>(in.position.xy - view.viewport.xy);
    let at = 3u * (pixel.y * u32(view.viewport.z) + pixel.x);
    var light = f32(splatted[at]) * settings.hue.xyz;
    if settings.hue.w == 0.0 {
        light = vec3<f32>(vec3(splatted[at], splatted[at + 1u], splatted[at + 2u]));
    }
    return vec4(min(light / #{SPLAT_SCALE}.0, vec3(MAX_EXPOSED_IRRADIANCE)), 0.0);
}
