//! A drawing's two outputs, from the same strokes: a raster (white paper, black ink, strokes
//! anti-aliased by OpenCV, the black shadow area filled) and an SVG with one group per layer
//! (Inkscape layers: shadow, branches, hatching, foliage) whose strokes an illustrator can edit.

use std::fmt::Write as _;

use image::GrayImage;
use opencv::core::{Mat, Point, Scalar, Vector};
use opencv::prelude::*;

use super::{Drawing, IllustrateError, Layer};

fn cv(e: opencv::Error) -> IllustrateError {
    IllustrateError::Raster(e.to_string())
}

/// Fixed-point bits for OpenCV's sub-pixel line drawing.
const SHIFT: i32 = 4;

/// A raster drawing as PNG bytes.
pub fn png_bytes(raster: &GrayImage) -> Result<Vec<u8>, IllustrateError> {
    let mut bytes = Vec::new();
    raster
        .write_to(
            &mut std::io::Cursor::new(&mut bytes),
            image::ImageFormat::Png,
        )
        .map_err(|e| IllustrateError::Raster(e.to_string()))?;
    Ok(bytes)
}

impl Drawing {
    /// The drawing as a grey image: 255 paper, 0 ink.
    pub fn raster(&self) -> Result<GrayImage, IllustrateError> {
        self.raster_layers(None)
    }

    /// One layer of the drawing (the black shadow area belongs to [`Layer::Shadow`]), or all
    /// of it with `None`.
    pub fn raster_layers(&self, only: Option<Layer>) -> Result<GrayImage, IllustrateError> {
        let (w, h) = (self.width as i32, self.height as i32);
        let mut mat =
            Mat::new_rows_cols_with_default(h, w, opencv::core::CV_8UC1, Scalar::all(255.0))
                .map_err(cv)?;
        {
            let data = mat.data_bytes_mut().map_err(cv)?;
            let fill_shadow = only.is_none_or(|l| l == Layer::Shadow);
            for (pixel, &fill) in data.iter_mut().zip(&self.shadow_fill) {
                if fill && fill_shadow {
                    *pixel = 0;
                }
            }
        }
        let scale = (1 << SHIFT) as f64;
        for stroke in self
            .strokes
            .iter()
            .filter(|s| only.is_none_or(|l| l == s.layer))
        {
            // COLMAP pixel (i, j) is centred at (i + ½, j + ½); OpenCV's at (i, j).
            let points: Vector<Point> = stroke
                .points_px
                .iter()
                .map(|p| {
                    Point::new(
                        ((p.x - 0.5) * scale).round() as i32,
                        ((p.y - 0.5) * scale).round() as i32,
                    )
                })
                .collect();
            let mut lines: Vector<Vector<Point>> = Vector::new();
            lines.push(points);
            let thickness = stroke.width_px.round().max(1.0) as i32;
            opencv::imgproc::polylines(
                &mut mat,
                &lines,
                false,
                Scalar::all(0.0),
                thickness,
                opencv::imgproc::LINE_AA,
                SHIFT,
            )
            .map_err(cv)?;
        }
        let bytes = mat.data_bytes().map_err(cv)?.to_vec();
        GrayImage::from_raw(self.width, self.height, bytes)
            .ok_or_else(|| IllustrateError::Raster("raster has the wrong size".into()))
    }

    /// The drawing as an SVG document: a white page, the black shadow area as paths traced
    /// from its mask, then one layer of stroked paths per [`Layer`].
    pub fn svg(&self) -> Result<String, IllustrateError> {
        let mut svg = String::new();
        let (w, h) = (self.width, self.height);
        let _ = writeln!(
            svg,
            r#"<?xml version="1.0" encoding="UTF-8"?>
<svg xmlns="http://www.w3.org/2000/svg" xmlns:inkscape="http://www.inkscape.org/namespaces/inkscape" width="{w}" height="{h}" viewBox="0 0 {w} {h}">
<title>Frond pen-and-ink drawing</title>
<rect width="{w}" height="{h}" fill="white"/>"#
        );
        let fill = self.shadow_paths()?;
        for layer in Layer::ALL {
            let _ = writeln!(
                svg,
                r#"<g id="{name}" inkscape:groupmode="layer" inkscape:label="{name}" fill="none" stroke="black" stroke-linecap="round" stroke-linejoin="round">"#,
                name = layer.name()
            );
            if layer == Layer::Shadow && !fill.is_empty() {
                let _ = writeln!(
                    svg,
                    r#"<path fill="black" stroke="none" fill-rule="evenodd" d="{fill}"/>"#
                );
            }
            for stroke in self.strokes.iter().filter(|s| s.layer == layer) {
                let mut d = String::new();
                for (k, p) in stroke.points_px.iter().enumerate() {
                    let _ = write!(
                        d,
                        "{}{:.2} {:.2}",
                        if k == 0 { "M" } else { " L" },
                        p.x,
                        p.y
                    );
                }
                let _ = writeln!(
                    svg,
                    r#"<path stroke-width="{:.2}" d="{d}"/>"#,
                    stroke.width_px
                );
            }
            svg.push_str("</g>\n");
        }
        svg.push_str("</svg>\n");
        Ok(svg)
    }

    /// The black shadow area as SVG path data: contours of the mask (OpenCV), holes included.
    fn shadow_paths(&self) -> Result<String, IllustrateError> {
        if !self.shadow_fill.iter().any(|&b| b) {
            return Ok(String::new());
        }
        let bytes: Vec<u8> = self
            .shadow_fill
            .iter()
            .map(|&b| if b { 255 } else { 0 })
            .collect();
        let mask = Mat::from_slice(&bytes)
            .and_then(|m| m.reshape(1, self.height as i32).and_then(|m| m.try_clone()))
            .map_err(cv)?;
        let mut contours: Vector<Vector<Point>> = Vector::new();
        opencv::imgproc::find_contours(
            &mask,
            &mut contours,
            opencv::imgproc::RETR_CCOMP,
            opencv::imgproc::CHAIN_APPROX_SIMPLE,
            Point::new(0, 0),
        )
        .map_err(cv)?;
        let mut d = String::new();
        for contour in contours.iter() {
            if contour.len() < 3 {
                continue;
            }
            for (k, p) in contour.iter().enumerate() {
                // Contour points are pixel indices; their centres are at +½.
                let _ = write!(
                    d,
                    "{}{} {}",
                    if k == 0 { "M" } else { " L" },
                    p.x as f64 + 0.5,
                    p.y as f64 + 0.5
                );
            }
            d.push_str(" Z ");
        }
        Ok(d.trim_end().to_owned())
    }
}
