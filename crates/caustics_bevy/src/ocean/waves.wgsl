// An ocean's waves evaluated on the GPU, straight into the vertex buffer Bevy draws its
// mesh from: the twin of `caustics_core::ocean::OceanSpectrum::evaluate_into`
// (Tessendorf 2001), in three kinds of dispatch:
//
// - `spectrum`: h̃(k, t) of eq. 43 per grid frequency, packed two real fields to a
//   complex one as the CPU packs them (height + i ∂h/∂x, ∂h/∂z + i Dx, and with
//   choppiness Dz + i ∂Dx/∂x, ∂Dz/∂z + i ∂Dx/∂z);
// - `fft_stage`: one radix-2 stage of an inverse Stockham FFT (unnormalised, as
//   rustfft's), along the rows (x) or the columns (z) of every field: 2 log₂ N
//   dispatches ping-ponging between two buffers, the result in natural order;
// - `write_vertices`: each of the (N + 1)² vertices' displaced position and the exact
//   normal of the displaced surface, written over the position and normal words of
//   the mesh's vertices (the last row and column repeat the first).

struct OceanStep {
    resolution: u32,
    fields: u32,
    // The sub-transform half-length p of an FFT stage (1, 2, … N/2).
    half_span: u32,
    // 0: along the rows (x), 1: along the columns (z).
    axis: u32,
    size: f32,
    choppiness: f32,
    time: f32,
    _pad: f32,
    // The mesh's first vertex word in `vertices`, its vertex stride, the position's and
    // the normal's word in a vertex.
    vertex: vec4<u32>,
}

@group(0) @binding(0) var<uniform> ocean: OceanStep;
// h̃₀(k) and h̃₀*(−k) as (re, im, re, im) per grid frequency; ω beside it.
@group(0) @binding(1) var<storage, read> amplitudes: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> omega: array<f32>;
@group(0) @binding(3) var<storage, read> fields_in: array<vec2<f32>>;
@group(0) @binding(4) var<storage, read_write> fields_out: array<vec2<f32>>;
@group(0) @binding(5) var<storage, read_write> vertices: array<f32>;

const PI: f32 = 3.14159265358979;
const TAU: f32 = 6.28318530717959;

fn mul(a: vec2<f32>, b: vec2<f32>) -> vec2<f32> {
    return vec2(a.x * b.x - a.y * b.y, a.x * b.y + a.y * b.x);
}

// i·a
fn mul_i(a: vec2<f32>) -> vec2<f32> {
    return vec2(-a.y, a.x);
}

@compute @workgroup_size(8, 8, 1)
fn spectrum(@builtin(global_invocation_id) id: vec3<u32>) {
    let n = ocean.resolution;
    if id.x >= n || id.y >= n {
        return;
    }
    let index = id.y * n + id.x;
    let cells = n * n;
    // k = 2π (m − N/2) / size (eq. 36).
    let k = (vec2(f32(id.x), f32(id.y)) - f32(n / 2u)) * (TAU / ocean.size);
    // h̃₀(k) e^{iωt} + h̃₀*(−k) e^{−iωt} (eq. 43). The phase in f32: its error grows as
    // ω t 2⁻²⁴ (a thousandth of a radian after twenty minutes for the shortest waves).
    let phase = (omega[index] * ocean.time) % TAU;
    let rotation = vec2(cos(phase), sin(phase));
    let modes = amplitudes[index];
    let centre = select(-1.0, 1.0, (id.x + id.y) % 2u == 0u);
    let h = (mul(modes.xy, rotation) + mul(modes.zw, vec2(rotation.x, -rotation.y))) * centre;
    let length_k = length(k);
    let unit = select(vec2(0.0), k / length_k, length_k > 0.0);
    fields_out[index] = h + mul_i(mul_i(k.x * h));
    fields_out[cells + index] = mul_i(k.y * h) + mul_i(-mul_i(unit.x * h));
    if ocean.fields == 4u {
        fields_out[2u * cells + index] = -mul_i(unit.y * h) + mul_i(unit.x * k.x * h);
        fields_out[3u * cells + index] = unit.y * k.y * h + mul_i(unit.x * k.y * h);
    }
}

// Element `e` of line `line` of field `field` along the step's axis.
fn element(field: u32, line: u32, e: u32) -> u32 {
    let n = ocean.resolution;
    let base = field * n * n;
    if ocean.axis == 0u {
        return base + line * n + e;
    }
    return base + e * n + line;
}

// Stockham radix-2 (the autosorting form of E. Bainville's "OpenCL Fast Fourier
// Transform", 2010): butterfly i of N/2 reads elements i and i + N/2 and writes
// 2i − k and 2i − k + p, k = i mod p, with the inverse twiddle e^{+iπk/p}.
@compute @workgroup_size(64, 1, 1)
fn fft_stage(@builtin(global_invocation_id) id: vec3<u32>) {
    let half = ocean.resolution / 2u;
    if id.x >= half || id.y >= ocean.resolution || id.z >= ocean.fields {
        return;
    }
    let p = ocean.half_span;
    let k = id.x & (p - 1u);
    let angle = PI * f32(k) / f32(p);
    let twiddled = mul(fields_in[element(id.z, id.y, id.x + half)], vec2(cos(angle), sin(angle)));
    let u = fields_in[element(id.z, id.y, id.x)];
    let out = 2u * id.x - k;
    fields_out[element(id.z, id.y, out)] = u + twiddled;
    fields_out[element(id.z, id.y, out + p)] = u - twiddled;
}

@compute @workgroup_size(8, 8, 1)
fn write_vertices(@builtin(global_invocation_id) id: vec3<u32>) {
    let n = ocean.resolution;
    if id.x > n || id.y > n {
        return;
    }
    let x = id.x % n;
    let z = id.y % n;
    let at = z * n + x;
    let cells = n * n;
    let sign = select(-1.0, 1.0, (x + z) % 2u == 0u);
    let f0 = fields_in[at] * sign;
    let f1 = fields_in[cells + at] * sign;
    var f2 = vec2(0.0);
    var f3 = vec2(0.0);
    if ocean.fields == 4u {
        f2 = fields_in[2u * cells + at] * sign;
        f3 = fields_in[3u * cells + at] * sign;
    }
    let chop = ocean.choppiness;
    // h, ∂h/∂x, ∂h/∂z, Dx, Dz, ∂Dx/∂x, ∂Dz/∂z, ∂Dx/∂z.
    let along_x = vec3(1.0 + chop * f2.y, f0.y, chop * f3.y);
    let along_z = vec3(chop * f3.y, f1.x, 1.0 + chop * f3.x);
    let cross_product = cross(along_z, along_x);
    let l = length(cross_product);
    var normal = vec3(0.0, 1.0, 0.0);
    if l > 0.0 && l <= 3.4028235e38 {
        normal = cross_product / l;
    }
    let spacing = ocean.size / f32(n);
    let rest = vec3(-0.5 * ocean.size + f32(id.x) * spacing, 0.0, -0.5 * ocean.size + f32(id.y) * spacing);
    let position = rest + vec3(chop * f1.y, f0.x, chop * f2.x);
    let word = ocean.vertex.x + (id.y * (n + 1u) + id.x) * ocean.vertex.y;
    for (var c = 0u; c < 3u; c++) {
        vertices[word + ocean.vertex.z + c] = position[c];
        vertices[word + ocean.vertex.w + c] = normal[c];
    }
}

// Does nothing: dispatched first under the waves' bindings while timestamps are recorded,
// so that lavapipe times the pass whole (`gpu_work::anchor_first_timestamp`).
@compute @workgroup_size(1)
fn anchor() {}
