// A caustic volume as the passes read it and the GPU build writes it
// (`GpuCausticVolume` in `render.rs`, `caustics_core::volumes::CausticVolume`).

#define_import_path bevy_caustics::warped_volumes

struct CausticVolume {
    origin: vec4<f32>,          // xyz: origin (a generator vertex), w: depth
    axis_x: vec4<f32>,
    axis_y: vec4<f32>,          // slicing axis: the caustic triangle lies at y = α
    axis_z: vec4<f32>,
    surface_normal: vec4<f32>,  // the generator triangle's normal, rays' side; w: owned sides (bits)
    vertex_x: vec4<f32>,        // §4.1 vertical layout: x of the three vertices
    vertex_z: vec4<f32>,
    ray_x: vec4<f32>,           // rays scaled to r_y = 1
    ray_z: vec4<f32>,
    fan_a: vec4<f32>,           // per-vertex fan area coefficients ā, b̄, c̄ (Fig. 5)
    fan_b: vec4<f32>,
    fan_c: vec4<f32>,
    triangle_abc: vec4<f32>,    // the triangle's own a, b, c
    flux: vec4<f32>,            // per-vertex irradiance on the slicing plane
    color: vec4<f32>,
    light_distance: vec4<f32>,  // the light's path to each vertex (in y = 0), w: 1/range² or 0
    slab: vec4<f32>,           // the slab near ≤ n·p ≤ far around the surface the rays land on (world): xyz n (zero: none), w near
    slab_far: vec4<f32>,       // x: far
    hit_planes: array<vec4<f32>, 3>, // per vertex ray: the first surface it meets, n·p + w < 0 behind
    corners: array<vec4<f32>, 8>,  // the bounding shape (§4.3) the in-scattering pass draws
    surface_corners: array<vec4<f32>, 8>, // the one the surface pass draws: the slice crossing the slab, or none, or `corners`
}
