// Illumination textures onto the view (§4.3): every pixel's receiver point, rebuilt
// from the depth prepass, takes the two planes around its depth (nearest texel), the
// cosine at its own normal from the light vector (or the paper's `cos γ`), and no light
// where the light, followed back through the virtual camera's depth map, crosses a
// receiver surface. The twin of `IlluminationTextures::irradiance_at`.

#import bevy_core_pipeline::fullscreen_vertex_shader::FullscreenVertexOutput
#import bevy_caustics::receiver::exposed
#import bevy_caustics::receiver_view::{view, receiver_point}
#import bevy_caustics::illumination_textures::{IlluminationFrame, FAR, plane_depth, seen_depths, texel_size, texel_coords, surface_index}

@group(0) @binding(3) var<uniform> frame: IlluminationFrame;
@group(0) @binding(4) var textures: texture_2d_array<f32>;
@group(0) @binding(5) var<storage, read> surface: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read> seen: array<u32, 2>;

fn depth_of_plane(k: u32) -> f32 {
    return plane_depth(frame, seen_depths(vec2(seen[0], seen[1])), k);
}

fn texel_at(index: u32, plane: u32) -> vec4<f32> {
    return textureLoad(textures, vec2(index % frame.size, index / frame.size), plane, 0);
}

// `IlluminationTextures::interpolated`: the planes around depth `z`, clamped to the
// first and last.
fn interpolated(index: u32, z: f32) -> vec4<f32> {
    var k = 0u;
    for (var i = 0u; i < frame.planes; i++) {
        if depth_of_plane(i) <= z {
            k = i + 1u;
        }
    }
    let last = frame.planes - 1u;
    if k == 0u {
        return texel_at(index, 0u);
    }
    if k > last {
        return texel_at(index, last);
    }
    let a = depth_of_plane(k - 1u);
    let b = depth_of_plane(k);
    let f = clamp((z - a) / max(b - a, 1e-12), 0.0, 1.0);
    let ta = texel_at(index, k - 1u);
    return ta + (texel_at(index, k) - ta) * f;
}

// `IlluminationTextures::shadowed`: light arriving along `r` at depth `z` over texel
// point `q`, on a surface of normal `n`, followed back texel by texel; stopped where it
// crosses a solid span from behind to in front.
fn shadowed(q: vec2<f32>, z: f32, r: vec3<f32>, n: vec3<f32>) -> bool {
    let axis = frame.axis.xyz;
    let along = dot(r, axis);
    if !(along > 0.0) {
        return false;
    }
    let texel = texel_size(frame);
    let unit = max(texel.x, texel.y);
    let size = f32(frame.size);
    let across = vec2(-dot(r, frame.u.xyz), -dot(r, frame.v.xyz)) / (along * texel);
    let to_top = z - depth_of_plane(0u);
    var cell = floor(q);
    var climbed = 0.0;
    for (var step = 0u; step < 2u * frame.size + 2u; step++) {
        if cell.x < 0.0 || cell.y < 0.0 || cell.x >= size || cell.y >= size {
            return false;
        }
        var exit = vec2(FAR);
        for (var k = 0; k < 2; k++) {
            if across[k] > 0.0 {
                exit[k] = (cell[k] + 1.0 - q[k]) / across[k];
            } else if across[k] < 0.0 {
                exit[k] = (cell[k] - q[k]) / across[k];
            }
        }
        let leave = min(min(exit.x, exit.y), to_top);
        let index = surface_index(u32(cell.y) * frame.size + u32(cell.x));
        if surface[index].w < FAR {
            // The point's own texel by its own slope, others flat.
            let m = select(axis, n, climbed == 0.0);
            let c = max(abs(dot(m, axis)), 0.1);
            let slack = frame.shadow_slack * unit * (1.0 + sqrt(1.0 - c * c) / c) + 1e-4 * (1.0 + abs(z));
            let deep = z - climbed;
            let shallow = z - leave;
            var spans = array(surface[index + 1u].xy, surface[index + 1u].zw, surface[index + 2u].xy, surface[index + 2u].zw);
            for (var s = 0; s < 4; s++) {
                if deep > spans[s].x + slack && shallow <= spans[s].y + slack {
                    return true;
                }
            }
        }
        if leave >= to_top {
            return false;
        }
        if exit.x <= exit.y {
            cell.x += sign(across.x);
        } else {
            cell.y += sign(across.y);
        }
        climbed = leave;
    }
    return false;
}

@fragment
fn project(in: FullscreenVertexOutput) -> @location(0) vec4<f32> {
    let receiver = receiver_point(in.position.xy);
    if !receiver.found {
        discard;
    }
    let p = receiver.position;
    let n = receiver.normal;
    let q = texel_coords(frame, p);
    let size = f32(frame.size);
    let depths = seen_depths(vec2(seen[0], seen[1]));
    if depths.x > depths.y || !(q.x >= 0.0 && q.y >= 0.0 && q.x < size && q.y < size) {
        discard;
    }
    let index = u32(q.y) * frame.size + u32(q.x);
    let z = dot(p, frame.axis.xyz);
    let light = interpolated(index, z);
    let e = select(max(-dot(light.xyz, n), 0.0), light.w, frame.cosine == 1u);
    if !(e > 0.0) || shadowed(q, z, light.xyz, n) {
        discard;
    }
    return exposed(frame.light_color.rgb * e, view.exposure);
}
