//! The far level: a star billboard (seed 000 §5 Fig. 9, seed 002's cross method) — three
//! vertical quads through the plant's axis at 60° to each other, 6 triangles, each quad's
//! normals equal to its plane normal, textured from an atlas the render core bakes by
//! rendering the plant perpendicular to each quad.

use image::{Rgba, RgbaImage};
use nalgebra::{Point2, Point3, Vector3};

use super::asset::PlantAsset;
use crate::mesh::TriMesh;
use crate::render::{Lighting, RenderError, Renderer, ViewCamera};
use crate::scene::synthetic::look_at;

/// Settings of [`bake_star`].
#[derive(Clone, Debug, PartialEq)]
pub struct BillboardOptions {
    /// Quads of the star (3: a star of three intersecting squares; 2: a cross).
    pub quads: usize,
    /// Texel height of each atlas tile (width follows the plant's aspect).
    pub tile_height: u32,
}

impl Default for BillboardOptions {
    fn default() -> Self {
        Self {
            quads: 3,
            tile_height: 256,
        }
    }
}

/// A baked star billboard.
#[derive(Clone, Debug)]
pub struct StarBillboard {
    /// Two triangles per quad (quad k is triangles 2k and 2k + 1), uvs into `atlas`.
    pub mesh: TriMesh,
    /// The quads' tiles side by side; alpha 255 where the plant covers the texel.
    pub atlas: RgbaImage,
    /// μ: largest distance from a vertex of the full plant to the nearest quad plane.
    pub error_world: f64,
    /// The camera each quad's front tile was rendered from.
    pub bake_cameras: Vec<ViewCamera>,
    /// What back faces add to u: the back tiles fill the atlas's right half.
    pub back_uv_offset: f32,
}

/// The plant's vertical axis (through the centre of its bounds), horizontal reach from that
/// axis, and height range.
struct StarFrame {
    axis: Point2<f32>,
    reach: f32,
    z_range: (f32, f32),
}

fn star_frame(asset: &PlantAsset) -> Option<StarFrame> {
    let (lo, hi) = asset.bounds()?;
    let (axis, reach) = asset.vertical_axis_and_reach()?;
    // A 2 % margin keeps silhouettes off the tile border.
    let margin = 0.02 * reach.max(hi.z - lo.z);
    (reach > 0.0 && hi.z > lo.z).then(|| StarFrame {
        axis,
        reach: reach + margin,
        z_range: (lo.z - margin, hi.z + margin),
    })
}

/// Bakes the star billboard of `asset`: one render per quad under the render core's default
/// light, seen along the quad's normal from 20 plant radii away, so the quad's plane maps to
/// its tile exactly. The billboard is meant to be drawn unlit (`KHR_materials_unlit`).
pub fn bake_star(
    renderer: &mut Renderer,
    asset: &PlantAsset,
    options: &BillboardOptions,
) -> Result<StarBillboard, RenderError> {
    let frame = star_frame(asset).ok_or_else(|| RenderError::Mesh {
        object_id: 1,
        message: "the plant has no extent to bake a billboard of".into(),
    })?;
    let quads = options.quads.clamp(2, 8);
    let height = frame.z_range.1 - frame.z_range.0;
    let tile_height = options.tile_height.clamp(8, 4096);
    let tile_width =
        ((tile_height as f32 * 2.0 * frame.reach / height).round() as u32).clamp(8, 4096);
    let mut gpu = renderer.new_scene();
    for part in &asset.parts {
        let texture = if part.alpha_test {
            renderer.add_cutout_texture(&mut gpu, &asset.textures[part.texture])
        } else {
            renderer.add_texture(&mut gpu, &asset.textures[part.texture])
        };
        let handle = renderer.add_mesh(&mut gpu, &part.mesh, texture, 1, part.alpha_test)?;
        renderer.set_shading(&gpu, handle, part.shading())?;
    }
    // The tiles hold the plant as lit by the render core's default light, and the billboard
    // is drawn unlit: lighting the quads again with their own (vertical) normals made distant
    // plants darker than the plants they replace.
    let lit = Lighting::default();
    let center = Point3::new(
        frame.axis.x,
        frame.axis.y,
        0.5 * (frame.z_range.0 + frame.z_range.1),
    );
    let extent = frame.reach.max(0.5 * height);
    let distance = 20.0 * extent;
    // Front tiles, then back tiles (each quad seen from behind, mirrored so that the quad's
    // uvs plus `back_uv_offset` address the same world points): the plant's sides are lit
    // differently, and a one-sided tile showed the lit side's mirror image from the dark side.
    let mut atlas = RgbaImage::new(2 * tile_width * quads as u32, tile_height);
    let mut mesh = TriMesh::default();
    let mut bake_cameras = Vec::with_capacity(quads);
    let mut error_world = 0.0f64;
    let normals: Vec<Vector3<f32>> = (0..quads)
        .map(|k| {
            let angle = std::f32::consts::PI * k as f32 / quads as f32;
            Vector3::new(-angle.sin(), angle.cos(), 0.0)
        })
        .collect();
    for (k, normal) in normals.iter().enumerate() {
        let along = Vector3::new(normal.y, -normal.x, 0.0);
        let eye = center + normal * distance;
        let focal = (tile_width as f64) * distance as f64 / (2.0 * frame.reach as f64);
        let camera = ViewCamera {
            width: tile_width,
            height: tile_height,
            fx: focal,
            fy: focal,
            cx: 0.5 * tile_width as f64,
            cy: 0.5 * tile_height as f64,
            camera_from_world: look_at(eye.cast::<f64>(), center.cast::<f64>()),
            near: (distance - 2.0 * extent) as f64,
            far: (distance + 2.0 * extent) as f64,
        };
        let out = renderer.render(&gpu, &camera, &lit)?;
        let offset = k as u32 * tile_width;
        for y in 0..tile_height {
            for x in 0..tile_width {
                let mut texel = *out.color.get_pixel(x, y);
                texel[3] = if out.id_at(x, y) != 0 { 255 } else { 0 };
                atlas.put_pixel(offset + x, y, texel);
            }
        }
        let back_camera = ViewCamera {
            camera_from_world: look_at(
                (center - normal * distance).cast::<f64>(),
                center.cast::<f64>(),
            ),
            ..camera.clone()
        };
        let back = renderer.render(&gpu, &back_camera, &lit)?;
        let back_offset = (quads + k) as u32 * tile_width;
        for y in 0..tile_height {
            for x in 0..tile_width {
                let mirrored = tile_width - 1 - x;
                let mut texel = *back.color.get_pixel(mirrored, y);
                texel[3] = if back.id_at(mirrored, y) != 0 { 255 } else { 0 };
                atlas.put_pixel(back_offset + x, y, texel);
            }
        }
        // The quad's corners, with uvs where the bake camera sees them.
        let base = mesh.positions.len() as u32;
        for (s, z) in [
            (-1.0f32, frame.z_range.0),
            (1.0, frame.z_range.0),
            (1.0, frame.z_range.1),
            (-1.0, frame.z_range.1),
        ] {
            let corner = Point3::new(frame.axis.x, frame.axis.y, z) + along * (s * frame.reach);
            let (pixel, _) = camera.project(&corner.cast::<f64>()).ok_or_else(|| {
                RenderError::Readback("billboard corner behind the bake camera".into())
            })?;
            mesh.positions.push(corner);
            mesh.normals.push(*normal);
            mesh.uvs.push([
                ((offset as f64 + pixel.x) / atlas.width() as f64) as f32,
                (pixel.y / tile_height as f64) as f32,
            ]);
        }
        // Wound so that the rasterizer calls the side facing +normal (where the front tile
        // was baked from) the front face.
        mesh.triangles.push([base, base + 2, base + 1]);
        mesh.triangles.push([base, base + 3, base + 2]);
        bake_cameras.push(camera);
    }
    for part in &asset.parts {
        for p in &part.mesh.positions {
            let nearest = normals
                .iter()
                .map(|n| {
                    let offset = Vector3::new(p.x - frame.axis.x, p.y - frame.axis.y, 0.0);
                    offset.dot(n).abs()
                })
                .fold(f32::INFINITY, f32::min);
            error_world = error_world.max(nearest as f64);
        }
    }
    dilate_colors(&mut atlas, 8);
    Ok(StarBillboard {
        mesh,
        atlas,
        error_world,
        bake_cameras,
        back_uv_offset: 0.5,
    })
}

/// Spreads colour from the interior of the opaque texels (`rounds` rings) into the texels on
/// the silhouette, whose baked colour the multisampled render blended with the black
/// background, and into the transparent ones, so that filtered and mipmapped lookups do not
/// pull in the background. Alpha is kept.
fn dilate_colors(image: &mut RgbaImage, rounds: usize) {
    let (w, h) = image.dimensions();
    let opaque = |x: i64, y: i64| {
        x >= 0
            && y >= 0
            && x < w as i64
            && y < h as i64
            && image.get_pixel(x as u32, y as u32)[3] > 0
    };
    let mut filled: Vec<bool> = (0..h as i64)
        .flat_map(|y| (0..w as i64).map(move |x| (x, y)))
        .map(|(x, y)| {
            opaque(x, y)
                && opaque(x - 1, y)
                && opaque(x + 1, y)
                && opaque(x, y - 1)
                && opaque(x, y + 1)
        })
        .collect();
    for _ in 0..rounds {
        let mut updates = Vec::new();
        for y in 0..h {
            for x in 0..w {
                if filled[(y * w + x) as usize] {
                    continue;
                }
                let mut sum = [0u32; 3];
                let mut count = 0;
                for (dx, dy) in [(-1i32, 0i32), (1, 0), (0, -1), (0, 1)] {
                    let (nx, ny) = (x as i32 + dx, y as i32 + dy);
                    if nx < 0 || ny < 0 || nx >= w as i32 || ny >= h as i32 {
                        continue;
                    }
                    if filled[(ny as u32 * w + nx as u32) as usize] {
                        let p = image.get_pixel(nx as u32, ny as u32);
                        for c in 0..3 {
                            sum[c] += p[c] as u32;
                        }
                        count += 1;
                    }
                }
                if count > 0 {
                    updates.push((x, y, sum.map(|s| (s / count) as u8)));
                }
            }
        }
        if updates.is_empty() {
            break;
        }
        for (x, y, rgb) in updates {
            let alpha = image.get_pixel(x, y)[3];
            image.put_pixel(x, y, Rgba([rgb[0], rgb[1], rgb[2], alpha]));
            filled[(y * w + x) as usize] = true;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::{Preset, generate_plant, plant_model};

    fn silhouette(
        renderer: &mut Renderer,
        meshes: &[(&TriMesh, &RgbaImage, bool)],
        camera: &ViewCamera,
    ) -> Vec<bool> {
        let mut gpu = renderer.new_scene();
        for (mesh, texture, cutout) in meshes {
            let t = if *cutout {
                renderer.add_cutout_texture(&mut gpu, texture)
            } else {
                renderer.add_texture(&mut gpu, texture)
            };
            renderer.add_mesh(&mut gpu, mesh, t, 1, *cutout).unwrap();
        }
        let out = renderer.render(&gpu, camera, &Lighting::default()).unwrap();
        out.object_id.iter().map(|&id| id != 0).collect()
    }

    fn iou(a: &[bool], b: &[bool]) -> f64 {
        let both = a.iter().zip(b).filter(|(x, y)| **x && **y).count();
        let either = a.iter().zip(b).filter(|(x, y)| **x || **y).count();
        both as f64 / either.max(1) as f64
    }

    #[test]
    fn star_billboard_reproduces_the_plant_from_its_bake_directions_and_reads_from_all_sides() {
        let plant = generate_plant(Preset::Broadleaf, 5);
        let asset = PlantAsset::from_model(&plant_model(&plant, 64));
        let mut renderer = Renderer::new().unwrap();
        let star = bake_star(&mut renderer, &asset, &BillboardOptions::default()).unwrap();
        assert_eq!(star.mesh.triangles.len(), 6);
        for (t, tri) in star.mesh.triangles.iter().enumerate() {
            let geometric = {
                let [a, b, c] = star.mesh.corners(t);
                (b - a).cross(&(c - a)).normalize()
            };
            for &v in tri {
                assert!(star.mesh.normals[v as usize].dot(&geometric).abs() > 0.9999);
            }
        }
        let opaque = star.atlas.pixels().filter(|p| p[3] == 255).count();
        assert!(opaque > 0 && opaque < star.atlas.pixels().count());
        // μ is at most the plant's reach (every vertex lies within it of the axis).
        let (_, radius) = asset.bounding_sphere().unwrap();
        assert!(star.error_world > 0.0 && star.error_world < radius as f64);

        // Quad k alone, seen from its bake camera, covers what the plant covers.
        let parts: Vec<(&TriMesh, &RgbaImage, bool)> = asset
            .parts
            .iter()
            .map(|p| (&p.mesh, &asset.textures[p.texture], p.alpha_test))
            .collect();
        for (k, camera) in star.bake_cameras.iter().enumerate() {
            let mut quad = star.mesh.clone();
            quad.triangles = star.mesh.triangles[2 * k..2 * k + 2].to_vec();
            let plant_view = silhouette(&mut renderer, &parts, camera);
            let quad_view = silhouette(&mut renderer, &[(&quad, &star.atlas, true)], camera);
            let score = iou(&plant_view, &quad_view);
            assert!(score > 0.9, "quad {k}: silhouette IoU {score}");
        }

        // Alpha coverage over 36 azimuths varies by at most 30 % (LOD_NOTES check 14).
        let (center, _) = asset.bounding_sphere().unwrap();
        let coverages: Vec<usize> = (0..36)
            .map(|i| {
                let azimuth = (i as f64 * 10.0 + 5.0).to_radians();
                let distance = 8.0 * radius as f64;
                let eye = center.cast::<f64>()
                    + Vector3::new(azimuth.cos(), azimuth.sin(), 0.15) * distance;
                let camera = ViewCamera {
                    width: 160,
                    height: 160,
                    fx: 600.0,
                    fy: 600.0,
                    cx: 80.0,
                    cy: 80.0,
                    camera_from_world: look_at(eye, center.cast::<f64>()),
                    near: 0.1 * distance,
                    far: 3.0 * distance,
                };
                silhouette(&mut renderer, &[(&star.mesh, &star.atlas, true)], &camera)
                    .iter()
                    .filter(|&&c| c)
                    .count()
            })
            .collect();
        let (lo, hi) = (
            *coverages.iter().min().unwrap() as f64,
            *coverages.iter().max().unwrap() as f64,
        );
        assert!(lo > 0.0 && (hi - lo) / hi <= 0.3, "coverage {lo}..{hi}");
    }
}
