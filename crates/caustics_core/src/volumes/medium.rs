//! Volumetric caustics in a homogeneous participating medium (§3.5).

use super::{CausticVolume, VolumeSettings};
use crate::optics::henyey_greenstein;
use crate::params::MediumCoefficients;
use glam::{Affine3A, Vec3};

/// A homogeneous medium filling an oriented box: the unit cube `[-½, ½]³` mapped by
/// `world_from_local` (the convention of Bevy's `FogVolume`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MediumBox {
    /// Maps the unit cube `[-½, ½]³` onto the box in the world.
    pub world_from_local: Affine3A,
    /// The medium's scattering, absorption and phase asymmetry.
    pub coefficients: MediumCoefficients,
}

impl MediumBox {
    /// The part `[t0, t1]` of the segment `origin + t·dir`, `t ∈ [0, length]`, inside the box.
    pub fn clip(&self, origin: Vec3, dir: Vec3, length: f32) -> Option<(f32, f32)> {
        let inverse = self.world_from_local.inverse();
        let o = inverse.transform_point3(origin);
        let d = inverse.transform_vector3(dir);
        let (mut t0, mut t1) = (0.0f32, length);
        for axis in 0..3 {
            if d[axis].abs() < 1e-12 {
                if o[axis].abs() > 0.5 {
                    return None;
                }
                continue;
            }
            let (a, b) = ((-0.5 - o[axis]) / d[axis], (0.5 - o[axis]) / d[axis]);
            t0 = t0.max(a.min(b));
            t1 = t1.min(a.max(b));
        }
        (t0 < t1).then_some((t0, t1))
    }
}

/// The most pieces [`ray_pieces`] returns: between the two ends, the slab's two
/// planes, two roots of each βᵢ and the three hit planes.
pub const MAX_RAY_PIECES: usize = 12;

/// The pieces `[t0, t1]` of the ray `o + t·d` (local frame) inside the warped volume,
/// within `[start, end]`: the βᵢ along the ray are quadratics in t (the caustic
/// triangle's corners move linearly with depth), so the boundary crossings are their
/// roots; the ray also crosses the vertex rays' hit planes, where the occlusion test
/// may change. The pieces between consecutive crossings that lie inside.
pub fn ray_pieces(volume: &CausticVolume, o: Vec3, d: Vec3, start: f32, end: f32) -> ([(f32, f32); MAX_RAY_PIECES], usize) {
    let mut cuts = [0.0f32; MAX_RAY_PIECES + 1];
    let mut n = 0;
    cuts[n] = start;
    n += 1;
    // The slab 0 ≤ α ≤ depth.
    if d.y.abs() > 1e-12 {
        for alpha in [0.0, volume.depth] {
            let t = (alpha - o.y) / d.y;
            if t > start && t < end {
                cuts[n] = t;
                n += 1;
            }
        }
    }
    // Roots of each βᵢ(t), found exactly from three samples of the quadratic.
    let mid = 0.5 * (start + end);
    let (b0, b1, b2) = (volume.beta(o + start * d), volume.beta(o + mid * d), volume.beta(o + end * d));
    let h = 0.5 * (end - start);
    for i in 0..3 {
        // β(s) = p + q s + r s², s = (t − mid)/h ∈ [−1, 1].
        let (p, q, r) = (b1[i], 0.5 * (b2[i] - b0[i]), 0.5 * (b2[i] + b0[i]) - b1[i]);
        for s in quadratic_roots(r, q, p) {
            let t = mid + s * h;
            if s > -1.0 && s < 1.0 && t > start && t < end {
                cuts[n] = t;
                n += 1;
            }
        }
    }
    for plane in volume.hit_planes {
        let along = plane.truncate().dot(d);
        let t = -(plane.truncate().dot(o) + plane.w) / along;
        if along != 0.0 && t > start && t < end {
            cuts[n] = t;
            n += 1;
        }
    }
    cuts[n] = end;
    n += 1;
    let cuts = &mut cuts[..n];
    cuts.sort_by(f32::total_cmp);
    let mut pieces = [(0.0, 0.0); MAX_RAY_PIECES];
    let mut count = 0;
    for w in cuts.windows(2) {
        let (a, b) = (w[0], w[1]);
        let mid = o + 0.5 * (a + b) * d;
        if b > a && volume.barycentric(mid).is_some_and(|lambda| !volume.occluded(mid, lambda)) {
            pieces[count] = (a, b);
            count += 1;
        }
    }
    (pieces, count)
}

/// The mean of `e^{−σₜ d}` over a piece whose path `d` grows linearly over
/// `σₜ d ∈ [m − x, m + x]`: `e^{−m} sinh(x)/x`, without overflow; per channel.
pub fn mean_attenuation(m: Vec3, x: Vec3) -> Vec3 {
    let mean = |m: f32, x: f32| {
        let x = x.abs();
        if x < 1e-3 { (-m).exp() * (1.0 + x * x / 6.0) } else { ((x - m).exp() - (-x - m).exp()) / (2.0 * x) }
    };
    Vec3::new(mean(m.x, x.x), mean(m.y, x.y), mean(m.z, x.z))
}

/// Real roots of `a s² + b s + c`, robust when `a` vanishes (then the linear root).
fn quadratic_roots(a: f32, b: f32, c: f32) -> [f32; 2] {
    let scale = a.abs().max(b.abs()).max(c.abs());
    if scale == 0.0 || !scale.is_finite() {
        return [f32::NAN; 2];
    }
    if a.abs() <= 1e-7 * scale {
        return [if b != 0.0 { -c / b } else { f32::NAN }, f32::NAN];
    }
    let disc = b * b - 4.0 * a * c;
    if disc < 0.0 {
        return [f32::NAN; 2];
    }
    // Numerically stable form: q = −½(b + sign(b)√disc), roots q/a and c/q.
    let q = -0.5 * (b + b.signum() * disc.sqrt());
    if q == 0.0 {
        return [0.0, f32::NAN];
    }
    [q / a, c / q]
}

/// Radiance scattered towards the eye by the caustic beams along the eye ray from
/// `eye` to `end` (the visible surface), inside `medium` (§3.5):
/// `L = Σ e^{−σₜ dₑ} e^{−σₜ dₛ} Δx σₛ p(cos θ) E_beam`, summed over every volume and
/// every piece of the ray inside it; `dₑ` is the medium path from where the eye ray
/// enters the medium to the piece's midpoint, `dₛ` the beam's path from its generator
/// triangle, `E_beam` the beam irradiance (flux per area across the beam). The
/// attenuation is integrated over the piece, along which `dₑ + dₛ` grows linearly
/// (exactly so with the midpoint's ray), rather than taken at its midpoint: a piece
/// down the length of a beam may be metres long.
pub fn in_scattered_radiance(volumes: &[CausticVolume], eye: Vec3, end: Vec3, medium: &MediumBox, settings: &VolumeSettings) -> Vec3 {
    let length = (end - eye).length();
    if length.is_nan() || length <= 0.0 || length.is_infinite() {
        return Vec3::ZERO;
    }
    let dir = (end - eye) / length;
    let Some((enter, exit)) = medium.clip(eye, dir, length) else {
        return Vec3::ZERO;
    };
    let c = medium.coefficients;
    let sigma_t = c.extinction();
    let mut radiance = Vec3::ZERO;
    for volume in volumes {
        let o = volume.to_local(eye);
        let d = Vec3::new(dir.dot(volume.axes[0]), dir.dot(volume.axes[1]), dir.dot(volume.axes[2]));
        let (pieces, count) = ray_pieces(volume, o, d, enter, exit);
        for &(a, b) in &pieces[..count] {
            let t = 0.5 * (a + b);
            let Some(sample) = volume.sample(eye + t * dir, settings) else {
                continue;
            };
            let beam_length = sample.ray.length();
            let beam = sample.ray / beam_length;
            let e_beam = sample.plane_irradiance * beam_length;
            let d_e = t - enter;
            let d_s = sample.depth * beam_length;
            let phase = henyey_greenstein(beam.dot(-dir), c.asymmetry);
            // The light's path dₑ + dₛ grows along the piece by (1 + d_α |r|) per unit.
            let attenuation = mean_attenuation(sigma_t * (d_e + d_s), 0.5 * sigma_t * (b - a) * (1.0 + d.y * beam_length));
            radiance += volume.color * attenuation * ((b - a) * c.scattering * phase * e_beam);
        }
    }
    radiance
}
