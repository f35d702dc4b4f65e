//! Simplification speed and quality (issue 9: ≥ 1M triangles/s; our half-edge collapse must
//! beat meshoptimizer on plant silhouettes to earn its place). Baseline in the same run:
//! `meshopt::simplify` (meshoptimizer) on the same mesh and triangle budget. The mesh is a
//! synthetic medium plant: every leaf mesh and every branch's generalized cylinder.

use std::hint::black_box;
use std::time::Instant;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use frond::branch::CylinderMeshing;
use frond::eval::geometry::symmetric_chamfer;
use frond::lod::chain::{ChainOptions, build_chain};
use frond::lod::simplify::{SimplifyOptions, simplify};
use frond::mesh::TriMesh;
use frond::synth::{Preset, generate_plant};

fn plant_mesh() -> TriMesh {
    let plant = generate_plant(Preset::Medium, 1);
    let mut mesh = TriMesh::default();
    for leaf in &plant.leaves {
        mesh.append(&leaf.mesh);
    }
    for branch in &plant.branches.branches {
        mesh.append(&branch.cylinder.mesh(&CylinderMeshing::default()));
    }
    mesh
}

fn meshopt_simplify(mesh: &TriMesh, target_triangles: usize) -> TriMesh {
    let bytes = meshopt::typed_to_bytes(&mesh.positions);
    let adapter = meshopt::VertexDataAdapter::new(bytes, 12, 0).expect("positions adapter");
    let indices: Vec<u32> = mesh.triangles.iter().flatten().copied().collect();
    let kept = meshopt::simplify(
        &indices,
        &adapter,
        target_triangles * 3,
        1.0,
        meshopt::SimplifyOptions::None,
        None,
    );
    let mut out = mesh.clone();
    out.triangles = kept.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    out
}

fn simplification(c: &mut Criterion) {
    let mesh = plant_mesh();
    let triangles = mesh.triangles.len();
    let extent = mesh
        .bounds()
        .map(|(lo, hi)| (hi - lo).norm() as f64)
        .unwrap_or(1.0);
    println!(
        "plant mesh: {triangles} triangles, {} vertices, diagonal {extent:.3} m",
        mesh.positions.len()
    );
    for ratio in [0.5, 0.1] {
        let target = (triangles as f64 * ratio) as usize;
        let started = Instant::now();
        let simplified = simplify(&mesh, &SimplifyOptions::to_triangles(target)).expect("simplify");
        let ours = simplified.mesh;
        let ours_time = started.elapsed().as_secs_f64();
        let started = Instant::now();
        let theirs = meshopt_simplify(&mesh, target);
        let theirs_time = started.elapsed().as_secs_f64();
        println!(
            "ratio {ratio}: {} collapses, {} refused",
            simplified.collapses, simplified.refused
        );
        let chamfer = |m: &TriMesh| symmetric_chamfer(&mesh, m, 4000, 7).unwrap_or(f64::NAN);
        println!(
            "ratio {ratio}: ours {} triangles in {ours_time:.3} s ({:.2} M tri/s), Chamfer {:.3e} m ({:.3} % of diagonal); meshopt {} triangles in {theirs_time:.3} s ({:.2} M tri/s), Chamfer {:.3e} m ({:.3} %)",
            ours.triangles.len(),
            triangles as f64 / ours_time / 1e6,
            chamfer(&ours),
            100.0 * chamfer(&ours) / extent,
            theirs.triangles.len(),
            triangles as f64 / theirs_time / 1e6,
            chamfer(&theirs),
            100.0 * chamfer(&theirs) / extent,
        );
    }

    let started = Instant::now();
    let chain = build_chain(&mesh, &ChainOptions::default()).expect("chain");
    println!(
        "LOD chain in {:.3} s: {}",
        started.elapsed().as_secs_f64(),
        chain
            .iter()
            .map(|l| format!("{} triangles, μ {:.2e} m", l.triangles, l.error_world))
            .collect::<Vec<_>>()
            .join("; ")
    );

    let mut group = c.benchmark_group("simplify_plant_to_10_percent");
    group.throughput(Throughput::Elements(triangles as u64));
    group.sample_size(10);
    let target = triangles / 10;
    group.bench_function("frond_half_edge_collapse", |b| {
        b.iter(|| black_box(simplify(&mesh, &SimplifyOptions::to_triangles(target))))
    });
    group.bench_function("meshopt_baseline", |b| {
        b.iter(|| black_box(meshopt_simplify(&mesh, target)))
    });
    group.finish();
}

criterion_group!(benches, simplification);
criterion_main!(benches);
