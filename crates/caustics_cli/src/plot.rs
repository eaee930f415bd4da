//! The bench figures: log–log line plots, one line per scene and method — relative L2
//! error against run time, and the caustic maps' processed photons against photon count.

use plotters::coord::combinators::{LogCoord, WithKeyPoints};
use plotters::prelude::*;
use plotters::style::{FontStyle, register_font};
use std::path::Path;

/// Points `(seconds, relative error)` of one scene × method.
pub struct Series {
    pub label: String,
    pub points: Vec<(f64, f64)>,
}

/// A plot's caption and axis descriptions.
pub struct Axes {
    pub caption: &'static str,
    pub x: &'static str,
    pub y: &'static str,
}

/// The main bench figure.
pub const ERROR_VS_TIME: Axes = Axes { caption: "Caustic irradiance error against run time", x: "run time (s)", y: "relative L2 vs reference" };

pub fn plot_error_vs_time(path: &Path, series: &[&Series]) -> Result<(), String> {
    plot_log_log(path, &ERROR_VS_TIME, series)
}

/// Draws `series` on log–log axes into a 900 × 600 PNG.
pub fn plot_log_log(path: &Path, axes: &Axes, series: &[&Series]) -> Result<(), String> {
    // ab_glyph needs one font; egui's default font is small, free and ships as a crate.
    register_font("sans-serif", FontStyle::Normal, epaint_default_fonts::UBUNTU_LIGHT).map_err(|_| "the plot font is not a valid TrueType font".to_string())?;
    let err = |e: &dyn std::fmt::Display| format!("cannot draw {}: {e}", path.display());
    let all = series.iter().flat_map(|s| s.points.iter()).filter(|p| p.0 > 0.0 && p.1 > 0.0);
    let (mut t0, mut t1, mut e0, mut e1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(t, e) in all {
        (t0, t1, e0, e1) = (t0.min(t), t1.max(t), e0.min(e), e1.max(e));
    }
    if t0 > t1 {
        return Err("nothing to plot: the bench produced no measurements".into());
    }
    const SIZE: (u32, u32) = (900, 600);
    let mut pixels = vec![0u8; (SIZE.0 * SIZE.1 * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut pixels, SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(&e))?;
        let mut chart = ChartBuilder::on(&root)
            .caption(axes.caption, ("sans-serif", 24))
            .margin(16)
            .x_label_area_size(48)
            .y_label_area_size(64)
            .build_cartesian_2d(log_axis(t0 / 1.5, t1 * 1.5), log_axis(e0 / 1.5, e1 * 1.5))
            .map_err(|e| err(&e))?;
        chart
            .configure_mesh()
            .x_desc(axes.x)
            .y_desc(axes.y)
            .label_style(("sans-serif", 15))
            .x_label_formatter(&|v| tick(*v))
            .y_label_formatter(&|v| tick(*v))
            .draw()
            .map_err(|e| err(&e))?;
        for (i, s) in series.iter().enumerate() {
            let color = Palette99::pick(i).to_rgba();
            chart
                .draw_series(LineSeries::new(s.points.iter().copied(), color.stroke_width(2)))
                .map_err(|e| err(&e))?
                .label(&s.label)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2)));
            chart.draw_series(s.points.iter().map(|&p| Circle::new(p, 4, color.filled()))).map_err(|e| err(&e))?;
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::LowerLeft)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 15))
            .draw()
            .map_err(|e| err(&e))?;
        root.present().map_err(|e| err(&e))?;
    }
    image::RgbImage::from_raw(SIZE.0, SIZE.1, pixels)
        .ok_or("plot buffer has the wrong size")?
        .save_with_format(path, image::ImageFormat::Png)
        .map_err(|e| err(&e))
}

/// A log axis over `lo..hi` labelled at 1, 2 and 5 times the powers of ten (every
/// digit when the range spans less than a decade), with a light line at every digit.
fn log_axis(lo: f64, hi: f64) -> WithKeyPoints<LogCoord<f64>> {
    let digits = |ms: &[f64]| -> Vec<f64> {
        let decades = lo.log10().floor() as i32..=hi.log10().ceil() as i32;
        decades.flat_map(|k| ms.iter().map(move |m| m * 10f64.powi(k))).filter(|v| (lo..=hi).contains(v)).collect()
    };
    let all = digits(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]);
    let labelled = digits(&[1.0, 2.0, 5.0]);
    let labelled = if labelled.len() >= 3 { labelled } else { all.clone() };
    (lo..hi).log_scale().with_key_points(labelled).with_light_points(all)
}

/// A tick label to three significant digits: a log axis's ticks are sums of binary
/// fractions (`0.30000000000000004`).
fn tick(value: f64) -> String {
    format!("{:.2e}", value).parse::<f64>().map_or_else(|_| value.to_string(), |v| v.to_string())
}

#[cfg(test)]
mod tests {
    #[test]
    fn ticks_read_as_people_write_them() {
        // 0.1 + 0.2 and 0.7 * 0.1 are not 0.3 and 0.07 in binary.
        let labels: Vec<String> = [0.1 + 0.2, 2.0, 0.7 * 0.1, 1234.5].map(super::tick).into();
        assert_eq!(labels, ["0.3", "2", "0.07", "1230"]);
    }
}
