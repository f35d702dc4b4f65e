//! The generic deformable leaf (seed 004 §6.1): two margin polylines and a midrib of about ten
//! vertices each, in a local frame whose x axis runs from the base (x = 0) to the tip (x = 1),
//! with the texture inside the boundary. Every reconstructed leaf is this template, affinely
//! warped, bent out of its plane and re-textured.

use image::{Rgba, RgbaImage};
use nalgebra::Point2;
use serde::{Deserialize, Serialize};

use crate::mesh::TriMesh;
use crate::util::polyline::resample;

/// Vertices per polyline (seed 004: "about 10").
pub const POLYLINE_VERTICES: usize = 11;

/// A generic leaf in template coordinates: base at (0, 0), tip at (1, 0).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LeafTemplate {
    /// Margin on the +y side, base to tip.
    pub upper: Vec<Point2<f64>>,
    /// Margin on the −y side, base to tip.
    pub lower: Vec<Point2<f64>>,
    /// Midrib, base to tip.
    pub midrib: Vec<Point2<f64>>,
    /// Texture covering the rectangle `texture_min`–`texture_max` (template coordinates; row 0
    /// of the image at `texture_max.y`). Alpha 0 outside the blade.
    #[serde(skip)]
    pub texture: RgbaImage,
    pub texture_min: Point2<f64>,
    pub texture_max: Point2<f64>,
}

/// Invalid template input.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TemplateError {
    #[error("the outline has {0} points; at least 6 are needed")]
    TooFewPoints(usize),
    #[error("the outline is degenerate (no length or no width)")]
    Degenerate,
}

/// Linear interpolation of a polyline sorted by x, at abscissa `x` (clamped).
fn y_at(polyline: &[Point2<f64>], x: f64) -> f64 {
    if polyline.is_empty() {
        return 0.0;
    }
    if x <= polyline[0].x {
        return polyline[0].y;
    }
    for w in polyline.windows(2) {
        if x <= w[1].x {
            let span = w[1].x - w[0].x;
            let t = if span.abs() < 1e-12 {
                0.0
            } else {
                (x - w[0].x) / span
            };
            return w[0].y + t * (w[1].y - w[0].y);
        }
    }
    polyline[polyline.len() - 1].y
}

impl LeafTemplate {
    /// Builds a template from a closed outline in a leaf frame whose x axis runs from base to
    /// tip (not yet normalised): the outline is split at its extreme points in x into the two
    /// margins, everything is scaled so the base is at x = 0 and the tip at x = 1, and the
    /// midrib runs halfway between the margins. `texture` covers the outline's bounding box.
    pub fn from_outline(
        outline: &[Point2<f64>],
        texture: RgbaImage,
    ) -> Result<Self, TemplateError> {
        if outline.len() < 6 {
            return Err(TemplateError::TooFewPoints(outline.len()));
        }
        let (base_index, _) = outline
            .iter()
            .enumerate()
            .min_by(|a, b| a.1.x.total_cmp(&b.1.x))
            .ok_or(TemplateError::Degenerate)?;
        let (tip_index, _) = outline
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.x.total_cmp(&b.1.x))
            .ok_or(TemplateError::Degenerate)?;
        let (base, tip) = (outline[base_index], outline[tip_index]);
        let length = tip.x - base.x;
        let (lo_y, hi_y) = outline
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
                (a.min(p.y), b.max(p.y))
            });
        if length <= 1e-12 || hi_y - lo_y <= 1e-12 {
            return Err(TemplateError::Degenerate);
        }
        let normalise =
            |p: &Point2<f64>| Point2::new((p.x - base.x) / length, (p.y - base.y) / length);
        // Walk the loop from base to tip both ways.
        let n = outline.len();
        let walk = |step: isize| -> Vec<Point2<f64>> {
            let mut chain = Vec::new();
            let mut i = base_index as isize;
            loop {
                chain.push(normalise(&outline[i.rem_euclid(n as isize) as usize]));
                if i.rem_euclid(n as isize) as usize == tip_index {
                    break;
                }
                i += step;
                if chain.len() > n {
                    break;
                }
            }
            chain
        };
        let (a, b) = (walk(1), walk(-1));
        let mean_y = |c: &[Point2<f64>]| c.iter().map(|p| p.y).sum::<f64>() / c.len().max(1) as f64;
        let (upper_chain, lower_chain) = if mean_y(&a) >= mean_y(&b) {
            (a, b)
        } else {
            (b, a)
        };
        let monotone = |chain: Vec<Point2<f64>>| {
            let mut best_x = f64::NEG_INFINITY;
            chain
                .into_iter()
                .filter(|p| {
                    let keep = p.x > best_x;
                    if keep {
                        best_x = p.x;
                    }
                    keep
                })
                .collect::<Vec<_>>()
        };
        let upper = resample(&monotone(upper_chain), POLYLINE_VERTICES);
        let lower = resample(&monotone(lower_chain), POLYLINE_VERTICES);
        let midrib = (0..POLYLINE_VERTICES)
            .map(|k| {
                let x = k as f64 / (POLYLINE_VERTICES - 1) as f64;
                Point2::new(x, 0.5 * (y_at(&upper, x) + y_at(&lower, x)))
            })
            .collect();
        Ok(Self {
            upper,
            lower,
            midrib,
            texture,
            texture_min: normalise(&Point2::new(base.x, lo_y)),
            texture_max: normalise(&Point2::new(tip.x, hi_y)),
        })
    }

    /// The closed outline (lower margin base → tip, then upper margin tip → base).
    pub fn outline(&self) -> Vec<Point2<f64>> {
        let mut loop_points = self.lower.clone();
        loop_points.extend(
            self.upper
                .iter()
                .rev()
                .skip(1)
                .take(self.upper.len().saturating_sub(2)),
        );
        loop_points
    }

    /// The outline resampled densely (for registration).
    pub fn dense_outline(&self, n: usize) -> Vec<Point2<f64>> {
        let mut closed = self.outline();
        if let Some(first) = closed.first().copied() {
            closed.push(first);
        }
        let mut dense = resample(&closed, n + 1);
        dense.pop();
        dense
    }

    /// Width of the blade at `x` (upper minus lower margin).
    pub fn width_at(&self, x: f64) -> f64 {
        y_at(&self.upper, x) - y_at(&self.lower, x)
    }

    /// Area of the flat template (in template units², length 1).
    pub fn area(&self) -> f64 {
        let n = 400;
        (0..n)
            .map(|k| self.width_at((k as f64 + 0.5) / n as f64) / n as f64)
            .sum()
    }

    /// Texture coordinates (glTF: origin top-left) of a template point.
    pub fn uv(&self, p: &Point2<f64>) -> [f32; 2] {
        let size = self.texture_max - self.texture_min;
        [
            ((p.x - self.texture_min.x) / size.x.max(1e-12)) as f32,
            ((self.texture_max.y - p.y) / size.y.max(1e-12)) as f32,
        ]
    }

    /// A triangle mesh of the flat template in template coordinates (z = 0): `along` stations
    /// between base and tip, `across` vertices per station from the lower to the upper margin.
    pub fn mesh(&self, along: usize, across: usize) -> (TriMesh, Vec<Point2<f64>>) {
        let along = along.max(2);
        let across = (across.max(3)) | 1;
        let mut flat = Vec::new();
        let base = Point2::new(0.0, self.midrib[0].y);
        let tip = Point2::new(1.0, self.midrib[self.midrib.len() - 1].y);
        flat.push(base);
        for i in 1..=along {
            let x = i as f64 / (along + 1) as f64;
            let (lo, hi) = (y_at(&self.lower, x), y_at(&self.upper, x));
            for j in 0..across {
                let s = j as f64 / (across - 1) as f64;
                flat.push(Point2::new(x, lo + (hi - lo) * s));
            }
        }
        flat.push(tip);
        let mut mesh = TriMesh {
            positions: flat
                .iter()
                .map(|p| nalgebra::Point3::new(p.x as f32, p.y as f32, 0.0))
                .collect(),
            normals: Vec::new(),
            uvs: flat.iter().map(|p| self.uv(p)).collect(),
            triangles: Vec::new(),
        };
        let across = across as u32;
        let row = |i: u32| 1 + (i - 1) * across;
        let tip_index = flat.len() as u32 - 1;
        // Counter-clockwise seen from +z (x along the leaf, y across).
        for j in 0..across - 1 {
            mesh.triangles.push([0, row(1) + j, row(1) + j + 1]);
            let last = row(along as u32);
            mesh.triangles.push([tip_index, last + j + 1, last + j]);
        }
        for i in 1..along as u32 {
            for j in 0..across - 1 {
                let a = row(i) + j;
                let (b, c, d) = (a + 1, row(i + 1) + j, row(i + 1) + j + 1);
                mesh.triangles.push([a, c, b]);
                mesh.triangles.push([b, c, d]);
            }
        }
        mesh.compute_normals();
        (mesh, flat)
    }

    /// A plain green texture for templates built without an image.
    pub fn plain_texture(size: u32) -> RgbaImage {
        RgbaImage::from_pixel(size, size, Rgba([70, 130, 55, 255]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ellipse(n: usize, a: f64, b: f64) -> Vec<Point2<f64>> {
        (0..n)
            .map(|k| {
                let t = std::f64::consts::TAU * k as f64 / n as f64;
                Point2::new(a + a * t.cos(), b * t.sin())
            })
            .collect()
    }

    #[test]
    fn template_from_an_ellipse() {
        let template =
            LeafTemplate::from_outline(&ellipse(200, 0.1, 0.03), LeafTemplate::plain_texture(8))
                .unwrap();
        assert_eq!(template.upper.len(), POLYLINE_VERTICES);
        assert_eq!(template.lower.len(), POLYLINE_VERTICES);
        assert!((template.upper[0] - Point2::new(0.0, 0.0)).norm() < 1e-9);
        assert!((template.upper[POLYLINE_VERTICES - 1] - Point2::new(1.0, 0.0)).norm() < 1e-9);
        // Width at the middle: 2b / (2a) = 0.3 of the length.
        assert!((template.width_at(0.5) - 0.3).abs() < 0.01);
        // Ellipse area π a b over length² (2a)².
        let expected = std::f64::consts::PI * 0.1 * 0.03 / 0.04;
        assert!((template.area() - expected).abs() / expected < 0.03);
        assert!(template.midrib.iter().all(|p| p.y.abs() < 1e-3));
        let (mesh, flat) = template.mesh(12, 7);
        assert!(mesh.validate().is_ok());
        assert_eq!(mesh.positions.len(), flat.len());
        assert!((mesh.area() - expected).abs() / expected < 0.06);
        // Triangles face +z.
        for t in 0..mesh.triangles.len() {
            let [a, b, c] = mesh.corners(t);
            assert!((b - a).cross(&(c - a)).z >= 0.0);
        }
    }

    #[test]
    fn degenerate_outlines_are_refused() {
        let line: Vec<Point2<f64>> = (0..10).map(|k| Point2::new(k as f64, 0.0)).collect();
        assert!(matches!(
            LeafTemplate::from_outline(&line, LeafTemplate::plain_texture(4)),
            Err(TemplateError::Degenerate)
        ));
        assert!(matches!(
            LeafTemplate::from_outline(&line[..3], LeafTemplate::plain_texture(4)),
            Err(TemplateError::TooFewPoints(3))
        ));
    }
}
