// The illumination textures (§4.2, eq. 3): each illumination volume's crossing with a
// plane, drawn as a quad over the texels it touches; each fragment adds the volume's
// intensity times the share of its texel the crossing covers — `w` times `cos γ` at
// the receiver the virtual camera sees there, `xyz` times the volume's direction (the
// light vector). The twin of `IlluminationVolume::draw` in the core crate.

#import bevy_caustics::illumination_textures::{
    IlluminationFrame, IlluminationVolume, FAR, plane_depth, seen_depths, texel_size, surface_index,
}

@group(0) @binding(0) var<uniform> frame: IlluminationFrame;
@group(0) @binding(1) var<storage, read> volumes: array<IlluminationVolume>;
@group(0) @binding(2) var<storage, read> surface: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> seen: array<u32, 2>;

struct Crossing {
    @builtin(position) position: vec4<f32>,
    // The crossing's corners in texels.
    @location(0) @interpolate(flat) q01: vec4<f32>,
    @location(1) @interpolate(flat) q2: vec2<f32>,
    // The volume's mean direction and intensity `flux / (S₀ cos δ)`.
    @location(2) @interpolate(flat) direction_intensity: vec4<f32>,
}

fn cross2(a: vec2<f32>, b: vec2<f32>) -> f32 {
    return a.x * b.y - a.y * b.x;
}

fn normalize_or_zero(v: vec3<f32>) -> vec3<f32> {
    let l = length(v);
    return select(vec3(0.0), v / l, l > 0.0 && l < 3.0e38);
}

@vertex
fn draw_vertex(@builtin(vertex_index) index: u32, @builtin(instance_index) plane: u32) -> Crossing {
    var out: Crossing;
    // Outside the clip volume: the quad is dropped.
    out.position = vec4(2.0, 2.0, 2.0, 1.0);
    let v = index / 6u;
    let depths = seen_depths(vec2(seen[0], seen[1]));
    // The virtual camera saw no receiver: nothing to light.
    if depths.x > depths.y {
        return out;
    }
    let depth = plane_depth(frame, depths, plane);
    let texel = texel_size(frame);
    let axis = frame.axis.xyz;
    var q: array<vec2<f32>, 3>;
    for (var k = 0u; k < 3u; k++) {
        let exit = volumes[v].exits[k].xyz;
        let direction = volumes[v].directions[k].xyz;
        let along = dot(direction, axis);
        let t = (depth - dot(exit, axis)) / along;
        // The plane is behind where this ray leaves the object.
        if !(along > 0.0 && t >= 0.0) {
            return out;
        }
        let p = exit + direction * t;
        q[k] = (vec2(dot(p, frame.u.xyz), dot(p, frame.v.xyz)) - frame.rectangle.xy) / texel;
    }
    let r = normalize_or_zero(volumes[v].directions[0].xyz + volumes[v].directions[1].xyz + volumes[v].directions[2].xyz);
    let area = 0.5 * cross2(q[1] - q[0], q[2] - q[0]);
    let s0_cos_delta = max(abs(area) * texel.x * texel.y * dot(r, axis), volumes[v].flux.y / frame.max_magnification);
    let n = f32(frame.size);
    let lo = max(floor(min(min(q[0], q[1]), q[2])), vec2(0.0));
    let hi = min(ceil(max(max(q[0], q[1]), q[2])), vec2(n));
    if area == 0.0 || lo.x >= hi.x || lo.y >= hi.y {
        return out;
    }
    var corners = array(lo, vec2(hi.x, lo.y), hi, lo, hi, vec2(lo.x, hi.y));
    let c = corners[index % 6u];
    out.position = vec4(c.x / n * 2.0 - 1.0, 1.0 - c.y / n * 2.0, 0.0, 1.0);
    out.q01 = vec4(q[0], q[1]);
    out.q2 = q[2];
    out.direction_intensity = vec4(r, volumes[v].flux.x / s0_cos_delta);
    return out;
}

// `planes::covered_area`: the area of triangle `t` inside the unit square at `corner`,
// clipped side by side (Sutherland–Hodgman) and summed by the shoelace formula.
fn covered_area(t: array<vec2<f32>, 3>, corner: vec2<f32>) -> f32 {
    var polygon: array<vec2<f32>, 8>;
    polygon[0] = t[0];
    polygon[1] = t[1];
    polygon[2] = t[2];
    var count = 3u;
    for (var side = 0u; side < 4u; side++) {
        let axis = side / 2u;
        let at = corner[axis] + f32(side % 2u);
        let keep = 1.0 - 2.0 * f32(side % 2u);
        var clipped: array<vec2<f32>, 8>;
        var kept = 0u;
        for (var i = 0u; i < count; i++) {
            let a = polygon[i];
            let b = polygon[(i + 1u) % count];
            let a_in = (a[axis] - at) * keep >= 0.0;
            let b_in = (b[axis] - at) * keep >= 0.0;
            if a_in && kept < 8u {
                clipped[kept] = a;
                kept++;
            }
            if a_in != b_in && kept < 8u {
                clipped[kept] = a + (b - a) * ((at - a[axis]) / (b[axis] - a[axis]));
                kept++;
            }
        }
        polygon = clipped;
        count = kept;
        if count < 3u {
            return 0.0;
        }
    }
    var twice = 0.0;
    for (var i = 0u; i < count; i++) {
        twice += cross2(polygon[i], polygon[(i + 1u) % count]);
    }
    return 0.5 * abs(twice);
}

@fragment
fn draw_fragment(in: Crossing) -> @location(0) vec4<f32> {
    let texel = floor(in.position.xy);
    let covered = covered_area(array(in.q01.xy, in.q01.zw, in.q2), texel);
    if covered <= 0.0 {
        discard;
    }
    let index = u32(texel.y) * frame.size + u32(texel.x);
    let seen = surface[surface_index(index)];
    let r = in.direction_intensity.xyz;
    let cos_gamma = select(max(-dot(r, seen.xyz), 0.0), 1.0, seen.w >= FAR);
    let e = in.direction_intensity.w * covered;
    return vec4(r * e, e * cos_gamma);
}
