//! Plots of a simulator run, drawn with plotters into an in-memory RGB image (the binary
//! saves them): cross-track error and steering against time, the driven path over a top view
//! of the track, and a sweep's RMS error against the swept value.
//!
//! The font is the system's DejaVu Sans, handed over as bytes by the binary
//! ([`register_font`]); the library reads no files. Units: metres, seconds.

use super::run::{StepOutput, Summary};
use super::scene::Scene;
use image::RgbImage;
use plotters::prelude::*;

/// A plot could not be drawn.
#[derive(Debug, thiserror::Error)]
#[error("plot: {0}")]
pub struct PlotError(String);

fn err<E: std::fmt::Display>(e: E) -> PlotError {
    PlotError(e.to_string())
}

/// Registers the TTF font used for all text (call once, before plotting).
pub fn register_font(bytes: &'static [u8]) {
    let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, bytes);
}

/// The time series a run's plots need.
#[derive(Debug, Clone, Default)]
pub struct Series {
    /// Frame times, seconds.
    pub t: Vec<f64>,
    /// Cross-track error, metres (positive = car left of the lane centre).
    pub xte: Vec<f64>,
    /// Steering command, −1..1.
    pub steer: Vec<f64>,
    /// Rear-axle positions, metres.
    pub path: Vec<(f64, f64)>,
}

impl Series {
    /// Adds one step.
    pub fn push(&mut self, s: &StepOutput) {
        self.push_parts(s.time_s, &s.truth, s.out.command.steer);
    }

    /// Adds one frame from its time, truth and steering command.
    pub fn push_parts(&mut self, time_s: f64, truth: &super::truth::FrameTruth, steer: f64) {
        self.t.push(time_s);
        self.xte.push(truth.offset_m);
        self.steer.push(steer);
        self.path.push((truth.pose[0], truth.pose[1]));
    }
}

const W: u32 = 1000;

/// Cross-track error (top) and steering (bottom) against time; dashed lines at ±5% of the
/// lane width.
pub fn time_plot(s: &Series, lane_width: f64) -> Result<RgbImage, PlotError> {
    let (w, h) = (W, 600);
    let mut buf = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let (top, bottom) = root.split_vertically(h / 2);
        let t_max = s.t.last().copied().unwrap_or(1.0).max(1e-3);
        let e_max = s.xte.iter().fold(lane_width * 0.1, |m, v| m.max(v.abs())) * 1.1;
        let mut c = ChartBuilder::on(&top)
            .caption("cross-track error (m, + = left of lane centre)", ("sans-serif", 18))
            .margin(10)
            .x_label_area_size(30)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..t_max, -e_max..e_max)
            .map_err(err)?;
        c.configure_mesh().x_desc("time (s)").draw().map_err(err)?;
        let band = 0.05 * lane_width;
        for y in [band, -band] {
            c.draw_series(DashedLineSeries::new([(0.0, y), (t_max, y)], 6, 4, RED.stroke_width(1)))
                .map_err(err)?;
        }
        c.draw_series(LineSeries::new(s.t.iter().copied().zip(s.xte.iter().copied()), &BLUE))
            .map_err(err)?;
        let mut c = ChartBuilder::on(&bottom)
            .caption("steering command (+1 = full right)", ("sans-serif", 18))
            .margin(10)
            .x_label_area_size(30)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..t_max, -1.05..1.05)
            .map_err(err)?;
        c.configure_mesh().x_desc("time (s)").draw().map_err(err)?;
        c.draw_series(LineSeries::new(
            s.t.iter().copied().zip(s.steer.iter().copied()),
            &BLACK,
        ))
        .map_err(err)?;
        root.present().map_err(err)?;
    }
    RgbImage::from_raw(w, h, buf).ok_or_else(|| PlotError("buffer size".into()))
}

/// The driven path (rear axle) over a top view of the track's lines and objects.
pub fn path_plot(s: &Series, scene: &Scene) -> Result<RgbImage, PlotError> {
    let track = &scene.track;
    let [x0, y0, x1, y1] = track.floor_rect;
    let (sx, sy) = (x1 - x0, y1 - y0);
    let h = 800u32;
    let w = ((h as f64 - 60.0) * sx / sy + 80.0).clamp(300.0, 2000.0) as u32;
    let mut buf = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&RGBColor(200, 195, 185)).map_err(err)?;
        let mut c = ChartBuilder::on(&root)
            .caption(format!("driven path on {}", track.name), ("sans-serif", 18))
            .margin(10)
            .x_label_area_size(25)
            .y_label_area_size(40)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(err)?;
        c.configure_mesh().disable_mesh().draw().map_err(err)?;
        // Lines of the road, sampled every 2 cm.
        let n = (track.length / 0.02).ceil() as usize;
        for &(off, dashed) in &track.lines {
            let pts: Vec<(f64, f64)> = (0..=n)
                .map(|i| {
                    let (p, hd) = track.pose_at(track.length * i as f64 / n as f64);
                    (p[0] - off * hd.sin(), p[1] + off * hd.cos())
                })
                .collect();
            let col = RGBColor(250, 250, 250);
            if dashed {
                c.draw_series(DashedLineSeries::new(pts, 4, 3, col.stroke_width(1)))
                    .map_err(err)?;
            } else {
                c.draw_series(LineSeries::new(pts, col.stroke_width(2))).map_err(err)?;
            }
        }
        for o in track.enabled_objects() {
            let col = match o.kind {
                super::track::ObjectKind::StopSign => RED,
                super::track::ObjectKind::TrafficLight => GREEN,
                super::track::ObjectKind::Obstacle => BLUE,
            };
            c.draw_series(std::iter::once(Circle::new((o.pos[0], o.pos[1]), 5, col.filled())))
                .map_err(err)?;
        }
        c.draw_series(LineSeries::new(
            s.path.iter().copied(),
            RGBColor(220, 30, 30).stroke_width(1),
        ))
        .map_err(err)?;
        if let Some(&p) = s.path.first() {
            c.draw_series(std::iter::once(Circle::new(p, 4, BLACK.filled())))
                .map_err(err)?;
        }
        root.present().map_err(err)?;
    }
    RgbImage::from_raw(w, h, buf).ok_or_else(|| PlotError("buffer size".into()))
}

/// RMS and max cross-track error against the swept value; runs that left the lane or
/// stalled are marked with a cross.
pub fn sweep_plot(key: &str, rows: &[(f64, Summary)]) -> Result<RgbImage, PlotError> {
    let (w, h) = (900u32, 500u32);
    let mut buf = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let lo = rows.iter().map(|r| r.0).fold(f64::INFINITY, f64::min);
        let hi = rows.iter().map(|r| r.0).fold(f64::NEG_INFINITY, f64::max);
        let (lo, hi) = if hi > lo { (lo, hi) } else { (lo - 1.0, lo + 1.0) };
        let y_max = rows.iter().map(|r| r.1.xte_max_m).fold(0.01, f64::max) * 1.1;
        let mut c = ChartBuilder::on(&root)
            .caption(format!("cross-track error vs {key}"), ("sans-serif", 18))
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(60)
            .build_cartesian_2d(lo..hi, 0.0..y_max)
            .map_err(err)?;
        c.configure_mesh().x_desc(key).y_desc("metres").draw().map_err(err)?;
        c.draw_series(LineSeries::new(rows.iter().map(|r| (r.0, r.1.xte_rms_m)), &BLUE))
            .map_err(err)?
            .label("RMS")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], BLUE));
        c.draw_series(LineSeries::new(rows.iter().map(|r| (r.0, r.1.xte_max_m)), &RED))
            .map_err(err)?
            .label("max")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], RED));
        c.draw_series(
            rows.iter()
                .filter(|r| {
                    r.1.lane_departures > 0
                        || matches!(
                            r.1.end,
                            super::run::EndReason::LeftTheRoad | super::run::EndReason::Stalled
                        )
                })
                .map(|r| Cross::new((r.0, r.1.xte_rms_m), 6, BLACK.stroke_width(2))),
        )
        .map_err(err)?;
        c.configure_series_labels().border_style(BLACK).draw().map_err(err)?;
        root.present().map_err(err)?;
    }
    RgbImage::from_raw(w, h, buf).ok_or_else(|| PlotError("buffer size".into()))
}
