// The view's depth prepass, single-sampled: what the surface pass tests its prisms'
// back faces against, so that a prism lying wholly in front of the receiver at a pixel
// shades nothing there. Multisampled, the nearest of the pixel's samples (reversed z:
// the greatest): the surface pass shades the receiver where the ray through the
// pixel's centre meets it, which lies among the samples' depths, and a back face just
// behind that point must pass.

#import bevy_core_pipeline::fullscreen_vertex_shader::FullscreenVertexOutput

#ifdef MULTISAMPLED
@group(0) @binding(0) var depth_prepass: texture_depth_multisampled_2d;
#else
@group(0) @binding(0) var depth_prepass: texture_depth_2d;
#endif

@fragment
fn copy_depth(in: FullscreenVertexOutput) -> @builtin(frag_depth) f32 {
    let pixel = vec2<i32>(in.position.xy);
#ifdef MULTISAMPLED
    var depth = 0.0;
    for (var i = 0; i < i32(textureNumSamples(depth_prepass)); i++) {
        depth = max(depth, textureLoad(depth_prepass, pixel, i));
    }
    return depth;
#else
    return textureLoad(depth_prepass, pixel, 0);
#endif
}
