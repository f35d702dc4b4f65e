//! Plant scenes (seeds 001–003): many plants on a height-map terrain, placed by half-toning a
//! density image, oriented between upright and the terrain normal, and drawn as instances of
//! a few master plants chosen by approximate instancing (vector quantization of the plants'
//! parameters). A scene is a JSON file next to the master plants' glb files; `flythrough`
//! renders it with LOD selection, frustum culling and instanced draws.
//!
//! Takes plant assets and scene options; returns an [`EcosystemScene`] (terrain, instances,
//! masters), written as a folder by [`folder`], and fly-through frames with their timings.

pub mod flythrough;
pub mod folder;
pub mod placement;
pub mod terrain;

use std::path::{Path, PathBuf};

use image::GrayImage;
use nalgebra::{Isometry3, Point3, Similarity3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use crate::lod::asset::PlantAsset;
use crate::lod::quantize::quantize;
use crate::util::rng::Rng;
use placement::halftone_positions;
use terrain::{Terrain, fractal_noise, plant_up};

/// Scene failures.
#[derive(Debug, thiserror::Error)]
pub enum EcosystemError {
    #[error("{path}: {message}")]
    File { path: String, message: String },
    #[error("no plants to place: {0}")]
    NoPlants(String),
    #[error("scene {path}: {message}")]
    Invalid { path: String, message: String },
}

/// Parameters that describe a plant's appearance, measured from its geometry.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PlantParameters {
    pub height_m: f64,
    /// Twice the largest horizontal distance from the plant's axis.
    pub crown_diameter_m: f64,
    /// One-sided area of the leaf parts.
    pub leaf_area_m2: f64,
    pub triangles: usize,
}

impl PlantParameters {
    /// Measures `asset` (z up).
    pub fn measure(asset: &PlantAsset) -> Option<Self> {
        let (lo, hi) = asset.bounds()?;
        let (_, reach) = asset.vertical_axis_and_reach()?;
        Some(Self {
            height_m: (hi.z - lo.z) as f64,
            crown_diameter_m: 2.0 * reach as f64,
            leaf_area_m2: asset
                .parts
                .iter()
                .filter(|p| p.is_leaf)
                .map(|p| p.mesh.area())
                .sum(),
            triangles: asset.triangles(),
        })
    }

    /// The vector quantization works on: logarithms (perceptual linearisation: equal
    /// relative differences look equally different), leaf area as a length.
    pub fn vector(&self, scale: f64) -> Vec<f64> {
        let ln = |v: f64| v.max(1e-6).ln();
        vec![
            ln(self.height_m * scale),
            ln(self.crown_diameter_m * scale),
            ln(self.leaf_area_m2.sqrt() * scale),
        ]
    }
}

/// A master plant of the scene.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ScenePlant {
    /// The glb, relative to the scene file.
    pub file: String,
    /// The point of the plant that stands on the ground (centre of its base), plant frame.
    pub base_m: [f64; 3],
    pub parameters: PlantParameters,
    /// Names of the source plants this master stands for.
    pub stands_for: Vec<String>,
}

/// One placed plant.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SceneInstance {
    /// Index into [`EcosystemScene::plants`].
    pub plant: usize,
    /// Where the plant's base stands, world frame.
    pub position_m: [f64; 3],
    /// world_from_plant rotation as a unit quaternion (x, y, z, w).
    pub rotation_xyzw: [f64; 4],
    pub scale: f64,
    /// The source plant it was before approximate instancing.
    pub source: usize,
}

/// How much approximate instancing changed the plants.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct QuantizationReport {
    pub source_plants: usize,
    pub masters: usize,
    /// Weighted RMS of the log-parameter change per instance (0.1 ≈ 10 % size change).
    pub rms_log_change: f64,
    /// Instances per master (the seed-003 database reduction).
    pub reduction: f64,
}

/// A scene file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EcosystemScene {
    pub version: u32,
    pub seed: u64,
    pub terrain: Terrain,
    pub plants: Vec<ScenePlant>,
    pub instances: Vec<SceneInstance>,
    pub quantization: QuantizationReport,
}

/// Settings of [`build_scene`].
#[derive(Clone, Debug)]
pub struct SceneOptions {
    pub count: usize,
    pub size_m: [f64; 2],
    /// Grey height map (default: seeded fractal noise).
    pub heightmap: Option<GrayImage>,
    pub height_scale_m: f64,
    /// Grey density image, black = no plants (default: seeded fractal noise).
    pub density: Option<GrayImage>,
    /// Code-book size of approximate instancing (seed 003: 10–20 per species).
    pub masters: usize,
    /// w of up = normalize(w·n + (1 − w)·z).
    pub orientation_weight: f64,
    /// Instance scale from vigor: min + (max − min) × density at the plant.
    pub scale_range: (f64, f64),
    pub seed: u64,
}

impl Default for SceneOptions {
    fn default() -> Self {
        Self {
            count: 1000,
            size_m: [40.0, 40.0],
            heightmap: None,
            height_scale_m: 2.0,
            density: None,
            masters: 12,
            orientation_weight: 0.3,
            scale_range: (0.8, 1.2),
            seed: 1,
        }
    }
}

/// A source plant offered to [`build_scene`].
pub struct SourcePlant {
    pub name: String,
    pub asset: PlantAsset,
}

/// Places `options.count` plants (about: half-toning is exact to ~1 %) chosen uniformly from
/// `sources`, then replaces them by instances of at most `options.masters` representatives.
/// Returns the scene (master files named `plants/master_NN.glb`) and, per master, the index
/// of its source plant.
pub fn build_scene(
    sources: &[SourcePlant],
    options: &SceneOptions,
) -> Result<(EcosystemScene, Vec<usize>), EcosystemError> {
    let measured: Vec<(PlantParameters, [f64; 3])> = sources
        .iter()
        .map(|source| {
            let parameters = PlantParameters::measure(&source.asset)
                .ok_or_else(|| EcosystemError::NoPlants(format!("{} is empty", source.name)))?;
            let (lo, hi) = source.asset.bounds().unwrap_or_default();
            let base = [
                0.5 * (lo.x + hi.x) as f64,
                0.5 * (lo.y + hi.y) as f64,
                lo.z as f64,
            ];
            Ok((parameters, base))
        })
        .collect::<Result<_, EcosystemError>>()?;
    if sources.is_empty() {
        return Err(EcosystemError::NoPlants("no source plants given".into()));
    }
    let resolution = 129;
    let heightmap = options
        .heightmap
        .clone()
        .unwrap_or_else(|| fractal_noise(resolution, 4, options.seed ^ 0x7e44));
    if heightmap.width() < 2 || heightmap.height() < 2 {
        return Err(EcosystemError::Invalid {
            path: "height map".into(),
            message: format!(
                "{}×{} pixels; a terrain needs at least 2×2",
                heightmap.width(),
                heightmap.height()
            ),
        });
    }
    if !(options.size_m.iter().all(|s| s.is_finite() && *s > 0.0)
        && options.height_scale_m.is_finite())
    {
        return Err(EcosystemError::Invalid {
            path: "scene options".into(),
            message: "field size must be positive and the height scale finite".into(),
        });
    }
    let terrain = Terrain::from_heightmap(&heightmap, options.size_m, options.height_scale_m);
    let density = options
        .density
        .clone()
        .unwrap_or_else(|| fractal_noise(64, 3, options.seed ^ 0xde45));
    let positions = halftone_positions(&density, options.count, options.size_m, options.seed);

    // Each plant: a source plant, a vigor-driven scale, an orientation.
    let mut rng = Rng::seed_from(options.seed ^ 0x91a7);
    struct Placed {
        source: usize,
        position: Point3<f64>,
        rotation: UnitQuaternion<f64>,
        scale: f64,
    }
    let placed: Vec<Placed> = positions
        .iter()
        .map(|p| {
            let source = rng.below(sources.len());
            let vigor =
                placement::sample(&density, p.x / options.size_m[0], p.y / options.size_m[1]);
            let (lo, hi) = options.scale_range;
            let scale = lo + (hi - lo) * vigor;
            let up = plant_up(&terrain.normal(p.x, p.y), options.orientation_weight);
            let tilt = UnitQuaternion::rotation_between(&Vector3::z(), &up)
                .unwrap_or_else(UnitQuaternion::identity);
            let yaw = UnitQuaternion::from_axis_angle(
                &Vector3::z_axis(),
                rng.range(0.0, std::f64::consts::TAU),
            );
            Placed {
                source,
                position: Point3::new(p.x, p.y, terrain.height(p.x, p.y)),
                rotation: tilt * yaw,
                scale,
            }
        })
        .collect();

    // Approximate instancing over the source plants, weighted by how many instances each has
    // and how large they are (screen area ∝ height × crown).
    let mut weights = vec![0.0f64; sources.len()];
    for plant in &placed {
        let p = &measured[plant.source].0;
        weights[plant.source] += plant.scale * plant.scale * p.height_m * p.crown_diameter_m;
    }
    let vectors: Vec<Vec<f64>> = measured.iter().map(|(p, _)| p.vector(1.0)).collect();
    let used: Vec<usize> = (0..sources.len()).filter(|&s| weights[s] > 0.0).collect();
    let used_vectors: Vec<Vec<f64>> = used.iter().map(|&s| vectors[s].clone()).collect();
    let used_weights: Vec<f64> = used.iter().map(|&s| weights[s]).collect();
    let book = quantize(&used_vectors, &used_weights, options.masters.max(1));
    let master_sources: Vec<usize> = book.representatives.iter().map(|&r| used[r]).collect();
    let mut master_of_source = vec![usize::MAX; sources.len()];
    for (k, &s) in used.iter().enumerate() {
        master_of_source[s] = book.assignment[k];
    }
    let plants: Vec<ScenePlant> = master_sources
        .iter()
        .enumerate()
        .map(|(m, &s)| ScenePlant {
            file: format!("plants/master_{m:02}.glb"),
            base_m: measured[s].1,
            parameters: measured[s].0,
            stands_for: used
                .iter()
                .enumerate()
                .filter(|(k, _)| book.assignment[*k] == m)
                .map(|(_, &u)| sources[u].name.clone())
                .collect(),
        })
        .collect();
    // Each instance keeps its height: the representative is scaled to the source's size.
    let mut change2 = 0.0;
    let mut instances = Vec::with_capacity(placed.len());
    for plant in &placed {
        let master = master_of_source[plant.source];
        let source_height = measured[plant.source].0.height_m;
        let master_height = plants[master].parameters.height_m.max(1e-9);
        let scale = plant.scale * source_height / master_height;
        let before = measured[plant.source].0.vector(plant.scale);
        let after = plants[master].parameters.vector(scale);
        change2 += before
            .iter()
            .zip(&after)
            .map(|(a, b)| (a - b) * (a - b))
            .sum::<f64>();
        let q = plant.rotation.coords;
        instances.push(SceneInstance {
            plant: master,
            position_m: plant.position.coords.into(),
            rotation_xyzw: [q.x, q.y, q.z, q.w],
            scale,
            source: plant.source,
        });
    }
    let quantization = QuantizationReport {
        source_plants: used.len(),
        masters: plants.len(),
        rms_log_change: if instances.is_empty() {
            0.0
        } else {
            (change2 / instances.len() as f64).sqrt()
        },
        reduction: instances.len() as f64 / plants.len().max(1) as f64,
    };
    Ok((
        EcosystemScene {
            version: 1,
            seed: options.seed,
            terrain,
            plants,
            instances,
            quantization,
        },
        master_sources,
    ))
}

impl SceneInstance {
    /// world_from_plant: the master's base to the instance's position, rotated and scaled.
    pub fn world_from_plant(&self, plant: &ScenePlant) -> Similarity3<f64> {
        let [x, y, z, w] = self.rotation_xyzw;
        let rotation = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
        let base = Vector3::from(plant.base_m);
        Similarity3::from_isometry(
            Isometry3::from_parts(Translation3::from(Vector3::from(self.position_m)), rotation),
            self.scale,
        ) * Similarity3::from_isometry(
            Isometry3::from_parts(Translation3::from(-base), UnitQuaternion::identity()),
            1.0,
        )
    }
}

impl EcosystemScene {
    /// Reads and checks a scene file.
    pub fn read(path: &Path) -> Result<Self, EcosystemError> {
        let text = std::fs::read_to_string(path).map_err(|e| EcosystemError::File {
            path: path.display().to_string(),
            message: e.to_string(),
        })?;
        let scene: Self = serde_json::from_str(&text).map_err(|e| EcosystemError::Invalid {
            path: path.display().to_string(),
            message: e.to_string(),
        })?;
        scene.check(path)?;
        Ok(scene)
    }

    fn check(&self, path: &Path) -> Result<(), EcosystemError> {
        let invalid = |message: String| EcosystemError::Invalid {
            path: path.display().to_string(),
            message,
        };
        let t = &self.terrain;
        if t.columns < 2 || t.rows < 2 || t.heights_m.len() != t.columns * t.rows {
            return Err(invalid(format!(
                "terrain has {} heights for {}×{} samples",
                t.heights_m.len(),
                t.columns,
                t.rows
            )));
        }
        if !(t.size_m[0] > 0.0 && t.size_m[1] > 0.0) || t.heights_m.iter().any(|h| !h.is_finite()) {
            return Err(invalid(
                "terrain size or heights are not finite and positive".into(),
            ));
        }
        for (i, instance) in self.instances.iter().enumerate() {
            let finite = instance
                .position_m
                .iter()
                .chain(&instance.rotation_xyzw)
                .all(|v| v.is_finite());
            let norm: f64 = instance
                .rotation_xyzw
                .iter()
                .map(|v| v * v)
                .sum::<f64>()
                .sqrt();
            if instance.plant >= self.plants.len() {
                return Err(invalid(format!(
                    "instance {i} refers to plant {} of {}",
                    instance.plant,
                    self.plants.len()
                )));
            }
            let valid = finite
                && instance.scale > 0.0
                && instance.scale.is_finite()
                && (norm - 1.0).abs() <= 1e-3;
            if !valid {
                return Err(invalid(format!(
                    "instance {i} has a non-finite position, a non-unit rotation or a non-positive scale"
                )));
            }
        }
        Ok(())
    }

    /// Path of master `plant`'s glb for a scene file at `scene_path`.
    pub fn plant_path(&self, scene_path: &Path, plant: usize) -> PathBuf {
        let dir = scene_path.parent().unwrap_or(Path::new("."));
        dir.join(&self.plants[plant].file)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::{Preset, generate_plant, plant_model};

    fn sources(n: usize) -> Vec<SourcePlant> {
        (0..n)
            .map(|i| {
                let preset = if i % 2 == 0 {
                    Preset::Broadleaf
                } else {
                    Preset::Medium
                };
                let plant = generate_plant(preset, 100 + i as u64);
                SourcePlant {
                    name: format!("{}_{}", preset.name(), 100 + i),
                    asset: PlantAsset::from_model(&plant_model(&plant, 8)),
                }
            })
            .collect()
    }

    #[test]
    fn plants_stand_on_the_terrain_and_masters_stand_for_their_sources() {
        let sources = sources(6);
        let options = SceneOptions {
            count: 300,
            size_m: [20.0, 15.0],
            masters: 3,
            ..Default::default()
        };
        let (scene, master_sources) = build_scene(&sources, &options).unwrap();
        assert!((scene.instances.len() as f64 - 300.0).abs() <= 3.0);
        assert_eq!(scene.plants.len(), 3);
        assert_eq!(master_sources.len(), 3);
        let stood_for: usize = scene.plants.iter().map(|p| p.stands_for.len()).sum();
        assert_eq!(stood_for, scene.quantization.source_plants);
        for instance in &scene.instances {
            let plant = &scene.plants[instance.plant];
            let world_from_plant = instance.world_from_plant(plant);
            // The master's base lands on the terrain at the instance's position.
            let base = world_from_plant.transform_point(&Point3::from(plant.base_m));
            let ground = scene.terrain.height(base.x, base.y);
            assert!((base.z - ground).abs() < 1e-6, "{} vs {ground}", base.z);
            // Heights are kept through approximate instancing.
            let source_height = PlantParameters::measure(&sources[instance.source].asset)
                .unwrap()
                .height_m;
            let drawn = plant.parameters.height_m * instance.scale;
            assert!(drawn >= 0.8 * source_height - 1e-9 && drawn <= 1.2 * source_height + 1e-9);
        }
        // Deterministic; a scene file round-trips.
        assert_eq!(build_scene(&sources, &options).unwrap().0, scene);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("scene.json");
        std::fs::write(&path, serde_json::to_string(&scene).unwrap()).unwrap();
        assert_eq!(EcosystemScene::read(&path).unwrap(), scene);
        // More masters, less change.
        let exact = build_scene(
            &sources,
            &SceneOptions {
                masters: 6,
                ..options.clone()
            },
        )
        .unwrap()
        .0;
        assert!(exact.quantization.rms_log_change < 1e-9);
        assert!(scene.quantization.rms_log_change > 0.0);
    }

    #[test]
    fn a_broken_scene_file_names_the_instance() {
        let sources = sources(2);
        let (mut scene, _) = build_scene(
            &sources,
            &SceneOptions {
                count: 20,
                size_m: [5.0, 5.0],
                ..Default::default()
            },
        )
        .unwrap();
        let tiny = SceneOptions {
            heightmap: Some(GrayImage::new(1, 1)),
            ..Default::default()
        };
        let err = build_scene(&sources, &tiny).unwrap_err().to_string();
        assert!(err.contains("height map") && err.contains("1×1"), "{err}");
        scene.instances[3].plant = 99;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("scene.json");
        std::fs::write(&path, serde_json::to_string(&scene).unwrap()).unwrap();
        let err = EcosystemScene::read(&path).unwrap_err().to_string();
        assert!(
            err.contains("instance 3") && err.contains("scene.json"),
            "{err}"
        );
    }
}
