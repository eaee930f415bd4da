// The view's depth prepass, single-sampled: what the surface pass tests its prisms'
// back faces against, so that a prism lying wholly in front of the receiver at a pixel
// shades nothing there. Multisampled, the nearest of the pixel's samples (reversed z:
// the greatest): the surface pass shades the receiver where the ray through the
// pixel's centre meets it, which lies among the samples' depths, and a back face just
// behind that point must pass. And, once for every volume that covers the pixel, the
// depth of that point itself (`centre_depth`), which both surface paths read.

#import bevy_core_pipeline::fullscreen_vertex_shader::FullscreenVertexOutput
#import bevy_caustics::receiver::centre_depth
#import bevy_caustics::receiver_view::{view, depth_prepass, normal_prepass}

struct ReceiverDepth {
    @builtin(frag_depth) test: f32,
    @location(0) centre: vec4<f32>,
}

@fragment
fn copy_depth(in: FullscreenVertexOutput) -> ReceiverDepth {
    let pixel = vec2<i32>(in.position.xy);
    let first = textureLoad(depth_prepass, pixel, 0);
    var out = ReceiverDepth(first, vec4(0.0));
#ifdef MULTISAMPLED
    for (var i = 1; i < i32(textureNumSamples(depth_prepass)); i++) {
        out.test = max(out.test, textureLoad(depth_prepass, pixel, i));
    }
#endif
    if first > 0.0 {
        let n = normalize(textureLoad(normal_prepass, pixel, 0).xyz * 2.0 - 1.0);
        out.centre = vec4(centre_depth(view, depth_prepass, pixel, n), 0.0, 0.0, 0.0);
    }
    return out;
}
