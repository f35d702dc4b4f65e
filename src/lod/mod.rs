//! Levels of detail for reconstructed plants (seeds 000, 002, 003): simplified levels,
//! screen-space-error selection.
//!
//! Takes a plant model (or glb); returns its levels (simplified meshes and a star billboard)
//! with their measured errors μ and switch distances, written as glTF with MSFT_lod.

pub mod asset;
pub mod billboard;
pub mod chain;
pub mod leaf_instancing;
pub mod plant;
pub mod quantize;
pub mod select;
pub mod simplify;
pub mod surfel;

/// Meshes shared by the LOD tests.
#[cfg(test)]
pub(crate) mod test_meshes {
    use crate::mesh::TriMesh;
    use nalgebra::Point3;

    /// An n×n grid of quads over [0, 1]², z = height(x, y), uv = (x, y).
    pub fn grid(n: usize, height: impl Fn(f32, f32) -> f32) -> TriMesh {
        let mut mesh = TriMesh::default();
        for j in 0..=n {
            for i in 0..=n {
                let (x, y) = (i as f32 / n as f32, j as f32 / n as f32);
                mesh.positions.push(Point3::new(x, y, height(x, y)));
                mesh.uvs.push([x, y]);
            }
        }
        let at = |i: usize, j: usize| (j * (n + 1) + i) as u32;
        for j in 0..n {
            for i in 0..n {
                mesh.triangles
                    .push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
                mesh.triangles
                    .push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
            }
        }
        mesh.compute_normals();
        mesh
    }
}
