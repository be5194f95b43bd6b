//! Where an experiment's houses come from, loaded and mapped.

use std::path::PathBuf;

use ferret_world::procthor::{AssetDatabase, HouseItem, HouseRange, HouseReader, LoadOptions};
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

/// One house of a source read house by house: a house, or why one was skipped.
#[derive(Debug)]
pub enum HouseEvent {
    /// A valid house.
    Scene(Box<Scene>),
    /// Why an invalid house was skipped (only with [`HouseSource::skip_invalid`]).
    Skipped(String),
}

/// The houses of a source in order, read as they are asked for.
pub type HouseStream<'a> = Box<dyn Iterator<Item = Result<HouseEvent>> + Send + 'a>;

/// A house source ready to be read house by house, as often as needed: what the readers
/// borrow (the asset database) is loaded once.
#[derive(Debug)]
pub struct OpenSource<'s> {
    source: &'s HouseSource,
    containers: ContainerSet,
    shard: Option<crate::shard::Shard>,
    db: Option<AssetDatabase>,
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
        self.load_mapped(containers, shard, |s| s)
    }

    /// [`load_for`](Self::load_for), each house kept as [`Scene::into_types_only`] as soon as it
    /// is read: what training a prior needs, in a fraction of the memory.
    pub fn load_types_only(&self, containers: ContainerSet) -> Result<LoadedHouses> {
        self.load_mapped(containers, None, Scene::into_types_only)
    }

    fn load_mapped(
        &self,
        containers: ContainerSet,
        shard: Option<crate::shard::Shard>,
        keep: impl Fn(Scene) -> Scene,
    ) -> Result<LoadedHouses> {
        let open = self.open(containers, shard)?;
        let mut loaded = LoadedHouses {
            scenes: Vec::new(),
            skipped: Vec::new(),
            source: self.describe(),
        };
        for event in open.houses()? {
            match event? {
                HouseEvent::Scene(scene) => loaded.scenes.push(keep(*scene)),
                HouseEvent::Skipped(why) => loaded.skipped.push(why),
            }
        }
        Ok(loaded)
    }

    /// Opens the source for reading house by house ([`OpenSource::houses`]), only the houses of
    /// `shard` (all without one); ProcTHOR files are read with the container set `containers`.
    ///
    /// # Errors
    /// An asset database that cannot be read; too many houses to generate.
    pub fn open(
        &self,
        containers: ContainerSet,
        shard: Option<crate::shard::Shard>,
    ) -> Result<OpenSource<'_>> {
        if self.houses.is_none() {
            ferret_world::generate::check_count(self.generate)
                .context_with(|| "generating the default houses".to_string())?;
        }
        let db = match (&self.houses, &self.asset_db) {
            (Some(path), Some(p)) if !ferret_world::scene::is_scene_file(path) => {
                Some(AssetDatabase::load(p)?)
            }
            _ => None,
        };
        Ok(OpenSource {
            source: self,
            containers,
            shard,
            db,
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

impl OpenSource<'_> {
    /// The houses, in order, from the start: each call reads the source again.
    ///
    /// # Errors
    /// A house file that cannot be opened (later errors of the file, and invalid houses without
    /// `skip_invalid`, come out of the stream, after the houses before them).
    pub fn houses(&self) -> Result<HouseStream<'_>> {
        let src = self.source;
        let shard = self.shard;
        let in_shard = move |i: usize| shard.is_none_or(|sh| sh.contains(i));
        let Some(path) = &src.houses else {
            let range = src.range;
            let seed = src.house_seed;
            let houses = (0..src.generate)
                .filter(move |&i| range.is_none_or(|r| r.contains(i)) && in_shard(i))
                .map(move |i| {
                    ferret_world::generate::default_scene(i, seed)
                        .map(|s| HouseEvent::Scene(Box::new(s)))
                        .context_with(|| "generating the default houses".to_string())
                });
            return Ok(Box::new(houses));
        };
        if ferret_world::scene::is_scene_file(path) {
            let scene = ferret_world::SceneFile::load(path)?;
            let keep = in_shard(scene.house.index);
            return Ok(Box::new(
                keep.then(|| Ok(HouseEvent::Scene(Box::new(scene))))
                    .into_iter(),
            ));
        }
        let opts = LoadOptions {
            shard: shard.map(|sh| (sh.index, sh.count)),
            asset_db: self.db.as_ref(),
            range: src.range.unwrap_or_default(),
            skip_invalid: src.skip_invalid,
            containers: self.containers,
        };
        let reader = HouseReader::open(path, &opts)?;
        Ok(Box::new(reader.map(|item| match item {
            Ok(HouseItem::Scene(scene)) => Ok(HouseEvent::Scene(scene)),
            Ok(HouseItem::Skipped(e)) => Ok(HouseEvent::Skipped(e.to_string())),
            Err(e) => Err(e.into()),
        })))
    }

    /// How many houses [`houses`](Self::houses) will yield, as far as is known without reading
    /// the file: exact for generated houses and scene files; for a file, the houses of a range
    /// with an end (fewer when houses are skipped or the file is shorter); 0 when unknown.
    pub fn len_hint(&self) -> usize {
        let src = self.source;
        let shard = self.shard;
        // Indices below `x` in the shard; by arithmetic, as a range's end may be huge.
        let below = |x: usize| match shard {
            Some(sh) if sh.count > 0 => {
                if x <= sh.index {
                    0
                } else {
                    (x - sh.index - 1) / sh.count + 1
                }
            }
            _ => x,
        };
        let count = |start: usize, end: usize| below(end).saturating_sub(below(start));
        match &src.houses {
            None => {
                let r = src.range.unwrap_or_default();
                count(r.start, r.end.map_or(src.generate, |e| e.min(src.generate)))
            }
            Some(path) if ferret_world::scene::is_scene_file(path) => 1,
            Some(_) => src
                .range
                .and_then(|r| r.end.map(|e| count(r.start, e)))
                .unwrap_or(0),
        }
    }

    /// Where the houses come from, as reports name it ([`HouseSource::describe`]).
    pub fn describe(&self) -> String {
        self.source.describe()
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
