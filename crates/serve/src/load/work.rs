//! What each robot of a fleet searches for, and where it starts.

use std::collections::{HashMap, HashSet};

use ferret_world::{GridParams, OccupancyGrid, Point, Scene};
use rand::{Rng, SeedableRng};

use super::LoadError;

/// A trial a robot runs, with what each container holds, to answer its searches.
#[derive(Clone, Debug)]
pub struct RobotTrial {
    /// The scene's name.
    pub scene: String,
    /// The target type.
    pub target: String,
    /// The start pose `[x, y, yaw°]`; `None`: the scene's start.
    pub pose: Option<[f64; 3]>,
    /// Object types by container id.
    pub contents: HashMap<String, Vec<String>>,
}

/// The trials of `robots` robots, `trials` each: robot d runs scenes d·trials .. in order
/// (wrapping), with the target drawn for its scene with `seed`, from the scene's start; or,
/// when `fresh`, from a reachable pose (on grids of `grid`) and with a target drawn for the
/// trial itself, none twice.
///
/// # Errors
/// A scene with no target to draw, or (when `fresh`) whose grid cannot be built or has no
/// reachable cell.
pub fn robot_trials(
    scenes: &[Scene],
    robots: usize,
    trials: usize,
    seed: u64,
    fresh: bool,
    grid: &GridParams,
) -> Result<Vec<Vec<RobotTrial>>, LoadError> {
    if scenes.is_empty() {
        return Err(LoadError::Setup("no scenes".into()));
    }
    let house_error = |scene: &Scene, e: &dyn std::fmt::Display| LoadError::House {
        house: scene.house.name.clone(),
        message: e.to_string(),
    };
    // The reachable free cells of each scene, built when a fresh trial first needs them.
    let mut reachable: Vec<Option<Vec<Point>>> = vec![None; scenes.len()];
    let mut drawn = HashSet::new();
    let mut plans = Vec::with_capacity(robots);
    for d in 0..robots {
        let mut mine = Vec::with_capacity(trials);
        for k in 0..trials {
            let n = d * trials + k;
            let i = n % scenes.len();
            let scene = &scenes[i];
            let (target, pose) = if fresh {
                let cells = match &mut reachable[i] {
                    Some(cells) => cells,
                    slot => {
                        let grid = OccupancyGrid::build(&scene.house, grid)
                            .map_err(|e| house_error(scene, &e))?;
                        let cells = grid
                            .cells()
                            .filter(|(c, _)| grid.is_reachable(*c))
                            .map(|(c, _)| grid.center(c))
                            .collect();
                        slot.insert(cells)
                    }
                };
                if cells.is_empty() {
                    return Err(house_error(scene, &"no reachable free cell"));
                }
                // Drawn again (a new seed) until the trial is one not drawn before.
                let mut attempt = 0u64;
                loop {
                    let seed = seed
                        .wrapping_add((n as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15))
                        .wrapping_add(attempt.wrapping_mul(0xbf58_476d_1ce4_e5b9));
                    let target = ferret_plan::draw_trial(&scene.house, &scene.truth, seed, 0.0)
                        .map_err(|e| house_error(scene, &e))?
                        .task
                        .first()
                        .clone();
                    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
                    let at = cells[rng.random_range(0..cells.len())];
                    let yaw = rng.random_range(-180.0..180.0_f64).round();
                    let key = (i, at.x.to_bits(), at.z.to_bits(), target.to_string());
                    if drawn.insert(key) || attempt >= 1_000 {
                        break (target, Some([at.x, at.z, yaw]));
                    }
                    attempt += 1;
                }
            } else {
                let target = ferret_plan::draw_trial(&scene.house, &scene.truth, seed, 0.0)
                    .map_err(|e| house_error(scene, &e))?
                    .task
                    .first()
                    .clone();
                (target, None)
            };
            let contents = scene
                .house
                .containers
                .iter()
                .enumerate()
                .map(|(c, container)| {
                    let held = scene
                        .truth
                        .contents(c)
                        .iter()
                        .map(|o| o.object_type.to_string())
                        .collect();
                    (container.id.clone(), held)
                })
                .collect();
            mine.push(RobotTrial {
                scene: scene.house.name.clone(),
                target: target.to_string(),
                pose,
                contents,
            });
        }
        plans.push(mine);
    }
    Ok(plans)
}
