//! The surfel level (seed 000): the plant as oriented square splats sampled from its surface,
//! each with the normal and the texture colour of where it was sampled, lit by the render core
//! like the leaves they replace. A splat is a quad whose four vertices share one uv, pointing at
//! its own texel of a palette texture, so the level is an ordinary textured mesh (and an
//! ordinary glTF primitive). Its error μ is the farthest any vertex of the full plant lies from
//! the nearest splat centre, and it switches by the same screen-space rule as the other levels.

use std::num::NonZero;

use image::{Rgba, RgbaImage};
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::{Point3, Vector3};

use super::asset::{AssetPart, PlantAsset};
use crate::mesh::TriMesh;
use crate::util::geometry::any_perpendicular;
use crate::util::rng::Rng;

/// A surfel level: one mesh of splats and its palette.
#[derive(Clone, Debug)]
pub struct SurfelLevel {
    pub mesh: TriMesh,
    pub palette: RgbaImage,
    pub error_world: f64,
    pub surfels: usize,
}

/// Texel of a texture at uv (nearest, clamped).
fn texel(image: &RgbaImage, uv: [f32; 2]) -> Rgba<u8> {
    let (w, h) = image.dimensions();
    let x = ((uv[0].rem_euclid(1.0) * w as f32) as u32).min(w.saturating_sub(1));
    let y = ((uv[1].rem_euclid(1.0) * h as f32) as u32).min(h.saturating_sub(1));
    *image.get_pixel(x, y)
}

/// About `count` splats over the surface of `asset` (area-weighted; samples on transparent
/// texels of cut-out parts are dropped), each a square of the area its sample stands for (times
/// 1.3, so that neighbours overlap). `None` for a plant without surface.
pub fn surfel_level(asset: &PlantAsset, count: usize, seed: u64) -> Option<SurfelLevel> {
    let total: f64 = asset.parts.iter().map(|p| p.mesh.area()).sum();
    if total <= 0.0 || count == 0 {
        return None;
    }
    let mut rng = Rng::seed_from(seed);
    let mut samples: Vec<(Point3<f32>, Vector3<f32>, Rgba<u8>)> = Vec::with_capacity(count);
    let mut kept_area = 0.0;
    for part in &asset.parts {
        let area = part.mesh.area();
        let wanted = ((count as f64 * area / total).round() as usize).max(1);
        let image = asset.textures.get(part.texture);
        let mut kept = 0usize;
        for s in part.mesh.sample_surface(wanted, &mut rng) {
            let colour = image.map_or(Rgba([128, 128, 128, 255]), |i| texel(i, s.uv));
            if part.alpha_test && colour[3] < 128 {
                continue;
            }
            samples.push((s.position, s.normal, colour));
            kept += 1;
        }
        kept_area += area * kept as f64 / wanted as f64;
    }
    if samples.is_empty() {
        return None;
    }
    let half = 0.5 * 1.3 * (kept_area / samples.len() as f64).sqrt() as f32;
    let side = (samples.len() as f64).sqrt().ceil() as u32;
    let mut palette = RgbaImage::from_pixel(side, side, Rgba([0, 0, 0, 255]));
    let mut mesh = TriMesh::default();
    for (k, (position, normal, colour)) in samples.iter().enumerate() {
        let (x, y) = (k as u32 % side, k as u32 / side);
        palette.put_pixel(x, y, Rgba([colour[0], colour[1], colour[2], 255]));
        let uv = [
            (x as f32 + 0.5) / side as f32,
            (y as f32 + 0.5) / side as f32,
        ];
        let n = normal.try_normalize(1e-12).unwrap_or_else(Vector3::z);
        let t = any_perpendicular(&n.cast::<f64>())
            .normalize()
            .cast::<f32>();
        let b = n.cross(&t);
        let base = mesh.positions.len() as u32;
        for (u, v) in [(-1.0f32, -1.0f32), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
            mesh.positions.push(position + (t * u + b * v) * half);
            mesh.normals.push(n);
            mesh.uvs.push(uv);
        }
        mesh.triangles.push([base, base + 1, base + 2]);
        mesh.triangles.push([base, base + 2, base + 3]);
    }
    let centres: Vec<[f32; 3]> = samples.iter().map(|(p, _, _)| [p.x, p.y, p.z]).collect();
    let tree = ImmutableKdTree::<f32, 3>::new_from_slice(&centres).ok()?;
    let one = NonZero::<usize>::MIN;
    let error_world = asset
        .parts
        .iter()
        .flat_map(|p| p.mesh.positions.iter())
        .map(|p| {
            tree.query(&[p.x, p.y, p.z])
                .nearest_n::<SquaredEuclidean<f32>>(one)
                .execute()
                .first()
                .map_or(f32::INFINITY, |n| n.distance.sqrt())
        })
        .fold(0.0f32, f32::max) as f64;
    Some(SurfelLevel {
        surfels: samples.len(),
        mesh,
        palette,
        error_world,
    })
}

impl SurfelLevel {
    /// The level as a part whose texture is `texture` (the palette's index in the plant's
    /// textures).
    pub fn part(&self, texture: usize) -> AssetPart {
        AssetPart {
            name: "surfels".into(),
            mesh: self.mesh.clone(),
            texture,
            alpha_test: false,
            is_leaf: true,
            shading: Default::default(),
        }
    }
}

/// The surfel level and the star billboard against full detail at one on-screen size.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct FarLevelRow {
    /// The plant's bounding diameter on a 1080-pixel, 60° screen.
    pub diameter_px: f64,
    /// Mean colour difference to full detail (0–1, RGB) over the pixels either covers, mean
    /// of four directions 5° above the horizon.
    pub surfel_difference: f64,
    pub billboard_difference: f64,
    /// GPU time of one frame of the level alone (ms, median of five).
    pub full_ms: f64,
    pub surfel_ms: f64,
    pub billboard_ms: f64,
}

fn upload(
    renderer: &crate::render::Renderer,
    parts: &[AssetPart],
    textures: &[RgbaImage],
) -> Result<crate::render::GpuScene, crate::render::RenderError> {
    let mut gpu = renderer.new_scene();
    let users: Vec<&AssetPart> = parts.iter().collect();
    let handles = super::asset::upload_textures(renderer, &mut gpu, textures, &users);
    for part in parts {
        let Some(&texture) = handles.get(part.texture) else {
            continue;
        };
        let handle = renderer.add_mesh(&mut gpu, &part.mesh, texture, 1, part.alpha_test)?;
        renderer.set_shading(&gpu, handle, part.shading())?;
    }
    Ok(gpu)
}

/// Renders full detail, the surfel level and the billboard (parts of `billboard` use the
/// textures of `billboard_textures`) at each on-screen diameter and compares them.
pub fn compare_far_levels(
    renderer: &mut crate::render::Renderer,
    asset: &PlantAsset,
    surfels: &SurfelLevel,
    billboard: (&[AssetPart], &[RgbaImage]),
    diameters_px: &[f64],
) -> Result<Vec<FarLevelRow>, crate::render::RenderError> {
    let Some((centre, radius)) = asset.bounding_sphere() else {
        return Ok(Vec::new());
    };
    let full = upload(renderer, &asset.parts, &asset.textures)?;
    let surfel_scene = upload(
        renderer,
        &[surfels.part(0)],
        std::slice::from_ref(&surfels.palette),
    )?;
    let star = upload(renderer, billboard.0, billboard.1)?;
    let lighting = crate::render::Lighting::default();
    let focal = 1080.0 / (2.0 * (30f64).to_radians().tan());
    let centre = centre.cast::<f64>();
    let mut rows = Vec::with_capacity(diameters_px.len());
    for &diameter_px in diameters_px {
        let distance = focal * 2.0 * radius as f64 / diameter_px.max(1.0);
        let side = ((1.5 * diameter_px).ceil() as u32).clamp(16, 2048);
        let (mut surfel_difference, mut billboard_difference) = (0.0, 0.0);
        let mut times = [Vec::new(), Vec::new(), Vec::new()];
        for k in 0..4 {
            let azimuth = std::f64::consts::TAU * (k as f64 + 0.125) / 4.0;
            let camera =
                super::plant::view_of(&centre, distance, azimuth, 5f64.to_radians(), side, focal);
            let reference = renderer.render(&full, &camera, &lighting)?;
            for (scene, sum) in [
                (&surfel_scene, &mut surfel_difference),
                (&star, &mut billboard_difference),
            ] {
                let out = renderer.render(scene, &camera, &lighting)?;
                let (mut total, mut pixels) = (0.0f64, 0usize);
                for (i, (a, b)) in reference.color.pixels().zip(out.color.pixels()).enumerate() {
                    if reference.object_id[i] == 0 && out.object_id[i] == 0 {
                        continue;
                    }
                    total += (0..3)
                        .map(|c| (a[c] as f64 - b[c] as f64).abs())
                        .sum::<f64>()
                        / (3.0 * 255.0);
                    pixels += 1;
                }
                *sum += total / pixels.max(1) as f64 / 4.0;
            }
            for (slot, scene) in [&full, &surfel_scene, &star].into_iter().enumerate() {
                for _ in 0..5 {
                    let (stats, _) =
                        renderer.render_instanced(scene, &camera, &lighting, &[], &[], false)?;
                    times[slot].push(stats.seconds * 1e3);
                }
            }
        }
        let median = |v: &mut Vec<f64>| {
            v.sort_by(f64::total_cmp);
            v[v.len() / 2]
        };
        rows.push(FarLevelRow {
            diameter_px,
            surfel_difference,
            billboard_difference,
            full_ms: median(&mut times[0]),
            surfel_ms: median(&mut times[1]),
            billboard_ms: median(&mut times[2]),
        });
    }
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splats_cover_the_plant_and_their_error_shrinks_with_their_number() {
        let (_, model) = crate::ecosystem::folder::built_in_plant(2, 0);
        let asset = PlantAsset::from_model(&model);
        let coarse = surfel_level(&asset, 300, 1).expect("surfels");
        let fine = surfel_level(&asset, 3000, 1).expect("surfels");
        assert!(
            coarse.surfels > 200 && coarse.surfels <= 330,
            "{}",
            coarse.surfels
        );
        assert_eq!(fine.mesh.triangles.len(), 2 * fine.surfels);
        fine.mesh.validate().expect("valid mesh");
        assert!(
            fine.error_world < coarse.error_world,
            "{} vs {}",
            fine.error_world,
            coarse.error_world
        );
        // The palette holds the sampled colours: leaves are green.
        let green = fine
            .palette
            .pixels()
            .take(fine.surfels)
            .filter(|p| p[1] > p[0] && p[1] > p[2])
            .count();
        assert!(
            green * 2 > fine.surfels,
            "{green} of {} splats green",
            fine.surfels
        );
        assert!(surfel_level(&PlantAsset::default(), 100, 1).is_none());
    }

    #[test]
    fn far_levels_are_compared_against_full_detail() {
        let (_, model) = crate::ecosystem::folder::built_in_plant(2, 1);
        let asset = PlantAsset::from_model(&model);
        let mut renderer = crate::render::Renderer::new().expect("renderer");
        let surfels = surfel_level(&asset, 2000, 1).expect("surfels");
        let star = crate::lod::billboard::bake_star(
            &mut renderer,
            &asset,
            &crate::lod::billboard::BillboardOptions::default(),
        )
        .expect("billboard");
        let part = AssetPart {
            name: "billboard".into(),
            mesh: star.mesh.clone(),
            texture: 0,
            alpha_test: true,
            is_leaf: true,
            shading: star.shading,
        };
        let rows = compare_far_levels(
            &mut renderer,
            &asset,
            &surfels,
            (
                std::slice::from_ref(&part),
                std::slice::from_ref(&star.atlas),
            ),
            &[24.0, 96.0],
        )
        .unwrap();
        assert_eq!(rows.len(), 2);
        for row in &rows {
            for d in [row.surfel_difference, row.billboard_difference] {
                assert!(d > 0.0 && d < 0.5, "{row:?}");
            }
        }
        eprintln!("{rows:#?}");
    }
}
