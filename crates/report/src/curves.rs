//! Line charts over trials k = 1..N (the paper's figure 4: average cost and cumulative regret of
//! the selection methods) and stacked areas of how often each strategy is chosen as k grows.

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::FontStyle;
use plotters::style::text_anchor::{HPos, VPos};

use crate::canvas::{
    Drawn, Format, Picture, axis_number, font, px, render, rgba, text, text_size, wrap,
};
use crate::color::{Rgb, plan_colors as pc};
use crate::error::{ReportError, Result};

/// One chart of lines sharing an x axis.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CurvePanel {
    /// Title above the chart.
    pub title: String,
    /// Label of the x axis, e.g. `trials k`.
    pub x_label: String,
    /// Label of the y axis, e.g. `average cost (m)`.
    pub y_label: String,
    /// `(name, points)` per line; line `i` gets [`Rgb::palette`]`(i)` in every panel, so the same
    /// order gives the same colours across panels.
    pub series: Vec<(String, Vec<(f64, f64)>)>,
    /// x values at which every line gets a marker (triangle, diamond, square, then circles), like
    /// the paper's k = 20, 50, 100.
    pub marks_at: Vec<f64>,
}

/// Draws one line chart into `out` (`.png` or `.svg`): a line per series in palette order, with a
/// legend in the emptiest corner.
pub fn draw_curves(
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[(String, Vec<(f64, f64)>)],
    out: &Path,
) -> Result<()> {
    let panel = CurvePanel {
        title: title.into(),
        x_label: x_label.into(),
        y_label: y_label.into(),
        series: series.to_vec(),
        marks_at: Vec::new(),
    };
    draw_curve_panels(std::slice::from_ref(&panel), out)
}

/// Draws several line charts side by side into `out`, e.g. average cost and cumulative regret
/// against k.
pub fn draw_curve_panels(panels: &[CurvePanel], out: &Path) -> Result<()> {
    Format::of(out)?;
    if panels.is_empty() {
        return Err(ReportError::invalid("curves", "no panels"));
    }
    for p in panels {
        for (name, pts) in &p.series {
            if let Some(&(x, y)) = pts.iter().find(|(x, y)| !(x.is_finite() && y.is_finite())) {
                return Err(ReportError::invalid(
                    format!("curves `{}`, series `{name}`", p.title),
                    format!("non-finite point ({x}, {y})"),
                ));
            }
        }
        if let Some(m) = p.marks_at.iter().find(|m| !m.is_finite()) {
            return Err(ReportError::invalid(
                format!("curves `{}`", p.title),
                format!("non-finite mark {m}"),
            ));
        }
    }
    let picture = Curves {
        panels,
        size: (PANEL_W * panels.len() as u32, PANEL_H),
    };
    render(&picture, out)
}

/// Draws a stacked area chart into `out`: for every x (e.g. trial k), the share of deployments
/// that chose each strategy, stacked in the order given, with a legend at the right. Each share
/// vector must have one entry per x; shares are usually fractions summing to 1 at every x.
pub fn draw_choice_shares(
    title: &str,
    x_label: &str,
    x: &[f64],
    shares: &[(String, Vec<f64>)],
    out: &Path,
) -> Result<()> {
    Format::of(out)?;
    if x.is_empty() || shares.is_empty() {
        return Err(ReportError::invalid("choice shares", "no data"));
    }
    if let Some(v) = x.iter().find(|v| !v.is_finite()) {
        return Err(ReportError::invalid(
            "choice shares",
            format!("non-finite x {v}"),
        ));
    }
    for (name, s) in shares {
        let what = format!("choice shares, strategy `{name}`");
        if s.len() != x.len() {
            return Err(ReportError::invalid(
                what,
                format!("{} shares for {} x values", s.len(), x.len()),
            ));
        }
        if let Some(v) = s.iter().find(|v| !(v.is_finite() && **v >= 0.0)) {
            return Err(ReportError::invalid(
                what,
                format!("share {v} is not a finite non-negative number"),
            ));
        }
    }
    crate::canvas::ensure_fonts()?;
    let legend_font = font(13.0, FontStyle::Normal);
    let names: Vec<Vec<String>> = shares
        .iter()
        .map(|(n, _)| wrap(n, &legend_font, 260.0))
        .collect();
    let legend_w = names
        .iter()
        .flatten()
        .map(|l| text_size(&legend_font, l).0)
        .fold(0.0, f64::max)
        .clamp(60.0, 270.0)
        + 56.0;
    let picture = Shares {
        title,
        x_label,
        x,
        shares,
        names,
        legend_w: legend_w as u32,
        size: (PANEL_W + legend_w as u32, PANEL_H),
    };
    render(&picture, out)
}

const PANEL_W: u32 = 640;
const PANEL_H: u32 = 460;

struct Curves<'a> {
    panels: &'a [CurvePanel],
    size: (u32, u32),
}

impl Picture for Curves<'_> {
    fn size(&self) -> (u32, u32) {
        self.size
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>, _format: Format) -> Drawn {
        let areas = root.split_evenly((1, self.panels.len()));
        for (area, panel) in areas.iter().zip(self.panels) {
            draw_curve_panel(area, panel)?;
        }
        Ok(())
    }
}

/// A range around `[lo, hi]` with a little room, never empty.
fn padded(lo: f64, hi: f64, pad: f64) -> (f64, f64) {
    if !(lo.is_finite() && hi.is_finite()) {
        return (0.0, 1.0);
    }
    let span = hi - lo;
    if span <= 1e-12 {
        let d = if lo.abs() > 1e-9 { lo.abs() * 0.1 } else { 1.0 };
        return (lo - d, hi + d);
    }
    (lo - pad * span, hi + pad * span)
}

/// The corner with the fewest data points, for the legend.
fn emptiest_corner(
    series: &[(String, Vec<(f64, f64)>)],
    xr: (f64, f64),
    yr: (f64, f64),
) -> SeriesLabelPosition {
    let mut counts = [0usize; 4]; // upper right, upper left, lower right, lower left
    for (x, y) in series.iter().flat_map(|(_, p)| p.iter()) {
        let u = (x - xr.0) / (xr.1 - xr.0);
        let v = (y - yr.0) / (yr.1 - yr.0);
        let upper = v > 0.55;
        let lower = v < 0.45;
        let right = u > 0.5;
        if upper && right {
            counts[0] += 1;
        }
        if upper && !right {
            counts[1] += 1;
        }
        if lower && right {
            counts[2] += 1;
        }
        if lower && !right {
            counts[3] += 1;
        }
    }
    let best = (0..4).min_by_key(|&i| (counts[i], i)).unwrap_or(0);
    [
        SeriesLabelPosition::UpperRight,
        SeriesLabelPosition::UpperLeft,
        SeriesLabelPosition::LowerRight,
        SeriesLabelPosition::LowerLeft,
    ][best]
        .clone()
}

fn draw_marker<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    at: (f64, f64),
    kind: usize,
    color: Rgb,
) -> Drawn {
    let (x, y) = at;
    let r = 6.0;
    let style = color.rgb().filled();
    let pts: Vec<(f64, f64)> = match kind {
        0 => vec![
            (x, y - r * 1.15),
            (x + r, y + r * 0.7),
            (x - r, y + r * 0.7),
        ],
        1 => vec![(x, y - r * 1.2), (x + r, y), (x, y + r * 1.2), (x - r, y)],
        2 => vec![
            (x - r * 0.85, y - r * 0.85),
            (x + r * 0.85, y - r * 0.85),
            (x + r * 0.85, y + r * 0.85),
            (x - r * 0.85, y + r * 0.85),
        ],
        _ => {
            root.draw(&Circle::new(px(at), 6, WHITE.filled()))?;
            root.draw(&Circle::new(px(at), 5, style))?;
            return Ok(());
        }
    };
    let ipts: Vec<(i32, i32)> = pts.iter().copied().map(px).collect();
    let mut ring = ipts.clone();
    ring.push(ipts[0]);
    root.draw(&Polygon::new(ipts, style))?;
    root.draw(&PathElement::new(ring, WHITE.stroke_width(1)))?;
    Ok(())
}

fn draw_curve_panel<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, p: &CurvePanel) -> Drawn {
    let pts = || p.series.iter().flat_map(|(_, s)| s.iter());
    let (x0, x1) = pts().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), q| {
        (a.min(q.0), b.max(q.0))
    });
    let (y0, y1) = pts().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), q| {
        (a.min(q.1), b.max(q.1))
    });
    let xr = if x0.is_finite() && x1 > x0 {
        (x0, x1)
    } else {
        padded(x0, x1, 0.0)
    };
    let yr = padded(y0, y1, 0.06);
    let mut chart = ChartBuilder::on(area)
        .caption(&p.title, font(18.0, FontStyle::Bold))
        .margin(14)
        .x_label_area_size(44)
        .y_label_area_size(64)
        .build_cartesian_2d(xr.0..xr.1, yr.0..yr.1)?;
    chart
        .configure_mesh()
        .x_desc(&p.x_label)
        .y_desc(&p.y_label)
        .axis_desc_style(font(14.0, FontStyle::Normal))
        .label_style(font(12.0, FontStyle::Normal))
        .x_label_formatter(&axis_number)
        .y_label_formatter(&axis_number)
        .light_line_style(TRANSPARENT)
        .bold_line_style(RGBColor(225, 225, 225))
        .draw()?;
    for (i, (name, s)) in p.series.iter().enumerate() {
        let color = Rgb::palette(i).rgb();
        chart
            .draw_series(LineSeries::new(s.iter().copied(), color.stroke_width(2)))?
            .label(name.as_str())
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 22, y)], color.stroke_width(3))
            });
    }
    for (i, (_, s)) in p.series.iter().enumerate() {
        for (k, &m) in p.marks_at.iter().enumerate() {
            let nearest = s
                .iter()
                .min_by(|a, b| (a.0 - m).abs().total_cmp(&(b.0 - m).abs()));
            if let Some(&(x, y)) = nearest {
                let (bx, by) = chart.backend_coord(&(x, y));
                draw_marker(area, (f64::from(bx), f64::from(by)), k, Rgb::palette(i))?;
            }
        }
    }
    if !p.series.is_empty() {
        chart
            .configure_series_labels()
            .position(emptiest_corner(&p.series, xr, yr))
            .margin(10)
            .label_font(font(12.5, FontStyle::Normal))
            .background_style(WHITE.mix(0.9))
            .border_style(RGBColor(170, 170, 170))
            .draw()?;
    }
    Ok(())
}

struct Shares<'a> {
    title: &'a str,
    x_label: &'a str,
    x: &'a [f64],
    shares: &'a [(String, Vec<f64>)],
    names: Vec<Vec<String>>,
    legend_w: u32,
    size: (u32, u32),
}

impl Picture for Shares<'_> {
    fn size(&self) -> (u32, u32) {
        self.size
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>, _format: Format) -> Drawn {
        let (chart_area, legend_area) = root.split_horizontally(self.size.0 - self.legend_w);
        let n = self.x.len();
        let mut lower = vec![0.0; n];
        let mut layers = Vec::with_capacity(self.shares.len());
        for (_, s) in self.shares {
            let upper: Vec<f64> = lower.iter().zip(s).map(|(l, v)| l + v).collect();
            layers.push((lower.clone(), upper.clone()));
            lower = upper;
        }
        let top = lower.iter().copied().fold(1.0, f64::max);
        let (x0, x1) = self
            .x
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                (a.min(v), b.max(v))
            });
        let xr = if x1 > x0 {
            (x0, x1)
        } else {
            (x0 - 0.5, x0 + 0.5)
        };
        let mut chart = ChartBuilder::on(&chart_area)
            .caption(self.title, font(18.0, FontStyle::Bold))
            .margin(14)
            .x_label_area_size(44)
            .y_label_area_size(64)
            .build_cartesian_2d(xr.0..xr.1, 0.0..top)?;
        chart
            .configure_mesh()
            .x_desc(self.x_label)
            .y_desc("share of deployments")
            .axis_desc_style(font(14.0, FontStyle::Normal))
            .label_style(font(12.0, FontStyle::Normal))
            .x_label_formatter(&axis_number)
            .y_label_formatter(&axis_number)
            .light_line_style(TRANSPARENT)
            .bold_line_style(RGBColor(225, 225, 225))
            .draw()?;
        for (i, (lo, hi)) in layers.iter().enumerate() {
            let color = Rgb::palette(i);
            let mut shape: Vec<(f64, f64)> =
                self.x.iter().copied().zip(hi.iter().copied()).collect();
            shape.extend(self.x.iter().copied().zip(lo.iter().copied()).rev());
            if n == 1 {
                // A single x: draw a thin bar so the share is still visible.
                let w = (xr.1 - xr.0) * 0.1;
                shape = vec![
                    (self.x[0] - w, lo[0]),
                    (self.x[0] + w, lo[0]),
                    (self.x[0] + w, hi[0]),
                    (self.x[0] - w, hi[0]),
                ];
            }
            chart.draw_series(std::iter::once(Polygon::new(
                shape,
                rgba(color, 0.85).filled(),
            )))?;
            let edge: Vec<(f64, f64)> = self.x.iter().copied().zip(hi.iter().copied()).collect();
            chart.draw_series(std::iter::once(PathElement::new(
                edge,
                WHITE.stroke_width(1),
            )))?;
        }
        let f = font(13.0, FontStyle::Normal);
        // Listed top to bottom as the layers are stacked, so the legend reads like the chart.
        let mut y = 60.0;
        for (i, lines) in self.names.iter().enumerate().rev() {
            let color = Rgb::palette(i);
            legend_area.draw(&Rectangle::new(
                [px((6.0, y - 7.0)), px((24.0, y + 7.0))],
                rgba(color, 0.85).filled(),
            ))?;
            for (k, line) in lines.iter().enumerate() {
                text(
                    &legend_area,
                    line,
                    (32.0, y + 16.0 * k as f64),
                    &f,
                    pc::TEXT,
                    (HPos::Left, VPos::Center),
                )?;
            }
            y += 16.0 * lines.len() as f64 + 10.0;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn legend_goes_where_the_lines_are_not() {
        // A rising line leaves the upper left empty.
        let s = vec![(
            "a".to_string(),
            (0..=10).map(|i| (i as f64, i as f64)).collect::<Vec<_>>(),
        )];
        let pos = emptiest_corner(&s, (0.0, 10.0), (0.0, 10.0));
        assert!(matches!(pos, SeriesLabelPosition::UpperLeft), "{pos:?}");
    }

    #[test]
    fn padding_never_gives_an_empty_range() {
        let (a, b) = padded(5.0, 5.0, 0.1);
        assert!(a < 5.0 && b > 5.0);
        let (a, b) = padded(0.0, 10.0, 0.1);
        assert_eq!((a, b), (-1.0, 11.0));
    }
}
