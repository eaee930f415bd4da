// What a fullscreen pass onto a view's receivers reads first: the view and its depth
// and normal prepasses (bindings 0 to 2 of group 0), and each pixel's receiver point.

#define_import_path bevy_caustics::receiver_view

#import bevy_render::view::View
#import bevy_caustics::receiver::{centre_depth, world_at}

@group(0) @binding(0) var<uniform> view: View;
#ifdef MULTISAMPLED
@group(0) @binding(1) var depth_prepass: texture_depth_multisampled_2d;
@group(0) @binding(2) var normal_prepass: texture_multisampled_2d<f32>;
#else
@group(0) @binding(1) var depth_prepass: texture_depth_2d;
@group(0) @binding(2) var normal_prepass: texture_2d<f32>;
#endif

struct ReceiverPoint {
    found: bool,        // false where the depth prepass holds nothing (the far plane)
    position: vec3<f32>,
    normal: vec3<f32>,
}

// The receiver point a fragment at `frag` sees, from the depth prepass (the MSAA
// centre's depth, `centre_depth`), and its normal.
fn receiver_point(frag: vec2<f32>) -> ReceiverPoint {
    let pixel = vec2<i32>(frag);
    let depth = textureLoad(depth_prepass, pixel, 0);
    if depth <= 0.0 {
        return ReceiverPoint(false, vec3(0.0), vec3(0.0));
    }
    let n = normalize(textureLoad(normal_prepass, pixel, 0).xyz * 2.0 - 1.0);
    return ReceiverPoint(true, world_at(view, frag, centre_depth(view, depth_prepass, pixel, n)), n);
}
