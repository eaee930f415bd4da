// Starts a view's caustic irradiance buffer from an application-supplied image of
// irradiance E (lux), stored as E · exposure, capped, so that any light level fits in
// half floats.

#import bevy_render::view::View
#import bevy_caustics::receiver::exposed

@group(0) @binding(0) var injected: texture_2d<f32>;
@group(0) @binding(1) var<uniform> view: View;

@fragment
fn fragment(@builtin(position) position: vec4<f32>) -> @location(0) vec4<f32> {
    // Nearest texel of the injected image, whatever its size relative to the view.
    let size = vec2<f32>(textureDimensions(injected));
    let texel = vec2<i32>(min(floor((position.xy - view.viewport.xy) * size / view.viewport.zw), size - 1.0));
    return exposed(textureLoad(injected, texel, 0).rgb, view.exposure);
}
