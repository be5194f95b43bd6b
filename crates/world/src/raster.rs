//! Bounds shared by every raster ferret handles, the occupancy maps it reads and the planning
//! grids it builds, so that a map it accepts is one it can plan on.

/// Largest number of cells in a grid (16.7 M, e.g. 200 m × 200 m at 0.05 m; 2 bytes per cell):
/// protects against absurd coordinates in bad input and absurdly fine resolutions.
pub const MAX_CELLS: u64 = 1 << 24;

/// Smallest resolution accepted, metres: finer grids of whole houses do not fit in memory.
pub const MIN_RESOLUTION: f64 = 0.005;
