//! Occupancy maps as a real robot builds them: the YAML + image pair that ROS's `map_saver`
//! writes and `map_server` reads (`image`, `resolution`, `origin`, `negate`, `occupied_thresh`,
//! `free_thresh`; PGM or PNG). A scene with such a map is navigated on the map's own cells
//! instead of on walls drawn from room polygons.
//!
//! Coordinates: the map's x is ferret's x and the map's y is ferret's z, so a scene written in the
//! robot's map frame keeps its numbers.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::{Result, WorldError};
use crate::geometry::Point;

/// What a map pixel says about the floor under it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[repr(u8)]
pub enum MapCell {
    /// Never observed.
    Unknown = 0,
    /// Free floor.
    Free = 1,
    /// Occupied: a wall or furniture.
    Occupied = 2,
}

/// A metric occupancy map: square cells `resolution` metres wide, row 0 at the bottom (lowest
/// z), as ferret's grid stores them (the image's first row is the map's top).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct OccupancyMap {
    /// Where the map came from, for messages.
    pub source: String,
    /// Cell size, metres.
    pub resolution: f64,
    /// World position of the lower-left corner of cell (0, 0).
    pub origin: Point,
    /// Cells per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// `width × height` cells, row-major from the bottom row.
    pub cells: Vec<MapCell>,
}

/// The largest map accepted, in pixels (the same bound as ferret's own grids).
pub const MAX_MAP_PIXELS: u64 = crate::raster::MAX_CELLS;

/// The largest `map_server` YAML file read, bytes (they hold six fields).
pub const MAX_MAP_YAML_BYTES: u64 = 1 << 20;

/// The fields of a `map_server` YAML file.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RosMapYaml {
    image: PathBuf,
    resolution: f64,
    origin: [f64; 3],
    #[serde(default)]
    negate: u8,
    #[serde(default = "default_occupied")]
    occupied_thresh: f64,
    #[serde(default = "default_free")]
    free_thresh: f64,
    /// `trinary` (the default), `scale` or `raw`; only how a pixel becomes free/occupied/unknown
    /// matters here, and `scale`/`raw` maps are read with the same thresholds.
    #[serde(default)]
    mode: Option<String>,
}

fn default_occupied() -> f64 {
    0.65
}

fn default_free() -> f64 {
    0.196
}

impl OccupancyMap {
    /// Reads a `map_server` YAML file and the image it names (relative to the YAML's folder).
    ///
    /// A pixel's occupancy is `p = (255 − v) / 255` (or `v / 255` with `negate: 1`), averaged over
    /// colour channels; `p > occupied_thresh` is occupied, `p < free_thresh` free, else unknown;
    /// a fully transparent PNG pixel is unknown. The map's rotation (origin yaw) must be 0, as
    /// `map_server` itself requires.
    ///
    /// # Errors
    /// [`WorldError::Map`] naming the file and field for unreadable files, bad fields, an
    /// unreadable or oversized image.
    pub fn load_ros(yaml: &Path) -> Result<OccupancyMap> {
        let text =
            crate::input::read_text(yaml, MAX_MAP_YAML_BYTES).map_err(|source| WorldError::Io {
                file: yaml.to_path_buf(),
                source,
            })?;
        let err = |field: &str, message: String| WorldError::Map {
            file: yaml.to_path_buf(),
            field: field.to_string(),
            message,
        };
        crate::input::check_yaml(&text).map_err(|m| err("", m))?;
        let de = serde_yaml_ng::Deserializer::from_str(&text);
        // The file is named by a scene, not by the user: it may be anything (a `.env`, a key), so
        // no value read from it is repeated in the error.
        let meta: RosMapYaml = serde_path_to_error::deserialize(de).map_err(|e| {
            let message = crate::input::without_values(&e.inner().to_string());
            let field = if message.starts_with("unknown field") || e.path().to_string() == "." {
                String::new()
            } else {
                e.path().to_string()
            };
            err(&field, message)
        })?;
        if !(meta.resolution.is_finite() && meta.resolution > 0.0) {
            return Err(err(
                "resolution",
                format!("{} is not a positive number of metres", meta.resolution),
            ));
        }
        if meta.resolution < crate::raster::MIN_RESOLUTION {
            return Err(err(
                "resolution",
                format!(
                    "{} m is finer than the finest grid ferret builds ({} m)",
                    meta.resolution,
                    crate::raster::MIN_RESOLUTION
                ),
            ));
        }
        if meta.origin.iter().any(|v| !v.is_finite()) {
            return Err(err(
                "origin",
                "must be three finite numbers [x, y, yaw]".into(),
            ));
        }
        if meta.origin[2].abs() > 1e-9 {
            return Err(err(
                "origin",
                "a rotated map (yaw ≠ 0) is not supported, as in map_server".into(),
            ));
        }
        if meta.negate > 1 {
            return Err(err("negate", format!("{} is neither 0 nor 1", meta.negate)));
        }
        let (occ, free) = (meta.occupied_thresh, meta.free_thresh);
        if !((0.0..=1.0).contains(&occ) && (0.0..=1.0).contains(&free) && free < occ) {
            return Err(err(
                "occupied_thresh",
                format!(
                    "thresholds must satisfy 0 ≤ free_thresh ({free}) < occupied_thresh ({occ}) ≤ 1"
                ),
            ));
        }
        if let Some(mode) = &meta.mode
            && !matches!(mode.as_str(), "trinary" | "scale" | "raw")
        {
            return Err(err(
                "mode",
                format!("{mode:?} is not trinary, scale or raw"),
            ));
        }
        let image_path = if meta.image.is_absolute() {
            meta.image.clone()
        } else {
            yaml.parent().unwrap_or(Path::new(".")).join(&meta.image)
        };
        let image_err = |message: String| WorldError::Map {
            file: image_path.clone(),
            field: "image".into(),
            message,
        };
        let bytes = crate::input::read_file(&image_path, crate::input::MAX_INPUT_BYTES).map_err(
            |source| WorldError::Io {
                file: image_path.clone(),
                source,
            },
        )?;
        let reader = || {
            image::io::Reader::new(std::io::Cursor::new(&bytes[..]))
                .with_guessed_format()
                .map_err(|e| image_err(e.to_string()))
        };
        let (w, h) = reader()?
            .into_dimensions()
            .map_err(|e| image_err(e.to_string()))?;
        if u64::from(w) * u64::from(h) > MAX_MAP_PIXELS || w == 0 || h == 0 {
            return Err(image_err(format!(
                "{w}×{h} pixels: a map must have between 1 and {MAX_MAP_PIXELS} pixels"
            )));
        }
        let img = reader()?
            .decode()
            .map_err(|e| image_err(e.to_string()))?
            .into_luma_alpha8();
        let mut cells = vec![MapCell::Unknown; w as usize * h as usize];
        for (x, y, px) in img.enumerate_pixels() {
            let [v, alpha] = px.0;
            let cell = if alpha == 0 {
                MapCell::Unknown
            } else {
                let v = f64::from(v) / 255.0;
                let p = if meta.negate == 1 { v } else { 1.0 - v };
                if p > occ {
                    MapCell::Occupied
                } else if p < free {
                    MapCell::Free
                } else {
                    MapCell::Unknown
                }
            };
            // Image row 0 is the top of the map.
            let row = (h - 1 - y) as usize;
            cells[row * w as usize + x as usize] = cell;
        }
        Ok(OccupancyMap {
            source: yaml.display().to_string(),
            resolution: meta.resolution,
            origin: Point::new(meta.origin[0], meta.origin[1]),
            width: w,
            height: h,
            cells,
        })
    }

    /// The cell under world point `p`, if it is on the map.
    pub fn cell_at(&self, p: Point) -> Option<MapCell> {
        let x = ((p.x - self.origin.x) / self.resolution).floor();
        let z = ((p.z - self.origin.z) / self.resolution).floor();
        (x >= 0.0 && z >= 0.0 && x < f64::from(self.width) && z < f64::from(self.height))
            .then(|| self.cells[z as usize * self.width as usize + x as usize])
    }

    /// Upper corner of the map, metres.
    pub fn max(&self) -> Point {
        Point::new(
            self.origin.x + f64::from(self.width) * self.resolution,
            self.origin.z + f64::from(self.height) * self.resolution,
        )
    }

    /// Checks the cell vector matches the stated size (maps can arrive deserialized).
    pub(crate) fn is_consistent(&self) -> bool {
        self.cells.len() == self.width as usize * self.height as usize
            && self.resolution.is_finite()
            && self.resolution > 0.0
            && self.origin.is_finite()
    }
}
