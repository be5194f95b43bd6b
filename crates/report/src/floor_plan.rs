//! Floor plans of a [`House`] and side-by-side trajectory panels (the paper's figure 3).
//!
//! Everything is drawn in pixel coordinates through a [`PlanLayout`] that maps metres to pixels
//! with one scale for both axes (equal aspect), world x to the right and world z upwards, as in a
//! top-down view of a ProcTHOR house.

use std::path::Path;

use ferret_world::geometry::segment_distance;
use ferret_world::{Footprint, House, Point, Pose};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::FontStyle;
use plotters::style::text_anchor::{HPos, VPos};

use crate::canvas::{
    Drawn, Format, Picture, arrow_head, font, nice_step, polyline, px, render, rgba, text,
    text_size, thick_segment, tick_label, wrap,
};
use crate::color::{Rgb, plan_colors as pc, room_tint};
use crate::error::{ReportError, Result};
use crate::labels::{BoxPx, Placer};

/// A path drawn over a floor plan: a trajectory, or the shortest path between two places.
#[derive(Clone, Debug, PartialEq)]
pub struct PlanPath {
    /// Shown in the legend.
    pub label: String,
    /// Line colour.
    pub color: Rgb,
    /// The points walked, metres, in order.
    pub points: Vec<Point>,
}

/// A free/occupied bitmap over the floor, for the occupancy overlay, kept independent of the
/// world crate's grid type. Cell `(i, j)` covers `origin + (i, j)·resolution` to
/// `origin + (i + 1, j + 1)·resolution`, with `i` along x and `j` along z; `free` is row-major
/// (`free[j * width + i]`).
#[derive(Clone, Debug, PartialEq)]
pub struct GridImage {
    /// World position of the corner of cell (0, 0), metres.
    pub origin: Point,
    /// Cell size, metres.
    pub resolution: f64,
    /// Cells along x.
    pub width: usize,
    /// Cells along z.
    pub height: usize,
    /// True for free cells, `width × height` entries.
    pub free: Vec<bool>,
}

impl GridImage {
    /// True when `p` falls in a free cell; points outside the grid are not free.
    pub fn is_free(&self, p: Point) -> bool {
        if !self.resolution.is_finite() || self.resolution <= 0.0 {
            return false;
        }
        let i = ((p.x - self.origin.x) / self.resolution).floor();
        let j = ((p.z - self.origin.z) / self.resolution).floor();
        if !(i >= 0.0 && j >= 0.0 && i < self.width as f64 && j < self.height as f64) {
            return false;
        }
        self.free
            .get(j as usize * self.width + i as usize)
            .copied()
            .unwrap_or(false)
    }
}

/// What to draw on a floor plan besides the house itself.
#[derive(Clone)]
pub struct PlanOptions<'a> {
    /// The title; the house's name when `None`.
    pub title: Option<String>,
    /// Paths drawn over the plan, with a legend entry each.
    pub paths: Vec<PlanPath>,
    /// Occupancy overlay: returns true where the floor is free. Sampled at every pixel (every
    /// few pixels for SVG) inside the rooms; occupied places are shaded. Use
    /// `&|p| grid.is_free(p)` with a [`GridImage`], or any closure over the caller's own grid.
    pub occupancy: Option<&'a dyn Fn(Point) -> bool>,
    /// Scale, pixels per metre. Default: 40, raised (up to 80) so the plan's longer side is at
    /// least 640 px, and lowered so it is at most 1800 px.
    pub px_per_m: Option<f64>,
    /// Name every container (type and short id). Default true.
    pub container_labels: bool,
}

impl Default for PlanOptions<'_> {
    fn default() -> Self {
        Self {
            title: None,
            paths: Vec::new(),
            occupancy: None,
            px_per_m: None,
            container_labels: true,
        }
    }
}

impl std::fmt::Debug for PlanOptions<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PlanOptions")
            .field("title", &self.title)
            .field("paths", &self.paths)
            .field("occupancy", &self.occupancy.map(|_| "<fn>"))
            .field("px_per_m", &self.px_per_m)
            .field("container_labels", &self.container_labels)
            .finish()
    }
}

/// Where a drawn plan put the house: image size and the metres-to-pixels map, so callers (and
/// tests) can find a world point in the picture.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlanLayout {
    /// Picture width, pixels.
    pub width: u32,
    /// Picture height, pixels.
    pub height: u32,
    /// Scale, pixels per metre (the same along both axes).
    pub px_per_m: f64,
    /// Left edge of the plotting area, pixels.
    pub plot_left: f64,
    /// Top edge of the plotting area, pixels.
    pub plot_top: f64,
    /// Width of the plotting area, pixels.
    pub plot_width: f64,
    /// Height of the plotting area, pixels.
    pub plot_height: f64,
    /// World x at the left edge of the plotting area, metres.
    pub min_x: f64,
    /// World z at the top edge of the plotting area, metres.
    pub max_z: f64,
}

impl PlanLayout {
    /// The pixel (fractional, from the top left) where world point `p` is drawn.
    pub fn to_pixel(&self, p: Point) -> (f64, f64) {
        (
            self.plot_left + (p.x - self.min_x) * self.px_per_m,
            self.plot_top + (self.max_z - p.z) * self.px_per_m,
        )
    }

    /// The world point drawn at pixel `(x, y)`.
    pub fn to_world(&self, (x, y): (f64, f64)) -> Point {
        Point::new(
            self.min_x + (x - self.plot_left) / self.px_per_m,
            self.max_z - (y - self.plot_top) / self.px_per_m,
        )
    }

    fn plot_box(&self) -> BoxPx {
        BoxPx {
            x0: self.plot_left,
            y0: self.plot_top,
            x1: self.plot_left + self.plot_width,
            y1: self.plot_top + self.plot_height,
        }
    }

    fn shifted(&self, left: f64, top: f64) -> Self {
        Self {
            plot_left: left,
            plot_top: top,
            ..*self
        }
    }
}

/// One strategy's trial in a trajectory figure.
#[derive(Clone, Debug, PartialEq)]
pub struct TrajectoryPanel {
    /// The strategy's name, e.g. `model/prior`.
    pub title: String,
    /// The trial's cost, metres (shown in the panel title).
    pub cost_m: f64,
    /// The path walked, metres, from the start.
    pub path: Vec<Point>,
    /// Indices into [`House::containers`] of the containers searched, in order.
    pub searched: Vec<usize>,
    /// Indices of the goal containers (those holding the target).
    pub goals: Vec<usize>,
    /// What each goal container holds of a task's targets, index-aligned with `goals`, shown
    /// in its label (`goal: Mug, Apple`); the container's type when empty.
    pub goal_labels: Vec<String>,
    /// Where a task brought what it found, drawn as a diamond; `None` without a destination.
    pub destination: Option<Point>,
    /// Path colour; [`Rgb::palette`] of the panel's index when `None`.
    pub color: Option<Rgb>,
    /// For a team: the paths of the robots after the first (whose path is `path`), each
    /// drawn in a colour of its own ([`Rgb::palette`] of the robot's index, the first robot's
    /// too); empty for one robot.
    pub team_paths: Vec<Vec<Point>>,
    /// For a team: which robot (0 first) searched each container of `searched`, its badge in
    /// that robot's colour; empty for one robot.
    pub searched_by: Vec<usize>,
}

/// Options of a trajectory figure.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TrajectoryOptions {
    /// Figure title; `Trajectories in <house name>` when `None`. Naming the target here helps.
    pub title: Option<String>,
    /// Panels per row; all in one row up to four panels, else three per row, when `None`.
    pub columns: Option<usize>,
    /// Scale, pixels per metre; chosen so a panel's longer side is about 480 px when `None`.
    pub px_per_m: Option<f64>,
}

/// Draws the floor plan of `house` into `out` (`.png` or `.svg`): rooms tinted by type and named,
/// walls, door openings, furniture, containers marked and named, the start pose, metre axes, the
/// optional paths with a legend and the optional occupancy overlay.
///
/// Returns where the house was drawn.
pub fn draw_floor_plan(house: &House, opts: &PlanOptions<'_>, out: &Path) -> Result<PlanLayout> {
    Format::of(out)?;
    check_house(house)?;
    for p in &opts.paths {
        check_points(&format!("path `{}`", p.label), &p.points)?;
    }
    let (min, max) = extent(
        house,
        opts.paths.iter().flat_map(|p| p.points.iter().copied()),
    );
    let (w_m, h_m) = (max.x - min.x, max.z - min.z);
    let s = match opts.px_per_m {
        Some(s) if s.is_finite() && s > 0.0 => s.min(4000.0 / w_m.max(h_m)),
        Some(s) => {
            return Err(ReportError::invalid(
                "floor plan",
                format!("scale {s} px/m is not positive"),
            ));
        }
        None => (640.0 / w_m.max(h_m))
            .clamp(40.0, 80.0)
            .min(1800.0 / w_m.max(h_m)),
    };
    let title = opts.title.clone().unwrap_or_else(|| house.name.clone());
    let plot_w = (w_m * s).ceil();
    let plot_h = (h_m * s).ceil();
    let width = (MARGIN + AXIS_LEFT + plot_w + MARGIN + 8.0).max(360.0);
    let mut legend = plan_legend(opts.occupancy.is_some());
    legend.splice(
        0..0,
        opts.paths
            .iter()
            .map(|p| LegendItem::line(p.color, &p.label)),
    );
    let legend_h = legend_height(&legend, width - 2.0 * MARGIN);
    let height = TITLE_H + plot_h + AXIS_BOTTOM + legend_h + MARGIN;
    let layout = PlanLayout {
        width: width as u32,
        height: height as u32,
        px_per_m: s,
        plot_left: MARGIN + AXIS_LEFT,
        plot_top: TITLE_H,
        plot_width: plot_w,
        plot_height: plot_h,
        min_x: min.x,
        max_z: max.z,
    };
    let picture = FloorPlan {
        house,
        opts,
        layout,
        title,
        legend,
    };
    render(&picture, out)?;
    Ok(layout)
}

/// Draws one floor plan per strategy side by side (the paper's figure 3): each panel shows its
/// path, the containers searched numbered in order, the goal containers in green, and the
/// strategy's name and cost in metres as its title, with the containers searched listed below.
pub fn draw_trajectories(
    house: &House,
    panels: &[TrajectoryPanel],
    opts: &TrajectoryOptions,
    out: &Path,
) -> Result<()> {
    Format::of(out)?;
    check_house(house)?;
    if panels.is_empty() {
        return Err(ReportError::invalid("trajectories", "no panels"));
    }
    for p in panels {
        let what = format!("trajectory panel `{}`", p.title);
        check_points(&what, &p.path)?;
        for path in &p.team_paths {
            check_points(&what, path)?;
        }
        check_points(&what, p.destination.as_slice())?;
        if !p.searched_by.is_empty() && p.searched_by.len() != p.searched.len() {
            return Err(ReportError::invalid(
                what,
                format!(
                    "{} robots named for {} containers searched",
                    p.searched_by.len(),
                    p.searched.len()
                ),
            ));
        }
        if !p.cost_m.is_finite() {
            return Err(ReportError::invalid(
                what,
                format!("cost {} is not finite", p.cost_m),
            ));
        }
        if let Some(&bad) = p
            .searched
            .iter()
            .chain(&p.goals)
            .find(|&&c| c >= house.containers.len())
        {
            return Err(ReportError::invalid(
                what,
                format!(
                    "container index {bad} but the house has {} containers",
                    house.containers.len()
                ),
            ));
        }
    }
    let (min, max) = extent(
        house,
        panels
            .iter()
            .flat_map(|p| p.path.iter().chain(p.team_paths.iter().flatten()).copied()),
    );
    let (w_m, h_m) = (max.x - min.x, max.z - min.z);
    let s = match opts.px_per_m {
        Some(s) if s.is_finite() && s > 0.0 => s.min(2000.0 / w_m.max(h_m)),
        Some(s) => {
            return Err(ReportError::invalid(
                "trajectories",
                format!("scale {s} px/m is not positive"),
            ));
        }
        // About 480 px a side; never more than 900 px, however large the house.
        None => (480.0 / w_m.max(h_m))
            .clamp(12.0, 60.0)
            .min(900.0 / w_m.max(h_m)),
    };
    let cols = opts
        .columns
        .filter(|&c| c > 0)
        .unwrap_or(if panels.len() <= 4 { panels.len() } else { 3 });
    let cols = cols.min(panels.len());
    let rows = panels.len().div_ceil(cols);
    let plot_w = (w_m * s).ceil();
    let plot_h = (h_m * s).ceil();
    let panel_w = plot_w.max(220.0);
    let title_font = font(15.0, FontStyle::Bold);
    let list_font = font(12.0, FontStyle::Normal);
    let titles: Vec<Vec<String>> = panels
        .iter()
        .map(|p| {
            wrap(
                &format!("{} — {:.1} m", p.title, p.cost_m),
                &title_font,
                panel_w,
            )
        })
        .collect();
    let lists: Vec<Vec<String>> = panels
        .iter()
        .map(|p| {
            let items: Vec<String> = p
                .searched
                .iter()
                .enumerate()
                .map(|(i, &c)| format!("{} {}", i + 1, house.containers[c].object_type.words()))
                .collect();
            wrap_items("searched: ", &items, &list_font, panel_w)
        })
        .collect();
    let title_lines = titles.iter().map(Vec::len).max().unwrap_or(1) as f64;
    let list_lines = lists.iter().map(Vec::len).max().unwrap_or(0) as f64;
    let panel_title_h = title_lines * 19.0 + 8.0;
    let panel_list_h = list_lines * 16.0 + 26.0;
    let cell_w = panel_w + PANEL_GAP;
    let cell_h = panel_title_h + plot_h + panel_list_h;
    let width = (2.0 * MARGIN + cols as f64 * cell_w - PANEL_GAP).max(400.0);
    let legend = trajectory_legend(panels.iter().any(|p| p.destination.is_some()));
    let legend_h = legend_height(&legend, width - 2.0 * MARGIN);
    let height = TITLE_H + rows as f64 * cell_h + legend_h + MARGIN;
    let layout = PlanLayout {
        width: width as u32,
        height: height as u32,
        px_per_m: s,
        plot_left: 0.0,
        plot_top: 0.0,
        plot_width: plot_w,
        plot_height: plot_h,
        min_x: min.x,
        max_z: max.z,
    };
    let title = opts
        .title
        .clone()
        .unwrap_or_else(|| format!("Trajectories in {}", house.name));
    let picture = Trajectories {
        house,
        panels,
        layout,
        cols,
        cell: (cell_w, cell_h),
        panel_w,
        panel_title_h,
        titles,
        lists,
        title,
        legend,
    };
    render(&picture, out)
}

const MARGIN: f64 = 12.0;
const TITLE_H: f64 = 44.0;
const AXIS_LEFT: f64 = 46.0;
const AXIS_BOTTOM: f64 = 44.0;
const PANEL_GAP: f64 = 24.0;
/// Opacity of the occupancy overlay: enough to see, light enough to keep room tints readable.
const OVERLAY_ALPHA: f64 = 0.3;
/// Room around the house so walls and labels near its outline are not clipped, metres.
const PAD_M: f64 = 0.45;

fn check_points(what: &str, points: &[Point]) -> Result<()> {
    match points.iter().find(|p| !p.is_finite()) {
        Some(p) => Err(ReportError::invalid(
            what,
            format!("non-finite point ({}, {})", p.x, p.z),
        )),
        None => Ok(()),
    }
}

fn check_footprint(what: &str, f: &Footprint) -> Result<()> {
    if f.center.is_finite() && f.size_x.is_finite() && f.size_z.is_finite() && f.yaw_deg.is_finite()
    {
        Ok(())
    } else {
        Err(ReportError::invalid(what, "non-finite footprint"))
    }
}

fn check_house(house: &House) -> Result<()> {
    let what = format!("house {}", house.name);
    if house.rooms.is_empty() {
        return Err(ReportError::invalid(what, "it has no rooms"));
    }
    for r in &house.rooms {
        check_points(&format!("{what}, room {}", r.id), &r.floor.vertices)?;
    }
    for w in &house.walls {
        check_points(&format!("{what}, wall {}", w.id), &[w.start, w.end])?;
    }
    for d in &house.doors {
        check_points(&format!("{what}, door {}", d.id), &[d.start, d.end])?;
    }
    for c in &house.containers {
        check_footprint(&format!("{what}, container {}", c.id), &c.footprint)?;
        check_points(&format!("{what}, container {}", c.id), &[c.position])?;
    }
    for o in &house.obstacles {
        check_footprint(&format!("{what}, obstacle {}", o.id), &o.footprint)?;
    }
    check_points(&format!("{what}, start"), &[house.start.position])?;
    if !house.start.yaw_deg.is_finite() {
        return Err(ReportError::invalid(what, "non-finite start heading"));
    }
    Ok(())
}

/// The world rectangle to draw: rooms, furniture, start and paths, padded.
fn extent(house: &House, extra: impl Iterator<Item = Point>) -> (Point, Point) {
    let pts = house
        .rooms
        .iter()
        .flat_map(|r| r.floor.vertices.iter().copied())
        .chain(house.walls.iter().flat_map(|w| [w.start, w.end]))
        .chain(house.containers.iter().flat_map(|c| c.footprint.corners()))
        .chain(house.obstacles.iter().flat_map(|o| o.footprint.corners()))
        .chain(std::iter::once(house.start.position))
        .chain(extra);
    let mut min = Point::new(f64::INFINITY, f64::INFINITY);
    let mut max = Point::new(f64::NEG_INFINITY, f64::NEG_INFINITY);
    for p in pts {
        min = Point::new(min.x.min(p.x), min.z.min(p.z));
        max = Point::new(max.x.max(p.x), max.z.max(p.z));
    }
    // At least a metre each way, so a degenerate house still gives a picture.
    let (cx, cz) = ((min.x + max.x) / 2.0, (min.z + max.z) / 2.0);
    let hw = ((max.x - min.x) / 2.0).max(0.5) + PAD_M;
    let hh = ((max.z - min.z) / 2.0).max(0.5) + PAD_M;
    (Point::new(cx - hw, cz - hh), Point::new(cx + hw, cz + hh))
}

/// The capitalised words of a type name: `LivingRoom` → `Living room`.
fn capitalised(words: &str) -> String {
    let mut c = words.chars();
    match c.next() {
        Some(f) => f.to_uppercase().chain(c).collect(),
        None => String::new(),
    }
}

/// A container's id without a leading copy of its type (`Fridge|2|0` → `2|0`; `4|0|0` stays).
fn short_id(id: &str, type_name: &str) -> String {
    match id.split_once('|') {
        Some((head, rest)) if head == type_name => rest.to_string(),
        _ => id.to_string(),
    }
}

/// The name a container is labelled with: type words and short id.
pub(crate) fn container_name(house: &House, i: usize) -> String {
    let c = &house.containers[i];
    let words = c.object_type.words();
    // Scene files name containers in words (`dining_table`): the type alone says it.
    let id_words = c.id.replace(['_', '-'], " ").to_lowercase();
    if id_words == words || id_words == words.replace(' ', "") {
        return words;
    }
    format!("{words} {}", short_id(&c.id, c.object_type.as_str()))
}

fn wrap_items(
    head: &str,
    items: &[String],
    font: &plotters::style::FontDesc<'_>,
    max_width: f64,
) -> Vec<String> {
    if items.is_empty() {
        return Vec::new();
    }
    let mut lines = Vec::new();
    let mut line = head.to_string();
    let mut first = true;
    for item in items {
        let candidate = if first {
            format!("{line}{item}")
        } else {
            format!("{line} · {item}")
        };
        if first || text_size(font, &candidate).0 <= max_width {
            line = candidate;
        } else {
            lines.push(std::mem::replace(&mut line, format!("   {item}")));
        }
        first = false;
    }
    lines.push(line);
    lines
}

// ---- legend -------------------------------------------------------------------------------

#[derive(Clone, Debug)]
enum Swatch {
    Line(Rgb),
    Rect { fill: Rgb, edge: Rgb },
    Door,
    Start,
    Destination,
    Badge(Rgb),
    Shade,
}

#[derive(Clone, Debug)]
struct LegendItem {
    swatch: Swatch,
    label: String,
}

impl LegendItem {
    fn line(c: Rgb, label: &str) -> Self {
        Self {
            swatch: Swatch::Line(c),
            label: label.to_string(),
        }
    }
}

fn plan_legend(occupancy: bool) -> Vec<LegendItem> {
    let mut items = vec![
        LegendItem {
            swatch: Swatch::Rect {
                fill: pc::CONTAINER,
                edge: pc::CONTAINER_EDGE,
            },
            label: "container".into(),
        },
        LegendItem {
            swatch: Swatch::Rect {
                fill: pc::OBSTACLE,
                edge: pc::OBSTACLE_EDGE,
            },
            label: "other furniture".into(),
        },
        LegendItem {
            swatch: Swatch::Door,
            label: "door".into(),
        },
        LegendItem {
            swatch: Swatch::Start,
            label: "start (heading)".into(),
        },
    ];
    if occupancy {
        items.push(LegendItem {
            swatch: Swatch::Shade,
            label: "not free (occupancy grid)".into(),
        });
    }
    items
}

fn trajectory_legend(destination: bool) -> Vec<LegendItem> {
    let mut items = vec![
        LegendItem {
            swatch: Swatch::Badge(Rgb::palette(0)),
            label: "containers searched, in order".into(),
        },
        LegendItem {
            swatch: Swatch::Rect {
                fill: pc::GOAL,
                edge: pc::GOAL_EDGE,
            },
            label: "goal container".into(),
        },
        LegendItem {
            swatch: Swatch::Rect {
                fill: pc::CONTAINER,
                edge: pc::CONTAINER_EDGE,
            },
            label: "container".into(),
        },
        LegendItem {
            swatch: Swatch::Rect {
                fill: pc::OBSTACLE,
                edge: pc::OBSTACLE_EDGE,
            },
            label: "other furniture".into(),
        },
        LegendItem {
            swatch: Swatch::Door,
            label: "door".into(),
        },
        LegendItem {
            swatch: Swatch::Start,
            label: "start".into(),
        },
    ];
    if destination {
        items.push(LegendItem {
            swatch: Swatch::Destination,
            label: "destination".into(),
        });
    }
    items
}

const LEGEND_ROW: f64 = 22.0;
const SWATCH_W: f64 = 26.0;

fn legend_font() -> plotters::style::FontDesc<'static> {
    font(13.0, FontStyle::Normal)
}

/// Positions of legend entries (relative to the legend's top left) and the legend's height.
fn legend_layout(items: &[LegendItem], width: f64) -> (Vec<(f64, f64)>, f64) {
    let f = legend_font();
    let (mut x, mut y) = (0.0, 0.0);
    let mut out = Vec::with_capacity(items.len());
    for it in items {
        let w = SWATCH_W + 6.0 + text_size(&f, &it.label).0 + 20.0;
        if x > 0.0 && x + w > width {
            x = 0.0;
            y += LEGEND_ROW;
        }
        out.push((x, y));
        x += w;
    }
    let h = if items.is_empty() {
        0.0
    } else {
        y + LEGEND_ROW + 6.0
    };
    (out, h)
}

fn legend_height(items: &[LegendItem], width: f64) -> f64 {
    legend_layout(items, width).1
}

fn draw_legend<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    items: &[LegendItem],
    left: f64,
    top: f64,
    width: f64,
) -> Drawn {
    let f = legend_font();
    let (pos, _) = legend_layout(items, width);
    for (it, (x, y)) in items.iter().zip(pos) {
        let (x, y) = (left + x, top + y + LEGEND_ROW / 2.0);
        match it.swatch {
            Swatch::Line(c) => polyline(root, &[(x, y), (x + SWATCH_W, y)], 4.0, rgba(c, 1.0))?,
            Swatch::Rect { fill, edge } => {
                let r = [px((x + 4.0, y - 6.0)), px((x + SWATCH_W - 4.0, y + 6.0))];
                root.draw(&Rectangle::new(r, fill.rgb().filled()))?;
                root.draw(&Rectangle::new(r, edge.rgb().stroke_width(1)))?;
            }
            Swatch::Door => {
                thick_segment(root, (x, y), (x + 6.0, y), 5.0, 0.0, rgba(pc::WALL, 1.0))?;
                thick_segment(
                    root,
                    (x + 6.0, y),
                    (x + SWATCH_W - 6.0, y),
                    7.0,
                    0.0,
                    rgba(pc::DOOR, 1.0),
                )?;
                thick_segment(
                    root,
                    (x + SWATCH_W - 6.0, y),
                    (x + SWATCH_W, y),
                    5.0,
                    0.0,
                    rgba(pc::WALL, 1.0),
                )?;
            }
            Swatch::Start => draw_start_marker(root, (x + 8.0, y), (1.0, 0.0))?,
            Swatch::Destination => draw_destination(root, (x + 10.0, y))?,
            Swatch::Badge(c) => draw_badge(root, (x + SWATCH_W / 2.0, y), "1", c)?,
            Swatch::Shade => {
                let r = [px((x + 4.0, y - 6.0)), px((x + SWATCH_W - 4.0, y + 6.0))];
                root.draw(&Rectangle::new(
                    r,
                    rgba(pc::OCCUPIED, OVERLAY_ALPHA).filled(),
                ))?;
            }
        }
        text(
            root,
            &it.label,
            (x + SWATCH_W + 6.0, y),
            &f,
            pc::TEXT,
            (HPos::Left, VPos::Center),
        )?;
    }
    Ok(())
}

// ---- drawing the house ----------------------------------------------------------------------

fn footprint_px(l: &PlanLayout, f: &Footprint) -> Vec<(f64, f64)> {
    f.corners().iter().map(|&c| l.to_pixel(c)).collect()
}

fn draw_quad<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    pts: &[(f64, f64)],
    fill: Rgb,
    edge: Rgb,
    edge_w: u32,
) -> Drawn {
    let ipts: Vec<(i32, i32)> = pts.iter().copied().map(px).collect();
    root.draw(&Polygon::new(ipts.clone(), fill.rgb().filled()))?;
    let mut closed = ipts;
    if let Some(&first) = closed.first() {
        closed.push(first);
    }
    root.draw(&PathElement::new(closed, edge.rgb().stroke_width(edge_w)))?;
    Ok(())
}

/// Rooms, occupancy overlay, furniture, containers, walls and doors.
fn draw_house<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    house: &House,
    l: &PlanLayout,
    occupancy: Option<&dyn Fn(Point) -> bool>,
    format: Format,
) -> Drawn {
    for r in &house.rooms {
        let pts: Vec<(i32, i32)> = r
            .floor
            .vertices
            .iter()
            .map(|&v| px(l.to_pixel(v)))
            .collect();
        root.draw(&Polygon::new(
            pts,
            room_tint(r.room_type.as_str()).rgb().filled(),
        ))?;
    }
    if let Some(free) = occupancy {
        draw_occupancy(root, house, l, free, format)?;
    }
    for o in &house.obstacles {
        draw_quad(
            root,
            &footprint_px(l, &o.footprint),
            pc::OBSTACLE,
            pc::OBSTACLE_EDGE,
            1,
        )?;
    }
    for c in &house.containers {
        draw_quad(
            root,
            &footprint_px(l, &c.footprint),
            pc::CONTAINER,
            pc::CONTAINER_EDGE,
            1,
        )?;
    }
    let wall_w = wall_width(l);
    for w in &house.walls {
        thick_segment(
            root,
            l.to_pixel(w.start),
            l.to_pixel(w.end),
            wall_w,
            wall_w / 2.0,
            rgba(pc::WALL, 1.0),
        )?;
    }
    for d in &house.doors {
        let (a, b) = (l.to_pixel(d.start), l.to_pixel(d.end));
        thick_segment(root, a, b, wall_w + 2.0, 0.0, rgba(pc::DOOR, 1.0))?;
    }
    Ok(())
}

fn wall_width(l: &PlanLayout) -> f64 {
    (0.1 * l.px_per_m).clamp(3.0, 8.0)
}

/// Shades the occupied places inside the rooms, merging runs of pixels into rectangles so the
/// SVG stays small.
fn draw_occupancy<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    house: &House,
    l: &PlanLayout,
    free: &dyn Fn(Point) -> bool,
    format: Format,
) -> Drawn {
    let step: i32 = match format {
        Format::Png => 1,
        Format::Svg => 3,
    };
    let color = rgba(pc::OCCUPIED, OVERLAY_ALPHA).filled();
    let (x0, y0) = (l.plot_left as i32, l.plot_top as i32);
    let (x1, y1) = (
        (l.plot_left + l.plot_width) as i32,
        (l.plot_top + l.plot_height) as i32,
    );
    let blocked = |x: i32, y: i32| {
        let p = l.to_world((
            f64::from(x) + f64::from(step) / 2.0,
            f64::from(y) + f64::from(step) / 2.0,
        ));
        house.room_at(p).is_some() && !free(p)
    };
    let mut y = y0;
    while y < y1 {
        let mut x = x0;
        let mut run: Option<i32> = None;
        while x <= x1 {
            let b = x < x1 && blocked(x, y);
            match (b, run) {
                (true, None) => run = Some(x),
                (false, Some(start)) => {
                    root.draw(&Rectangle::new([(start, y), (x, y + step)], color))?;
                    run = None;
                }
                _ => {}
            }
            x += step;
        }
        y += step;
    }
    Ok(())
}

fn draw_start_marker<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    at: (f64, f64),
    dir: (f64, f64),
) -> Drawn {
    let tip = (at.0 + dir.0 * 22.0, at.1 + dir.1 * 22.0);
    let shaft_end = (at.0 + dir.0 * 14.0, at.1 + dir.1 * 14.0);
    thick_segment(root, at, shaft_end, 3.0, 0.0, rgba(pc::START, 1.0))?;
    arrow_head(root, tip, dir, 10.0, rgba(pc::START, 1.0))?;
    root.draw(&Circle::new(px(at), 8, WHITE.filled()))?;
    root.draw(&Circle::new(px(at), 6, pc::START.rgb().filled()))?;
    Ok(())
}

/// Where a task brings what it found: a green diamond with a white rim, the end of the last
/// leg.
fn draw_destination<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, at: (f64, f64)) -> Drawn {
    let diamond = |r: f64| {
        [(0.0, -r), (r, 0.0), (0.0, r), (-r, 0.0)].map(|(dx, dz)| px((at.0 + dx, at.1 + dz)))
    };
    root.draw(&Polygon::new(diamond(11.0).to_vec(), WHITE.filled()))?;
    root.draw(&Polygon::new(
        diamond(8.5).to_vec(),
        pc::DESTINATION.rgb().filled(),
    ))?;
    root.draw(&Circle::new(px(at), 2, WHITE.filled()))?;
    Ok(())
}

/// A goal container: yellow, with a yellow halo so it still shows around a search badge on a
/// small container.
fn draw_goal<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, pts: &[(f64, f64)]) -> Drawn {
    let halo = rgba(pc::GOAL, 1.0);
    for k in 0..pts.len() {
        thick_segment(root, pts[k], pts[(k + 1) % pts.len()], 8.0, 4.0, halo)?;
    }
    draw_quad(root, pts, pc::GOAL, pc::GOAL_EDGE, 1)?;
    let outer = grow_rect(pts, 4.0);
    for k in 0..outer.len() {
        let (a, b) = (outer[k], outer[(k + 1) % outer.len()]);
        thick_segment(root, a, b, 1.5, 0.75, rgba(pc::GOAL_EDGE, 1.0))?;
    }
    Ok(())
}

/// The corners of a rectangle (in order) moved `d` pixels outwards: each corner along its
/// bisector by d·√2.
fn grow_rect(pts: &[(f64, f64)], d: f64) -> Vec<(f64, f64)> {
    let n = pts.len();
    let unit = |v: (f64, f64)| {
        let len = v.0.hypot(v.1).max(1e-9);
        (v.0 / len, v.1 / len)
    };
    (0..n)
        .map(|k| {
            let (p, prev, next) = (pts[k], pts[(k + n - 1) % n], pts[(k + 1) % n]);
            let u1 = unit((p.0 - prev.0, p.1 - prev.1));
            let u2 = unit((p.0 - next.0, p.1 - next.1));
            let b = unit((u1.0 + u2.0, u1.1 + u2.1));
            let r = d * std::f64::consts::SQRT_2;
            (p.0 + b.0 * r, p.1 + b.1 * r)
        })
        .collect()
}

/// Boxes covering the start marker and its heading arrow.
fn start_boxes(house: &House, l: &PlanLayout) -> Vec<BoxPx> {
    let at = l.to_pixel(house.start.position);
    let dir = heading_px(&house.start);
    (0..=4)
        .map(|k| {
            let t = f64::from(k) * 5.5;
            BoxPx::centred((at.0 + dir.0 * t, at.1 + dir.1 * t), (16.0, 16.0))
        })
        .collect()
}

/// Small boxes of side `size` pixels along a path.
fn path_boxes(l: &PlanLayout, points: &[Point], size: f64) -> Vec<BoxPx> {
    let step = (size * 0.8 / l.px_per_m).max(0.02);
    densify(points, step)
        .into_iter()
        .map(|q| BoxPx::centred(l.to_pixel(q), (size, size)))
        .collect()
}

/// Unity's yaw turns clockwise seen from above: 0° faces +z, 90° faces +x. On the picture +z is
/// up, so the heading in pixels is (sin, −cos).
fn heading_px(pose: &Pose) -> (f64, f64) {
    let (s, c) = pose.yaw_deg.to_radians().sin_cos();
    (s, -c)
}

fn draw_badge<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    at: (f64, f64),
    label: &str,
    color: Rgb,
) -> Drawn {
    let f = font(11.5, FontStyle::Bold);
    let r = if label.len() > 1 { 10 } else { 9 };
    root.draw(&Circle::new(px(at), r + 2, WHITE.filled()))?;
    root.draw(&Circle::new(px(at), r, color.rgb().filled()))?;
    text(
        root,
        label,
        (at.0, at.1 + 0.5),
        &f,
        Rgb::new(255, 255, 255),
        (HPos::Center, VPos::Center),
    )
}

/// Draws a path: line, a dot where it starts and an arrow head where it ends.
fn draw_path<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    l: &PlanLayout,
    pts: &[Point],
    color: Rgb,
) -> Drawn {
    let p: Vec<(f64, f64)> = pts.iter().map(|&q| l.to_pixel(q)).collect();
    polyline(root, &p, 3.5, rgba(color, 1.0))?;
    if let (Some(&first), Some(&last)) = (p.first(), p.last()) {
        root.draw(&Circle::new(px(first), 4, color.rgb().filled()))?;
        // The arrow points along the last stretch at least a few pixels long.
        if let Some(&from) = p
            .iter()
            .rev()
            .find(|q| (q.0 - last.0).hypot(q.1 - last.1) > 4.0)
        {
            let dir = (last.0 - from.0, last.1 - from.1);
            arrow_head(root, last, dir, 12.0, rgba(color, 1.0))?;
        }
    }
    Ok(())
}

/// A good place (pixels) for a room's name of pixel size `size`: inside the room, covering as
/// little furniture and as few of the `avoid` boxes (start, paths, badges) as possible, and
/// otherwise as far from the walls as possible.
fn room_label_point(
    house: &House,
    room: usize,
    l: &PlanLayout,
    size: (f64, f64),
    furniture: &[BoxPx],
    avoid: &[BoxPx],
) -> (f64, f64) {
    let r = &house.rooms[room];
    let fallback = l.to_pixel(r.floor.centroid());
    let Some(b) = r.floor.bounds() else {
        return fallback;
    };
    let n = 28;
    let verts = &r.floor.vertices;
    let area = (size.0 * size.1).max(1.0);
    let mut best = (f64::NEG_INFINITY, fallback);
    for i in 0..=n {
        for j in 0..=n {
            let p = Point::new(
                b.min.x + b.width() * (i as f64 + 0.5) / (n as f64 + 1.0),
                b.min.z + b.depth() * (j as f64 + 0.5) / (n as f64 + 1.0),
            );
            if !r.floor.contains(p) {
                continue;
            }
            let c = l.to_pixel(p);
            let rect = BoxPx::centred(c, size);
            let corners = [
                (rect.x0, rect.y0),
                (rect.x1, rect.y0),
                (rect.x0, rect.y1),
                (rect.x1, rect.y1),
            ];
            let outside = corners
                .iter()
                .filter(|&&q| !r.floor.contains(l.to_world(q)))
                .count() as f64;
            let mut clear = f64::INFINITY;
            for k in 0..verts.len() {
                clear = clear.min(segment_distance(verts[k], verts[(k + 1) % verts.len()], p));
            }
            let clear_px = (clear * l.px_per_m).min(80.0) / 80.0;
            let on_furniture: f64 = furniture.iter().map(|f| rect.overlap(f)).sum::<f64>() / area;
            let hits = avoid.iter().filter(|a| rect.overlap(a) > 0.0).count() as f64;
            let score =
                clear_px - 3.0 * on_furniture.min(1.0) - 0.6 * hits.min(5.0) - 2.0 * outside;
            if score > best.0 {
                best = (score, c);
            }
        }
    }
    best.1
}

/// The points of a polyline with extra points so that none is more than `step` metres from the
/// next.
fn densify(points: &[Point], step: f64) -> Vec<Point> {
    let mut out = Vec::with_capacity(points.len());
    for w in points.windows(2) {
        let n = (w[0].distance(w[1]) / step).ceil().clamp(1.0, 10_000.0) as usize;
        for k in 0..n {
            let t = k as f64 / n as f64;
            out.push(Point::new(
                w[0].x + t * (w[1].x - w[0].x),
                w[0].z + t * (w[1].z - w[0].z),
            ));
        }
    }
    out.extend(points.last().copied());
    out
}

/// A text label on a translucent white box so it stays readable over walls and paths.
fn boxed_text<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    rect: BoxPx,
    label: &str,
    f: &plotters::style::FontDesc<'_>,
    color: Rgb,
    bg_alpha: f64,
) -> Drawn {
    root.draw(&Rectangle::new(
        [px((rect.x0, rect.y0)), px((rect.x1, rect.y1))],
        WHITE.mix(bg_alpha).filled(),
    ))?;
    text(
        root,
        label,
        rect.center(),
        f,
        color,
        (HPos::Center, VPos::Center),
    )
}

fn padded_size(f: &plotters::style::FontDesc<'_>, label: &str) -> (f64, f64) {
    let (w, h) = text_size(f, label);
    (w + 6.0, h + 4.0)
}

/// Places and draws the room names; returns their boxes.
fn draw_room_labels<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    house: &House,
    l: &PlanLayout,
    placer: &mut Placer,
    size: f64,
    avoid: &[BoxPx],
) -> Drawn {
    let furniture: Vec<BoxPx> = house
        .containers
        .iter()
        .map(|c| &c.footprint)
        .chain(house.obstacles.iter().map(|o| &o.footprint))
        .map(|f| BoxPx::around(footprint_px(l, f)))
        .collect();
    for (i, r) in house.rooms.iter().enumerate() {
        let label = capitalised(&r.room_type.words());
        // Shrink the name to fit narrow rooms, down to a legible minimum.
        let room_w = r.floor.bounds().map_or(0.0, |b| b.width() * l.px_per_m);
        let mut f = font(size, FontStyle::Bold);
        while text_size(&f, &label).0 > room_w * 0.9 && f.get_size() > 10.0 {
            f = font(f.get_size() - 1.0, FontStyle::Bold);
        }
        let at = room_label_point(house, i, l, padded_size(&f, &label), &furniture, avoid);
        let rect = BoxPx::centred(at, padded_size(&f, &label));
        placer.reserve(rect);
        text(
            root,
            &label,
            at,
            &f,
            pc::ROOM_TEXT,
            (HPos::Center, VPos::Center),
        )?;
    }
    Ok(())
}

/// Places and draws labels for the given containers (`(index, text, colour)`), with leader lines
/// when a label had to move away.
fn draw_container_labels<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    house: &House,
    l: &PlanLayout,
    placer: &mut Placer,
    labels: &[(usize, String, Rgb)],
    size: f64,
) -> Drawn {
    let f = font(size, FontStyle::Normal);
    for (i, label, color) in labels {
        let anchor = BoxPx::around(footprint_px(l, &house.containers[*i].footprint));
        let placed = placer.place(anchor, padded_size(&f, label));
        if placed.leader {
            // From the container's outline to the label's, with a dot on the container.
            let (c, a) = (placed.rect.center(), anchor.center());
            let at_label = clip_to_box(a, c, &placed.rect);
            let at_container = clip_to_box(c, a, &anchor);
            root.draw(&PathElement::new(
                vec![px(at_container), px(at_label)],
                rgba(pc::TEXT, 0.85).stroke_width(1),
            ))?;
            root.draw(&Circle::new(px(at_container), 2, pc::TEXT.rgb().filled()))?;
        }
        boxed_text(root, placed.rect, label, &f, *color, 0.78)?;
    }
    Ok(())
}

/// The point where the segment from `from` to the centre of `b` enters `b`.
fn clip_to_box(from: (f64, f64), to: (f64, f64), b: &BoxPx) -> (f64, f64) {
    let mut t_lo = 0.0_f64;
    let (dx, dy) = (to.0 - from.0, to.1 - from.1);
    for (p, d, lo, hi) in [(from.0, dx, b.x0, b.x1), (from.1, dy, b.y0, b.y1)] {
        if d.abs() > 1e-9 {
            let (t0, t1) = ((lo - p) / d, (hi - p) / d);
            t_lo = t_lo.max(t0.min(t1));
        }
    }
    let t = t_lo.clamp(0.0, 1.0);
    (from.0 + t * dx, from.1 + t * dy)
}

/// Metre ticks and labels around the plotting area.
fn draw_axes<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, l: &PlanLayout) -> Drawn {
    let grey = RGBColor(110, 110, 110);
    let b = l.plot_box();
    root.draw(&Rectangle::new(
        [px((b.x0, b.y0)), px((b.x1, b.y1))],
        grey.stroke_width(1),
    ))?;
    let f = font(12.0, FontStyle::Normal);
    let max_x = l.min_x + l.plot_width / l.px_per_m;
    let min_z = l.max_z - l.plot_height / l.px_per_m;
    let step = nice_step(
        (max_x - l.min_x).max(l.max_z - min_z),
        (l.plot_width.max(l.plot_height) / 70.0).max(2.0),
    );
    let mut t = (l.min_x / step).ceil() * step;
    while t <= max_x + 1e-9 {
        let x = l.to_pixel(Point::new(t, 0.0)).0;
        root.draw(&PathElement::new(
            vec![px((x, b.y1)), px((x, b.y1 + 5.0))],
            grey.stroke_width(1),
        ))?;
        text(
            root,
            &tick_label(t, step),
            (x, b.y1 + 8.0),
            &f,
            pc::TEXT,
            (HPos::Center, VPos::Top),
        )?;
        t += step;
    }
    let mut t = (min_z / step).ceil() * step;
    while t <= l.max_z + 1e-9 {
        let y = l.to_pixel(Point::new(0.0, t)).1;
        root.draw(&PathElement::new(
            vec![px((b.x0 - 5.0, y)), px((b.x0, y))],
            grey.stroke_width(1),
        ))?;
        text(
            root,
            &tick_label(t, step),
            (b.x0 - 8.0, y),
            &f,
            pc::TEXT,
            (HPos::Right, VPos::Center),
        )?;
        t += step;
    }
    let af = font(13.0, FontStyle::Normal);
    text(
        root,
        "x (m)",
        ((b.x0 + b.x1) / 2.0, b.y1 + 26.0),
        &af,
        pc::TEXT,
        (HPos::Center, VPos::Top),
    )?;
    let rotated = af.transform(FontTransform::Rotate270);
    text(
        root,
        "z (m)",
        (b.x0 - 40.0, (b.y0 + b.y1) / 2.0),
        &rotated,
        pc::TEXT,
        (HPos::Center, VPos::Center),
    )?;
    Ok(())
}

/// A scale bar of a round length in the bottom left corner of a panel.
fn draw_scale_bar<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, l: &PlanLayout) -> Drawn {
    let len_m = nice_step(l.plot_width / l.px_per_m, 5.0);
    let len_px = len_m * l.px_per_m;
    let (x, y) = (l.plot_left + 4.0, l.plot_top + l.plot_height + 12.0);
    let c = rgba(pc::TEXT, 1.0);
    thick_segment(root, (x, y), (x + len_px, y), 3.0, 0.0, c)?;
    thick_segment(root, (x, y - 4.0), (x, y + 4.0), 2.0, 0.0, c)?;
    thick_segment(
        root,
        (x + len_px, y - 4.0),
        (x + len_px, y + 4.0),
        2.0,
        0.0,
        c,
    )?;
    let label = format!("{} m", tick_label(len_m, len_m));
    text(
        root,
        &label,
        (x + len_px + 6.0, y),
        &font(12.0, FontStyle::Normal),
        pc::TEXT,
        (HPos::Left, VPos::Center),
    )
}

/// What labels had better not cover: furniture, and walls (axis-aligned ones; the box of a
/// slanted wall would cover too much floor).
fn furniture_boxes(house: &House, l: &PlanLayout) -> Vec<BoxPx> {
    let ww = wall_width(l) / 2.0;
    let walls = house.walls.iter().filter_map(|w| {
        let (a, b) = (l.to_pixel(w.start), l.to_pixel(w.end));
        let straight = (a.0 - b.0).abs() < 1.0 || (a.1 - b.1).abs() < 1.0;
        straight.then(|| BoxPx::around([a, b]).grown(ww))
    });
    house
        .containers
        .iter()
        .map(|c| &c.footprint)
        .chain(house.obstacles.iter().map(|o| &o.footprint))
        .map(|f| BoxPx::around(footprint_px(l, f)))
        .chain(walls)
        .collect()
}

fn draw_title<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, title: &str, width: f64) -> Drawn {
    let mut f = font(19.0, FontStyle::Bold);
    while text_size(&f, title).0 > width - 2.0 * MARGIN && f.get_size() > 11.0 {
        f = font(f.get_size() - 1.0, FontStyle::Bold);
    }
    text(
        root,
        title,
        (width / 2.0, TITLE_H / 2.0),
        &f,
        pc::TEXT,
        (HPos::Center, VPos::Center),
    )
}

struct FloorPlan<'a> {
    house: &'a House,
    opts: &'a PlanOptions<'a>,
    layout: PlanLayout,
    title: String,
    legend: Vec<LegendItem>,
}

impl Picture for FloorPlan<'_> {
    fn size(&self) -> (u32, u32) {
        (self.layout.width, self.layout.height)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>, format: Format) -> Drawn {
        let (house, l) = (self.house, &self.layout);
        draw_house(root, house, l, self.opts.occupancy, format)?;
        for p in &self.opts.paths {
            draw_path(root, l, &p.points, p.color)?;
        }
        let start = l.to_pixel(house.start.position);
        draw_start_marker(root, start, heading_px(&house.start))?;

        let mut soft = furniture_boxes(house, l);
        soft.extend(start_boxes(house, l));
        // Labels may cross a path but had better not sit along it.
        for p in &self.opts.paths {
            soft.extend(path_boxes(l, &p.points, 5.0));
        }
        let bounds = l.plot_box().grown(-2.0);
        let mut placer = Placer::new(bounds, soft);
        for b in start_boxes(house, l) {
            placer.reserve(b);
        }
        let mut avoid = start_boxes(house, l);
        for p in &self.opts.paths {
            avoid.extend(path_boxes(l, &p.points, 8.0));
        }
        draw_room_labels(root, house, l, &mut placer, 16.0, &avoid)?;
        if self.opts.container_labels {
            let labels: Vec<(usize, String, Rgb)> = (0..house.containers.len())
                .map(|i| (i, container_name(house, i), pc::TEXT))
                .collect();
            draw_container_labels(root, house, l, &mut placer, &labels, 11.0)?;
        }
        draw_axes(root, l)?;
        draw_title(root, &self.title, f64::from(l.width))?;
        let legend_top = l.plot_top + l.plot_height + AXIS_BOTTOM;
        draw_legend(
            root,
            &self.legend,
            MARGIN,
            legend_top,
            f64::from(l.width) - 2.0 * MARGIN,
        )
    }
}

struct Trajectories<'a> {
    house: &'a House,
    panels: &'a [TrajectoryPanel],
    layout: PlanLayout,
    cols: usize,
    cell: (f64, f64),
    panel_w: f64,
    panel_title_h: f64,
    titles: Vec<Vec<String>>,
    lists: Vec<Vec<String>>,
    title: String,
    legend: Vec<LegendItem>,
}

impl Picture for Trajectories<'_> {
    fn size(&self) -> (u32, u32) {
        (self.layout.width, self.layout.height)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>, format: Format) -> Drawn {
        let house = self.house;
        let width = f64::from(self.layout.width);
        draw_title(root, &self.title, width)?;
        let title_font = font(15.0, FontStyle::Bold);
        let list_font = font(12.0, FontStyle::Normal);
        for (k, panel) in self.panels.iter().enumerate() {
            let color = panel.color.unwrap_or_else(|| Rgb::palette(k));
            let (row, col) = (k / self.cols, k % self.cols);
            let cell_left = MARGIN + col as f64 * self.cell.0;
            let cell_top = TITLE_H + row as f64 * self.cell.1;
            let plot_left = cell_left + (self.panel_w - self.layout.plot_width) / 2.0;
            let l = self
                .layout
                .shifted(plot_left, cell_top + self.panel_title_h);
            for (i, line) in self.titles[k].iter().enumerate() {
                let at = (
                    cell_left + self.panel_w / 2.0,
                    cell_top + 9.0 + 19.0 * i as f64,
                );
                text(
                    root,
                    line,
                    at,
                    &title_font,
                    pc::TEXT,
                    (HPos::Center, VPos::Center),
                )?;
            }
            draw_house(root, house, &l, None, format)?;
            for &g in &panel.goals {
                draw_goal(root, &footprint_px(&l, &house.containers[g].footprint))?;
            }
            let b = l.plot_box();
            root.draw(&Rectangle::new(
                [px((b.x0, b.y0)), px((b.x1, b.y1))],
                RGBColor(150, 150, 150).stroke_width(1),
            ))?;
            let team = !panel.team_paths.is_empty() || !panel.searched_by.is_empty();
            let robot_color = |r: usize| if team { Rgb::palette(r) } else { color };
            draw_path(root, &l, &panel.path, robot_color(0))?;
            for (r, path) in panel.team_paths.iter().enumerate() {
                draw_path(root, &l, path, robot_color(r + 1))?;
            }
            let start = l.to_pixel(house.start.position);
            draw_start_marker(root, start, heading_px(&house.start))?;
            let destination = panel.destination.map(|d| l.to_pixel(d));
            if let Some(at) = destination {
                draw_destination(root, at)?;
            }

            let mut soft = furniture_boxes(house, &l);
            soft.extend(path_boxes(&l, &panel.path, 5.0));
            for path in &panel.team_paths {
                soft.extend(path_boxes(&l, path, 5.0));
            }
            soft.extend(start_boxes(house, &l));
            let mut placer = Placer::new(b.grown(-2.0), soft);
            for b in start_boxes(house, &l) {
                placer.reserve(b);
            }
            if let Some(at) = destination {
                placer.reserve(BoxPx::centred(at, (24.0, 24.0)));
            }
            // Badges first: they sit on their containers and labels must not hide them.
            let mut badges = Vec::new();
            for (n, &c) in panel.searched.iter().enumerate() {
                let at = BoxPx::around(footprint_px(&l, &house.containers[c].footprint)).center();
                placer.reserve(BoxPx::centred(at, (22.0, 22.0)));
                badges.push((at, n + 1, panel.searched_by.get(n).copied().unwrap_or(0)));
            }
            let mut avoid = start_boxes(house, &l);
            avoid.extend(path_boxes(&l, &panel.path, 8.0));
            avoid.extend(
                badges
                    .iter()
                    .map(|&(at, _, _)| BoxPx::centred(at, (24.0, 24.0))),
            );
            draw_room_labels(root, house, &l, &mut placer, 13.0, &avoid)?;
            let goal_labels: Vec<(usize, String, Rgb)> = panel
                .goals
                .iter()
                .enumerate()
                .map(|(i, &g)| {
                    let holds = match panel.goal_labels.get(i) {
                        Some(l) if !l.is_empty() => l.clone(),
                        _ => house.containers[g].object_type.words(),
                    };
                    (g, format!("goal: {holds}"), pc::GOAL_EDGE)
                })
                .collect();
            draw_container_labels(root, house, &l, &mut placer, &goal_labels, 11.5)?;
            for (at, n, r) in badges {
                draw_badge(root, at, &n.to_string(), robot_color(r))?;
            }
            draw_scale_bar(root, &l)?;
            for (i, line) in self.lists[k].iter().enumerate() {
                // Continuation lines are indented by position, not spaces: SVG collapses those.
                let indent = if line.starts_with(' ') { 14.0 } else { 0.0 };
                let at = (cell_left + indent, b.y1 + 30.0 + 16.0 * i as f64);
                text(
                    root,
                    line.trim_start(),
                    at,
                    &list_font,
                    pc::TEXT,
                    (HPos::Left, VPos::Center),
                )?;
            }
        }
        let rows = self.panels.len().div_ceil(self.cols);
        let legend_top = TITLE_H + rows as f64 * self.cell.1;
        draw_legend(root, &self.legend, MARGIN, legend_top, width - 2.0 * MARGIN)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn short_ids_drop_a_repeated_type() {
        assert_eq!(short_id("Fridge|2|0", "Fridge"), "2|0");
        assert_eq!(short_id("4|0|0", "Fridge"), "4|0|0");
        assert_eq!(capitalised("living room"), "Living room");
    }

    #[test]
    fn grid_image_lookup() {
        let g = GridImage {
            origin: Point::new(1.0, 2.0),
            resolution: 0.5,
            width: 2,
            height: 2,
            free: vec![true, false, false, true],
        };
        assert!(g.is_free(Point::new(1.1, 2.1)));
        assert!(!g.is_free(Point::new(1.6, 2.1)));
        assert!(!g.is_free(Point::new(1.1, 2.6)));
        assert!(g.is_free(Point::new(1.6, 2.6)));
        assert!(!g.is_free(Point::new(0.9, 2.1)));
        assert!(!g.is_free(Point::new(1.1, 3.1)));
    }

    #[test]
    fn layout_round_trips() {
        let l = PlanLayout {
            width: 100,
            height: 100,
            px_per_m: 40.0,
            plot_left: 10.0,
            plot_top: 20.0,
            plot_width: 80.0,
            plot_height: 60.0,
            min_x: -1.0,
            max_z: 3.0,
        };
        let p = Point::new(0.5, 1.25);
        let q = l.to_world(l.to_pixel(p));
        assert!((p.x - q.x).abs() < 1e-12 && (p.z - q.z).abs() < 1e-12);
        // z grows upwards on the picture.
        assert!(l.to_pixel(Point::new(0.0, 2.0)).1 < l.to_pixel(Point::new(0.0, 1.0)).1);
    }
}
