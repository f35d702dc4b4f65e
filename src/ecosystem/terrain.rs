//! Height-map terrain (seed 003 §3, seed 000): altitude = scale × grey value on a regular
//! grid, bilinear heights, normals from central differences, and its render mesh.

use image::{GrayImage, Luma};
use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};

use crate::mesh::TriMesh;
use crate::util::rng::Rng;

/// A height field over `[0, size_x] × [0, size_y]` (metres), `columns × rows` samples.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Terrain {
    pub size_m: [f64; 2],
    pub columns: usize,
    pub rows: usize,
    /// Row-major heights in metres.
    pub heights_m: Vec<f32>,
}

/// Value noise on a lattice of `cells` per side, smoothly interpolated, in [0, 1].
struct ValueNoise {
    cells: usize,
    lattice: Vec<f32>,
}

impl ValueNoise {
    fn new(cells: usize, rng: &mut Rng) -> Self {
        let cells = cells.max(1);
        let lattice = (0..(cells + 1) * (cells + 1))
            .map(|_| rng.uniform() as f32)
            .collect();
        Self { cells, lattice }
    }

    fn sample(&self, u: f32, v: f32) -> f32 {
        let n = self.cells;
        let (x, y) = (u.clamp(0.0, 1.0) * n as f32, v.clamp(0.0, 1.0) * n as f32);
        let (i, j) = ((x as usize).min(n - 1), (y as usize).min(n - 1));
        let smooth = |t: f32| t * t * (3.0 - 2.0 * t);
        let (fx, fy) = (smooth(x - i as f32), smooth(y - j as f32));
        let at = |i: usize, j: usize| self.lattice[j * (n + 1) + i];
        let top = at(i, j) * (1.0 - fx) + at(i + 1, j) * fx;
        let bottom = at(i, j + 1) * (1.0 - fx) + at(i + 1, j + 1) * fx;
        top * (1.0 - fy) + bottom * fy
    }
}

/// Fractal (octave) value noise in [0, 1]: the seed-003 "Perlin-octave" mask, seeded.
pub fn fractal_noise(resolution: usize, octaves: usize, seed: u64) -> GrayImage {
    let mut rng = Rng::seed_from(seed);
    let layers: Vec<ValueNoise> = (0..octaves.max(1))
        .map(|o| ValueNoise::new(3 << o, &mut rng))
        .collect();
    let resolution = resolution.max(2) as u32;
    let mut values = vec![0.0f32; (resolution * resolution) as usize];
    let mut total = 0.0f32;
    for (o, layer) in layers.iter().enumerate() {
        let amplitude = 0.5f32.powi(o as i32);
        total += amplitude;
        for y in 0..resolution {
            for x in 0..resolution {
                let (u, v) = (
                    x as f32 / (resolution - 1) as f32,
                    y as f32 / (resolution - 1) as f32,
                );
                values[(y * resolution + x) as usize] += amplitude * layer.sample(u, v);
            }
        }
    }
    GrayImage::from_fn(resolution, resolution, |x, y| {
        Luma([(255.0 * values[(y * resolution + x) as usize] / total).round() as u8])
    })
}

impl Terrain {
    /// altitude = `height_scale_m` × grey / 255 per pixel (x along columns, y along rows).
    pub fn from_heightmap(image: &GrayImage, size_m: [f64; 2], height_scale_m: f64) -> Self {
        let (w, h) = image.dimensions();
        Self {
            size_m,
            columns: w.max(1) as usize,
            rows: h.max(1) as usize,
            heights_m: image
                .pixels()
                .map(|p| (height_scale_m * p[0] as f64 / 255.0) as f32)
                .collect(),
        }
    }

    fn spacing(&self) -> (f64, f64) {
        (
            self.size_m[0] / (self.columns.max(2) - 1) as f64,
            self.size_m[1] / (self.rows.max(2) - 1) as f64,
        )
    }

    fn at(&self, i: usize, j: usize) -> f64 {
        let i = i.min(self.columns - 1);
        let j = j.min(self.rows - 1);
        self.heights_m[j * self.columns + i] as f64
    }

    /// Bilinear height at `(x, y)` (clamped to the terrain).
    pub fn height(&self, x: f64, y: f64) -> f64 {
        let (dx, dy) = self.spacing();
        let gx = (x / dx).clamp(0.0, (self.columns - 1) as f64);
        let gy = (y / dy).clamp(0.0, (self.rows - 1) as f64);
        let (i, j) = (gx.floor() as usize, gy.floor() as usize);
        let (fx, fy) = (gx - i as f64, gy - j as f64);
        let top = self.at(i, j) * (1.0 - fx) + self.at(i + 1, j) * fx;
        let bottom = self.at(i, j + 1) * (1.0 - fx) + self.at(i + 1, j + 1) * fx;
        top * (1.0 - fy) + bottom * fy
    }

    /// Unit normal at `(x, y)` from central differences of the bilinear height.
    pub fn normal(&self, x: f64, y: f64) -> Vector3<f64> {
        let (dx, dy) = self.spacing();
        let gx = (self.height(x + dx, y) - self.height(x - dx, y)) / (2.0 * dx);
        let gy = (self.height(x, y + dy) - self.height(x, y - dy)) / (2.0 * dy);
        Vector3::new(-gx, -gy, 1.0).normalize()
    }

    /// The render mesh: one vertex per sample, uv repeating every `metres_per_texture`.
    pub fn mesh(&self, metres_per_texture: f64) -> TriMesh {
        let (dx, dy) = self.spacing();
        let mut mesh = TriMesh::default();
        for j in 0..self.rows {
            for i in 0..self.columns {
                let (x, y) = (i as f64 * dx, j as f64 * dy);
                mesh.positions
                    .push(Point3::new(x as f32, y as f32, self.at(i, j) as f32));
                mesh.normals.push(self.normal(x, y).cast::<f32>());
                mesh.uvs.push([
                    (x / metres_per_texture) as f32,
                    (y / metres_per_texture) as f32,
                ]);
            }
        }
        let index = |i: usize, j: usize| (j * self.columns + i) as u32;
        for j in 0..self.rows.saturating_sub(1) {
            for i in 0..self.columns.saturating_sub(1) {
                mesh.triangles
                    .push([index(i, j), index(i + 1, j), index(i + 1, j + 1)]);
                mesh.triangles
                    .push([index(i, j), index(i + 1, j + 1), index(i, j + 1)]);
            }
        }
        mesh
    }
}

/// Plant orientation on the terrain (seed 003): up = normalize(w·n + (1 − w)·z).
pub fn plant_up(normal: &Vector3<f64>, weight: f64) -> Vector3<f64> {
    let w = weight.clamp(0.0, 1.0);
    (normal * w + Vector3::z() * (1.0 - w)).normalize()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn altitude_is_scale_times_grey_and_normals_match_finite_differences() {
        let image = GrayImage::from_fn(9, 9, |x, y| Luma([(10 * x + 20 * y) as u8]));
        let terrain = Terrain::from_heightmap(&image, [8.0, 8.0], 2.55);
        // A plane: z = 0.1·x + 0.2·y on the 1 m grid.
        assert!((terrain.height(3.0, 5.0) - (0.3 + 1.0)).abs() < 1e-6);
        assert!((terrain.height(2.5, 4.25) - (0.25 + 0.85)).abs() < 1e-6);
        let n = terrain.normal(4.0, 4.0);
        let expected = Vector3::new(-0.1, -0.2, 1.0).normalize();
        assert!((n - expected).norm() < 1e-6, "{n:?}");
        let mesh = terrain.mesh(1.0);
        assert_eq!(mesh.triangles.len(), 2 * 8 * 8);
        mesh.validate().unwrap();
    }

    #[test]
    fn orientation_blends_upright_and_terrain_normal() {
        let n = Vector3::new(0.3, 0.0, 1.0).normalize();
        assert!((plant_up(&n, 0.0) - Vector3::z()).norm() < 1e-12);
        assert!((plant_up(&n, 1.0) - n).norm() < 1e-12);
    }

    #[test]
    fn fractal_noise_is_seeded_and_spans_a_range() {
        let a = fractal_noise(64, 4, 7);
        assert_eq!(a, fractal_noise(64, 4, 7));
        assert_ne!(a, fractal_noise(64, 4, 8));
        let (lo, hi) = a
            .pixels()
            .fold((255u8, 0u8), |(lo, hi), p| (lo.min(p[0]), hi.max(p[0])));
        assert!(hi - lo > 60, "{lo}..{hi}");
    }
}
