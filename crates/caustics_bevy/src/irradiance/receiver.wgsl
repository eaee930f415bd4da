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

// The depth prepass's depth at the centre of `pixel`, where the passes rebuild the
// receiver point (`world_at`), for a surface of normal `n` at sample 0. With Bevy's 4
// samples per pixel no sample lies at the centre, but their centroid is the centre
// (the standard sample locations, on which Vulkan, D3D12 and Metal agree) and NDC
// depth is affine in screen space on a plane: where the samples' points lie on sample
// 0's tangent plane, the mean of their depths is the centre's. Elsewhere (an edge, a
// silhouette, another sample count), sample 0's depth. Rebuilt at the centre from
// sample 0's depth alone, a receiver seen at a slant left its surface by the depth's
// slope over sample 0's offset (millimetres to centimetres), enough to put it behind
// the caustic volumes' hit planes.
#ifdef MULTISAMPLED
fn centre_depth(view: View, depth: texture_depth_multisampled_2d, pixel: vec2<i32>, n: vec3<f32>) -> f32 {
    let first = textureLoad(depth, pixel, 0);
    if textureNumSamples(depth) != 4u {
        return first;
    }
    let at = array(vec2(0.375, 0.125), vec2(0.875, 0.375), vec2(0.125, 0.625), vec2(0.625, 0.875));
    let corner = vec2<f32>(pixel);
    let p0 = world_at(view, corner + at[0], first);
    var sum = first;
    for (var i = 1; i < 4; i++) {
        let d = textureLoad(depth, pixel, i);
        let p = world_at(view, corner + at[i], d);
        // Off the tangent plane by more than 3° seen from sample 0: another surface.
        if d <= 0.0 || abs(dot(p - p0, n)) > 0.05 * distance(p, p0) {
            return first;
        }
        sum += d;
    }
    return 0.25 * sum;
}
#else
fn centre_depth(view: View, depth: texture_depth_2d, pixel: vec2<i32>, n: vec3<f32>) -> f32 {
    return textureLoad(depth, pixel, 0);
}
#endif

// A `ParticipatingMedium` (`caustics_bevy::irradiance::GpuMedium`): the unit cube
// [-½, ½]³ of `local_from_world`, σt per linear RGB channel, and (σs, g).
struct Medium {
    local_from_world: mat4x4<f32>,
    extinction: vec4<f32>,
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

// σt ℓ per channel of medium `m` along the segment from `start` to `end`, ℓ the length
// inside its box; with `tint`, only its σt beyond its least channel (the part of σa that
// Bevy's grey fog leaves to `medium_fog::tint`). Callers sum it over their uniform's
// media, indexing the uniform in place: an array of media passed by value is a copy
// indexed at run time, which a GPU keeps in scratch memory (lavapipe spent 40 ms of a
// 960 × 540 frame's composite on it).
fn medium_optical_depth(m: Medium, start: vec3<f32>, end: vec3<f32>, tint: bool) -> vec3<f32> {
    let len = distance(start, end);
    if !(len > 0.0) {
        return vec3(0.0);
    }
    let t = clip_medium(m, start, (end - start) / len, len);
    let sigma_t = m.extinction.xyz;
    let grey = select(0.0, min(sigma_t.x, min(sigma_t.y, sigma_t.z)), tint);
    return (sigma_t - grey) * max(t.y - t.x, 0.0);
}
