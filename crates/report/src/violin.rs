//! Violin plots of cost distributions per strategy (the paper's appendix E): a Gaussian kernel
//! density violin per strategy, dotted quartile lines, and the individual trials as jittered
//! points.

use std::path::Path;

use plotters::coord::Shift;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::FontStyle;
use plotters::style::text_anchor::{HPos, VPos};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::canvas::{
    Drawn, Format, Picture, axis_number, font, render, rgba, text, text_size, wrap,
};
use crate::color::{Rgb, plan_colors as pc};
use crate::error::{ReportError, Result};
use crate::stats::{gaussian_kde, quartiles, silverman_bandwidth};

/// Options of a violin plot.
#[derive(Clone, Debug, PartialEq)]
pub struct ViolinOptions {
    /// Title above the plot.
    pub title: String,
    /// Label of the y axis.
    pub y_label: String,
    /// Seed of the horizontal jitter of the points, so pictures are reproducible.
    pub seed: u64,
    /// Picture width in pixels; about 120 px per strategy (at least 640) when `None`.
    pub width: Option<u32>,
    /// Picture height in pixels; 560 when `None` (more when names need several lines).
    pub height: Option<u32>,
}

impl Default for ViolinOptions {
    fn default() -> Self {
        Self {
            title: "Cost per strategy".into(),
            y_label: "cost (m)".into(),
            seed: 0,
            width: None,
            height: None,
        }
    }
}

/// Draws one violin per series (`(strategy name, costs)`) into `out` (`.png` or `.svg`): the
/// kernel density estimate (Gaussian, Silverman bandwidth, cut two bandwidths beyond the data and
/// never below zero for non-negative data), scaled to a common maximum width; dotted lines at the
/// quartiles (the median thicker); every value as a point, jittered horizontally inside the
/// violin with a seeded RNG. Names go under the violins, wrapped after `/` and `+` when long.
/// Series with fewer than two distinct values get a line at their value instead of a violin.
pub fn draw_violins(series: &[(String, Vec<f64>)], opts: &ViolinOptions, out: &Path) -> Result<()> {
    Format::of(out)?;
    if series.is_empty() {
        return Err(ReportError::invalid("violin plot", "no series"));
    }
    for (name, values) in series {
        if let Some(v) = values.iter().find(|v| !v.is_finite()) {
            return Err(ReportError::invalid(
                format!("violin plot, series `{name}`"),
                format!("non-finite value {v}"),
            ));
        }
    }
    crate::canvas::ensure_fonts()?;
    let violins: Vec<Violin> = series
        .iter()
        .map(|(name, v)| Violin::new(name, v))
        .collect();
    let all: Vec<f64> = violins
        .iter()
        .flat_map(|v| [v.lo, v.hi])
        .filter(|x| x.is_finite())
        .collect();
    let (mut y0, mut y1) = all
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
            (a.min(x), b.max(x))
        });
    if !(y0.is_finite() && y1.is_finite()) {
        (y0, y1) = (0.0, 1.0);
    }
    let span = (y1 - y0).max(1e-9);
    let nonneg = series.iter().all(|(_, v)| v.iter().all(|&x| x >= 0.0));
    let y0 = if nonneg {
        (y0 - 0.03 * span).max(0.0)
    } else {
        y0 - 0.03 * span
    };
    let y1 = if span <= 1e-9 {
        y1 + 1.0
    } else {
        y1 + 0.05 * span
    };

    let n = series.len();
    let width = opts
        .width
        .unwrap_or_else(|| ((n as u32).saturating_mul(120).saturating_add(110)).max(640))
        .clamp(200, MAX_SIDE);
    let col_w = (f64::from(width) - 110.0) / n as f64;
    let name_font = font(13.0, FontStyle::Normal);
    let names: Vec<Vec<String>> = series
        .iter()
        .map(|(name, _)| wrap(name, &name_font, col_w - 8.0))
        .collect();
    let name_lines = names.iter().map(Vec::len).max().unwrap_or(1) as u32;
    let x_area = name_lines * 16 + 16;
    let height = opts.height.unwrap_or(520 + x_area).clamp(200, MAX_SIDE);
    let picture = ViolinPlot {
        opts,
        violins,
        names,
        y: (y0, y1),
        size: (width, height),
        x_area,
    };
    render(&picture, out)
}

/// One violin, computed before drawing.
struct Violin {
    values: Vec<f64>,
    /// (y, half width in x units) along the outline; empty without a density.
    outline: Vec<(f64, f64)>,
    quartiles: Option<[f64; 3]>,
    lo: f64,
    hi: f64,
}

const HALF_WIDTH: f64 = 0.4;
/// Largest picture side, pixels: bounds memory whatever the options say.
const MAX_SIDE: u32 = 8000;
const SAMPLES: usize = 160;

impl Violin {
    fn new(_name: &str, values: &[f64]) -> Self {
        let q = quartiles(values);
        let (min, max) = values
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
                (a.min(x), b.max(x))
            });
        let mut outline = Vec::new();
        let (mut lo, mut hi) = (min, max);
        if let Some(h) = silverman_bandwidth(values) {
            lo = min - 2.0 * h;
            hi = max + 2.0 * h;
            if min >= 0.0 {
                lo = lo.max(0.0);
            }
            let dens: Vec<(f64, f64)> = (0..=SAMPLES)
                .map(|i| {
                    let y = lo + (hi - lo) * i as f64 / SAMPLES as f64;
                    (y, gaussian_kde(values, h, y))
                })
                .collect();
            let peak = dens.iter().map(|d| d.1).fold(0.0, f64::max);
            if peak > 0.0 {
                outline = dens
                    .into_iter()
                    .map(|(y, d)| (y, HALF_WIDTH * d / peak))
                    .collect();
            }
        }
        Self {
            values: values.to_vec(),
            outline,
            quartiles: q,
            lo,
            hi,
        }
    }

    /// Half width of the violin at `y`, by linear interpolation along the outline.
    fn half_width_at(&self, y: f64) -> f64 {
        let o = &self.outline;
        if o.len() < 2 {
            return 0.06;
        }
        let pos = o.partition_point(|p| p.0 < y);
        if pos == 0 || pos >= o.len() {
            return o.get(pos.min(o.len() - 1)).map_or(0.0, |p| p.1);
        }
        let (a, b) = (o[pos - 1], o[pos]);
        let t = if b.0 > a.0 {
            (y - a.0) / (b.0 - a.0)
        } else {
            0.0
        };
        a.1 + t * (b.1 - a.1)
    }
}

struct ViolinPlot<'a> {
    opts: &'a ViolinOptions,
    violins: Vec<Violin>,
    names: Vec<Vec<String>>,
    y: (f64, f64),
    size: (u32, u32),
    x_area: u32,
}

impl Picture for ViolinPlot<'_> {
    fn size(&self) -> (u32, u32) {
        self.size
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>, _format: Format) -> Drawn {
        let n = self.violins.len();
        let mut chart = ChartBuilder::on(root)
            .caption(&self.opts.title, font(20.0, FontStyle::Bold))
            .margin(14)
            .x_label_area_size(self.x_area)
            .y_label_area_size(64)
            .build_cartesian_2d(-0.5..(n as f64 - 0.5), self.y.0..self.y.1)?;
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_labels(0)
            .x_label_formatter(&|_| String::new())
            .y_desc(&self.opts.y_label)
            .axis_desc_style(font(14.0, FontStyle::Normal))
            .label_style(font(12.0, FontStyle::Normal))
            .y_label_formatter(&axis_number)
            .light_line_style(TRANSPARENT)
            .bold_line_style(RGBColor(225, 225, 225))
            .draw()?;

        let mut rng = ChaCha8Rng::seed_from_u64(self.opts.seed);
        for (i, v) in self.violins.iter().enumerate() {
            let x = i as f64;
            let color = Rgb::palette(i);
            if v.outline.len() >= 2 {
                let mut shape: Vec<(f64, f64)> =
                    v.outline.iter().map(|&(y, w)| (x - w, y)).collect();
                shape.extend(v.outline.iter().rev().map(|&(y, w)| (x + w, y)));
                chart.draw_series(std::iter::once(Polygon::new(
                    shape.clone(),
                    rgba(color, 0.28).filled(),
                )))?;
                shape.push(shape[0]);
                chart.draw_series(std::iter::once(PathElement::new(
                    shape,
                    rgba(color, 1.0).stroke_width(2),
                )))?;
            } else if let Some(&value) = v.values.first() {
                chart.draw_series(std::iter::once(PathElement::new(
                    vec![(x - 0.25, value), (x + 0.25, value)],
                    rgba(color, 1.0).stroke_width(2),
                )))?;
            }
            if let Some(q) = v.quartiles.filter(|_| v.outline.len() >= 2) {
                for (k, &y) in q.iter().enumerate() {
                    let w = v.half_width_at(y);
                    let stroke = if k == 1 { 2 } else { 1 };
                    chart.draw_series(std::iter::once(DashedPathElement::new(
                        vec![(x - w, y), (x + w, y)],
                        if k == 1 { 5 } else { 2 },
                        3,
                        RGBColor(30, 30, 30).stroke_width(stroke),
                    )))?;
                }
            }
            let dark = Rgb::new(color.r / 2, color.g / 2, color.b / 2);
            for &y in &v.values {
                let w = v.half_width_at(y) * 0.85;
                let jitter: f64 = rng.random_range(-1.0..=1.0);
                chart.draw_series(std::iter::once(Circle::new(
                    (x + jitter * w, y),
                    2,
                    rgba(dark, 0.75).filled(),
                )))?;
            }
        }
        let name_font = font(13.0, FontStyle::Normal);
        let note_font = font(11.0, FontStyle::Normal);
        for (i, lines) in self.names.iter().enumerate() {
            let (cx, cy) = chart.backend_coord(&(i as f64, self.y.0));
            for (k, line) in lines.iter().enumerate() {
                let at = (f64::from(cx), f64::from(cy) + 8.0 + 16.0 * k as f64);
                text(
                    root,
                    line,
                    at,
                    &name_font,
                    pc::TEXT,
                    (HPos::Center, VPos::Top),
                )?;
            }
            let v = &self.violins[i];
            if v.values.is_empty() {
                let (mx, my) = chart.backend_coord(&(i as f64, (self.y.0 + self.y.1) / 2.0));
                text(
                    root,
                    "no data",
                    (f64::from(mx), f64::from(my)),
                    &note_font,
                    pc::TEXT,
                    (HPos::Center, VPos::Center),
                )?;
            }
        }
        // A key for the line styles, top right, inside the margin under the caption.
        let key = "dotted: quartiles (median bold)";
        let (kw, _) = text_size(&note_font, key);
        let (w, _) = self.size;
        text(
            root,
            key,
            (f64::from(w) - kw - 16.0, 40.0),
            &note_font,
            Rgb::new(90, 90, 90),
            (HPos::Left, VPos::Center),
        )?;
        Ok(())
    }
}
