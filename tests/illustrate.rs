//! Pen-and-ink drawings of a known plant: ink where the plant is and nowhere else, the SVG holds
//! the same strokes as the raster, hatching that sticks to the bark stays put in a slow
//! fly-around, and the command writes what it says.

use std::path::{Path, PathBuf};
use std::process::Command;

use frond::illustrate::{
    Drawing, Hatching, Layer, PreparedSketch, SketchPlant, SketchScene, Style, coherence,
    orbit_views,
};
use frond::lod::asset::PlantAsset;
use frond::render::{Lighting, Renderer};

/// A built-in synthetic medium plant (about 100 leaves, branches and petioles) as a glb.
fn plant_glb(dir: &Path) -> (PathBuf, frond::model::PlantModel) {
    let (_, model) = frond::ecosystem::folder::built_in_plant(5, 1);
    model.export(dir).unwrap();
    (dir.join("plant.glb"), model)
}

fn renderer() -> Renderer {
    Renderer::new().expect("a GPU adapter (llvmpipe on CI)")
}

#[test]
fn a_drawing_has_ink_where_the_plant_is_and_nowhere_else() {
    let dir = tempfile::tempdir().unwrap();
    let (glb, model) = plant_glb(dir.path());
    let plant = SketchPlant::from_glb(&glb).unwrap();
    // Every leaf and branch node of the glb is found (merged parts come apart).
    assert_eq!(plant.leaves.len(), model.leaves.len());
    assert_eq!(plant.branches.len(), model.branches.len());
    assert_eq!(
        plant.branches.iter().filter(|b| b.order == 0).count(),
        1,
        "one stem"
    );
    let scene = SketchScene::single(plant);
    let options = Style::Detailed.options(scene.median_leaf_length());
    let views = orbit_views(&scene, 480, 360, None, 1, 0.0).unwrap();
    let mut renderer = renderer();
    let prepared = PreparedSketch::new(&scene, &options, &views[0]).unwrap();
    let drawing = prepared.draw(&mut renderer, &views[0]).unwrap();
    let raster = drawing.raster().unwrap();

    // Where the plant's real geometry is, from the same view.
    let asset = PlantAsset::from_model(&model);
    let mut gpu = renderer.new_scene();
    let textures: Vec<_> = asset
        .textures
        .iter()
        .map(|t| renderer.add_cutout_texture(&mut gpu, t))
        .collect();
    for (k, part) in asset.parts.iter().enumerate() {
        renderer
            .add_mesh(
                &mut gpu,
                &part.mesh,
                textures[part.texture],
                k as u32 + 1,
                part.alpha_test,
            )
            .unwrap();
    }
    let truth = renderer
        .render(&gpu, &views[0], &Lighting::default())
        .unwrap();
    // Primitives reach half their size beyond the leaf points they stand for.
    let nearest_depth = truth
        .depth
        .iter()
        .copied()
        .filter(|d| *d > 0.0)
        .fold(f32::INFINITY, f32::min) as f64;
    let reach = (0.5 * options.size * views[0].fx / nearest_depth).ceil() as i64 + 3;
    let (w, h) = (drawing.width as i64, drawing.height as i64);
    let mut near_plant = vec![false; (w * h) as usize];
    for y in 0..h {
        for x in 0..w {
            if truth.object_id[(y * w + x) as usize] == 0 {
                continue;
            }
            for dy in -reach..=reach {
                for dx in -reach..=reach {
                    let (qx, qy) = (x + dx, y + dy);
                    if qx >= 0 && qy >= 0 && qx < w && qy < h && dx * dx + dy * dy <= reach * reach
                    {
                        near_plant[(qy * w + qx) as usize] = true;
                    }
                }
            }
        }
    }
    let ink: Vec<(i64, i64)> = raster
        .enumerate_pixels()
        .filter(|(_, _, p)| p[0] < 128)
        .map(|(x, y, _)| (x as i64, y as i64))
        .collect();
    let stray = ink
        .iter()
        .filter(|(x, y)| !near_plant[(y * w + x) as usize])
        .count();
    assert_eq!(
        stray,
        0,
        "{stray} of {} ink pixels away from the plant",
        ink.len()
    );
    // And the plant is drawn: ink spans the plant's extent and every layer has strokes.
    let extent = |points: &mut dyn Iterator<Item = (i64, i64)>| {
        points.fold(
            (i64::MAX, i64::MIN, i64::MAX, i64::MIN),
            |(x0, x1, y0, y1), (x, y)| (x0.min(x), x1.max(x), y0.min(y), y1.max(y)),
        )
    };
    let plant_box = extent(
        &mut (0..w * h)
            .filter(|&i| truth.object_id[i as usize] != 0)
            .map(|i| (i % w, i / w)),
    );
    let ink_box = extent(&mut ink.iter().copied());
    let (pw, ph) = (plant_box.1 - plant_box.0, plant_box.3 - plant_box.2);
    let (iw, ih) = (ink_box.1 - ink_box.0, ink_box.3 - ink_box.2);
    assert!(
        iw * 10 >= pw * 9 && ih * 10 >= ph * 9,
        "ink {ink_box:?} vs plant {plant_box:?}"
    );
    for layer in [Layer::Branch, Layer::Hatching, Layer::Foliage] {
        assert!(
            drawing.strokes.iter().any(|s| s.layer == layer),
            "no {layer:?} strokes: {:?}",
            drawing.stats
        );
    }
    // Foliage outlines only where the depth jumps: the drawing is not every primitive's
    // outline.
    let outline_px: f64 = drawing
        .strokes
        .iter()
        .filter(|s| s.layer == Layer::Foliage)
        .map(|s| frond::util::polyline::length(&s.points_px))
        .sum();
    let all_outlines_px: f64 = prepared
        .sizes
        .iter()
        .zip(&prepared.particles)
        .filter_map(|(size, p)| {
            let (_, z) = views[0].project(&p.position_world)?;
            Some(std::f64::consts::PI * size * views[0].fx / z)
        })
        .sum();
    assert!(
        outline_px < 0.6 * all_outlines_px,
        "{outline_px:.0} px of outline of {all_outlines_px:.0}"
    );
}

/// The `d` attributes of the SVG's stroked paths, as point lists, in document order.
fn svg_strokes(svg: &str) -> Vec<Vec<(f64, f64)>> {
    svg.lines()
        .filter(|l| l.starts_with("<path stroke-width="))
        .map(|line| {
            let d = line.split(" d=\"").nth(1).unwrap().trim_end_matches("\"/>");
            d.split(['M', 'L'])
                .filter(|t| !t.trim().is_empty())
                .map(|t| {
                    let mut xy = t.split_whitespace().map(|v| v.parse::<f64>().unwrap());
                    (xy.next().unwrap(), xy.next().unwrap())
                })
                .collect()
        })
        .collect()
}

/// A fly-around's coherence, each frame's whole raster made here.
fn fly_coherence(frames: &[Drawing]) -> coherence::CoherenceReport {
    let rasters: Vec<_> = frames.iter().map(|d| d.raster().unwrap()).collect();
    coherence::coherence(frames, &rasters).unwrap()
}

fn draw(scene: &SketchScene, style: Style, hatching: Hatching, frames: usize) -> Vec<Drawing> {
    let mut options = style.options(scene.median_leaf_length());
    options.hatching = hatching;
    let views = orbit_views(scene, 400, 300, None, frames, 0.5).unwrap();
    let prepared = PreparedSketch::new(scene, &options, &views[0]).unwrap();
    let mut renderer = renderer();
    views
        .iter()
        .map(|v| prepared.draw(&mut renderer, v).unwrap())
        .collect()
}

#[test]
fn the_svg_holds_the_strokes_of_the_raster_in_layers() {
    let dir = tempfile::tempdir().unwrap();
    let (glb, _) = plant_glb(dir.path());
    let scene = SketchScene::single(SketchPlant::from_glb(&glb).unwrap());
    let drawing = draw(&scene, Style::Abstract, Hatching::Surface, 1).remove(0);
    let svg = drawing.svg().unwrap();
    for layer in Layer::ALL {
        assert!(svg.contains(&format!("inkscape:label=\"{}\"", layer.name())));
    }
    // The abstract style fills the full shadow black: a traced area in the shadow layer.
    assert!(drawing.stats.shadow_pixels > 0);
    assert!(svg.contains("fill=\"black\" stroke=\"none\""));
    let parsed = svg_strokes(&svg);
    let mut expected = drawing.strokes.clone();
    expected.sort_by_key(|s| s.layer);
    assert_eq!(parsed.len(), expected.len());
    for (p, s) in parsed.iter().zip(&expected) {
        assert_eq!(p.len(), s.points_px.len());
        for (a, b) in p.iter().zip(&s.points_px) {
            assert!((a.0 - b.x).abs() < 0.006 && (a.1 - b.y).abs() < 0.006);
        }
    }
}

#[test]
fn hatching_on_the_bark_stays_put_in_a_slow_fly_around() {
    let dir = tempfile::tempdir().unwrap();
    let (glb, _) = plant_glb(dir.path());
    let scene = SketchScene::single(SketchPlant::from_glb(&glb).unwrap());
    let surface = fly_coherence(&draw(&scene, Style::Detailed, Hatching::Surface, 4));
    let screen = fly_coherence(&draw(&scene, Style::Detailed, Hatching::Screen, 4));
    let hatching = |c: &coherence::CoherenceReport| c.by_layer["hatching"].mean_stable_ink;
    assert!(
        surface.all.mean_motion_px > 0.3,
        "the camera moves: {surface:?}"
    );
    assert!(
        hatching(&surface) > hatching(&screen) + 0.02,
        "surface {:.3} vs screen {:.3}",
        hatching(&surface),
        hatching(&screen)
    );
    assert!(surface.all.mean_stable_ink > 0.8, "{surface:?}");
}

fn frond(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_frond"))
        .args(args)
        .output()
        .unwrap()
}

#[test]
fn frond_illustrate_writes_the_drawing_its_svg_and_a_report() {
    let dir = tempfile::tempdir().unwrap();
    let (glb, _) = plant_glb(&dir.path().join("plant"));
    let out = dir.path().join("drawing.png");
    let svg = dir.path().join("drawing.svg");
    let output = frond(&[
        "illustrate",
        glb.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--svg",
        svg.to_str().unwrap(),
        "--style",
        "sketchy",
        "--size",
        "320x240",
        "--frames",
        "2",
    ]);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    for name in [
        "drawing_000.png",
        "drawing_001.png",
        "drawing.svg",
        "drawing.json",
    ] {
        assert!(dir.path().join(name).is_file(), "{name} missing");
    }
    let png = image::open(dir.path().join("drawing_000.png"))
        .unwrap()
        .to_luma8();
    assert_eq!(png.dimensions(), (320, 240));
    assert!(png.pixels().any(|p| p[0] < 128), "no ink");
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("drawing.json")).unwrap())
            .unwrap();
    assert_eq!(report["format"], "frond illustration");
    assert_eq!(report["options"]["primitive"], "ellipse");
    assert_eq!(report["frames"].as_array().unwrap().len(), 2);
    assert!(
        report["coherence"]["all"]["mean_stable_ink"]
            .as_f64()
            .unwrap()
            > 0.5
    );

    let bad = frond(&[
        "illustrate",
        glb.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--style",
        "oil",
    ]);
    assert!(!bad.status.success());
    let message = String::from_utf8_lossy(&bad.stderr);
    assert!(
        message.contains("'oil' is not one of detailed, abstract"),
        "{message}"
    );
    let missing = dir.path().join("nothing.glb");
    let bad = frond(&[
        "illustrate",
        missing.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!bad.status.success());
    let message = String::from_utf8_lossy(&bad.stderr);
    assert!(message.contains("nothing.glb"), "{message}");
}

#[test]
fn a_scene_is_drawn_with_its_terrain_hiding_what_is_behind() {
    let dir = tempfile::tempdir().unwrap();
    let output = frond(&[
        "scene",
        "--out",
        dir.path().join("scene").to_str().unwrap(),
        "--variants",
        "2",
        "--count",
        "12",
        "--size",
        "6x6",
        "--masters",
        "2",
    ]);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let scene =
        frond::illustrate::read_sketch_scene(&dir.path().join("scene").join("scene.json")).unwrap();
    assert_eq!(scene.plants.len(), 12);
    assert!(scene.terrain.is_some());
    let drawing = draw(&scene, Style::Detailed, Hatching::Surface, 1).remove(0);
    assert!(
        drawing.stats.visible_particles > 0 && drawing.stats.strokes > 0,
        "{:?}",
        drawing.stats
    );
}
