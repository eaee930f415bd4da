// Pool caustics by convolution (Trendall & Stewart 2000, §4): the GPU twin of
// `caustics_core::convolution`. Three compute entry points run in order over the
// pool's texels: `ripple_heights` (the rippling surface of §4.3 from its impulses and
// their wall images), `convolution_terms` (normals, Snell, Fresnel: §4.2 passes 1–5),
// `convolve` (the three kernels of §4.1, pass 6), then `deficit_ratios` and `lift`
// (`lift_negative_irradiance`: no texel below zero, the flux kept).

#import bevy_caustics::convolution::{Pool, Waves}
#import bevy_caustics::optics::fresnel_transmittance

@group(0) @binding(0) var<uniform> pool: Pool;
@group(0) @binding(1) var<storage, read> waves: Waves;
@group(0) @binding(2) var<storage, read> taps: array<vec4<f32>>;    // k₁, k₂, k₀ over −r..=r², per mirror parity
@group(0) @binding(3) var<storage, read_write> heights: array<f32>;
@group(0) @binding(4) var<storage, read_write> terms: array<vec4<f32>>;  // w: the lift's deficit ratio
@group(0) @binding(5) var<storage, read_write> irradiance: array<f32>;
// `write_vertices` alone: Bevy's vertex buffer of the pool's water mesh.
@group(0) @binding(6) var<storage, read_write> vertices: array<f32>;

// `caustics_core::convolution::MIN_DOWNWARD_COSINE`.
const MIN_DOWNWARD_COSINE: f32 = 1.0e-3;

fn texel_index(c: u32, r: u32) -> u32 {
    return r * pool.columns + c;
}

// `Boundary::Mirror.fold`: the texel the surface, mirrored across the pool's walls,
// shows at `index` along a side of `texels`, and whether it is mirrored there.
fn fold(index: i32, texels: u32) -> vec2<i32> {
    let n = i32(texels);
    let folded = ((index % (2 * n)) + 2 * n) % (2 * n);
    if folded < n {
        return vec2(folded, 0);
    }
    return vec2(2 * n - 1 - folded, 1);
}

fn height(c: i32, r: i32) -> f32 {
    return heights[texel_index(u32(fold(c, pool.columns).x), u32(fold(r, pool.rows).x))];
}

// `RippleSettings::impulse_height` summed over the impulses and their nine wall images
// (`mirror_images`, §4.3), in `PoolRipples::height_at`'s order.
@compute @workgroup_size(8, 8, 1)
fn ripple_heights(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= pool.columns || id.y >= pool.rows {
        return;
    }
    let point = (vec2<f32>(id.xy) + 0.5) * pool.cell_size;
    let size = vec2(f32(pool.columns), f32(pool.rows)) * pool.cell_size;
    var h = 0.0;
    for (var i = 0u; i < waves.impulse_count; i++) {
        let impulse = waves.impulses[i];
        let elapsed = waves.time - impulse.w;
        if elapsed <= 0.0 {
            continue;
        }
        let front = pool.angular_frequency * elapsed / pool.wave_number;
        let xs = vec3(impulse.x, -impulse.x, 2.0 * size.x - impulse.x);
        let zs = vec3(impulse.y, -impulse.y, 2.0 * size.y - impulse.y);
        for (var k = 0u; k < 9u; k++) {
            let distance = length(point - vec2(xs[k % 3u], zs[k / 3u]));
            if distance <= front {
                let envelope = -pool.front_damping * (front - distance) - pool.time_damping * elapsed;
                h += impulse.z * exp(envelope) * sin(pool.wave_number * distance - pool.angular_frequency * elapsed);
            }
        }
    }
    heights[texel_index(id.x, id.y)] = h;
}

// `Heightfield::normal` with `Boundary::Mirror`: the upward normal from central
// differences of the heights.
fn surface_normal(c: i32, r: i32) -> vec3<f32> {
    let span = 2.0 * pool.cell_size;
    let slope = vec2(height(c + 1, r) - height(c - 1, r), height(c, r + 1) - height(c, r - 1)) / span;
    let scale = max(max(abs(slope.x), abs(slope.y)), 1.0);
    return normalize(vec3(-slope.x, 1.0, -slope.y) / scale);
}

// The water's mesh, one vertex over each texel centre centred on the pool
// (`ripples.rs`' `positions` and `normals`), written in Bevy's vertex buffer from
// `ripple_heights`' heights: the pool moves with no CPU work and no upload.
@compute @workgroup_size(8, 8, 1)
fn write_vertices(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= pool.columns || id.y >= pool.rows {
        return;
    }
    let half = 0.5 * vec2(f32(pool.columns), f32(pool.rows)) * pool.cell_size;
    let at = (vec2<f32>(id.xy) + 0.5) * pool.cell_size - half;
    let position = vec3(at.x, heights[texel_index(id.x, id.y)], at.y);
    let normal = surface_normal(i32(id.x), i32(id.y));
    let base = pool.vertex.x + texel_index(id.x, id.y) * pool.vertex.y;
    for (var k = 0u; k < 3u; k++) {
        vertices[base + pool.vertex.z + k] = position[k];
        vertices[base + pool.vertex.w + k] = normal[k];
    }
}

// `transmitted_light` and `ConvolutionKernels::terms`: what each texel convolves.
@compute @workgroup_size(8, 8, 1)
fn convolution_terms(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= pool.columns || id.y >= pool.rows {
        return;
    }
    let normal = surface_normal(i32(id.x), i32(id.y));
    let sun = pool.sun.xyz;
    let eta = 1.0 / pool.ior;
    let cos_i = -dot(sun, normal);
    var term = vec4(0.0);
    if cos_i > 0.0 {
        let sin2_t = eta * eta * (1.0 - min(cos_i, 1.0) * min(cos_i, 1.0));
        let cos_t = sqrt(max(0.0, 1.0 - sin2_t));
        var direction = sun;
        if eta != 1.0 {
            direction = normalize(eta * sun + (eta * min(cos_i, 1.0) - cos_t) * normal);
        }
        let along = dot(direction, pool.lobe_axis.xyz);
        if -direction.y >= MIN_DOWNWARD_COSINE && along >= MIN_DOWNWARD_COSINE {
            let flux = pool.sun.w * fresnel_transmittance(cos_i, eta) * cos_i;
            let per_tap = flux / pool.normaliser;
            let tilt = vec2(dot(direction, pool.lobe_first.xyz), dot(direction, pool.lobe_second.xyz)) / along;
            term = vec4(per_tap * tilt, per_tap, 0.0);
        }
    }
    terms[texel_index(id.x, id.y)] = term;
}

// `ConvolutionCaustics::irradiance` as a direct sum over the (2r + 1)² taps: the floor
// below texel x₀ gets Σ k(x₀ − x)·term(x) over the extended surface, with the kernels
// of the mirror parity the source texel is seen in.
@compute @workgroup_size(8, 8, 1)
fn convolve(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= pool.columns || id.y >= pool.rows {
        return;
    }
    let r = pool.kernel_radius;
    let width = 2 * r + 1;
    var e = 0.0;
    for (var dz = -r; dz <= r; dz++) {
        let row = fold(i32(id.y) - dz, pool.rows);
        for (var dx = -r; dx <= r; dx++) {
            let column = fold(i32(id.x) - dx, pool.columns);
            let term = terms[texel_index(u32(column.x), u32(row.x))];
            let parity = column.y + 2 * row.y;
            let k = taps[(parity * width + dz + r) * width + dx + r];
            e += dot(k.xyz, term.xyz);
        }
    }
    irradiance[texel_index(id.x, id.y)] = e;
}

// `caustics_core::convolution::LIFT_RADIUS`.
const LIFT_RADIUS: u32 = 5u;

// The texels within `LIFT_RADIUS` of (c, r), clipped to the pool: (first, last) corners.
fn lift_window(c: u32, r: u32) -> vec4<u32> {
    let first = vec2(max(c, LIFT_RADIUS) - LIFT_RADIUS, max(r, LIFT_RADIUS) - LIFT_RADIUS);
    let last = vec2(min(c + LIFT_RADIUS, pool.columns - 1u), min(r + LIFT_RADIUS, pool.rows - 1u));
    return vec4(first, last);
}

// `lift_negative_irradiance`, first gather: a texel's deficit over the positive
// irradiance around it, R(x) = D(x)/S(x), into `terms[x].w`.
@compute @workgroup_size(8, 8, 1)
fn deficit_ratios(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= pool.columns || id.y >= pool.rows {
        return;
    }
    let deficit = max(-irradiance[texel_index(id.x, id.y)], 0.0);
    var ratio = 0.0;
    if deficit > 0.0 {
        let w = lift_window(id.x, id.y);
        var supply = 0.0;
        for (var r = w.y; r <= w.w; r++) {
            for (var c = w.x; c <= w.z; c++) {
                supply += max(irradiance[texel_index(c, r)], 0.0);
            }
        }
        if supply > 0.0 {
            ratio = deficit / supply;
        }
    }
    terms[texel_index(id.x, id.y)].w = ratio;
}

// `lift_negative_irradiance`, second gather: E′ = max(E, 0)·max(0, 1 − Σ R around).
@compute @workgroup_size(8, 8, 1)
fn lift(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= pool.columns || id.y >= pool.rows {
        return;
    }
    let w = lift_window(id.x, id.y);
    var taken = 0.0;
    for (var r = w.y; r <= w.w; r++) {
        for (var c = w.x; c <= w.z; c++) {
            taken += terms[texel_index(c, r)].w;
        }
    }
    let i = texel_index(id.x, id.y);
    irradiance[i] = max(irradiance[i], 0.0) * max(0.0, 1.0 - taken);
}

// Does nothing: dispatched first under the pool's bindings while timestamps are recorded,
// so that lavapipe times the pass whole (`gpu_work::anchor_first_timestamp`).
@compute @workgroup_size(1)
fn anchor() {}
