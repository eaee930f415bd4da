// Adds caustic light to the receivers: each `CausticReceiver` mesh is drawn again
// after the opaque pass, depth-tested against the scene (so only where it is visible),
// with additive blending of the Lambertian radiance (albedo / π) · E · exposure. The
// buffer already holds E · exposure, each pass's share capped; their sum is capped
// again here.

#import bevy_pbr::mesh_functions::{get_world_from_local, mesh_position_local_to_clip}
#import bevy_render::maths::PI
#import bevy_caustics::receiver::MAX_EXPOSED_IRRADIANCE

struct ReceiverMaterial {
    base_color: vec4<f32>,
    uv_transform: mat3x3<f32>,
}

@group(1) @binding(0) var caustic_irradiance: texture_2d<f32>;
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
}

@vertex
fn vertex(vertex: Vertex) -> VertexOutput {
    var out: VertexOutput;
    let world_from_local = get_world_from_local(vertex.instance_index);
    out.clip_position = mesh_position_local_to_clip(world_from_local, vec4(vertex.position, 1.0));
#ifdef VERTEX_UVS
    out.uv = vertex.uv;
#else
    out.uv = vec2(0.0);
#endif
    return out;
}

@fragment
fn fragment(in: VertexOutput) -> @location(0) vec4<f32> {
    let stored = textureLoad(caustic_irradiance, vec2<i32>(floor(in.clip_position.xy)), 0).rgb;
    let exposed_irradiance = min(stored, vec3(MAX_EXPOSED_IRRADIANCE));
    let uv = (material.uv_transform * vec3(in.uv, 1.0)).xy;
    let albedo = material.base_color.rgb * textureSample(base_color_texture, base_color_sampler, uv).rgb;
    return vec4(albedo / PI * exposed_irradiance, 0.0);
}
