// What the virtual camera sees (§4.2): one invocation a texel casts a ray along the
// axis through the receivers (`bevy_caustics::triangle_bvh`), from its centre on the
// camera's near plane, and keeps the nearest surface's depth and normal and the solid
// spans behind it (from a face towards the camera to the next face away from it), in
// the depth map's three vec4s; the nearest and farthest depth seen go to `seen` for
// the planes. The twin of `IlluminationTextures::see` and `SeenSurface::along`.

#import bevy_caustics::illumination_textures::{IlluminationFrame, FAR, ordered, surface_index}
#import bevy_caustics::triangle_bvh::{NO_MESH, intersect_triangles}

@group(0) @binding(0) var<uniform> frame: IlluminationFrame;
@group(0) @binding(1) var<storage, read_write> surface: array<vec4<f32>>;
// The largest `~ordered` and `ordered` depth seen: the nearest and the farthest.
@group(0) @binding(2) var<storage, read_write> seen: array<atomic<u32>, 2>;

// `planes::SOLID_SPANS`.
const SOLID_SPANS: u32 = 4u;
const INFINITY: f32 = 3.4028235e38;

@compute @workgroup_size(8, 8, 1)
fn see(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= frame.size || id.y >= frame.size {
        return;
    }
    let at = surface_index(id.y * frame.size + id.x);
    let texel = frame.rectangle.zw / f32(frame.size);
    let q = frame.rectangle.xy + (vec2(f32(id.x), f32(id.y)) + 0.5) * texel;
    let axis = frame.axis.xyz;
    let origin = frame.u.xyz * q.x + frame.v.xyz * q.y + axis * frame.start;
    let depth0 = dot(origin, axis);
    var solid = array(vec2(FAR), vec2(FAR), vec2(FAR), vec2(FAR));
    var found = false;
    var first = 0.0;
    var normal = vec3(0.0);
    var span = 0u;
    var inside = false;
    var t = 0.0;
    for (var i = 0u; i < 4u * SOLID_SPANS; i++) {
        let hit = intersect_triangles(frame.receivers, NO_MESH, origin, axis, t, INFINITY);
        if hit.t < 0.0 {
            break;
        }
        let towards = dot(hit.geometric_normal, axis) < 0.0;
        if !found {
            found = true;
            first = hit.t;
            normal = hit.normal;
        }
        let depth = min(depth0 + hit.t, FAR);
        if !inside {
            solid[span].x = depth;
            inside = true;
            if !towards {
                solid[span].y = depth;
                span += 1u;
                inside = false;
            }
        } else if !towards {
            solid[span].y = depth;
            span += 1u;
            inside = false;
        }
        if span == SOLID_SPANS {
            break;
        }
        t = hit.t * (1.0 + 1e-5) + 1e-5;
    }
    if !found {
        surface[at] = vec4(0.0, 0.0, 0.0, FAR);
        surface[at + 1u] = vec4(FAR);
        surface[at + 2u] = vec4(FAR);
        return;
    }
    let depth = depth0 + first;
    surface[at] = vec4(normal, depth);
    surface[at + 1u] = vec4(solid[0], solid[1]);
    surface[at + 2u] = vec4(solid[2], solid[3]);
    atomicMax(&seen[0], ~ordered(depth));
    atomicMax(&seen[1], ordered(depth));
}

// Does nothing: dispatched first under the see pass's bindings while timestamps are recorded,
// so that lavapipe times the pass whole (`gpu_work::anchor_first_timestamp`).
@compute @workgroup_size(1)
fn anchor() {}
