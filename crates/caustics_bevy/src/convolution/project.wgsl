// Pool caustics by convolution: adds a pool's floor irradiance to the view's caustic
// irradiance buffer at every pixel whose receiver point lies on the pool's floor,
// interpolated bilinearly between the texel centres below which it was computed.

#import bevy_render::view::View
#import bevy_core_pipeline::fullscreen_vertex_shader::FullscreenVertexOutput
#import bevy_caustics::convolution::Pool
#import bevy_caustics::receiver::{centre_depth, exposed, world_at}

@group(0) @binding(0) var<uniform> view: View;
#ifdef MULTISAMPLED
@group(0) @binding(1) var depth_prepass: texture_depth_multisampled_2d;
#else
@group(0) @binding(1) var depth_prepass: texture_depth_2d;
#endif
@group(0) @binding(2) var<uniform> pool: Pool;
@group(0) @binding(3) var<storage, read> irradiance: array<f32>;

// The floor irradiance below a texel, the nearest edge texel past the walls.
fn floor_at(c: i32, r: i32) -> f32 {
    let column = clamp(c, 0, i32(pool.columns) - 1);
    let row = clamp(r, 0, i32(pool.rows) - 1);
    return irradiance[u32(row) * pool.columns + u32(column)];
}

@fragment
fn project(in: FullscreenVertexOutput) -> @location(0) vec4<f32> {
    let pixel = vec2<i32>(in.position.xy);
    let depth = textureLoad(depth_prepass, pixel, 0);
    if depth <= 0.0 {
        discard;
    }
    // The floor's normal in the world: pool_from_world's transpose carries normals.
    let m = pool.pool_from_world;
    let floor_normal = normalize(vec3(m[0].y, m[1].y, m[2].y));
    let p = (m * vec4(world_at(view, in.position.xy, centre_depth(view, depth_prepass, pixel, floor_normal)), 1.0)).xyz;
    let size = vec2(f32(pool.columns), f32(pool.rows)) * pool.cell_size;
    if abs(p.y + pool.depth) > pool.floor_tolerance || any(p.xz < vec2(0.0)) || any(p.xz > size) {
        discard;
    }
    let t = p.xz / pool.cell_size - 0.5;
    let base = floor(t);
    let f = t - base;
    let c = i32(base.x);
    let r = i32(base.y);
    let e = mix(mix(floor_at(c, r), floor_at(c + 1, r), f.x), mix(floor_at(c, r + 1), floor_at(c + 1, r + 1), f.x), f.y);
    return exposed(pool.color.rgb * e, view.exposure);
}
