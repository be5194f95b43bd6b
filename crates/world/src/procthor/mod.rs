//! Reading ProcTHOR houses (`.json`, `.jsonl`, `.jsonl.gz`) into [`Scene`](crate::Scene)s.
//!
//! ```no_run
//! use std::path::Path;
//! use ferret_world::procthor::{load_scenes, AssetDatabase, HouseRange, LoadOptions};
//!
//! let db = AssetDatabase::load(Path::new("databases/asset-database.json"))?;
//! let opts = LoadOptions {
//!     asset_db: Some(&db),
//!     range: "0..150".parse().expect("a valid range"),
//!     skip_invalid: true,
//!     ..Default::default()
//! };
//! let report = load_scenes(Path::new("multiroom-val150.jsonl.gz"), &opts)?;
//! for scene in &report.scenes {
//!     println!("{}: {} containers", scene.house.name, scene.house.containers.len());
//! }
//! # Ok::<(), ferret_world::WorldError>(())
//! ```

mod assets;
mod range;
mod reader;
pub mod schema;
pub mod types;

pub use assets::AssetDatabase;
pub use range::{HouseRange, ParseRangeError};
pub use reader::{
    HouseItem, HouseReader, IGNORED_TYPES, LoadOptions, LoadReport, MAX_CONTAINERS, MAX_COORDINATE,
    MAX_LINE_BYTES, ROOM_TOLERANCE, START_TOLERANCE, is_ignored_type, load_scenes, parse_house,
    parse_house_with, scene_from_raw, scene_from_raw_with,
};
