// The light maps (`caustics_core::hierarchical::light_maps`): the generators' nearest
// front faces and farthest back faces, and the receivers' nearest surfaces, rasterised
// from a light view (the generators over the photons' part of it). Each texel stores the view depth of its surface and, for the
// generators, its smooth normal (octahedral) and generator index.

#import bevy_caustics::caustic_maps::{LightView, depth_of, oct_encode}

struct Instance {
    world_from_local: mat4x4<f32>,
    // The inverse transpose of `world_from_local`'s upper 3×3, for normals.
    normal_from_local: mat4x4<f32>,
    // x: the generator's index in the materials.
    material: vec4<u32>,
}

@group(0) @binding(0) var<uniform> view: LightView;
@group(0) @binding(1) var<storage, read> instances: array<Instance>;

struct SurfaceOutput {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) @interpolate(flat) material: u32,
}

@vertex
fn generator_vertex(
    @builtin(instance_index) instance: u32,
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
) -> SurfaceOutput {
    let i = instances[instance];
    let world = (i.world_from_local * vec4(position, 1.0)).xyz;
    let n = (i.normal_from_local * vec4(normal, 0.0)).xyz;
    // The photons' part of the view (`LightView::emission`) fills the front and back maps.
    let clip = view.clip_from_world * vec4(world, 1.0);
    return SurfaceOutput(vec4(clip.xy / view.emission, clip.zw), world, n, i.material.x);
}

// Depth, the normal as the mesh orients it, and the generator.
@fragment
fn surface_fragment(in: SurfaceOutput) -> @location(0) vec4<f32> {
    let n = normalize(in.normal);
    return vec4(depth_of(view, in.world), oct_encode(n), f32(in.material));
}

struct ReceiverOutput {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
}

@vertex
fn receiver_vertex(@builtin(instance_index) instance: u32, @location(0) position: vec3<f32>) -> ReceiverOutput {
    let world = (instances[instance].world_from_local * vec4(position, 1.0)).xyz;
    return ReceiverOutput(view.clip_from_world * vec4(world, 1.0), world);
}

@fragment
fn receiver_fragment(in: ReceiverOutput) -> @location(0) vec4<f32> {
    return vec4(depth_of(view, in.world), 0.0, 0.0, 0.0);
}
