//! Procedural textures for synthetic plants and their surroundings: leaves (own hue, veins,
//! fine noise), bark, pot, soil, floor tiles and a backdrop. Deterministic per seed.
//!
//! Every texture has high-frequency detail, as real surfaces do: multi-view stereo finds points
//! on texture, and the segmentation's 2D term (seed 004 §5.1) needs colour edges between leaves.

use image::{Rgba, RgbaImage};

use crate::util::rng::Rng;

/// Smooth value noise on a periodic integer lattice (period `period` cells), in [0, 1].
#[derive(Clone, Debug)]
pub struct ValueNoise {
    period: usize,
    lattice: Vec<f32>,
}

impl ValueNoise {
    pub fn new(period: usize, rng: &mut Rng) -> Self {
        let period = period.max(1);
        let lattice = (0..period * period).map(|_| rng.uniform() as f32).collect();
        Self { period, lattice }
    }

    fn at(&self, x: i64, y: i64) -> f32 {
        let p = self.period as i64;
        self.lattice[(y.rem_euclid(p) * p + x.rem_euclid(p)) as usize]
    }

    /// Noise at `(u, v)` ∈ [0, 1)² (tiles seamlessly).
    pub fn sample(&self, u: f32, v: f32) -> f32 {
        let x = u * self.period as f32;
        let y = v * self.period as f32;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let smooth = |t: f32| t * t * (3.0 - 2.0 * t);
        let (sx, sy) = (smooth(fx), smooth(fy));
        let (ix, iy) = (x0 as i64, y0 as i64);
        let top = self.at(ix, iy) * (1.0 - sx) + self.at(ix + 1, iy) * sx;
        let bottom = self.at(ix, iy + 1) * (1.0 - sx) + self.at(ix + 1, iy + 1) * sx;
        top * (1.0 - sy) + bottom * sy
    }
}

/// Fractal sum of value-noise octaves, normalised to [0, 1].
#[derive(Clone, Debug)]
pub struct Fbm {
    octaves: Vec<ValueNoise>,
}

impl Fbm {
    pub fn new(base_period: usize, octaves: usize, rng: &mut Rng) -> Self {
        Self {
            octaves: (0..octaves)
                .map(|o| ValueNoise::new(base_period << o, rng))
                .collect(),
        }
    }

    pub fn sample(&self, u: f32, v: f32) -> f32 {
        let mut sum = 0.0;
        let mut weight = 1.0;
        let mut total = 0.0;
        for octave in &self.octaves {
            sum += weight * octave.sample(u, v);
            total += weight;
            weight *= 0.5;
        }
        sum / total
    }
}

/// HSV (h in degrees, s and v in [0, 1]) to 8-bit sRGB.
pub fn hsv_to_rgb(h: f32, s: f32, v: f32) -> [u8; 3] {
    let h = h.rem_euclid(360.0) / 60.0;
    let (s, v) = (s.clamp(0.0, 1.0), v.clamp(0.0, 1.0));
    let c = v * s;
    let x = c * (1.0 - ((h % 2.0) - 1.0).abs());
    let (r, g, b) = match h as u32 {
        0 => (c, x, 0.0),
        1 => (x, c, 0.0),
        2 => (0.0, c, x),
        3 => (0.0, x, c),
        4 => (x, 0.0, c),
        _ => (c, 0.0, x),
    };
    let m = v - c;
    [r, g, b].map(|channel| ((channel + m) * 255.0).round().clamp(0.0, 255.0) as u8)
}

fn fill(width: u32, height: u32, f: impl Fn(f32, f32) -> [u8; 3]) -> RgbaImage {
    RgbaImage::from_fn(width, height, |x, y| {
        let u = (x as f32 + 0.5) / width as f32;
        let v = (y as f32 + 0.5) / height as f32;
        let [r, g, b] = f(u, v);
        Rgba([r, g, b, 255])
    })
}

/// Appearance parameters of one leaf.
#[derive(Clone, Copy, Debug)]
pub struct LeafLook {
    pub hue: f32,
    pub saturation: f32,
    pub value: f32,
    /// Secondary veins per unit of leaf length (texture u).
    pub vein_count: f32,
    /// Strength of the fine noise (fraction of value).
    pub noise: f32,
}

impl LeafLook {
    /// A random green with per-leaf variation.
    pub fn random(rng: &mut Rng) -> Self {
        Self {
            hue: rng.range(82.0, 140.0) as f32,
            saturation: rng.range(0.45, 0.85) as f32,
            value: rng.range(0.30, 0.66) as f32,
            vein_count: rng.range(7.0, 12.0) as f32,
            noise: rng.range(0.05, 0.10) as f32,
        }
    }
}

/// A leaf texture. `u` runs from base (0) to tip (1) along the midrib; `v` across the blade
/// from one margin (0) through the midrib (0.5) to the other (1).
pub fn leaf_texture(look: &LeafLook, size: u32, rng: &mut Rng) -> RgbaImage {
    let coarse = Fbm::new(4, 3, rng);
    let fine = Fbm::new(32, 2, rng);
    fill(size, size, |u, v| {
        let across = (v - 0.5).abs() * 2.0; // 0 at the midrib, 1 at the margin
        let mut value = look.value * (0.88 + 0.24 * coarse.sample(u, v));
        value *= 1.0 - look.noise + 2.0 * look.noise * fine.sample(u, v);
        let mut saturation = look.saturation;
        // Midrib: a light stripe.
        let midrib = (1.0 - across / 0.035).max(0.0);
        // Secondary veins leave the midrib toward the tip at ~35°.
        let phase = u * look.vein_count - across * 0.7;
        let distance = (phase - phase.round()).abs();
        let vein = (1.0 - distance / 0.06).max(0.0) * (1.0 - across).powf(0.5);
        // Veins are lighter than the blade, the midrib most (upper leaf surfaces show them
        // subtly; they must not out-contrast the edges between leaves).
        let light = midrib.max(0.5 * vein);
        value *= 1.0 + 0.25 * light;
        saturation *= 1.0 - 0.25 * light;
        // Margins slightly darker.
        if across > 0.9 {
            value *= 1.0 - 0.8 * (across - 0.9);
        }
        hsv_to_rgb(
            look.hue + 6.0 * (coarse.sample(v, u) - 0.5),
            saturation,
            value,
        )
    })
}

/// Bark for stems and petioles: longitudinal streaks.
pub fn bark_texture(size: u32, hue: f32, rng: &mut Rng) -> RgbaImage {
    let streaks = Fbm::new(16, 3, rng);
    let fine = ValueNoise::new(64, rng);
    fill(size, size, |u, v| {
        let value = 0.3 + 0.2 * streaks.sample(u, v * 0.125) + 0.1 * fine.sample(u, v);
        hsv_to_rgb(hue, 0.45, value)
    })
}

/// Terracotta pot with mottling.
pub fn pot_texture(size: u32, rng: &mut Rng) -> RgbaImage {
    let mottle = Fbm::new(8, 4, rng);
    fill(size, size, |u, v| {
        let m = mottle.sample(u, v);
        hsv_to_rgb(18.0 + 6.0 * m, 0.62, 0.45 + 0.25 * m)
    })
}

/// Dark, grainy soil.
pub fn soil_texture(size: u32, rng: &mut Rng) -> RgbaImage {
    let grain = Fbm::new(32, 3, rng);
    fill(size, size, |u, v| {
        let g = grain.sample(u, v);
        hsv_to_rgb(28.0, 0.5, 0.12 + 0.22 * g * g)
    })
}

/// Paints `count` random discs (log-uniform radii between `min_radius` and `max_radius`
/// texels, colours from `palette` with jittered value) onto `image`.
fn paint_discs(
    image: &mut RgbaImage,
    count: usize,
    min_radius: f64,
    max_radius: f64,
    palette: &[(f32, f32, f32)],
    rng: &mut Rng,
) {
    let (w, h) = image.dimensions();
    for _ in 0..count {
        let radius = min_radius * (max_radius / min_radius).powf(rng.uniform());
        let (cx, cy) = (rng.range(0.0, w as f64), rng.range(0.0, h as f64));
        let (hue, saturation, value) = palette[rng.below(palette.len())];
        let jitter = rng.range(0.75, 1.25) as f32;
        let [r, g, b] = hsv_to_rgb(
            hue + rng.range(-12.0, 12.0) as f32,
            saturation,
            value * jitter,
        );
        let aspect = rng.range(0.6, 1.0);
        let angle = rng.range(0.0, std::f64::consts::PI);
        let (sin, cos) = angle.sin_cos();
        let reach = radius.ceil() as i64 + 1;
        for dy in -reach..=reach {
            for dx in -reach..=reach {
                let (x, y) = (cx as i64 + dx, cy as i64 + dy);
                // Wrap horizontally and vertically so the texture still tiles.
                let (xw, yw) = (x.rem_euclid(w as i64) as u32, y.rem_euclid(h as i64) as u32);
                let (fx, fy) = (x as f64 + 0.5 - cx, y as f64 + 0.5 - cy);
                let u = (fx * cos + fy * sin) / radius;
                let v = (-fx * sin + fy * cos) / (radius * aspect);
                if u * u + v * v <= 1.0 {
                    image.put_pixel(xw, yw, Rgba([r, g, b, 255]));
                }
            }
        }
    }
}

/// Adds fine grain (±`amount` of value) to every texel.
fn add_grain(image: &mut RgbaImage, amount: f32, rng: &mut Rng) {
    let grain = ValueNoise::new(256, rng);
    let (w, h) = image.dimensions();
    for (x, y, pixel) in image.enumerate_pixels_mut() {
        let g = 1.0 + amount * (2.0 * grain.sample(x as f32 / w as f32, y as f32 / h as f32) - 1.0);
        for c in 0..3 {
            pixel[c] = (pixel[c] as f32 * g).round().clamp(0.0, 255.0) as u8;
        }
    }
}

/// A terrazzo-like floor: stone chips of many sizes and colours on a mottled ground. Every
/// region looks different, so feature matching (SIFT) finds unambiguous correspondences.
pub fn floor_texture(size: u32, rng: &mut Rng) -> RgbaImage {
    let ground = Fbm::new(8, 5, rng);
    let mut image = fill(size, size, |u, v| {
        let g = ground.sample(u, v);
        hsv_to_rgb(32.0 + 10.0 * g, 0.18, 0.45 + 0.25 * g)
    });
    let palette = [
        (25.0, 0.45, 0.55),
        (40.0, 0.2, 0.8),
        (0.0, 0.0, 0.25),
        (200.0, 0.15, 0.6),
        (15.0, 0.6, 0.4),
    ];
    let chips = (size as usize * size as usize) / 180;
    paint_discs(&mut image, chips, 1.5, 14.0, &palette, rng);
    add_grain(&mut image, 0.08, rng);
    image
}

/// A backdrop like a patterned wall: soft large-scale colour variation with scattered marks
/// of many sizes, feature-rich but calm behind the plant.
pub fn backdrop_texture(width: u32, height: u32, rng: &mut Rng) -> RgbaImage {
    let pattern = Fbm::new(6, 5, rng);
    let mut image = fill(width, height, |u, v| {
        let p = pattern.sample(u, v);
        hsv_to_rgb(210.0 + 40.0 * p, 0.18 + 0.15 * p, 0.55 + 0.3 * p)
    });
    let palette = [
        (220.0, 0.35, 0.45),
        (30.0, 0.25, 0.85),
        (260.0, 0.2, 0.7),
        (190.0, 0.4, 0.3),
    ];
    let marks = (width as usize * height as usize) / 300;
    paint_discs(&mut image, marks, 2.0, 22.0, &palette, rng);
    add_grain(&mut image, 0.06, rng);
    image
}

/// Dark matte cloth as phenotyping cabins hang behind and under the plant: soft folds of a few
/// percent of its brightness and a fine weave, nothing a feature or stereo matcher can lock on
/// to.
pub fn cloth_texture(width: u32, height: u32, rng: &mut Rng) -> RgbaImage {
    let folds = Fbm::new(6, 3, rng);
    let mut image = fill(width, height, |u, v| {
        let f = folds.sample(u, v);
        hsv_to_rgb(225.0, 0.15, 0.10 + 0.04 * f)
    });
    add_grain(&mut image, 0.04, rng);
    image
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hsv_primaries() {
        assert_eq!(hsv_to_rgb(0.0, 1.0, 1.0), [255, 0, 0]);
        assert_eq!(hsv_to_rgb(120.0, 1.0, 1.0), [0, 255, 0]);
        assert_eq!(hsv_to_rgb(240.0, 1.0, 0.5), [0, 0, 128]);
        assert_eq!(hsv_to_rgb(77.0, 0.0, 1.0), [255, 255, 255]);
    }

    #[test]
    fn noise_tiles_and_stays_in_range() {
        let mut rng = Rng::seed_from(5);
        let noise = ValueNoise::new(8, &mut rng);
        for k in 0..100 {
            let v = k as f32 / 100.0;
            let s = noise.sample(0.3, v);
            assert!((0.0..=1.0).contains(&s));
            assert!((noise.sample(0.0, v) - noise.sample(1.0, v)).abs() < 1e-5);
        }
    }

    #[test]
    fn leaf_textures_differ_per_leaf_and_are_green() {
        let mut rng = Rng::seed_from(9);
        let a = leaf_texture(&LeafLook::random(&mut rng), 64, &mut rng);
        let b = leaf_texture(&LeafLook::random(&mut rng), 64, &mut rng);
        assert_ne!(a, b);
        let mean = |img: &RgbaImage, c: usize| {
            img.pixels().map(|p| p[c] as f64).sum::<f64>() / img.pixels().len() as f64
        };
        assert!(mean(&a, 1) > mean(&a, 0) && mean(&a, 1) > mean(&a, 2));
    }

    #[test]
    fn cloth_is_dark_and_nearly_textureless_beside_the_patterned_wall() {
        let mut rng = Rng::seed_from(3);
        let cloth = cloth_texture(512, 256, &mut rng);
        let wall = backdrop_texture(512, 256, &mut rng);
        let luma = |p: &image::Rgba<u8>| (p[0] as f64 + p[1] as f64 + p[2] as f64) / 3.0;
        let mean =
            |img: &RgbaImage| img.pixels().map(luma).sum::<f64>() / img.pixels().len() as f64;
        // Texture a matcher sees: mean absolute difference of neighbouring texels.
        let detail = |img: &RgbaImage| {
            let (w, h) = img.dimensions();
            let mut sum = 0.0;
            for y in 0..h {
                for x in 1..w {
                    sum += (luma(img.get_pixel(x, y)) - luma(img.get_pixel(x - 1, y))).abs();
                }
            }
            sum / ((w - 1) * h) as f64
        };
        assert!(mean(&cloth) < 0.2 * 255.0, "cloth mean {}", mean(&cloth));
        assert!(mean(&wall) > 2.0 * mean(&cloth));
        let (cloth_detail, wall_detail) = (detail(&cloth), detail(&wall));
        assert!(
            cloth_detail < 0.5 && cloth_detail < 0.1 * wall_detail,
            "cloth {cloth_detail}, wall {wall_detail}"
        );
    }
}
