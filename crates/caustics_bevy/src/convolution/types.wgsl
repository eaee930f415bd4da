// The pool as every convolution shader reads it (`GpuPool` in `render.rs`).

#define_import_path bevy_caustics::convolution

struct Pool {
    columns: u32,
    rows: u32,
    cell_size: f32,
    wave_number: f32,       // K
    angular_frequency: f32, // ω
    time_damping: f32,      // α
    front_damping: f32,     // β
    ior: f32,
    normaliser: f32,        // K, `ConvolutionKernels::normaliser`
    sun: vec4<f32>,         // xyz: the sunlight's unit direction in pool space, w: L_s
    lobe_first: vec4<f32>,     // the lobe's frame [e₁, e₂, D] (`ConvolutionKernels::frame`)
    lobe_second: vec4<f32>,
    lobe_axis: vec4<f32>,
    kernel_radius: i32,
    // Projection: pool space (x, z ∈ [0, size], surface rest level y = 0) from world.
    depth: f32,
    floor_tolerance: f32,
    pool_from_world: mat4x4<f32>,
    color: vec4<f32>,
    // `write_vertices`: the water mesh's layout in its vertex buffer, in words (first
    // vertex, stride, position, normal; `MeshVertices`).
    vertex: vec4<u32>,
}

// The water's waves at the frame's time (`GpuWaves` in `render.rs`).
struct Waves {
    time: f32,
    impulse_count: u32,
    impulses: array<vec4<f32>>,     // x, z, strength, drop time
}
