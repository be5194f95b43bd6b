//! # ferret-report
//!
//! Every picture ferret draws, from plain data, as PNG or SVG chosen by the output file's
//! extension:
//!
//! - [`draw_floor_plan`]: a [`House`](ferret_world::House) as a person wants to see it — rooms
//!   tinted by type and named, walls, door openings, furniture, containers named, the start pose,
//!   metre axes — optionally with paths ([`PlanPath`]) and an occupancy overlay.
//! - [`draw_trajectories`]: one plan per strategy side by side, with its path, the containers it
//!   searched numbered in order, the goal containers and its cost (the paper's figure 3).
//! - [`draw_violins`]: cost distributions per strategy (the paper's appendix E).
//! - [`draw_curves`], [`draw_curve_panels`]: lines against trials k (the paper's figure 4), and
//!   [`draw_choice_shares`]: how often each strategy is chosen as k grows.
//!
//! Text uses DejaVu Sans embedded in the binary (the `dejavu` crate) through plotters'
//! `ab_glyph` feature; no system font library is involved. In SVG files text stays text and is
//! shown in the viewer's sans-serif font.
//!
//! ```no_run
//! use ferret_report::{ViolinOptions, draw_violins};
//! let series = vec![("optimistic+greedy".to_string(), vec![12.0, 30.5, 18.2])];
//! draw_violins(&series, &ViolinOptions::default(), std::path::Path::new("costs.svg"))?;
//! # Ok::<(), ferret_report::ReportError>(())
//! ```

mod canvas;
mod color;
mod curves;
mod error;
mod floor_plan;
mod glyphs;
mod labels;
mod stats;
mod violin;

pub use canvas::Format;
pub use color::{PALETTE, Rgb, plan_colors, room_tint};
pub use curves::{CurvePanel, draw_choice_shares, draw_curve_panels, draw_curves};
pub use error::{ReportError, Result};
pub use floor_plan::{
    GridImage, PlanLayout, PlanOptions, PlanPath, TrajectoryOptions, TrajectoryPanel,
    draw_floor_plan, draw_trajectories,
};
pub use stats::{gaussian_kde, quartiles, silverman_bandwidth};
pub use violin::{ViolinOptions, draw_violins};
