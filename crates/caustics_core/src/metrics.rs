//! Error measures between irradiance images, as every technique reports them.

/// Relative L2 difference `‖a − b‖₂ / ‖b‖₂` of `a` against reference `b`.
/// Returns infinity when the lengths differ and 0 when both are zero.
pub fn relative_l2(a: &[f32], b: &[f32]) -> f32 {
    if a.len() != b.len() {
        return f32::INFINITY;
    }
    let (num, den) = a.iter().zip(b).fold((0f64, 0f64), |(n, d), (&x, &y)| (n + ((x - y) as f64).powi(2), d + (y as f64).powi(2)));
    if den == 0.0 { if num == 0.0 { 0.0 } else { f32::INFINITY } } else { (num / den).sqrt() as f32 }
}

/// Relative L1 difference `‖a − b‖₁ / ‖b‖₁` of `a` against reference `b`: unlike L2,
/// not dominated by a few samples where irradiance has a heavy tail (a point sample
/// near a caustic's cusp). Infinity when the lengths differ, 0 when both are zero.
pub fn relative_l1(a: &[f32], b: &[f32]) -> f32 {
    if a.len() != b.len() {
        return f32::INFINITY;
    }
    let (num, den) = a.iter().zip(b).fold((0f64, 0f64), |(n, d), (&x, &y)| (n + (x - y).abs() as f64, d + y.abs() as f64));
    if den == 0.0 { if num == 0.0 { 0.0 } else { f32::INFINITY } } else { (num / den) as f32 }
}

/// Separable Gaussian blur of a row-major `width × height` image with standard
/// deviation `sigma` cells, truncated at 3σ and renormalised at the borders (edges
/// are not darkened).
pub fn gaussian_blur(image: &[f32], width: usize, height: usize, sigma: f32) -> Vec<f32> {
    if sigma <= 0.0 || image.len() != width * height {
        return image.to_vec();
    }
    let radius = (3.0 * sigma).ceil() as isize;
    let kernel: Vec<f32> = (-radius..=radius).map(|i| (-0.5 * (i as f32 / sigma).powi(2)).exp()).collect();
    let pass = |src: &[f32], stride_along: usize, len: usize, lines: usize, stride_line: usize| {
        let mut dst = vec![0.0; src.len()];
        for l in 0..lines {
            for i in 0..len as isize {
                let (mut acc, mut wsum) = (0.0, 0.0);
                for (k, w) in kernel.iter().enumerate() {
                    let j = i + k as isize - radius;
                    if (0..len as isize).contains(&j) {
                        acc += w * src[l * stride_line + j as usize * stride_along];
                        wsum += w;
                    }
                }
                dst[l * stride_line + i as usize * stride_along] = acc / wsum;
            }
        }
        dst
    };
    let rows = pass(image, 1, width, height, width);
    pass(&rows, width, height, width, 1)
}

/// Reads a comma-separated table of numbers (one image row per line).
pub fn read_csv_image(text: &str) -> Result<(Vec<f32>, usize, usize), String> {
    let mut data = Vec::new();
    let mut width = None;
    let mut height = 0;
    for (line_no, line) in text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty()) {
        let row = line.split(',').map(|v| v.trim().parse::<f32>().map_err(|e| format!("line {}: {v:?}: {e}", line_no + 1))).collect::<Result<Vec<_>, _>>()?;
        match width {
            None => width = Some(row.len()),
            Some(w) if w != row.len() => {
                return Err(format!("line {}: {} values, expected {w}", line_no + 1, row.len()));
            }
            _ => {}
        }
        data.extend(row);
        height += 1;
    }
    Ok((data, width.unwrap_or(0), height))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn relative_errors_weigh_a_spike_differently() {
        // One sample of a hundred off by 10 against a flat reference of ones: L1 sees
        // a tenth of the total, L2 a whole reference norm.
        let reference = vec![1.0; 100];
        let mut spiked = reference.clone();
        spiked[7] += 10.0;
        assert!((relative_l1(&spiked, &reference) - 0.1).abs() < 1e-6);
        assert!((relative_l2(&spiked, &reference) - 1.0).abs() < 1e-6);
        assert_eq!((relative_l1(&[0.0], &[0.0]), relative_l1(&[1.0], &[0.0])), (0.0, f32::INFINITY));
        assert_eq!(relative_l1(&[1.0], &[1.0, 2.0]), f32::INFINITY);
    }
}
