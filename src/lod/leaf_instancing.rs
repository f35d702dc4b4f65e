//! Approximate instancing below the plant (seed 003 applied to leaves): every leaf is described
//! in its own frame (centroid, main axis, normal) by its shape relative to its length — width
//! and mean height at eight stations along the main axis — and the leaves are clustered by the
//! same variance-minimising splits as whole plants (weighted by leaf area). Each cluster keeps
//! one master leaf, the member nearest the cluster's mean; every other member becomes an
//! instance of it: the master's mesh moved into the member's frame and scaled to its length.
//!
//! Reported per number of masters: unique meshes, geometry memory against the exact plant, the
//! geometric error (largest distance from an exact leaf's vertex to its instance, and back) and
//! the pixel error (renders of the exact and the instanced plant from several views: pixels
//! whose leaf coverage differs, over the exact plant's pixels).

use nalgebra::{Matrix3, Matrix4, Point3, Rotation3, Vector3};
use serde::Serialize;

use super::quantize::quantize;
use crate::mesh::TriMesh;

/// Stations along the main axis of the shape descriptor.
const STATIONS: usize = 8;

/// A leaf's own frame: where it is, how it is turned, how long it is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LeafFrame {
    pub origin_world: Point3<f64>,
    /// Columns: main axis (base to tip), across, normal.
    pub world_from_leaf: Rotation3<f64>,
    pub length: f64,
}

impl LeafFrame {
    /// World from the leaf frame scaled to unit length.
    fn world_from_unit(&self) -> Matrix4<f64> {
        let mut m = Matrix4::identity();
        m.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&(self.world_from_leaf.matrix() * self.length));
        m.fixed_view_mut::<3, 1>(0, 3)
            .copy_from(&self.origin_world.coords);
        m
    }
}

/// The frame of a leaf mesh: area-weighted centroid and principal axes of its triangles; the
/// main axis points to the narrower end (leaves are widest near the base, so the area's
/// third moment along the axis is negative toward the tip... the sign is fixed by the side
/// with more area), the normal to the side its triangles face.
pub fn leaf_frame(mesh: &TriMesh) -> Option<LeafFrame> {
    let mut area = 0.0;
    let mut centroid = Vector3::zeros();
    let triangles: Vec<(Vector3<f64>, f64)> = (0..mesh.triangles.len())
        .map(|t| {
            let [a, b, c] = mesh.corners(t).map(|p| p.cast::<f64>().coords);
            ((a + b + c) / 3.0, 0.5 * (b - a).cross(&(c - a)).norm())
        })
        .collect();
    for (c, a) in &triangles {
        centroid += c * *a;
        area += a;
    }
    if area <= 0.0 {
        return None;
    }
    centroid /= area;
    let mut covariance = Matrix3::zeros();
    for p in &mesh.positions {
        let d = p.cast::<f64>().coords - centroid;
        covariance += d * d.transpose();
    }
    let eigen = covariance.symmetric_eigen();
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eigen.eigenvalues[b].total_cmp(&eigen.eigenvalues[a]));
    let mut main: Vector3<f64> = eigen.eigenvectors.column(order[0]).into_owned();
    let mut normal: Vector3<f64> = eigen.eigenvectors.column(order[2]).into_owned();
    // More area behind the centroid than ahead means the wide base is behind: keep the axis
    // pointing to the tip.
    let skew: f64 = triangles
        .iter()
        .map(|(c, a)| a * (c - centroid).dot(&main).powi(3))
        .sum();
    if skew > 0.0 {
        main = -main;
    }
    if normal.dot(&mesh.mean_normal().cast::<f64>()) < 0.0 {
        normal = -normal;
    }
    let across = normal.cross(&main);
    let normal = main.cross(&across);
    let (lo, hi) = mesh
        .positions
        .iter()
        .fold((f64::MAX, f64::MIN), |(lo, hi), p| {
            let t = (p.cast::<f64>().coords - centroid).dot(&main);
            (lo.min(t), hi.max(t))
        });
    let length = hi - lo;
    (length > 0.0).then(|| LeafFrame {
        origin_world: Point3::from(centroid),
        world_from_leaf: Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[
            main, across, normal,
        ])),
        length,
    })
}

/// Shape relative to length: half-width and mean height at `STATIONS` stations along the main
/// axis, each over the length.
fn descriptor(mesh: &TriMesh, frame: &LeafFrame) -> Vec<f64> {
    let leaf_from_world = frame.world_from_leaf.inverse();
    let mut width = [0.0f64; STATIONS];
    let mut height = [(0.0f64, 0usize); STATIONS];
    for p in &mesh.positions {
        let local = leaf_from_world * (p.cast::<f64>() - frame.origin_world) / frame.length;
        let s = (((local.x + 0.5) * STATIONS as f64).floor() as i64).clamp(0, STATIONS as i64 - 1)
            as usize;
        width[s] = width[s].max(local.y.abs());
        height[s].0 += local.z;
        height[s].1 += 1;
    }
    width
        .iter()
        .copied()
        .chain(height.iter().map(|(sum, n)| sum / (*n).max(1) as f64))
        .collect()
}

/// One leaf replaced by an instance of `master`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LeafInstance {
    pub master: usize,
    /// World from the master's mesh (its own world coordinates).
    pub world_from_master: Matrix4<f64>,
}

/// The leaves of a plant as instances of a few masters.
#[derive(Clone, Debug)]
pub struct LeafInstancing {
    /// Leaf index of each master.
    pub masters: Vec<usize>,
    /// One per leaf (a master is an instance of itself, with the identity).
    pub instances: Vec<LeafInstance>,
}

/// Clusters `leaves` into at most `masters` shapes.
pub fn instance_leaves(leaves: &[TriMesh], masters: usize) -> LeafInstancing {
    let frames: Vec<Option<LeafFrame>> = leaves.iter().map(leaf_frame).collect();
    let vectors: Vec<Vec<f64>> = leaves
        .iter()
        .zip(&frames)
        .map(|(mesh, frame)| match frame {
            Some(frame) => descriptor(mesh, frame),
            None => vec![0.0; 2 * STATIONS],
        })
        .collect();
    let weights: Vec<f64> = leaves.iter().map(|m| m.area().max(1e-12)).collect();
    let codebook = quantize(&vectors, &weights, masters.max(1));
    let instances = (0..leaves.len())
        .map(|i| {
            let cluster = codebook.assignment[i];
            let master = codebook.representatives[cluster];
            let world_from_master = match (frames[i], frames[master]) {
                _ if master == i => Matrix4::identity(),
                (Some(member), Some(source)) => {
                    let unit_from_world = source
                        .world_from_unit()
                        .try_inverse()
                        .unwrap_or_else(Matrix4::identity);
                    member.world_from_unit() * unit_from_world
                }
                _ => Matrix4::identity(),
            };
            LeafInstance {
                master: codebook
                    .representatives
                    .iter()
                    .position(|&r| r == master)
                    .unwrap_or(0),
                world_from_master,
            }
        })
        .collect();
    LeafInstancing {
        masters: codebook.representatives.clone(),
        instances,
    }
}

impl LeafInstancing {
    /// The mesh instance `i` draws (the master's mesh moved into leaf `i`'s place).
    pub fn instance_mesh(&self, leaves: &[TriMesh], i: usize) -> TriMesh {
        let instance = &self.instances[i];
        let mut mesh = leaves[self.masters[instance.master]].clone();
        let m = instance.world_from_master;
        for p in &mut mesh.positions {
            let q = m.transform_point(&p.cast::<f64>());
            *p = q.cast::<f32>();
        }
        mesh.compute_normals();
        mesh
    }
}

/// Largest distance from a vertex of either mesh to the other's nearest vertex (a symmetric
/// Hausdorff distance over vertices).
fn vertex_hausdorff(a: &TriMesh, b: &TriMesh) -> f64 {
    let one_way = |from: &TriMesh, to: &TriMesh| {
        from.positions
            .iter()
            .map(|p| {
                to.positions
                    .iter()
                    .map(|q| (p - q).norm() as f64)
                    .fold(f64::INFINITY, f64::min)
            })
            .fold(0.0f64, f64::max)
    };
    one_way(a, b).max(one_way(b, a))
}

/// One row of the instancing curve.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct InstancingLevel {
    pub masters_asked: usize,
    /// Unique leaf meshes.
    pub unique_meshes: usize,
    pub leaves: usize,
    /// Leaf geometry bytes (32 per vertex, 12 per triangle, 64 per instance transform) over
    /// the exact leaves' bytes.
    pub memory_ratio: f64,
    /// Largest vertex Hausdorff distance between an exact item (leaf or twig) and its
    /// instance, over the median item length.
    pub max_error_lengths: f64,
    /// Median over the items of the same distance, over the median item length.
    pub median_error_lengths: f64,
    /// Pixels whose leaf coverage differs from the exact plant's, over the exact plant's
    /// leaf pixels (mean of the views).
    pub pixel_error: f64,
}

fn leaf_bytes(mesh: &TriMesh) -> usize {
    32 * mesh.positions.len() + 12 * mesh.triangles.len()
}

/// Leaf coverage masks of a set of leaf meshes from `views`.
fn coverage(
    renderer: &mut crate::render::Renderer,
    leaves: &[TriMesh],
    views: &[crate::render::ViewCamera],
) -> Result<Vec<Vec<bool>>, crate::render::RenderError> {
    let mut scene = renderer.new_scene();
    let white = renderer.add_texture(
        &mut scene,
        &image::RgbaImage::from_pixel(1, 1, image::Rgba([255; 4])),
    );
    for leaf in leaves {
        renderer.add_mesh(&mut scene, leaf, white, 1, false)?;
    }
    views
        .iter()
        .map(|v| {
            let out = renderer.render(&scene, v, &crate::render::Lighting::default())?;
            Ok(out.object_id.iter().map(|&id| id != 0).collect())
        })
        .collect()
}

/// The instancing curve of a plant's leaves: for each number of masters asked, what the
/// instanced leaves cost and how far they are from the exact ones (geometry and pixels from
/// six views around the plant, 30° above the horizon, `size_px` square).
pub fn instancing_curve(
    renderer: &mut crate::render::Renderer,
    leaves: &[TriMesh],
    up: &Vector3<f64>,
    masters: &[usize],
    size_px: u32,
) -> Result<Vec<InstancingLevel>, crate::render::RenderError> {
    let points: Vec<Point3<f64>> = leaves
        .iter()
        .flat_map(|m| m.positions.iter().map(|p| p.cast::<f64>()))
        .collect();
    let Some(mut orbit) = crate::render::Orbit::framing(&points, up) else {
        return Ok(Vec::new());
    };
    orbit.pitch = 30f64.to_radians();
    let views: Vec<_> = (0..6)
        .map(|k| {
            let mut o = orbit;
            o.yaw += std::f64::consts::TAU * k as f64 / 6.0;
            o.view_camera(size_px, size_px)
        })
        .collect();
    let exact = coverage(renderer, leaves, &views)?;
    let exact_bytes: usize = leaves.iter().map(leaf_bytes).sum();
    let lengths: Vec<f64> = leaves
        .iter()
        .filter_map(leaf_frame)
        .map(|f| f.length)
        .collect();
    let median_length = crate::util::stats::median(lengths)
        .unwrap_or(1.0)
        .max(1e-12);
    let mut rows = Vec::with_capacity(masters.len());
    for &asked in masters {
        let instancing = instance_leaves(leaves, asked);
        let instanced: Vec<TriMesh> = (0..leaves.len())
            .map(|i| instancing.instance_mesh(leaves, i))
            .collect();
        let mut errors: Vec<f64> = leaves
            .iter()
            .zip(&instanced)
            .map(|(a, b)| vertex_hausdorff(a, b) / median_length)
            .collect();
        errors.sort_by(f64::total_cmp);
        let drawn = coverage(renderer, &instanced, &views)?;
        let pixel_error = exact
            .iter()
            .zip(&drawn)
            .map(|(a, b)| {
                let differing = a.iter().zip(b).filter(|(x, y)| x != y).count();
                let covered = a.iter().filter(|&&x| x).count().max(1);
                differing as f64 / covered as f64
            })
            .sum::<f64>()
            / views.len() as f64;
        let unique: usize = instancing
            .masters
            .iter()
            .map(|&m| leaf_bytes(&leaves[m]))
            .sum();
        rows.push(InstancingLevel {
            masters_asked: asked,
            unique_meshes: instancing.masters.len(),
            leaves: leaves.len(),
            memory_ratio: (unique + 64 * leaves.len()) as f64 / exact_bytes.max(1) as f64,
            max_error_lengths: errors.last().copied().unwrap_or(0.0),
            median_error_lengths: crate::util::stats::quantile_sorted(&errors, 0.5),
            pixel_error,
        });
    }
    Ok(rows)
}

/// A glb's plant split for leaf instancing: each leaf (a connected piece of a leaf part, so
/// merged atlas pages come apart) with the image it is textured from, and every other part
/// (wood) as it is.
#[derive(Clone, Debug)]
pub struct GlbLeaves {
    pub leaves: Vec<TriMesh>,
    pub leaf_images: Vec<Option<usize>>,
    pub wood: Vec<crate::model::gltf::GlbPart>,
    pub images: Vec<image::RgbaImage>,
    pub up_world: Vector3<f64>,
}

/// Reads a plant glb for leaf instancing (leaves: nodes named `leaf*` or cut-out materials).
pub fn read_glb_leaves(path: &std::path::Path) -> Result<GlbLeaves, crate::model::gltf::GltfError> {
    let bytes = std::fs::read(path).map_err(|e| crate::model::gltf::GltfError::Invalid {
        path: path.display().to_string(),
        message: e.to_string(),
    })?;
    let parts = crate::model::gltf::read_glb_parts(&bytes, path)?;
    let up_world = crate::model::gltf::read_glb_up(&bytes, path)?.unwrap_or_else(Vector3::z);
    let mut out = GlbLeaves {
        leaves: Vec::new(),
        leaf_images: Vec::new(),
        wood: Vec::new(),
        images: parts.images,
        up_world,
    };
    for part in parts.parts {
        if part.name.starts_with("leaf") || part.alpha_mask {
            for piece in part.mesh.connected_components() {
                out.leaves.push(piece);
                out.leaf_images.push(part.image);
            }
        } else {
            out.wood.push(part);
        }
    }
    Ok(out)
}

/// A glb builder for an instanced plant: the plant's up direction in the asset's extras and
/// its images added as textures (their indices, in order).
fn instanced_builder(plant: &GlbLeaves) -> (crate::model::gltf::GlbBuilder, Vec<usize>) {
    use crate::model::gltf::{GlbBuilder, UP_KEY};
    let mut builder = GlbBuilder::new(&format!("frond {}", env!("CARGO_PKG_VERSION")));
    builder.set_asset_extras(serde_json::json!({
        UP_KEY: [plant.up_world.x, plant.up_world.y, plant.up_world.z]
    }));
    let textures = plant
        .images
        .iter()
        .map(|i| builder.add_texture(i))
        .collect();
    (builder, textures)
}

/// One scene node per instance (`{prefix}_NNN`), using its master's mesh with the instance
/// transform as its `matrix`; instances whose master has no mesh are skipped.
fn add_instance_nodes(
    builder: &mut crate::model::gltf::GlbBuilder,
    instancing: &LeafInstancing,
    master_meshes: &[Option<usize>],
    prefix: &str,
) {
    for (i, instance) in instancing.instances.iter().enumerate() {
        let Some(mesh) = master_meshes[instance.master] else {
            continue;
        };
        let matrix: Vec<f64> = instance.world_from_master.iter().copied().collect();
        let node = builder.add_node(serde_json::json!({
            "name": format!("{prefix}_{i:03}"),
            "mesh": mesh,
            "matrix": matrix,
        }));
        builder.add_to_scene(node);
    }
}

/// The plant with its leaves instanced, as a glb any viewer reads: one mesh per master leaf,
/// and a node per leaf that uses its master's mesh with the instance transform as its
/// `matrix` (glTF's own instancing: nodes sharing a mesh); wood as it was.
pub fn write_instanced_glb(plant: &GlbLeaves, instancing: &LeafInstancing) -> Vec<u8> {
    use crate::model::gltf::PrimitiveSpec;
    let (mut builder, textures) = instanced_builder(plant);
    let master_meshes: Vec<Option<usize>> = instancing
        .masters
        .iter()
        .enumerate()
        .map(|(k, &leaf)| {
            builder.add_mesh(
                &format!("leaf_master_{k:03}"),
                &[PrimitiveSpec::leaf(
                    &plant.leaves[leaf],
                    plant.leaf_images[leaf].and_then(|i| textures.get(i).copied()),
                )],
            )
        })
        .collect();
    add_instance_nodes(&mut builder, instancing, &master_meshes, "leaf");
    for (k, part) in plant.wood.iter().enumerate() {
        let mesh = builder.add_mesh(
            &part.name,
            &[PrimitiveSpec {
                alpha_mask: part.alpha_mask,
                shading: part.shading,
                ..PrimitiveSpec::solid(
                    &part.mesh,
                    part.image.and_then(|i| textures.get(i).copied()),
                    part.color,
                )
            }],
        );
        if let Some(mesh) = mesh {
            let node = builder.add_node(serde_json::json!({
                "name": if part.name.is_empty() { format!("wood_{k}") } else { part.name.clone() },
                "mesh": mesh,
            }));
            builder.add_to_scene(node);
        }
    }
    builder.finish()
}

/// A twig: a tube without child tubes and the leaves whose base lies nearest to it.
#[derive(Clone, Debug)]
pub struct Twig {
    pub wood: TriMesh,
    /// Index into [`GlbLeaves::wood`] of the part the tube came from (its material).
    pub wood_part: usize,
    /// Indices into [`GlbLeaves::leaves`].
    pub leaves: Vec<usize>,
}

impl Twig {
    /// The tube and its leaves as one mesh.
    pub fn mesh(&self, plant: &GlbLeaves) -> TriMesh {
        let mut mesh = self.wood.clone();
        for &leaf in &self.leaves {
            mesh.append(&plant.leaves[leaf]);
        }
        mesh
    }
}

/// The twigs of a plant: its wood comes apart into tubes, the tubes form a tree
/// ([`crate::branch::tube`]), and every leaf joins the tube its base (the end of its main axis
/// away from the tip) lies nearest to; the tubes without children that got leaves are twigs.
pub fn twigs(plant: &GlbLeaves) -> Vec<Twig> {
    use crate::branch::tube::{branch_tree, distance_to_polyline, tube_axis};
    let mut tubes = Vec::new();
    let mut axes = Vec::new();
    for (k, part) in plant.wood.iter().enumerate() {
        for piece in part.mesh.connected_components() {
            if let Some(axis) = tube_axis(&piece) {
                tubes.push((piece, k));
                axes.push(axis);
            }
        }
    }
    if tubes.is_empty() {
        return Vec::new();
    }
    let parents = branch_tree(&mut axes, &plant.up_world);
    let mut leaves_of = vec![Vec::new(); tubes.len()];
    for (i, leaf) in plant.leaves.iter().enumerate() {
        let Some(frame) = leaf_frame(leaf) else {
            continue;
        };
        let base = frame.origin_world - frame.world_from_leaf * Vector3::x() * (0.5 * frame.length);
        let nearest = (0..axes.len()).min_by(|&a, &b| {
            distance_to_polyline(&base, &axes[a].0)
                .total_cmp(&distance_to_polyline(&base, &axes[b].0))
        });
        if let Some(t) = nearest {
            leaves_of[t].push(i);
        }
    }
    tubes
        .into_iter()
        .zip(leaves_of)
        .enumerate()
        .filter(|(t, (_, leaves))| !leaves.is_empty() && !parents.contains(&Some(*t)))
        .map(|(_, ((wood, wood_part), leaves))| Twig {
            wood,
            wood_part,
            leaves,
        })
        .collect()
}

/// The plant with its twigs instanced (`instancing` made from the twigs' meshes, in order), as
/// a glb: one mesh per master twig (its tube and its leaves, by material), a node per twig
/// using its master's mesh with the instance transform; every leaf and tube outside the twigs
/// as it was.
pub fn write_instanced_twigs_glb(
    plant: &GlbLeaves,
    twigs: &[Twig],
    instancing: &LeafInstancing,
) -> Vec<u8> {
    use crate::model::gltf::PrimitiveSpec;
    let (mut builder, textures) = instanced_builder(plant);
    let leaf_primitives = |leaves: &[usize]| -> Vec<(TriMesh, Option<usize>)> {
        let mut by_image: Vec<(TriMesh, Option<usize>)> = Vec::new();
        for &leaf in leaves {
            let image = plant.leaf_images[leaf].and_then(|i| textures.get(i).copied());
            match by_image.iter_mut().find(|(_, im)| *im == image) {
                Some((mesh, _)) => mesh.append(&plant.leaves[leaf]),
                None => by_image.push((plant.leaves[leaf].clone(), image)),
            }
        }
        by_image
    };
    let wood_spec = |mesh: &TriMesh, part: usize| {
        let source = &plant.wood[part];
        (
            mesh.clone(),
            source.image.and_then(|i| textures.get(i).copied()),
            source.color,
        )
    };
    let master_meshes: Vec<Option<usize>> = instancing
        .masters
        .iter()
        .enumerate()
        .map(|(k, &t)| {
            let twig = &twigs[t];
            let (wood, wood_texture, wood_color) = wood_spec(&twig.wood, twig.wood_part);
            let leaves = leaf_primitives(&twig.leaves);
            let mut primitives = vec![PrimitiveSpec::solid(&wood, wood_texture, wood_color)];
            primitives.extend(
                leaves
                    .iter()
                    .map(|(mesh, texture)| PrimitiveSpec::leaf(mesh, *texture)),
            );
            builder.add_mesh(&format!("twig_master_{k:03}"), &primitives)
        })
        .collect();
    add_instance_nodes(&mut builder, instancing, &master_meshes, "twig");
    // What is not in a twig: its leaves one by one, the wood whole minus the twigs' tubes.
    let in_twig: std::collections::BTreeSet<usize> = twigs
        .iter()
        .flat_map(|t| t.leaves.iter().copied())
        .collect();
    for (i, leaf) in plant
        .leaves
        .iter()
        .enumerate()
        .filter(|(i, _)| !in_twig.contains(i))
    {
        let texture = plant.leaf_images[i].and_then(|im| textures.get(im).copied());
        if let Some(mesh) = builder.add_mesh(
            &format!("leaf_{i:03}"),
            &[PrimitiveSpec::leaf(leaf, texture)],
        ) {
            let node =
                builder.add_node(serde_json::json!({"name": format!("leaf_{i:03}"), "mesh": mesh}));
            builder.add_to_scene(node);
        }
    }
    let twig_wood: Vec<&TriMesh> = twigs.iter().map(|t| &t.wood).collect();
    for (k, part) in plant.wood.iter().enumerate() {
        let mut rest = TriMesh::default();
        for piece in part.mesh.connected_components() {
            if !twig_wood.iter().any(|w| w.positions == piece.positions) {
                rest.append(&piece);
            }
        }
        let (mesh, texture, color) = wood_spec(&rest, k);
        if let Some(mesh_index) = builder.add_mesh(
            &format!("wood_{k}"),
            &[PrimitiveSpec::solid(&mesh, texture, color)],
        ) {
            let node = builder
                .add_node(serde_json::json!({"name": format!("wood_{k}"), "mesh": mesh_index}));
            builder.add_to_scene(node);
        }
    }
    builder.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn leaves() -> Vec<TriMesh> {
        let (_, model) = crate::ecosystem::folder::built_in_plant(5, 1);
        model.leaves.into_iter().map(|l| l.mesh).collect()
    }

    #[test]
    fn a_leaf_instanced_from_itself_is_itself_and_frames_are_right_handed() {
        let leaves = leaves();
        for leaf in &leaves {
            let frame = leaf_frame(leaf).expect("frame");
            let m = frame.world_from_leaf.matrix();
            assert!((m.determinant() - 1.0).abs() < 1e-9);
            assert!(frame.length > 0.0);
        }
        let all = instance_leaves(&leaves, leaves.len());
        assert_eq!(all.masters.len(), leaves.len());
        for (i, leaf) in leaves.iter().enumerate() {
            assert!(vertex_hausdorff(leaf, &all.instance_mesh(&leaves, i)) < 1e-6);
        }
    }

    #[test]
    fn the_instanced_glb_reads_back_as_the_instances() {
        let dir = tempfile::tempdir().unwrap();
        let (_, model) = crate::ecosystem::folder::built_in_plant(5, 1);
        model.export(dir.path()).unwrap();
        let plant = read_glb_leaves(&dir.path().join("plant.glb")).unwrap();
        assert_eq!(plant.leaves.len(), model.leaves.len());
        assert_eq!(plant.wood.len(), model.branches.len());
        let instancing = instance_leaves(&plant.leaves, 6);
        let path = dir.path().join("instanced.glb");
        std::fs::write(&path, write_instanced_glb(&plant, &instancing)).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let text = String::from_utf8_lossy(&bytes);
        assert_eq!(
            text.matches("leaf_master_").count(),
            6 * 2,
            "6 meshes and their materials"
        );
        let back = read_glb_leaves(&path).unwrap();
        assert_eq!(back.leaves.len(), plant.leaves.len());
        assert_eq!(back.wood.len(), plant.wood.len());
        // Every leaf read back is its instance, placed by the node's matrix.
        let expected: Vec<TriMesh> = (0..plant.leaves.len())
            .map(|i| instancing.instance_mesh(&plant.leaves, i))
            .collect();
        for leaf in &back.leaves {
            let best = expected
                .iter()
                .map(|e| vertex_hausdorff(leaf, e))
                .fold(f64::INFINITY, f64::min);
            assert!(
                best < 1e-4,
                "a leaf read back is {best} from every instance"
            );
        }
    }

    #[test]
    fn twigs_are_petioles_with_their_leaves_and_instance_like_leaves() {
        let dir = tempfile::tempdir().unwrap();
        let (_, model) = crate::ecosystem::folder::built_in_plant(5, 1);
        model.export(dir.path()).unwrap();
        let plant = read_glb_leaves(&dir.path().join("plant.glb")).unwrap();
        let twigs = twigs(&plant);
        // The synthetic plant carries most leaves on petioles of their own.
        let leaves_in_twigs: usize = twigs.iter().map(|t| t.leaves.len()).sum();
        assert!(
            twigs.len() * 2 > plant.leaves.len(),
            "{} twigs",
            twigs.len()
        );
        assert!(
            leaves_in_twigs * 10 > plant.leaves.len() * 8,
            "{leaves_in_twigs}"
        );
        let meshes: Vec<TriMesh> = twigs.iter().map(|t| t.mesh(&plant)).collect();
        let instancing = instance_leaves(&meshes, 8);
        assert_eq!(instancing.masters.len(), 8);
        let path = dir.path().join("twigs.glb");
        std::fs::write(
            &path,
            write_instanced_twigs_glb(&plant, &twigs, &instancing),
        )
        .unwrap();
        let back = read_glb_leaves(&path).unwrap();
        // The leaves outside twigs, and in each twig the leaves of its master.
        let outside = plant.leaves.len() - leaves_in_twigs;
        let instanced: usize = instancing
            .instances
            .iter()
            .map(|i| twigs[instancing.masters[i.master]].leaves.len())
            .sum();
        assert_eq!(back.leaves.len(), outside + instanced);
        let mut renderer = crate::render::Renderer::new().expect("renderer");
        let curve = instancing_curve(
            &mut renderer,
            &meshes,
            &Vector3::z(),
            &[1, 8, meshes.len()],
            160,
        )
        .unwrap();
        assert!(curve[0].memory_ratio < curve[1].memory_ratio);
        assert!(curve[2].pixel_error < 1e-9, "{curve:?}");
    }

    #[test]
    fn more_masters_cost_more_and_err_less() {
        let leaves = leaves();
        let mut renderer = crate::render::Renderer::new().expect("renderer");
        let curve = instancing_curve(
            &mut renderer,
            &leaves,
            &Vector3::z(),
            &[1, 4, 16, leaves.len()],
            160,
        )
        .unwrap();
        for pair in curve.windows(2) {
            assert!(pair[1].unique_meshes > pair[0].unique_meshes);
            assert!(pair[1].memory_ratio > pair[0].memory_ratio);
            assert!(
                pair[1].median_error_lengths <= pair[0].median_error_lengths + 1e-9,
                "{curve:?}"
            );
        }
        let exact = curve.last().unwrap();
        assert!(
            exact.max_error_lengths < 1e-6 && exact.pixel_error < 1e-9,
            "{exact:?}"
        );
        // One master for ~100 leaves: a sixth of the memory or less, and leaves still where
        // the exact ones are (instances are placed and scaled by each leaf's own frame).
        let one = &curve[0];
        assert!(one.memory_ratio < 0.2, "{one:?}");
        assert!(one.median_error_lengths < 0.5, "{one:?}");
    }
}
