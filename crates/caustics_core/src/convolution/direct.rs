//! Eq. 2 evaluated as written: no `d ≫ h`, the Gaussian lobe itself.

use super::{ConvolutionSettings, Heightfield, TransmittedLight, transmitted_light};
use crate::params::ParamError;
use glam::DVec3;
use rayon::prelude::*;

/// The floor irradiance of eq. 2 below every texel centre, row-major: the midpoint rule
/// over the footprint's texels, each with its exact `P` from the surface point
/// `(x, h(x, z), z)` to the floor point and its Gaussian lobe, normalised as the module
/// documentation says. `f64` throughout, lobes in the log domain, so a huge `a` or `ε`
/// gives zeros, never NaN. Errors: invalid settings, or a height at or below the floor.
pub fn direct_irradiance(heightfield: &Heightfield, settings: &ConvolutionSettings) -> Result<Vec<f32>, ParamError> {
    let light = transmitted_light(heightfield, settings)?;
    let (columns, rows) = (heightfield.columns(), heightfield.rows());
    let cell = heightfield.cell_size() as f64;
    let radius = settings.kernel_radius as isize;
    let offsets: Vec<(isize, isize)> = (-radius..=radius).flat_map(|dz| (-radius..=radius).map(move |dx| (dx, dz))).collect();
    let lobe = Lobe { depth: settings.depth as f64, scattering: settings.scattering as f64, cell };

    // ln of each texel's lobe summed over the footprint without extinction.
    let log_normalisers: Vec<f64> = light
        .par_iter()
        .zip(heightfield.heights())
        .map(|(texel, &height)| {
            let direction = texel.direction.as_dvec3();
            log_sum_exp(offsets.iter().map(|&offset| lobe.log_weight(offset, direction, height as f64).0))
        })
        .collect();

    let extinction = settings.extinction as f64;
    let boundary = settings.boundary;
    let irradiance = (0..columns * rows).into_par_iter().map(|floor| {
        let (column, row) = ((floor % columns) as isize, (floor / columns) as isize);
        let mut sum = 0.0;
        for &(dx, dz) in &offsets {
            let (source_column, mirrored_x) = boundary.fold(column - dx, columns);
            let (source_row, mirrored_z) = boundary.fold(row - dz, rows);
            let source = source_row * columns + source_column;
            let TransmittedLight { flux, direction } = light[source];
            if flux == 0.0 {
                continue;
            }
            let mut direction = direction.as_dvec3();
            if mirrored_x {
                direction.x = -direction.x;
            }
            if mirrored_z {
                direction.z = -direction.z;
            }
            let (log_weight, distance) = lobe.log_weight((dx, dz), direction, heightfield.heights()[source] as f64);
            sum += flux as f64 * (log_weight - extinction * distance - log_normalisers[source]).exp();
        }
        sum as f32
    });
    Ok(irradiance.collect())
}

/// The unnormalised integrand of eq. 2 without flux and extinction.
struct Lobe {
    depth: f64,
    scattering: f64,
    cell: f64,
}

impl Lobe {
    /// `ln(P̂_v exp(−a(1 − (L̂t·P̂)²)))` and `‖P‖` for the floor point `offset` texels
    /// from a surface point at `height`, whose light leaves along `direction`.
    fn log_weight(&self, (dx, dz): (isize, isize), direction: DVec3, height: f64) -> (f64, f64) {
        let column = self.depth + height;
        let path = DVec3::new(dx as f64 * self.cell, -column, dz as f64 * self.cell);
        let distance = path.length();
        let cosine = direction.dot(path) / distance;
        let spread = (1.0 - cosine * cosine).max(0.0);
        ((column / distance).ln() - self.scattering * spread, distance)
    }
}

/// `ln Σ exp(xᵢ)` without overflow or underflow (one pass, rescaling at each new maximum).
fn log_sum_exp(terms: impl Iterator<Item = f64>) -> f64 {
    let (max, sum) =
        terms.fold((f64::NEG_INFINITY, 0.0), |(max, sum), x| if x > max { (x, sum * (max - x).exp() + 1.0) } else { (max, sum + (x - max).exp()) });
    max + sum.ln()
}
