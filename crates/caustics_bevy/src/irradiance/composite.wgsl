// Adds caustic light to the receivers: each `CausticReceiver` mesh is drawn again
// after the opaque pass, depth-tested against the scene (so only where it is visible),
// with additive blending of the Lambertian radiance (albedo / π) · E · exposure, as
// the rest of the frame sees it: scaled by the view's `Caustics::intensity`,
// dimmed along the eye ray by the participating media it crosses (none where Bevy's
// volumetric fog draws them and dims the whole pixel), and fogged by the
// view's `DistanceFog` as bevy_pbr fogs the receiver's own light. The buffer already
// holds E · exposure, each pass's share capped; their sum is capped again here.

#import bevy_pbr::mesh_functions::{get_world_from_local, mesh_position_local_to_clip}
#import bevy_pbr::mesh_view_bindings::view
#import bevy_render::maths::PI
#import bevy_caustics::receiver::{MAX_EXPOSED_IRRADIANCE, Medium, medium_optical_depth, world_at}
#ifdef DISTANCE_FOG
#import bevy_pbr::mesh_view_bindings::fog
#import bevy_pbr::fog::{linear_fog, exponential_fog, exponential_squared_fog, atmospheric_fog}
#endif

struct ViewCaustics {
    intensity: f32,
    medium_count: u32,
    media: array<Medium, 4>,
}

struct ReceiverMaterial {
    base_color: vec4<f32>,
    uv_transform: mat3x3<f32>,
    // 1 where the receiver's `StandardMaterial::fog_enabled`, else 0.
    fog_enabled: u32,
}

@group(1) @binding(0) var caustic_irradiance: texture_2d<f32>;
@group(1) @binding(1) var<uniform> caustics: ViewCaustics;
@group(3) @binding(0) var<uniform> material: ReceiverMaterial;
@group(3) @binding(1) var base_color_texture: texture_2d<f32>;
@group(3) @binding(2) var base_color_sampler: sampler;

struct Vertex {
    @builtin(instance_index) instance_index: u32,
    @location(0) position: vec3<f32>,
#ifdef VERTEX_UVS
    @location(1) uv: vec2<f32>,
#endif
}

struct VertexOutput {
    @builtin(position) clip_position: vec4<f32>,
    @location(0) uv: vec2<f32>,
    @location(1) world_position: vec3<f32>,
}

@vertex
fn vertex(vertex: Vertex) -> VertexOutput {
    var out: VertexOutput;
    let world_from_local = get_world_from_local(vertex.instance_index);
    let world = world_from_local * vec4(vertex.position, 1.0);
    out.clip_position = mesh_position_local_to_clip(world_from_local, vec4(vertex.position, 1.0));
    out.world_position = world.xyz / world.w;
#ifdef VERTEX_UVS
    out.uv = vertex.uv;
#else
    out.uv = vec2(0.0);
#endif
    return out;
}

// What reaches the eye of radiance `c` leaving `p`, through the view's fog: bevy_pbr's
// fog is affine in the colour it fogs (`mix(c, fog, f)`, or `c·(1 − ext) + ins`), so the
// fogged light minus the fogged black is `c` times the fog's transmittance, the part of
// the receiver's radiance that bevy_pbr lets through (its in-scattering is already in
// the frame).
fn through_fog(c: vec3<f32>, p: vec3<f32>) -> vec3<f32> {
#ifdef DISTANCE_FOG
    if material.fog_enabled == 0u {
        return c;
    }
    let d = distance(p, view.world_position);
    let lit = vec4(c, 1.0);
    let black = vec4(0.0, 0.0, 0.0, 1.0);
    let none = vec3(0.0);
    switch fog.mode {
        case 1u: { return linear_fog(fog, lit, d, none).rgb - linear_fog(fog, black, d, none).rgb; }
        case 2u: { return exponential_fog(fog, lit, d, none).rgb - exponential_fog(fog, black, d, none).rgb; }
        case 3u: { return exponential_squared_fog(fog, lit, d, none).rgb - exponential_squared_fog(fog, black, d, none).rgb; }
        case 4u: { return atmospheric_fog(fog, lit, d, none).rgb - atmospheric_fog(fog, black, d, none).rgb; }
        default: { return c; }
    }
#else
    return c;
#endif
}

@fragment
fn fragment(in: VertexOutput) -> @location(0) vec4<f32> {
    let stored = textureLoad(caustic_irradiance, vec2<i32>(floor(in.clip_position.xy)), 0).rgb;
    let exposed_irradiance = min(stored, vec3(MAX_EXPOSED_IRRADIANCE));
    let uv = (material.uv_transform * vec3(in.uv, 1.0)).xy;
    let albedo = material.base_color.rgb * textureSample(base_color_texture, base_color_sampler, uv).rgb;
    // The eye ray from the near plane (any projection) to the receiver.
    let eye = world_at(view, in.clip_position.xy, 1.0);
    var optical_depth = vec3(0.0);
    for (var i = 0u; i < min(caustics.medium_count, 4u); i++) {
        optical_depth += medium_optical_depth(caustics.media[i], eye, in.world_position, false);
    }
    let seen = exp(-optical_depth);
    let radiance = albedo / PI * exposed_irradiance * seen * caustics.intensity;
    return vec4(through_fog(radiance, in.world_position), 0.0);
}
