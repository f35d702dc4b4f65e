//! A scene folder as `frond scene` writes it: `scene.json` beside `plants/master_NN.glb`, the
//! master plants' glb files, written into a staging folder and moved into place at once (a
//! killed run leaves no half scene). Takes source plants (glb files, or built-in synthetic
//! plants) and the scene options; returns the scene written.

use std::path::{Path, PathBuf};

use super::{EcosystemError, EcosystemScene, SceneOptions, SourcePlant, build_scene};
use crate::lod::asset::PlantAsset;
use crate::model::PlantModel;
use crate::synth::{Preset, generate_plant, plant_model};
use crate::util::atomic::{StagedDir, write_atomic};
use crate::util::progress::Progress;

/// Where a scene's plants come from.
#[derive(Clone, Debug)]
pub enum PlantSources {
    /// Plant glb files (e.g. `frond reconstruct` outputs).
    Files(Vec<PathBuf>),
    /// This many built-in synthetic plants, broadleaf and medium in turn, seeded from the
    /// scene's seed.
    BuiltIn(usize),
}

/// Built-in source plant `index` of a scene seeded `seed`: broadleaf and medium synthetic
/// plants in turn (name, model with 64² leaf textures).
pub fn built_in_plant(seed: u64, index: usize) -> (String, PlantModel) {
    let preset = if index.is_multiple_of(2) {
        Preset::Broadleaf
    } else {
        Preset::Medium
    };
    let plant_seed = seed.wrapping_mul(1000).wrapping_add(index as u64);
    let plant = generate_plant(preset, plant_seed);
    (
        format!("{}_{plant_seed}", preset.name()),
        plant_model(&plant, 64),
    )
}

fn file_error(path: &Path, message: impl std::fmt::Display) -> EcosystemError {
    EcosystemError::File {
        path: path.display().to_string(),
        message: message.to_string(),
    }
}

/// Builds a scene from `sources` and writes its folder at `out` (see the module docs).
pub fn write_scene_folder(
    out: &Path,
    sources: &PlantSources,
    options: &SceneOptions,
    progress: &dyn Progress,
) -> Result<EcosystemScene, EcosystemError> {
    let plants: Vec<SourcePlant> = match sources {
        PlantSources::BuiltIn(0) => {
            return Err(EcosystemError::NoPlants(
                "at least one built-in variant is needed when no plant file is given".into(),
            ));
        }
        PlantSources::BuiltIn(variants) => {
            progress.stage("generating plants", *variants as u64);
            (0..*variants)
                .map(|i| {
                    let (name, model) = built_in_plant(options.seed, i);
                    progress.advance(1);
                    SourcePlant {
                        name,
                        asset: PlantAsset::from_model(&model),
                    }
                })
                .collect()
        }
        PlantSources::Files(paths) => paths
            .iter()
            .map(|path| {
                Ok(SourcePlant {
                    name: path.display().to_string(),
                    asset: PlantAsset::read_glb(path).map_err(|e| file_error(path, e))?,
                })
            })
            .collect::<Result<_, EcosystemError>>()?,
    };
    progress.stage("placing plants", 0);
    let (scene, master_sources) = build_scene(&plants, options)?;
    let staged = StagedDir::new(out).map_err(|e| file_error(out, e))?;
    let plants_dir = staged.path().join("plants");
    std::fs::create_dir_all(&plants_dir).map_err(|e| file_error(&plants_dir, e))?;
    for (plant, &source) in scene.plants.iter().zip(&master_sources) {
        let path = staged.path().join(&plant.file);
        let bytes = match sources {
            PlantSources::Files(paths) => {
                let original = &paths[source];
                std::fs::read(original).map_err(|e| file_error(original, e))?
            }
            PlantSources::BuiltIn(_) => built_in_plant(options.seed, source).1.to_glb(),
        };
        write_atomic(&path, &bytes).map_err(|e| file_error(&path, e))?;
    }
    let scene_path = staged.path().join("scene.json");
    let text = serde_json::to_string(&scene).map_err(|e| file_error(&scene_path, e))?;
    write_atomic(&scene_path, text.as_bytes()).map_err(|e| file_error(&scene_path, e))?;
    staged.commit().map_err(|e| file_error(out, e))?;
    Ok(scene)
}
