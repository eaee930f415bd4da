// What the passes that add caustic light share: the world point a pixel sees, rebuilt
// from its depth, the exposed, capped value they store, and the participating media.

#define_import_path bevy_caustics::receiver

#import bevy_render::view::View

// `caustics_bevy::irradiance::MAX_EXPOSED_IRRADIANCE`.
const MAX_EXPOSED_IRRADIANCE: f32 = 2048.0;

// Irradiance `e` (the light's units per m²) as the buffer holds it: times the view's
// exposure, within [0, MAX_EXPOSED_IRRADIANCE], and 0 for NaN.
fn exposed(e: vec3<f32>, exposure: f32) -> vec4<f32> {
    let x = e * exposure;
    return vec4(clamp(select(vec3(0.0), x, x == x), vec3(0.0), vec3(MAX_EXPOSED_IRRADIANCE)), 0.0);
}

// World position at a pixel for an NDC depth (reverse Z: 1 near, 0 infinitely far).
fn world_at(view: View, frag: vec2<f32>, depth: f32) -> vec3<f32> {
    let uv = (frag - view.viewport.xy) / view.viewport.zw;
    let clip = view.world_from_clip * vec4(uv.x * 2.0 - 1.0, 1.0 - uv.y * 2.0, depth, 1.0);
    return clip.xyz / clip.w;
}

// Where in `pixel` sample 0 lies, the sample the passes read of a depth prepass with
// `samples` samples per pixel: the standard sample locations (Vulkan, D3D12 and Metal
// agree on them), the centre when single-sampled.
fn sample_zero(pixel: vec2<i32>, samples: u32) -> vec2<f32> {
    var offset = vec2(0.5);
    switch samples {
        case 2u: { offset = vec2(0.75, 0.75); }
        case 4u: { offset = vec2(0.375, 0.125); }
        case 8u: { offset = vec2(0.5625, 0.3125); }
        case 16u: { offset = vec2(0.5625, 0.5625); }
        default: {}
    }
    return vec2<f32>(pixel) + offset;
}

// Where the eye ray through `frag` meets the plane through `p` with normal `n` (`p`
// itself where the ray grazes the plane).
fn on_tangent_plane(view: View, frag: vec2<f32>, p: vec3<f32>, n: vec3<f32>) -> vec3<f32> {
    let eye = world_at(view, frag, 1.0);
    let dir = normalize(world_at(view, frag, 0.5) - eye);
    let along = dot(dir, n);
    if abs(along) < 1.0e-3 {
        return p;
    }
    return eye + dir * (dot(p - eye, n) / along);
}

// The receiver point the centre of `pixel` sees, from the depth prepass's `depth` at
// sample 0 (of `samples` per pixel) and the surface's normal `n` there. Multisampled,
// sample 0 lies off the centre: its point, moved along the surface's tangent plane
// onto the centre's eye ray. Rebuilt at the centre from sample 0's depth instead, a
// receiver seen at a slant leaves its surface by the depth's slope over the offset
// (millimetres to centimetres), enough to put it behind the caustic volumes' hit
// planes; kept at sample 0, the image shifts by a fraction of a pixel.
fn receiver_at(view: View, pixel: vec2<i32>, samples: u32, depth: f32, n: vec3<f32>) -> vec3<f32> {
    let centre = vec2<f32>(pixel) + 0.5;
    if samples <= 1u {
        return world_at(view, centre, depth);
    }
    return on_tangent_plane(view, centre, world_at(view, sample_zero(pixel, samples), depth), n);
}

// A `ParticipatingMedium` (`caustics_bevy::irradiance::GpuMedium`): the unit cube
// [-½, ½]³ of `local_from_world`, and (σs, σa, g).
struct Medium {
    local_from_world: mat4x4<f32>,
    coefficients: vec4<f32>,
}

// Where the segment o + t·d, t ∈ [0, len], is inside a medium's unit box (empty when x ≥ y).
fn clip_medium(m: Medium, o: vec3<f32>, d: vec3<f32>, len: f32) -> vec2<f32> {
    let lo = (m.local_from_world * vec4(o, 1.0)).xyz;
    let ld = (m.local_from_world * vec4(d, 0.0)).xyz;
    var t = vec2(0.0, len);
    for (var axis = 0; axis < 3; axis++) {
        if abs(ld[axis]) < 1e-12 {
            if abs(lo[axis]) > 0.5 {
                return vec2(1.0, 0.0);
            }
            continue;
        }
        let a = (-0.5 - lo[axis]) / ld[axis];
        let b = (0.5 - lo[axis]) / ld[axis];
        t = vec2(max(t.x, min(a, b)), min(t.y, max(a, b)));
    }
    return t;
}

// exp(−σt · ℓ) along the segment from `start` to `end`, ℓ the length inside each medium.
fn transmittance(media: array<Medium, 4>, count: u32, start: vec3<f32>, end: vec3<f32>) -> f32 {
    let len = distance(start, end);
    if len <= 0.0 {
        return 1.0;
    }
    let d = (end - start) / len;
    var optical_depth = 0.0;
    for (var i = 0u; i < min(count, 4u); i++) {
        let t = clip_medium(media[i], start, d, len);
        optical_depth += (media[i].coefficients.x + media[i].coefficients.y) * max(t.y - t.x, 0.0);
    }
    return exp(-optical_depth);
}
