//! The far level: a star billboard (seed 000 §5 Fig. 9, seed 002's cross method) — vertical
//! quads through the plant's axis (six by default, 30° apart, 12 triangles), each quad's
//! normals equal to its plane normal, textured from an atlas the render core bakes by
//! rendering the plant perpendicular to each quad, from both sides and several elevations.
//! Drawn, each quad fades out as it turns edge-on and blends the elevations nearest the view.

use image::{Rgba, RgbaImage};
use nalgebra::{Point2, Point3, Vector3};

use super::asset::PlantAsset;
use crate::mesh::TriMesh;
use crate::render::{BillboardViews, Lighting, RenderError, Renderer, Shading, ViewCamera};
use crate::scene::synthetic::look_at;

/// Settings of [`bake_star`].
#[derive(Clone, Debug, PartialEq)]
pub struct BillboardOptions {
    /// Quads of the star (3: a star of three intersecting squares; 2: a cross).
    pub quads: usize,
    /// Texel height of each atlas tile (width follows the plant's aspect).
    pub tile_height: u32,
    /// View elevations baked per quad, `elevation_step_deg` apart from the horizon up (1: the
    /// horizontal view only).
    pub elevation_rows: usize,
    pub elevation_step_deg: f32,
}

impl Default for BillboardOptions {
    fn default() -> Self {
        Self {
            // Six quads, each drawn only where it faces the viewer most: with three (60°
            // apart) the billboard's brightness strayed 14–24 % RMS over the directions seen
            // from 5° up on two broadleaf plants, with six 7–8 %.
            quads: 6,
            tile_height: 256,
            // 0° to 60° in steps of 15°: one tile baked from the side made the plant 17–24 %
            // too dark seen from 15° to 60° up (leaves show more of their lit upper sides
            // there), and rows up to 45° left it 36–48 % short of light seen from 60°.
            elevation_rows: 5,
            elevation_step_deg: 15.0,
        }
    }
}

/// A baked star billboard.
#[derive(Clone, Debug)]
pub struct StarBillboard {
    /// Two triangles per quad (quad k is triangles 2k and 2k + 1), uvs into `atlas`'s first
    /// row.
    pub mesh: TriMesh,
    /// Rows of tiles, one row per baked elevation; in a row, each quad's front tile, then
    /// each quad's back tile. Alpha 255 where the plant covers the texel.
    pub atlas: RgbaImage,
    /// μ: largest distance from a vertex of the full plant to a quad plane it may be drawn on
    /// (every quad is drawn from some view, so the farthest plane).
    pub error_world: f64,
    /// The camera each quad's front tile was rendered from, per elevation row (row-major:
    /// `bake_cameras[row * quads + quad]`).
    pub bake_cameras: Vec<ViewCamera>,
    /// How the render core draws it: unlit, the back tiles' u offset, the elevation rows and
    /// the fading of quads seen edge-on (alpha as coverage is added by
    /// [`super::asset::AssetPart::shading`]).
    pub shading: Shading,
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

/// Bakes the star billboard of `asset`: one render per quad, side and elevation under the
/// render core's default light, seen from 2000 plant radii away (nearly parallel rays) along
/// the quad's normal tilted up by the row's elevation, with the vertical focal length
/// stretched by 1/cos(elevation) so that the quad's plane maps to the same texels in every
/// row. Each row holds what a viewer at that elevation sees through the quad (the plant
/// projected along the view onto the quad's plane), so the quads reach `reach · tan(highest
/// elevation)` below and above the plant. The billboard is meant to be drawn unlit
/// (`KHR_materials_unlit`) with its [`StarBillboard::shading`].
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
    let rows = options.elevation_rows.clamp(1, 8);
    let step = if rows > 1 && options.elevation_step_deg.is_finite() {
        options
            .elevation_step_deg
            .clamp(1.0, 80.0 / (rows - 1) as f32)
    } else {
        0.0
    }
    .to_radians();
    let highest = step * (rows - 1) as f32;
    let overhang = frame.reach * highest.tan();
    let z_range = (frame.z_range.0 - overhang, frame.z_range.1 + overhang);
    let height = z_range.1 - z_range.0;
    let tile_height = options.tile_height.clamp(8, 4096);
    let tile_width =
        ((tile_height as f32 * 2.0 * frame.reach / height).round() as u32).clamp(8, 4096);
    let mut gpu = renderer.new_scene();
    let parts: Vec<&super::asset::AssetPart> = asset.parts.iter().collect();
    let textures = super::asset::upload_textures(renderer, &mut gpu, &asset.textures, &parts);
    for part in &asset.parts {
        let texture = textures[part.texture];
        let handle = renderer.add_mesh(&mut gpu, &part.mesh, texture, 1, part.alpha_test)?;
        renderer.set_shading(&gpu, handle, part.shading())?;
    }
    // The tiles hold the plant as lit by the render core's default light, and the billboard
    // is drawn unlit: lighting the quads again with their own (vertical) normals made distant
    // plants darker than the plants they replace.
    let lit = Lighting::default();
    let center = Point3::new(frame.axis.x, frame.axis.y, 0.5 * (z_range.0 + z_range.1));
    let extent = frame.reach.max(0.5 * height) as f64;
    let distance = 2000.0 * extent;
    let fx = tile_width as f64 * distance / (2.0 * frame.reach as f64);
    let fy = tile_height as f64 * distance / height as f64;
    // Front tiles, then back tiles (each quad seen from behind, mirrored so that the quad's
    // uvs plus `back_uv_offset` address the same world points): the plant's sides are lit
    // differently, and a one-sided tile showed the lit side's mirror image from the dark side.
    let mut atlas = RgbaImage::new(2 * tile_width * quads as u32, tile_height * rows as u32);
    let mut mesh = TriMesh::default();
    let mut bake_cameras = Vec::with_capacity(quads * rows);
    let normals: Vec<Vector3<f32>> = (0..quads)
        .map(|k| {
            let angle = std::f32::consts::PI * k as f32 / quads as f32;
            Vector3::new(-angle.sin(), angle.cos(), 0.0)
        })
        .collect();
    let up = Vector3::z();
    for row in 0..rows {
        let elevation = (step * row as f32) as f64;
        for (k, normal) in normals.iter().enumerate() {
            let normal = normal.cast::<f64>();
            let camera_from = |side: f64| {
                let toward = normal * (side * elevation.cos()) + up * elevation.sin();
                ViewCamera {
                    width: tile_width,
                    height: tile_height,
                    fx,
                    fy: fy / elevation.cos(),
                    cx: 0.5 * tile_width as f64,
                    cy: 0.5 * tile_height as f64,
                    camera_from_world: look_at(
                        center.cast::<f64>() + toward * distance,
                        center.cast::<f64>(),
                    ),
                    near: distance - 2.0 * extent,
                    far: distance + 2.0 * extent,
                }
            };
            let y0 = row as u32 * tile_height;
            for (side, tile) in [(1.0, k), (-1.0, quads + k)] {
                let camera = camera_from(side);
                let out = renderer.render(&gpu, &camera, &lit)?;
                let x0 = tile as u32 * tile_width;
                for y in 0..tile_height {
                    for x in 0..tile_width {
                        // Back tiles mirrored: the quad's u runs the other way seen from
                        // behind.
                        let source = if side > 0.0 { x } else { tile_width - 1 - x };
                        let mut texel = *out.color.get_pixel(source, y);
                        texel[3] = if out.id_at(source, y) != 0 { 255 } else { 0 };
                        atlas.put_pixel(x0 + x, y0 + y, texel);
                    }
                }
                if side > 0.0 {
                    bake_cameras.push(camera);
                }
            }
        }
    }
    for (k, normal) in normals.iter().enumerate() {
        // The quad's corners, with uvs where the horizontal bake camera sees them (every
        // row's camera sees them at the same texels, a row lower).
        let camera = &bake_cameras[k];
        let along = Vector3::new(normal.y, -normal.x, 0.0);
        let base = mesh.positions.len() as u32;
        for (s, z) in [
            (-1.0f32, z_range.0),
            (1.0, z_range.0),
            (1.0, z_range.1),
            (-1.0, z_range.1),
        ] {
            let corner = Point3::new(frame.axis.x, frame.axis.y, z) + along * (s * frame.reach);
            let (pixel, _) = camera.project(&corner.cast::<f64>()).ok_or_else(|| {
                RenderError::Readback("billboard corner behind the bake camera".into())
            })?;
            mesh.positions.push(corner);
            mesh.normals.push(*normal);
            mesh.uvs.push([
                ((k as f64 * tile_width as f64 + pixel.x) / atlas.width() as f64) as f32,
                (pixel.y / atlas.height() as f64) as f32,
            ]);
        }
        // Wound so that the rasterizer calls the side facing +normal (where the front tile
        // was baked from) the front face.
        mesh.triangles.push([base, base + 2, base + 1]);
        mesh.triangles.push([base, base + 3, base + 2]);
    }
    // μ: how far a point of the plant is drawn from where it is. A point at distance d from
    // the quad that shows it is displaced by d·tan(φ) for a view φ off the direction the
    // quad was baked from; a quad is drawn within half the quads' spacing of its normal, and
    // a view's elevation lies within half a row step of a baked one (views above the last
    // row are not bounded).
    let spread = ((0.5 * std::f32::consts::PI / quads as f32).tan().powi(2)
        + (0.5 * step).tan().powi(2))
    .sqrt();
    let mut error_world = 0.0f64;
    for part in &asset.parts {
        for p in &part.mesh.positions {
            let offset = Vector3::new(p.x - frame.axis.x, p.y - frame.axis.y, 0.0);
            let farthest = normals
                .iter()
                .map(|n| offset.dot(n).abs())
                .fold(0.0f32, f32::max);
            error_world = error_world.max((farthest * spread) as f64);
        }
    }
    dilate_colors(&mut atlas, 8);
    Ok(StarBillboard {
        mesh,
        atlas,
        error_world,
        bake_cameras,
        shading: Shading {
            unlit: true,
            back_uv_offset: 0.5,
            views: Some(BillboardViews {
                elevation_rows: rows as u32,
                elevation_step_rad: step,
                quads: quads as u32,
                axis: [frame.axis.x, frame.axis.y],
                plant_z: [frame.z_range.0, frame.z_range.1],
            }),
            // Derived where it is drawn (`AssetPart::shading`: a cut-out with views).
            alpha_coverage: false,
        },
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
        shading: Shading,
    ) -> Vec<bool> {
        let mut gpu = renderer.new_scene();
        for (mesh, texture, cutout) in meshes {
            let t = if shading.views.is_some() {
                renderer.add_coverage_texture(&mut gpu, texture)
            } else if *cutout {
                renderer.add_cutout_texture(&mut gpu, texture)
            } else {
                renderer.add_texture(&mut gpu, texture)
            };
            let handle = renderer.add_mesh(&mut gpu, mesh, t, 1, *cutout).unwrap();
            let shading = Shading {
                alpha_coverage: shading.views.is_some(),
                ..shading
            };
            renderer.set_shading(&gpu, handle, shading).unwrap();
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
        assert_eq!(
            star.mesh.triangles.len(),
            2 * BillboardOptions::default().quads
        );
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

        // Every row's bake camera sees the quad's corners where the first row's does (the
        // uvs are shared, a row lower), to a tenth of a texel.
        let quads = star.mesh.triangles.len() / 2;
        assert_eq!(star.bake_cameras.len(), 5 * quads);
        for (i, camera) in star.bake_cameras.iter().enumerate() {
            let first = &star.bake_cameras[i % quads];
            for corner in &star.mesh.positions[4 * (i % quads)..4 * (i % quads) + 4] {
                let (a, _) = camera.project(&corner.cast::<f64>()).unwrap();
                let (b, _) = first.project(&corner.cast::<f64>()).unwrap();
                assert!((a - b).norm() < 0.1, "row {}: {a} against {b}", i / quads);
            }
        }

        // Quad k alone, seen from its bake camera at each elevation, covers what the plant
        // covers.
        let parts: Vec<(&TriMesh, &RgbaImage, bool)> = asset
            .parts
            .iter()
            .map(|p| (&p.mesh, &asset.textures[p.texture], p.alpha_test))
            .collect();
        for (i, camera) in star.bake_cameras.iter().enumerate() {
            let k = i % quads;
            let mut quad = star.mesh.clone();
            quad.triangles = star.mesh.triangles[2 * k..2 * k + 2].to_vec();
            let plant_view = silhouette(&mut renderer, &parts, camera, Shading::default());
            let quad_view = silhouette(
                &mut renderer,
                &[(&quad, &star.atlas, true)],
                camera,
                star.shading,
            );
            let score = iou(&plant_view, &quad_view);
            assert!(
                score > 0.9,
                "quad {k}, row {}: silhouette IoU {score}",
                i / quads
            );
        }

        // From every one of 36 azimuths, 20 plant radii away (where a far level is drawn), the
        // billboard covers about what the plant covers (it reads from all sides, LOD_NOTES
        // check 14, and follows the plant's silhouette).
        let (center, _) = asset.bounding_sphere().unwrap();
        let ratios: Vec<f64> = (0..36)
            .map(|i| {
                let azimuth = (i as f64 * 10.0 + 5.0).to_radians();
                let distance = 20.0 * radius as f64;
                let eye = center.cast::<f64>()
                    + Vector3::new(azimuth.cos(), azimuth.sin(), 0.15) * distance;
                let camera = ViewCamera {
                    width: 160,
                    height: 160,
                    fx: 1500.0,
                    fy: 1500.0,
                    cx: 80.0,
                    cy: 80.0,
                    camera_from_world: look_at(eye, center.cast::<f64>()),
                    near: 0.1 * distance,
                    far: 3.0 * distance,
                };
                let count = |covered: Vec<bool>| covered.iter().filter(|&&c| c).count() as f64;
                let plant = count(silhouette(
                    &mut renderer,
                    &parts,
                    &camera,
                    Shading::default(),
                ));
                let billboard = count(silhouette(
                    &mut renderer,
                    &[(&star.mesh, &star.atlas, true)],
                    &camera,
                    star.shading,
                ));
                billboard / plant.max(1.0)
            })
            .collect();
        let lo = ratios.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = ratios.iter().copied().fold(0.0, f64::max);
        eprintln!("coverage ratio {lo:.2}..{hi:.2}");
        assert!(lo > 0.7 && hi < 1.4, "coverage ratio {lo:.2}..{hi:.2}");
    }
}
