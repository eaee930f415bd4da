// Light shafts integrated at one pixel in every SHAFT_SCALE² block (`volumetric` in
// `volumes.wgsl`), spread bilinearly over the view's pixels: each sample stands at
// the centre of its block.

#import bevy_core_pipeline::fullscreen_vertex_shader::FullscreenVertexOutput

@group(0) @binding(0) var shafts: texture_2d<f32>;
@group(0) @binding(1) var shaft_sampler: sampler;

@fragment
fn upsample(in: FullscreenVertexOutput) -> @location(0) vec4<f32> {
    let size = vec2<f32>(textureDimensions(shafts));
    let uv = in.position.xy / (f32(#{SHAFT_SCALE}) * size);
    return vec4(textureSampleLevel(shafts, shaft_sampler, uv, 0.0).rgb, 0.0);
}
