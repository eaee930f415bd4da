// What the passes that add caustic irradiance at receivers share: the world point a
// pixel sees, rebuilt from its depth, and the exposed, capped value they store.

#define_import_path bevy_caustics::receiver

#import bevy_render::view::View

// `caustics_bevy::irradiance::MAX_EXPOSED_IRRADIANCE`.
const MAX_EXPOSED_IRRADIANCE: f32 = 2048.0;

// Irradiance `e` (the light's units per m²) as the buffer holds it: times the view's
// exposure, within [0, MAX_EXPOSED_IRRADIANCE], and 0 for NaN.
fn exposed(e: vec3<f32>, exposure: f32) -> vec4<f32> {
    let x = e * exposure;
    return vec4(clamp(select(vec3(0.0), x, x == x), vec3(0.0), vec3(MAX_EXPOSED_IRRADIANCE)), 0.0);
}

// World position at a pixel for an NDC depth (reverse Z: 1 near, 0 infinitely far).
fn world_at(view: View, frag: vec2<f32>, depth: f32) -> vec3<f32> {
    let uv = (frag - view.viewport.xy) / view.viewport.zw;
    let clip = view.world_from_clip * vec4(uv.x * 2.0 - 1.0, 1.0 - uv.y * 2.0, depth, 1.0);
    return clip.xyz / clip.w;
}
