//! Render core: views per second at 800x600 for each synthetic preset (colour with 4× MSAA,
//! object ids and depth, read back to the CPU). Baseline in the same run: the same view with
//! only the floor and backdrop (fixed cost of passes and readback).

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use frond::render::{Lighting, Renderer, ViewCamera};
use frond::synth::dataset::ring_cameras;
use frond::synth::scene::{Backdrop, Part, build_scene};
use frond::synth::{Preset, generate_plant};

fn render_views(c: &mut Criterion) {
    let mut renderer = Renderer::new().expect("a GPU adapter (llvmpipe)");
    eprintln!("adapter: {}", renderer.adapter_description());
    let mut group = c.benchmark_group("render_800x600");
    group.sample_size(10);
    group.throughput(Throughput::Elements(1));
    for preset in Preset::ALL {
        let plant = generate_plant(preset, 1);
        let scene = build_scene(&plant, 2.5, 1, None, Backdrop::Patterned);
        let (camera, poses) = ring_cameras(&plant, 36, 800, 600);
        let view = ViewCamera::from_colmap(&camera, &poses[3], 0.02, 10.0).expect("pinhole");
        for (label, keep) in [("environment_only", false), ("full", true)] {
            if !keep && preset != Preset::Broadleaf {
                continue;
            }
            let mut gpu = renderer.new_scene();
            let textures: Vec<_> = scene
                .textures
                .iter()
                .map(|t| renderer.add_texture(&mut gpu, t))
                .collect();
            for object in &scene.objects {
                if keep || matches!(object.part, Part::Floor | Part::Background) {
                    renderer
                        .add_mesh(
                            &mut gpu,
                            &object.mesh,
                            textures[object.texture],
                            object.object_id,
                            false,
                        )
                        .expect("valid mesh");
                }
            }
            let name = if keep {
                format!(
                    "{preset}_{}_meshes_{}_triangles",
                    gpu.num_meshes(),
                    gpu.num_triangles()
                )
            } else {
                label.to_owned()
            };
            group.bench_function(name, |b| {
                b.iter(|| {
                    black_box(
                        renderer
                            .render(&gpu, &view, &Lighting::default())
                            .expect("render"),
                    )
                })
            });
        }
    }
    group.finish();
}

criterion_group!(benches, render_views);
criterion_main!(benches);
