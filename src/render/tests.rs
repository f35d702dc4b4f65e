//! Rendering tests of the whole core: meshes uploaded, drawn from a view and read back, checked
//! against the camera's own projection.

use image::RgbaImage;
use nalgebra::{Point2, Point3, Vector3};

use super::*;
use crate::mesh::TriMesh;
use crate::scene::synthetic::look_at;

fn renderer() -> Renderer {
    Renderer::new().expect("a GPU adapter (llvmpipe on CI)")
}

/// An empty scene and a white texture in it.
fn white_scene(renderer: &Renderer) -> (GpuScene, TextureHandle) {
    let mut scene = renderer.new_scene();
    let white = RgbaImage::from_pixel(4, 4, image::Rgba([255, 255, 255, 255]));
    let texture = renderer.add_texture(&mut scene, &white);
    (scene, texture)
}

fn square_at(center: Point3<f32>, half: f32) -> TriMesh {
    let mut mesh = TriMesh {
        positions: vec![
            center + Vector3::new(-half, -half, 0.0),
            center + Vector3::new(half, -half, 0.0),
            center + Vector3::new(half, half, 0.0),
            center + Vector3::new(-half, half, 0.0),
        ],
        normals: Vec::new(),
        uvs: vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]],
        triangles: vec![[0, 1, 2], [0, 2, 3]],
    };
    mesh.compute_normals();
    mesh
}

/// A square 0.4 wide at `x` on the plane z = 0, uploaded with `object_id`.
fn add_square(
    renderer: &Renderer,
    scene: &mut GpuScene,
    texture: TextureHandle,
    x: f32,
    object_id: u32,
) -> MeshHandle {
    renderer
        .add_mesh(
            scene,
            &square_at(Point3::new(x, 0.0, 0.0), 0.2),
            texture,
            object_id,
            false,
        )
        .unwrap()
}

fn camera(width: u32, height: u32) -> ViewCamera {
    ViewCamera {
        width,
        height,
        fx: 180.0,
        fy: 175.0,
        cx: 0.5 * width as f64 + 3.25,
        cy: 0.5 * height as f64 - 1.75,
        camera_from_world: look_at(Point3::new(0.3, -2.0, 1.5), Point3::new(0.1, 0.05, 0.0)),
        near: 0.05,
        far: 20.0,
    }
}

#[test]
fn projected_square_covers_exactly_the_pixels_whose_centres_it_contains() {
    let mut renderer = renderer();
    let (mut scene, texture) = white_scene(&renderer);
    let square = square_at(Point3::new(0.1, 0.05, 0.0), 0.3);
    renderer
        .add_mesh(&mut scene, &square, texture, 7, false)
        .unwrap();
    let view = camera(160, 120);
    let out = renderer
        .render(&scene, &view, &Lighting::default())
        .unwrap();
    // Project the corners; a pixel is covered iff its centre (i+½, j+½) is inside.
    let corners: Vec<Point2<f64>> = square
        .positions
        .iter()
        .map(|p| view.project(&p.cast::<f64>()).unwrap().0)
        .collect();
    let inside = |p: Point2<f64>| {
        (0..4).all(|k| {
            let a = corners[k];
            let b = corners[(k + 1) % 4];
            let cross = (b - a).perp(&(p - a));
            cross.abs() > 1e-3
                && cross.signum()
                    == (corners[1] - corners[0])
                        .perp(&(corners[2] - corners[0]))
                        .signum()
        })
    };
    let mut disagreements = 0;
    let mut covered = 0;
    for y in 0..view.height {
        for x in 0..view.width {
            let centre = Point2::new(x as f64 + 0.5, y as f64 + 0.5);
            let drawn = out.id_at(x, y) == 7;
            covered += drawn as usize;
            // Pixels within 1e-3 px of an edge may go either way (tie rules).
            let near_edge = (0..4).any(|k| {
                let a = corners[k];
                let b = corners[(k + 1) % 4];
                ((b - a).perp(&(centre - a)) / (b - a).norm()).abs() < 1e-3
            });
            if !near_edge && drawn != inside(centre) {
                disagreements += 1;
            }
        }
    }
    assert!(covered > 500, "square too small: {covered} pixels");
    assert_eq!(disagreements, 0, "rasterizer and projection disagree");
}

#[test]
fn a_single_sample_colour_pass_covers_exactly_the_id_pass_pixels() {
    let mut renderer = Renderer::new_with_samples(1).unwrap();
    let (mut scene, texture) = white_scene(&renderer);
    renderer
        .add_mesh(
            &mut scene,
            &square_at(Point3::new(0.1, 0.05, 0.0), 0.3),
            texture,
            7,
            false,
        )
        .unwrap();
    let out = renderer
        .render(&scene, &camera(160, 120), &Lighting::default())
        .unwrap();
    let mut covered = 0;
    for (pixel, id) in out.color.pixels().zip(&out.object_id) {
        let lit = pixel.0[..3].iter().any(|&c| c > 0);
        assert_eq!(lit, *id != 0);
        covered += lit as usize;
    }
    assert!(covered > 100, "{covered}");
    assert!(Renderer::new_with_samples(2).is_err());
}

#[test]
fn hidden_meshes_are_not_drawn_until_shown_again() {
    let mut renderer = renderer();
    let (mut scene, texture) = white_scene(&renderer);
    let left = add_square(&renderer, &mut scene, texture, -0.3, 3);
    add_square(&renderer, &mut scene, texture, 0.3, 4);
    let view = camera(160, 120);
    let ids = |renderer: &mut Renderer, scene: &GpuScene| {
        let out = renderer.render(scene, &view, &Lighting::default()).unwrap();
        let mut ids: Vec<u32> = out.object_id.into_iter().filter(|&i| i != 0).collect();
        ids.sort_unstable();
        ids.dedup();
        ids
    };
    assert_eq!(ids(&mut renderer, &scene), [3, 4]);
    scene.set_visible(left, false);
    assert_eq!(ids(&mut renderer, &scene), [4]);
    scene.set_visible(left, true);
    assert_eq!(ids(&mut renderer, &scene), [3, 4]);
}

#[test]
fn replaced_geometry_is_drawn_with_the_same_id_and_texture() {
    let mut renderer = renderer();
    let (mut scene, texture) = white_scene(&renderer);
    let mesh = add_square(&renderer, &mut scene, texture, -0.3, 7);
    let view = camera(160, 120);
    // Mean column of the pixels showing id 7, and how many there are.
    let where_drawn = |renderer: &mut Renderer, scene: &GpuScene| {
        let out = renderer.render(scene, &view, &Lighting::default()).unwrap();
        let columns: Vec<usize> = out
            .object_id
            .iter()
            .enumerate()
            .filter(|(_, id)| **id == 7)
            .map(|(k, _)| k % 160)
            .collect();
        let mean = columns.iter().sum::<usize>() as f64 / columns.len().max(1) as f64;
        (mean, columns.len())
    };
    let (left, count) = where_drawn(&mut renderer, &scene);
    assert!(left < 80.0 && count > 100, "{left} {count}");
    let moved = square_at(Point3::new(0.3, 0.0, 0.0), 0.2);
    renderer
        .replace_mesh_geometry(&mut scene, mesh, &moved)
        .unwrap();
    let (right, count_after) = where_drawn(&mut renderer, &scene);
    assert!(right > 80.0, "{right}");
    assert!(
        count_after.abs_diff(count) < count / 10,
        "{count} {count_after}"
    );
    assert_eq!(scene.num_triangles(), 2);
    // An empty mesh draws nothing; bad input is refused and changes nothing.
    let mut bad = moved.clone();
    bad.positions[0].x = f32::NAN;
    assert!(matches!(
        renderer.replace_mesh_geometry(&mut scene, mesh, &bad),
        Err(RenderError::Mesh { object_id: 7, .. })
    ));
    assert!(matches!(
        renderer.replace_mesh_geometry(&mut scene, MeshHandle(9), &moved),
        Err(RenderError::UnknownMesh(9))
    ));
    assert_eq!(where_drawn(&mut renderer, &scene).1, count_after);
    renderer
        .replace_mesh_geometry(&mut scene, mesh, &TriMesh::default())
        .unwrap();
    assert_eq!(where_drawn(&mut renderer, &scene).1, 0);
    assert_eq!(scene.num_triangles(), 0);
}

#[test]
fn projected_vertex_lands_where_the_rasterizer_drew_it() {
    let mut renderer = renderer();
    let (mut scene, texture) = white_scene(&renderer);
    let view = camera(200, 150);
    // Tiny squares around several world points: each must appear at the pixel its centre
    // projects to, with the right depth.
    for (k, p) in [
        Point3::new(0.1f32, 0.05, 0.0),
        Point3::new(0.5, -0.2, 0.1),
        Point3::new(-0.4, 0.3, -0.2),
    ]
    .iter()
    .enumerate()
    {
        renderer
            .add_mesh(
                &mut scene,
                &square_at(*p, 0.03),
                texture,
                10 + k as u32,
                false,
            )
            .unwrap();
    }
    let out = renderer
        .render(&scene, &view, &Lighting::default())
        .unwrap();
    for (k, p) in [
        Point3::new(0.1f64, 0.05, 0.0),
        Point3::new(0.5, -0.2, 0.1),
        Point3::new(-0.4, 0.3, -0.2),
    ]
    .iter()
    .enumerate()
    {
        let (uv, depth) = view.project(p).unwrap();
        let (x, y) = (uv.x.floor() as u32, uv.y.floor() as u32);
        assert_eq!(out.id_at(x, y), 10 + k as u32, "point {k} at {uv:?}");
        let d = out.depth_at(x, y) as f64;
        assert!((d - depth).abs() < 0.01, "depth {d} vs {depth}");
    }
    // Background stays empty.
    assert_eq!(out.id_at(0, 0), 0);
    assert_eq!(out.depth_at(0, 0), 0.0);
}

#[test]
fn colour_pass_shades_and_textures() {
    let mut renderer = renderer();
    let mut scene = renderer.new_scene();
    let red = RgbaImage::from_pixel(8, 8, image::Rgba([200, 20, 20, 255]));
    let texture = renderer.add_texture(&mut scene, &red);
    renderer
        .add_mesh(
            &mut scene,
            &square_at(Point3::new(0.1, 0.05, 0.0), 0.3),
            texture,
            1,
            false,
        )
        .unwrap();
    let view = camera(120, 90);
    let out = renderer
        .render(&scene, &view, &Lighting::default())
        .unwrap();
    let (uv, _) = view.project(&Point3::new(0.1, 0.05, 0.0)).unwrap();
    let pixel = out.color.get_pixel(uv.x as u32, uv.y as u32);
    assert!(
        pixel[0] > 100 && pixel[1] < 40 && pixel[2] < 40,
        "{pixel:?}"
    );
    assert_eq!(out.color.get_pixel(0, 0)[0], 0);
}

/// Column-major transform: uniform `scale`, rotation about z by `yaw`, then `offset`.
fn instance(offset: Vector3<f32>, yaw: f32, scale: f32) -> InstanceTransform {
    let m = nalgebra::Similarity3::new(offset, Vector3::z() * yaw, scale).to_homogeneous();
    let mut out = [0.0; 16];
    out.copy_from_slice(m.as_slice());
    out
}

#[test]
fn an_instance_draws_what_the_transformed_static_mesh_draws() {
    let mut renderer = renderer();
    let view = camera(160, 120);
    let texture_image = RgbaImage::from_fn(8, 8, |x, y| {
        image::Rgba([30 * x as u8, 30 * y as u8, 90, 255])
    });
    let (offset, yaw, scale) = (Vector3::new(0.15f32, -0.05, 0.1), 0.6f32, 1.3f32);
    let local = square_at(Point3::origin(), 0.25);
    let transform = instance(offset, yaw, scale);
    let mut placed = local.clone();
    let similarity = nalgebra::Similarity3::new(offset, Vector3::z() * yaw, scale);
    for p in &mut placed.positions {
        *p = similarity.transform_point(p);
    }
    placed.compute_normals();

    let mut static_scene = renderer.new_scene();
    let t = renderer.add_texture(&mut static_scene, &texture_image);
    renderer
        .add_mesh(&mut static_scene, &placed, t, 1, false)
        .unwrap();
    let (static_stats, static_color) = renderer
        .render_instanced(&static_scene, &view, &Lighting::default(), &[], &[], true)
        .unwrap();
    assert_eq!((static_stats.draw_calls, static_stats.triangles), (1, 2));

    let mut instanced_scene = renderer.new_scene();
    let t = renderer.add_texture(&mut instanced_scene, &texture_image);
    let mesh = renderer
        .add_instanced_mesh(&mut instanced_scene, &local, t, 1, false)
        .unwrap();
    // A second instance far behind the camera draws nothing visible.
    let transforms = [transform, instance(Vector3::new(0.0, -50.0, 0.0), 0.0, 1.0)];
    let batches = [InstanceBatch {
        mesh,
        instances: 0..2,
    }];
    let (stats, color) = renderer
        .render_instanced(
            &instanced_scene,
            &view,
            &Lighting::default(),
            &transforms,
            &batches,
            true,
        )
        .unwrap();
    assert_eq!(
        (stats.draw_calls, stats.instances, stats.triangles),
        (1, 2, 4)
    );
    let (a, b) = (static_color.unwrap(), color.unwrap());
    let sky = *a.get_pixel(0, 0);
    let covered = a.pixels().filter(|p| **p != sky).count();
    let differing = a
        .pixels()
        .zip(b.pixels())
        .filter(|(p, q)| (0..3).any(|c| p[c].abs_diff(q[c]) > 8))
        .count();
    assert!(covered > 1000, "square covers {covered} pixels");
    assert!(
        differing * 100 < covered,
        "{differing} of {covered} pixels differ"
    );

    let bad = [InstanceBatch {
        mesh,
        instances: 1..3,
    }];
    assert!(
        renderer
            .render_instanced(
                &instanced_scene,
                &view,
                &Lighting::default(),
                &transforms,
                &bad,
                false
            )
            .is_err()
    );
}

#[test]
fn depth_difference_on_the_gpu_matches_the_cpu_reference() {
    let renderer = renderer();
    let (width, height) = (67u32, 45u32);
    // Background, a far slab, a nearer disc overlapping it, noise on the slab, and the frame.
    let mut rng = crate::util::rng::Rng::seed_from(3);
    let mut depth = vec![0.0f32; (width * height) as usize];
    for y in 0..height {
        for x in 0..width {
            let at = (y * width + x) as usize;
            if (5..60).contains(&x) && (3..40).contains(&y) {
                depth[at] = 4.0 + 0.01 * rng.uniform() as f32;
            }
            let (dx, dy) = (x as f32 - 30.0, y as f32 - 20.0);
            if dx * dx + dy * dy < 100.0 {
                depth[at] = 2.5;
            }
            if x == 0 && y < 10 {
                depth[at] = 3.0;
            }
        }
    }
    let background = 50.0;
    let gpu = renderer
        .depth_difference(&depth, width, height, background)
        .unwrap();
    let cpu = depth_difference_cpu(&depth, width, height, background);
    assert_eq!(gpu.len(), cpu.len());
    for (i, (g, c)) in gpu.iter().zip(&cpu).enumerate() {
        assert!(
            (g - c).abs() <= 1e-5 * c.abs().max(1.0),
            "pixel ({}, {}): GPU {g} vs CPU {c}",
            i % width as usize,
            i / width as usize
        );
    }
    // What the buffer means: the disc's rim is 1.5 in front of the slab, the slab's rim 46 in
    // front of the background, the inside of either nothing.
    let at = |x: u32, y: u32| cpu[(y * width + x) as usize];
    assert!((at(30, 11) - 1.5).abs() < 0.02, "disc rim {}", at(30, 11));
    assert_eq!(at(30, 20), 0.0);
    assert!((at(5, 20) - 46.0).abs() < 0.02, "slab rim {}", at(5, 20));
    assert_eq!(at(2, 42), 0.0, "background has no outline");
    // Wrong sizes are refused.
    assert!(
        renderer
            .depth_difference(&depth[1..], width, height, background)
            .is_err()
    );
}

#[test]
fn rendered_depth_difference_outlines_the_front_square() {
    let mut renderer = renderer();
    let (mut scene, texture) = white_scene(&renderer);
    // A square in front of a larger one, 0.5 nearer the camera.
    renderer
        .add_mesh(
            &mut scene,
            &square_at(Point3::new(0.1, 0.05, 0.0), 0.6),
            texture,
            1,
            false,
        )
        .unwrap();
    renderer
        .add_mesh(
            &mut scene,
            &square_at(Point3::new(0.1, 0.05, 0.5), 0.15),
            texture,
            2,
            false,
        )
        .unwrap();
    let view = camera(160, 120);
    let (out, difference) = renderer
        .render_with_depth_difference(&scene, &view, &Lighting::default(), view.far as f32)
        .unwrap();
    let reference = depth_difference_cpu(&out.depth, view.width, view.height, view.far as f32);
    let mismatched = difference
        .iter()
        .zip(&reference)
        .filter(|(g, c)| (**g - **c).abs() > 1e-4 * c.abs().max(1.0))
        .count();
    assert_eq!(mismatched, 0);
    // Pixels of the front square next to the back one stand about 0.5·(view ray) in front;
    // its interior and the back square's interior stand in front of nothing.
    let front_rim = (0..out.object_id.len())
        .filter(|&i| out.object_id[i] == 2 && difference[i] > 0.2)
        .count();
    let front = out.object_id.iter().filter(|&&id| id == 2).count();
    assert!(
        front_rim > 20 && front_rim < front / 2,
        "{front_rim} rim of {front}"
    );
    let back_inner = (0..out.object_id.len())
        .filter(|&i| out.object_id[i] == 1 && difference[i] > 0.2 && difference[i] < 5.0)
        .count();
    assert_eq!(
        back_inner, 0,
        "the back square is in front of nothing but the background"
    );
}
