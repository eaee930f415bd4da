// The view's depth prepass, single-sampled (sample 0, as the passes read it): what the
// surface pass tests its prisms' back faces against, so that a prism lying wholly in
// front of the receiver at a pixel shades nothing there.

#import bevy_core_pipeline::fullscreen_vertex_shader::FullscreenVertexOutput

#ifdef MULTISAMPLED
@group(0) @binding(0) var depth_prepass: texture_depth_multisampled_2d;
#else
@group(0) @binding(0) var depth_prepass: texture_depth_2d;
#endif

@fragment
fn copy_depth(in: FullscreenVertexOutput) -> @builtin(frag_depth) f32 {
    return textureLoad(depth_prepass, vec2<i32>(in.position.xy), 0);
}
