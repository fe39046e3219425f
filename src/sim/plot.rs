//! Plots of a simulator run, drawn with plotters into an in-memory RGB image (the binary
//! saves them): cross-track error and steering against time, the driven path over a top view
//! of the track, a sweep's RMS error against the swept value, a two-key sweep's heat map, a
//! step response with its rise, overshoot and settling marks, and any telemetry fields of
//! several runs against time (`rccar plot`).
//!
//! The font is the system's DejaVu Sans, handed over as bytes by the binary
//! ([`register_font`]); the library reads no files. Units: metres, seconds.

use crate::classes::SimShape;
use super::run::{StepOutput, Summary};
use super::scene::Scene;
use super::step::StepMetrics;
use super::sweep::{axis_label, SweepRun};
use image::RgbImage;
use plotters::prelude::*;

/// A plot could not be drawn.
#[derive(Debug, thiserror::Error)]
#[error("plot: {0}")]
pub struct PlotError(String);

fn err<E: std::fmt::Display>(e: E) -> PlotError {
    PlotError(e.to_string())
}

/// Where the plot font is looked for (Debian's fonts-dejavu-core; never committed).
pub const SYSTEM_FONT: &str = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf";

/// The plot font read from [`SYSTEM_FONT`], kept for the life of the process (`None`: not
/// installed).
pub fn system_font() -> Option<&'static [u8]> {
    std::fs::read(SYSTEM_FONT).ok().map(|b| &*Box::leak(b.into_boxed_slice()))
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
        // Lines of every road (the main loop, then the branches), sampled every 2 cm.
        for (r, road) in track.roads.iter().enumerate() {
        let n = (road.length / 0.02).ceil() as usize;
        for &(off, dashed) in &track.lines {
            let pts: Vec<(f64, f64)> = (0..=n)
                .map(|i| {
                    let (p, hd) = track.road_pose_at(r, road.length * i as f64 / n as f64);
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
        }
        for o in track.enabled_objects() {
            // by how the class is drawn (the registry's shape), so a new class needs no entry here
            let col = match o.kind.info().shape {
                SimShape::Octagon | SimShape::Triangle => RED,
                SimShape::LightHousing => GREEN,
                SimShape::Box | SimShape::ArrowDisc => BLUE,
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

/// The viridis colour map (perceptually even, readable in grey), `f` in 0..1.
pub fn viridis(f: f64) -> RGBColor {
    const STOPS: [(f64, [f64; 3]); 5] = [
        (0.0, [68.0, 1.0, 84.0]),
        (0.25, [59.0, 82.0, 139.0]),
        (0.5, [33.0, 145.0, 140.0]),
        (0.75, [94.0, 201.0, 98.0]),
        (1.0, [253.0, 231.0, 37.0]),
    ];
    let f = if f.is_finite() { f.clamp(0.0, 1.0) } else { 0.0 };
    let i = STOPS.iter().position(|s| s.0 >= f).unwrap_or(4).max(1);
    let (a, b) = (STOPS[i - 1], STOPS[i]);
    let u = (f - a.0) / (b.0 - a.0);
    let c = |k: usize| (a.1[k] + u * (b.1[k] - a.1[k])).round() as u8;
    RGBColor(c(0), c(1), c(2))
}

/// A tick label for a swept value: as few decimals as tell the values apart.
fn tick(v: f64, values: &[f64]) -> String {
    for d in 0..6 {
        let shown: Vec<String> = values.iter().map(|x| format!("{x:.d$}")).collect();
        let mut u = shown.clone();
        u.dedup();
        if u.len() == shown.len() && (v - format!("{v:.d$}").parse::<f64>().unwrap_or(v)).abs() < 1e-9 * v.abs().max(1.0) {
            return format!("{v:.d$}");
        }
    }
    format!("{v}")
}

/// A two-key sweep as a heat map: one cell per run, coloured by cross-track RMS (viridis,
/// colour bar in millimetres on the right), the RMS written in each cell, and a red cross
/// over every run that left the lane (a departure, off the road or stalled). `xs`/`ys` are the
/// axes' values (cells in that order, labelled with them); `runs` hold `[x, y]` in their
/// `values`.
pub fn grid_plot(kx: &str, ky: &str, xs: &[f64], ys: &[f64], runs: &[SweepRun]) -> Result<RgbImage, PlotError> {
    use plotters::style::text_anchor::{HPos, Pos, VPos};
    let (w, h) = (1000u32, 720u32);
    let mut buf = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let (main, _) = root.split_horizontally(w - 150);
        let (nx, ny) = (xs.len().max(1) as f64, ys.len().max(1) as f64);
        let rms_mm: Vec<f64> = runs.iter().map(|r| r.summary.xte_rms_m * 1000.0).collect();
        let (vmin, vmax) = value_range(&rms_mm);
        let frac = |v: f64| (v - vmin) / (vmax - vmin);
        // Cell (i, j) spans i−0.5..i+0.5 and j−0.5..j+0.5; ticks are drawn here at the
        // cells' centres, labelled with the swept values.
        let mut c = ChartBuilder::on(&main)
            .caption(
                format!("cross-track RMS (mm) over {kx} × {ky}   (red × = left the lane)"),
                ("sans-serif", 18),
            )
            .margin(12)
            .x_label_area_size(55)
            .y_label_area_size(85)
            .build_cartesian_2d(-0.5..nx - 0.5, -0.5..ny - 0.5)
            .map_err(err)?;
        c.configure_mesh()
            .disable_mesh()
            .x_labels(0)
            .y_labels(0)
            .x_desc(axis_label(kx))
            .y_desc(axis_label(ky))
            .axis_desc_style(("sans-serif", 16))
            .draw()
            .map_err(err)?;
        let idx = |vals: &[f64], v: f64| vals.iter().position(|x| (x - v).abs() <= 1e-9 * x.abs().max(1.0));
        let cell_px = ((w as f64 - 280.0) / nx).min((h as f64 - 130.0) / ny);
        let font = (cell_px / 4.0).clamp(9.0, 20.0) as u32;
        let decimals = if vmax < 10.0 { 2 } else { 1 };
        for (r, &v) in runs.iter().zip(&rms_mm) {
            let (Some(i), Some(j)) = (
                r.values.first().and_then(|&x| idx(xs, x)),
                r.values.get(1).and_then(|&y| idx(ys, y)),
            ) else {
                continue;
            };
            let (x, y) = (i as f64, j as f64);
            let col = viridis(frac(v));
            c.draw_series(std::iter::once(Rectangle::new([(x - 0.5, y - 0.5), (x + 0.5, y + 0.5)], col.filled())))
                .map_err(err)?;
            if r.left_lane() {
                let d = (cell_px * 0.3) as i32;
                let red = RGBColor(230, 20, 20).mix(0.8).stroke_width(4);
                c.draw_series([
                    EmptyElement::at((x, y)) + PathElement::new(vec![(-d, -d), (d, d)], red),
                    EmptyElement::at((x, y)) + PathElement::new(vec![(-d, d), (d, -d)], red),
                ])
                .map_err(err)?;
            }
            let ink = if frac(v) > 0.6 { BLACK } else { WHITE };
            let style = ("sans-serif", font).into_font().color(&ink).pos(Pos::new(HPos::Center, VPos::Center));
            c.draw_series(std::iter::once(Text::new(format!("{v:.decimals$}"), (x, y), style)))
                .map_err(err)?;
        }
        // Tick marks and labels at the cells' centres (pixel positions from the chart).
        let ink = BLACK.stroke_width(1);
        let below = ("sans-serif", 14).into_font().color(&BLACK).pos(Pos::new(HPos::Center, VPos::Top));
        let left = ("sans-serif", 14).into_font().color(&BLACK).pos(Pos::new(HPos::Right, VPos::Center));
        for (i, v) in xs.iter().enumerate() {
            let (px, py) = c.backend_coord(&(i as f64, -0.5));
            root.draw(&PathElement::new(vec![(px, py), (px, py + 5)], ink)).map_err(err)?;
            root.draw(&Text::new(tick(*v, xs), (px, py + 8), below.clone())).map_err(err)?;
        }
        for (j, v) in ys.iter().enumerate() {
            let (px, py) = c.backend_coord(&(-0.5, j as f64));
            root.draw(&PathElement::new(vec![(px - 5, py), (px, py)], ink)).map_err(err)?;
            root.draw(&Text::new(tick(*v, ys), (px - 8, py), left.clone())).map_err(err)?;
        }
        colour_bar(&root, (w, h), (vmin, vmax), decimals)?;
        root.present().map_err(err)?;
    }
    RgbImage::from_raw(w, h, buf).ok_or_else(|| PlotError("buffer size".into()))
}

/// The smallest and largest of `v` (a unit-wide range around a single value; 0..1 for none).
fn value_range(v: &[f64]) -> (f64, f64) {
    let vmin = v.iter().copied().fold(f64::INFINITY, f64::min);
    let vmax = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if vmax > vmin {
        (vmin, vmax)
    } else if vmin.is_finite() {
        (vmin - 0.5, vmin + 0.5)
    } else {
        (0.0, 1.0)
    }
}

/// The heat map's colour bar right of the map, `vmin` (bottom) to `vmax` (top), in pixels of
/// the `(w, h)` picture.
fn colour_bar(
    root: &DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>,
    (w, h): (u32, u32),
    (vmin, vmax): (f64, f64),
    decimals: usize,
) -> Result<(), PlotError> {
    use plotters::style::text_anchor::{HPos, Pos, VPos};
    let ink = BLACK.stroke_width(1);
    // The colour bar: 100 bands bottom (vmin) to top (vmax), six labels, drawn in pixels.
    let (bx, top, bottom) = (w as i32 - 120, 60i32, h as i32 - 80);
    let n = 100;
    for k in 0..n {
        let y1 = bottom - (bottom - top) * k / n;
        let y0 = bottom - (bottom - top) * (k + 1) / n;
        root.draw(&Rectangle::new([(bx, y0), (bx + 28, y1)], viridis(k as f64 / (n - 1) as f64).filled()))
            .map_err(err)?;
    }
    root.draw(&Rectangle::new([(bx, top), (bx + 28, bottom)], BLACK.stroke_width(1)))
        .map_err(err)?;
    let lab = ("sans-serif", 13).into_font().color(&BLACK).pos(Pos::new(HPos::Left, VPos::Center));
    for k in 0..=5 {
        let v = vmin + (vmax - vmin) * k as f64 / 5.0;
        let py = bottom - (bottom - top) * k / 5;
        root.draw(&PathElement::new(vec![(bx + 28, py), (bx + 33, py)], ink)).map_err(err)?;
        root.draw(&Text::new(format!("{v:.decimals$}"), (bx + 36, py), lab.clone())).map_err(err)?;
    }
    let t = ("sans-serif", 15).into_font().color(&BLACK).pos(Pos::new(HPos::Center, VPos::Bottom));
    root.draw(&Text::new("RMS (mm)", (bx + 14, top - 10), t)).map_err(err)?;
    Ok(())
}

/// A step response: cross-track error (cm) against time from just before the step to the
/// end of the analysed window, with the 10 % and 90 % levels, the settling band, and marks at
/// the rise's start and end, the overshoot's peak and the settling time.
pub fn step_plot(t: &[f64], xte: &[f64], m: &StepMetrics) -> Result<RgbImage, PlotError> {
    let (w, h) = (1000u32, 550u32);
    let mut buf = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let (ta, tb) = (m.t0_s - 0.5, m.t0_s + m.window_s.max(0.5));
        let pts: Vec<(f64, f64)> = t
            .iter()
            .zip(xte)
            .filter(|(&ti, xi)| ti >= ta && ti <= tb && xi.is_finite())
            .map(|(&ti, &xi)| (ti, xi * 100.0))
            .collect();
        let x0 = m.initial_offset_m * 100.0;
        let lo = pts.iter().map(|p| p.1).fold(x0.min(0.0), f64::min);
        let hi = pts.iter().map(|p| p.1).fold(x0.max(0.0), f64::max);
        let pad = (hi - lo).max(0.5) * 0.08;
        let mut c = ChartBuilder::on(&root)
            .caption(
                format!(
                    "step response from {:+.1} cm at t = {:.2} s (+ = left of lane centre)",
                    x0, m.t0_s
                ),
                ("sans-serif", 18),
            )
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(ta..tb, (lo - pad)..(hi + pad))
            .map_err(err)?;
        c.configure_mesh()
            .x_desc("time (s)")
            .y_desc("cross-track error (cm)")
            .draw()
            .map_err(err)?;
        let grey = RGBColor(120, 120, 120);
        for lvl in [0.9, 0.1] {
            c.draw_series(DashedLineSeries::new([(ta, lvl * x0), (tb, lvl * x0)], 6, 4, grey.stroke_width(1)))
                .map_err(err)?;
        }
        let band = m.band_m * 100.0;
        let green = RGBColor(0, 150, 0);
        c.draw_series(DashedLineSeries::new([(ta, band), (tb, band)], 3, 3, green.stroke_width(1)))
            .map_err(err)?
            .label(format!("settling band ±{:.1} mm", m.band_m * 1000.0))
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], green));
        c.draw_series(DashedLineSeries::new([(ta, -band), (tb, -band)], 3, 3, green.stroke_width(1)))
            .map_err(err)?;
        c.draw_series(LineSeries::new(pts, BLUE.stroke_width(2)))
            .map_err(err)?
            .label("cross-track error (truth)")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], BLUE.stroke_width(2)));
        let (ylo, yhi) = (lo - pad, hi + pad);
        let vline = |c: &mut ChartContext<'_, BitMapBackend<'_>, Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>>,
                     at: f64,
                     col: RGBColor,
                     label: String|
         -> Result<(), PlotError> {
            c.draw_series(LineSeries::new([(at, ylo), (at, yhi)], col.stroke_width(2)))
                .map_err(err)?
                .label(label)
                .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], col.stroke_width(2)));
            Ok(())
        };
        if let (Some(a), Some(b), Some(r)) = (m.rise_start_s, m.rise_end_s, m.rise_time_s) {
            let orange = RGBColor(230, 130, 0);
            vline(&mut c, m.t0_s + a, orange, format!("rise 10→90 %: {r:.2} s"))?;
            c.draw_series(LineSeries::new([(m.t0_s + b, ylo), (m.t0_s + b, yhi)], orange.stroke_width(2)))
                .map_err(err)?;
        }
        if let Some(s) = m.settling_time_s {
            vline(&mut c, m.t0_s + s, green, format!("settled (±{:.1} mm) after {s:.2} s", m.band_m * 1000.0))?;
        }
        if let Some(p) = m.peak_s {
            let i = t.iter().position(|&ti| ti >= m.t0_s + p - 1e-9);
            if let Some(i) = i {
                c.draw_series(std::iter::once(Circle::new((t[i], xte[i] * 100.0), 6, RED.filled())))
                    .map_err(err)?
                    .label(format!("overshoot {:.1} %", m.overshoot_pct))
                    .legend(|(x, y)| Circle::new((x + 10, y), 5, RED.filled()));
            }
        }
        // The legend where the response is not: away from the centre it settles at.
        c.configure_series_labels()
            .position(if x0 > 0.0 { SeriesLabelPosition::UpperRight } else { SeriesLabelPosition::LowerRight })
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 15))
            .draw()
            .map_err(err)?;
        root.present().map_err(err)?;
    }
    RgbImage::from_raw(w, h, buf).ok_or_else(|| PlotError("buffer size".into()))
}

/// One run's data for [`fields_plot`]: a label and, per field, its points (x, y); a NaN y
/// breaks the line (e.g. frames where the lane was lost).
#[derive(Debug, Clone, Default)]
pub struct Trace {
    /// Legend text.
    pub label: String,
    /// Points per field, in the order of the fields.
    pub panels: Vec<Vec<(f64, f64)>>,
}

/// Distinct colours for runs on one chart.
pub const RUN_COLOURS: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
];

/// Height of one panel of [`fields_plot`], pixels.
pub const PANEL_H: u32 = 260;
/// Most panels of [`fields_plot`] (1000 × 16,680 pixels, 50 MB).
pub const MAX_PANELS: usize = 64;

/// Several runs' telemetry fields against `x_name`: one panel per field (stacked), one colour
/// per run, a legend in the first panel. 1000 × (40 + 260·fields) pixels.
pub fn fields_plot(x_name: &str, fields: &[String], traces: &[Trace]) -> Result<RgbImage, PlotError> {
    if fields.is_empty() {
        return Err(PlotError("no field to plot".into()));
    }
    if fields.len() > MAX_PANELS {
        return Err(PlotError(format!(
            "{} fields: at most {MAX_PANELS} panels in one image",
            fields.len()
        )));
    }
    let (w, h) = (1000u32, 40 + PANEL_H * fields.len() as u32);
    let mut buf = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let (title, body) = root.split_vertically(40);
        let names: Vec<&str> = traces.iter().map(|t| t.label.as_str()).collect();
        title
            .titled(&format!("{} against {x_name}: {}", fields.join(", "), names.join(" vs ")), ("sans-serif", 18))
            .map_err(err)?;
        let panels = body.split_evenly((fields.len(), 1));
        let finite = |p: &&(f64, f64)| p.0.is_finite() && p.1.is_finite();
        let all = || traces.iter().flat_map(|t| t.panels.iter().flatten());
        let xa = all().filter(finite).map(|p| p.0).fold(f64::INFINITY, f64::min);
        let xb = all().filter(finite).map(|p| p.0).fold(f64::NEG_INFINITY, f64::max);
        let (xa, xb) = if xb > xa { (xa, xb) } else if xa.is_finite() { (xa - 1.0, xa + 1.0) } else { (0.0, 1.0) };
        for (k, (field, area)) in fields.iter().zip(panels.iter()).enumerate() {
            let pts = || traces.iter().filter_map(|t| t.panels.get(k)).flatten().filter(finite);
            let ya = pts().map(|p| p.1).fold(f64::INFINITY, f64::min);
            let yb = pts().map(|p| p.1).fold(f64::NEG_INFINITY, f64::max);
            let (ya, yb) = if yb > ya {
                let pad = (yb - ya) * 0.05;
                (ya - pad, yb + pad)
            } else if ya.is_finite() {
                (ya - 1.0, ya + 1.0)
            } else {
                (-1.0, 1.0)
            };
            let mut c = ChartBuilder::on(area)
                .caption(field, ("sans-serif", 16))
                .margin(8)
                .x_label_area_size(35)
                .y_label_area_size(70)
                .build_cartesian_2d(xa..xb, ya..yb)
                .map_err(err)?;
            c.configure_mesh().x_desc(x_name).y_desc(field.as_str()).draw().map_err(err)?;
            for (i, t) in traces.iter().enumerate() {
                let col = RUN_COLOURS[i % RUN_COLOURS.len()];
                let Some(p) = t.panels.get(k) else { continue };
                // Split at NaNs so a gap stays a gap.
                let mut first = true;
                for seg in p.split(|q| !q.1.is_finite() || !q.0.is_finite()) {
                    if seg.is_empty() {
                        continue;
                    }
                    let s = c
                        .draw_series(LineSeries::new(seg.iter().copied(), col.stroke_width(2)))
                        .map_err(err)?;
                    if k == 0 && first {
                        s.label(t.label.clone())
                            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], col.stroke_width(2)));
                        first = false;
                    }
                }
            }
            if k == 0 {
                c.configure_series_labels()
                    .position(SeriesLabelPosition::UpperRight)
                    .background_style(WHITE.mix(0.85))
                    .border_style(BLACK)
                    .draw()
                    .map_err(err)?;
            }
        }
        root.present().map_err(err)?;
    }
    RgbImage::from_raw(w, h, buf).ok_or_else(|| PlotError("buffer size".into()))
}
