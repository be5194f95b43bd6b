//! The ProcTHOR generator's asset database (`asset-database.json`): for every assetId its object
//! type and bounding box.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::error::{Result, WorldError};
use crate::house::ObjectType;

/// One asset as the database describes it; other fields (materials, scenes, states) are ignored.
#[derive(Deserialize)]
#[serde(rename_all = "camelCase")]
struct RawAsset {
    asset_id: String,
    #[serde(default)]
    object_type: Option<String>,
    #[serde(default)]
    bounding_box: Option<RawBox>,
    #[serde(default)]
    secondary_properties: Vec<String>,
}

#[derive(Deserialize)]
struct RawBox {
    x: f64,
    z: f64,
}

/// What ferret keeps of one asset.
#[derive(Clone, Debug, PartialEq)]
struct Asset {
    object_type: ObjectType,
    /// Bounding box along the asset's own x and z, metres.
    size: Option<(f64, f64)>,
    receptacle: bool,
}

/// The generator's asset database: assetId → object type and bounding box.
///
/// The file maps each object type to its assets (`{"Fridge": [{"assetId": "Fridge_1",
/// "boundingBox": {"x": .., "y": .., "z": ..}, ..}], ..}`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct AssetDatabase {
    // Sorted so that iteration (reports, agreement tests) is deterministic.
    assets: BTreeMap<String, Asset>,
}

impl AssetDatabase {
    /// Reads `asset-database.json`.
    pub fn load(path: &Path) -> Result<AssetDatabase> {
        // Bounded like every file read whole, so that a wrong path cannot exhaust memory.
        let text =
            crate::input::read_text(path, crate::input::MAX_INPUT_BYTES).map_err(|source| {
                WorldError::Io {
                    file: path.to_path_buf(),
                    source,
                }
            })?;
        Self::parse(&text, path)
    }

    /// Parses the database from its JSON text; `file` only names it in errors.
    pub fn parse(json: &str, file: &Path) -> Result<AssetDatabase> {
        let err = |message: String| WorldError::AssetDatabase {
            file: PathBuf::from(file),
            message,
        };
        let mut de = serde_json::Deserializer::from_str(json);
        let raw: HashMap<String, Vec<RawAsset>> =
            serde_path_to_error::deserialize(&mut de).map_err(|e| err(e.to_string()))?;
        de.end().map_err(|e| err(e.to_string()))?;
        let mut assets = BTreeMap::new();
        for (type_name, list) in raw {
            for a in list {
                let size = match a.bounding_box {
                    None => None,
                    Some(b) if b.x.is_finite() && b.z.is_finite() && b.x >= 0.0 && b.z >= 0.0 => {
                        Some((b.x, b.z))
                    }
                    Some(b) => {
                        return Err(err(format!(
                            "{}: bounding box {} x {} is not a size",
                            a.asset_id, b.x, b.z
                        )));
                    }
                };
                let object_type = ObjectType::new(
                    a.object_type
                        .filter(|t| !t.is_empty())
                        .unwrap_or_else(|| type_name.clone()),
                );
                let receptacle = a.secondary_properties.iter().any(|p| p == "Receptacle");
                let asset = Asset {
                    object_type,
                    size,
                    receptacle,
                };
                if assets.insert(a.asset_id.clone(), asset).is_some() {
                    return Err(err(format!("assetId {} appears twice", a.asset_id)));
                }
            }
        }
        Ok(AssetDatabase { assets })
    }

    /// The object type of an asset, when the database knows it.
    pub fn object_type(&self, asset_id: &str) -> Option<&ObjectType> {
        self.assets.get(asset_id).map(|a| &a.object_type)
    }

    /// The asset's bounding box along its own x and z axes, metres.
    pub fn footprint_size(&self, asset_id: &str) -> Option<(f64, f64)> {
        self.assets.get(asset_id).and_then(|a| a.size)
    }

    /// Whether the database marks the asset a receptacle (`secondaryProperties`).
    pub fn is_receptacle(&self, asset_id: &str) -> Option<bool> {
        self.assets.get(asset_id).map(|a| a.receptacle)
    }

    /// Number of assets.
    pub fn len(&self) -> usize {
        self.assets.len()
    }

    /// True when the database holds no assets.
    pub fn is_empty(&self) -> bool {
        self.assets.is_empty()
    }

    /// Every (assetId, object type), sorted by assetId.
    pub fn iter(&self) -> impl Iterator<Item = (&str, &ObjectType)> {
        self.assets
            .iter()
            .map(|(id, a)| (id.as_str(), &a.object_type))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const DB: &str = r#"{
        "Fridge": [{"assetId": "Fridge_1", "objectType": "Fridge",
                    "boundingBox": {"x": 0.9, "y": 1.8, "z": 0.7},
                    "secondaryProperties": ["Receptacle", "CanOpen"], "scenes": []}],
        "Sofa": [{"assetId": "RoboTHOR_sofa_kramfors", "boundingBox": {"x": 2.1, "y": 0.8, "z": 0.9}},
                 {"assetId": "Sofa_2"}]
    }"#;

    #[test]
    fn parses_types_sizes_and_receptacles() {
        let db = AssetDatabase::parse(DB, Path::new("db.json")).unwrap();
        assert_eq!(db.len(), 3);
        assert_eq!(db.object_type("Fridge_1").unwrap().as_str(), "Fridge");
        assert_eq!(
            db.object_type("RoboTHOR_sofa_kramfors").unwrap().as_str(),
            "Sofa"
        );
        assert_eq!(db.footprint_size("Fridge_1"), Some((0.9, 0.7)));
        assert_eq!(db.footprint_size("Sofa_2"), None);
        assert_eq!(db.is_receptacle("Fridge_1"), Some(true));
        assert_eq!(db.is_receptacle("Sofa_2"), Some(false));
        assert_eq!(db.object_type("Nope"), None);
        let ids: Vec<&str> = db.iter().map(|(id, _)| id).collect();
        assert_eq!(ids, ["Fridge_1", "RoboTHOR_sofa_kramfors", "Sofa_2"]);
    }

    #[test]
    fn bad_databases_are_errors_naming_the_file() {
        for bad in [
            "[1, 2]",
            r#"{"Fridge": [{"objectType": "Fridge"}]}"#,
            r#"{"A": [{"assetId": "x"}], "B": [{"assetId": "x"}]}"#,
            r#"{"A": [{"assetId": "x", "boundingBox": {"x": -1, "z": 1}}]}"#,
            "{} trailing",
        ] {
            match AssetDatabase::parse(bad, Path::new("bad.json")) {
                Err(e @ WorldError::AssetDatabase { .. }) => {
                    assert!(e.to_string().contains("bad.json"), "{e}")
                }
                other => panic!("{bad}: {other:?}"),
            }
        }
    }
}
