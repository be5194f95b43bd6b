//! Where an experiment's houses come from, loaded and mapped.

use std::path::PathBuf;

use ferret_world::procthor::{AssetDatabase, HouseRange, LoadOptions, load_scenes};
use ferret_world::{ContainerSet, Distances, GridParams, OccupancyGrid, Scene, WorldError};
use rayon::prelude::*;

use crate::error::{Context, Result};
use crate::feedback::Feedback;

/// The houses of an experiment: a ProcTHOR file (all of it or a range), a scene file, or houses
/// generated from a seed.
#[derive(Clone, Debug, Default)]
pub struct HouseSource {
    /// A ProcTHOR `.json`/`.jsonl`/`.jsonl.gz` or a scene file; `None` generates houses.
    pub houses: Option<PathBuf>,
    /// Which houses of the file, by 0-based index.
    pub range: Option<HouseRange>,
    /// The ProcTHOR generator's asset database, for exact footprints and types.
    pub asset_db: Option<PathBuf>,
    /// Report invalid houses and go on instead of stopping at the first.
    pub skip_invalid: bool,
    /// Houses to generate when `houses` is `None`.
    pub generate: usize,
    /// Seed of the generated houses.
    pub house_seed: u64,
}

/// Houses ready for use, and what was skipped on the way.
#[derive(Debug)]
pub struct LoadedHouses {
    /// The valid houses.
    pub scenes: Vec<Scene>,
    /// One message per skipped house.
    pub skipped: Vec<String>,
    /// Where they came from, for reports.
    pub source: String,
}

impl HouseSource {
    /// Loads the houses, ProcTHOR files read with the container set `containers` (generated
    /// houses and scene files name their containers themselves).
    pub fn load_for(&self, containers: ContainerSet) -> Result<LoadedHouses> {
        self.load_shard(containers, None)
    }

    /// [`load_for`](Self::load_for), keeping only the houses of `shard` (all without one). The
    /// lines of a ProcTHOR file that belong to other shards are skipped without being parsed.
    pub fn load_shard(
        &self,
        containers: ContainerSet,
        shard: Option<crate::shard::Shard>,
    ) -> Result<LoadedHouses> {
        let mut loaded = self.load_inner(containers, shard)?;
        if let Some(sh) = shard {
            loaded.scenes.retain(|s| sh.contains(s.house.index));
        }
        Ok(loaded)
    }

    fn load_inner(
        &self,
        containers: ContainerSet,
        shard: Option<crate::shard::Shard>,
    ) -> Result<LoadedHouses> {
        let Some(path) = &self.houses else {
            let scenes = ferret_world::generate::default_scenes(self.generate, self.house_seed)
                .context_with(|| "generating the default houses".to_string())?;
            let scenes = match &self.range {
                Some(r) => scenes
                    .into_iter()
                    .filter(|s| r.contains(s.house.index))
                    .collect(),
                None => scenes,
            };
            return Ok(LoadedHouses {
                scenes,
                skipped: vec![],
                source: self.describe(),
            });
        };
        if ferret_world::scene::is_scene_file(path) {
            let scene = ferret_world::SceneFile::load(path)?;
            return Ok(LoadedHouses {
                scenes: vec![scene],
                skipped: vec![],
                source: self.describe(),
            });
        }
        let db = match &self.asset_db {
            Some(p) => Some(AssetDatabase::load(p)?),
            None => None,
        };
        let opts = LoadOptions {
            shard: shard.map(|sh| (sh.index, sh.count)),
            asset_db: db.as_ref(),
            range: self.range.unwrap_or_default(),
            skip_invalid: self.skip_invalid,
            containers,
        };
        let report = load_scenes(path, &opts)?;
        Ok(LoadedHouses {
            scenes: report.scenes,
            skipped: report.skipped.iter().map(ToString::to_string).collect(),
            source: self.describe(),
        })
    }

    /// Where the houses come from, as reports name it: the file (with its range), the scene
    /// file, or the generated houses and their seed.
    pub fn describe(&self) -> String {
        match &self.houses {
            None => format!(
                "{} generated houses (seed {})",
                self.generate, self.house_seed
            ),
            Some(path) if ferret_world::scene::is_scene_file(path) => path.display().to_string(),
            Some(path) => match &self.range {
                Some(r) => format!("{} [{r}]", path.display()),
                None => path.display().to_string(),
            },
        }
    }
}

/// A house with its map, or why it has none.
pub type Mapped = std::result::Result<(OccupancyGrid, Distances), WorldError>;

/// Builds grid and distances for every scene, in parallel.
pub fn build_maps(scenes: &[Scene], params: &GridParams, feedback: &dyn Feedback) -> Vec<Mapped> {
    feedback.begin("maps", scenes.len());
    let maps = scenes
        .par_iter()
        .map(|s| {
            let m = ferret_world::distance::build(&s.house, params);
            feedback.tick();
            m
        })
        .collect();
    feedback.end();
    maps
}
