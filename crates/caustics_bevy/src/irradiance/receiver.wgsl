// What the passes that add caustic irradiance at receivers share: the world point a
// pixel sees, rebuilt from its depth.

#define_import_path bevy_caustics::receiver

#import bevy_render::view::View

// World position at a pixel for an NDC depth (reverse Z: 1 near, 0 infinitely far).
fn world_at(view: View, frag: vec2<f32>, depth: f32) -> vec3<f32> {
    let uv = (frag - view.viewport.xy) / view.viewport.zw;
    let clip = view.world_from_clip * vec4(uv.x * 2.0 - 1.0, 1.0 - uv.y * 2.0, depth, 1.0);
    return clip.xyz / clip.w;
}
