// Caustic maps onto the view (Wyman 2008, Fig. 2's third pass): every pixel's receiver
// point, rebuilt from the depth prepass, looks its light view's caustic map up like a
// shadow map — only where the receiver map shows it is the surface the light sees —
// and adds the irradiance to the view's caustic irradiance buffer
// (`caustic_map::irradiance_at`).

#import bevy_core_pipeline::fullscreen_vertex_shader::FullscreenVertexOutput
#import bevy_caustics::receiver::exposed
#import bevy_caustics::receiver_view::{view, receiver_point}
#import bevy_caustics::caustic_maps::{
    LightView, NO_SURFACE, map_uv, depth_of, light_ray, texel_of, texel_size, receiver_jacobian, map_texels_per_photon, bilinear_taps,
    bilinear_mix,
}

@group(0) @binding(3) var<uniform> light: LightView;
@group(0) @binding(4) var receiver_map: texture_2d<f32>;
@group(0) @binding(5) var<storage, read> resolved: array<f32>;

fn resolved_at(x: u32, y: u32) -> f32 {
    return resolved[y * light.map_resolution + x];
}

@fragment
fn project(in: FullscreenVertexOutput) -> @location(0) vec4<f32> {
    let receiver = receiver_point(in.position.xy);
    if !receiver.found {
        discard;
    }
    let p = receiver.position;
    let n = receiver.normal;
    let m = light.map_resolution;
    let uv = map_uv(light, p);
    if uv.z == 0.0 {
        discard;
    }
    let texel = texel_of(uv.xy, m);
    if texel.z == 0u {
        discard;
    }
    // `caustic_map::visible_from_light`.
    let surface = textureLoad(receiver_map, vec2<i32>(texel.xy), 0).x;
    let z = depth_of(light, p);
    let cos = max(abs(dot(n, light_ray(light, uv.xy).direction)), 0.1);
    let tan = sqrt(1.0 - cos * cos) / cos;
    if surface >= NO_SURFACE || z > surface + texel_size(light, z, m) * (1.0 + tan) + 1.0e-5 * abs(z) {
        discard;
    }
    // `caustic_map::bilinear` of the resolved map.
    let b = bilinear_taps(uv.xy * f32(m) - 0.5, m);
    let c = bilinear_mix(b, resolved_at(b.low.x, b.low.y), resolved_at(b.high.x, b.low.y), resolved_at(b.low.x, b.high.y), resolved_at(b.high.x, b.high.y));
    let ratio = map_texels_per_photon(light);
    let e = c * ratio * ratio * receiver_jacobian(light, p, n);
    return exposed(light.color.rgb * e, view.exposure);
}
