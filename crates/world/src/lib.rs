//! # ferret-world
//!
//! Everything ferret knows about a house before it searches: rooms, walls, doors, furniture and
//! containers ([`House`]), kept apart from what the containers really hold ([`GroundTruth`]) so
//! that planning code cannot peek. This crate reads ProcTHOR houses ([`procthor`]), generates
//! houses of its own in the same schema ([`generate`], the embedded default), turns a house into
//! an occupancy grid ([`grid`]) and computes shortest-path travel distances between the robot's
//! start and every container ([`distance`]). It knows nothing of planning, LLMs or selection.

pub mod distance;
pub mod error;
pub mod generate;
pub mod geometry;
pub mod grid;
pub mod house;
pub mod input;
pub mod map;
pub mod procthor;
pub mod raster;
pub mod rules;
pub mod scene;
pub mod soft;
pub mod target_name;

pub use distance::{Distances, Place, Spot};
pub use error::{HouseLocation, Result, WorldError, error_chain};
pub use geometry::{Footprint, Point, Polygon, Rect};
pub use grid::{GridParams, OccupancyGrid};
pub use house::{
    Container, Door, GroundTruth, House, MAX_TYPE_NAME, ObjectType, Obstacle, Pose, Room, RoomType,
    Scene, SmallObject, Wall, type_name_problem,
};
pub use map::{MapCell, OccupancyMap};
pub use rules::{AccessRule, ContainerSet, TravelCost};
pub use scene::SceneFile;
pub use soft::{SoftCache, SoftGrid};
pub use target_name::{UnknownTarget, check_target};
