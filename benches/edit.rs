//! Interactive latencies (issue targets: split or merge of a ~5k-point segment < 10 ms; one
//! segment's image boundary at 800x600 < 50 ms once the view is oversegmented) and
//! Boykov–Kolmogorov against petgraph's Dinic on a 10k-node grid (same run).

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use frond::edit::{Command, PixelRef, Session};
use frond::graph::maxflow::MaxFlow;
use frond::scene::Scene;
use frond::segment::boundary::{BoundaryOptions, Oversegmentation};
use frond::segment::{SegmentLabel, SegmentOptions, segment_scene};
use frond::synth::{Preset, SynthOptions, write_dataset};
use frond::util::progress::NoProgress;
use frond::util::rng::Rng;
use petgraph::Graph;

/// A flow problem: node count, terminal (source, sink) capacities per node, edges (a, b, capacity).
type GridProblem = (usize, Vec<(f64, f64)>, Vec<(usize, usize, f64)>);

/// A 100×100 grid with 4-neighbour capacities and random terminal weights (a typical vision
/// graph).
fn grid(seed: u64) -> GridProblem {
    let side = 100;
    let mut rng = Rng::seed_from(seed);
    let terminals = (0..side * side)
        .map(|i| {
            let x = (i % side) as f64 / side as f64;
            // Source-leaning on the left, sink-leaning on the right, noisy.
            ((1.0 - x) * rng.range(0.0, 4.0), x * rng.range(0.0, 4.0))
        })
        .collect();
    let mut edges = Vec::new();
    for y in 0..side {
        for x in 0..side {
            let i = y * side + x;
            if x + 1 < side {
                edges.push((i, i + 1, rng.range(0.5, 3.0)));
            }
            if y + 1 < side {
                edges.push((i, i + side, rng.range(0.5, 3.0)));
            }
        }
    }
    (side * side, terminals, edges)
}

fn maxflow(c: &mut Criterion) {
    let (n, terminals, edges) = grid(3);
    let mut group = c.benchmark_group("maxflow_grid_100x100");
    group.sample_size(10);
    group.bench_function("boykov_kolmogorov", |b| {
        b.iter(|| {
            let mut flow = MaxFlow::new(n);
            for (v, &(s, t)) in terminals.iter().enumerate() {
                flow.add_terminal_weights(v, s, t).expect("valid");
            }
            for &(a, b, c) in &edges {
                flow.add_edge(a, b, c, c).expect("valid");
            }
            black_box(flow.solve())
        })
    });
    group.bench_function("baseline_petgraph_dinics", |b| {
        b.iter(|| {
            let mut graph = Graph::<(), f64>::with_capacity(n + 2, 2 * edges.len() + 2 * n);
            let nodes: Vec<_> = (0..n + 2).map(|_| graph.add_node(())).collect();
            for (v, &(s, t)) in terminals.iter().enumerate() {
                graph.add_edge(nodes[n], nodes[v], s);
                graph.add_edge(nodes[v], nodes[n + 1], t);
            }
            for &(a, b, c) in &edges {
                graph.add_edge(nodes[a], nodes[b], c);
                graph.add_edge(nodes[b], nodes[a], c);
            }
            black_box(petgraph::algo::dinics(&graph, nodes[n], nodes[n + 1]).0)
        })
    });
    group.finish();
}

fn edits(c: &mut Criterion) {
    let dir = tempfile::tempdir().expect("temp dir");
    let root = dir.path().join("plant");
    let options = SynthOptions {
        preset: Preset::Broadleaf,
        seed: 21,
        target_points: 120_000,
        ..SynthOptions::default()
    };
    write_dataset(&options, &root, &NoProgress).expect("dataset");
    let scene = Scene::open(&root).expect("scene");
    let segmentation =
        segment_scene(&scene, &SegmentOptions::default(), &NoProgress).expect("segmentation");
    let mut session = Session::new(scene, segmentation);
    // The leaf segment closest to 5,000 points, and the view that sees most of it.
    let mut sizes = vec![0usize; session.segments().len()];
    for &s in session.segment_of() {
        if s >= 0 {
            sizes[s as usize] += 1;
        }
    }
    let segment = (0..sizes.len())
        .filter(|&s| session.segments()[s].is_some_and(|st| st.label == SegmentLabel::Leaf))
        .min_by_key(|&s| sizes[s].abs_diff(5_000))
        .expect("a leaf segment");
    let members = session.members(segment as u32);
    let points = session.segmentation().points.clone();
    let model = session.scene().reconstruction.clone();
    let view = (0..model.images().len())
        .max_by_key(|&v| {
            members
                .iter()
                .filter(|&&p| points.views[p as usize].binary_search(&(v as u32)).is_ok())
                .count()
        })
        .expect("a view");
    let image = model.images()[view].clone();
    let image = &image;
    let uv: Vec<nalgebra::Point2<f64>> = members
        .iter()
        .filter(|&&p| {
            points.views[p as usize]
                .binary_search(&(view as u32))
                .is_ok()
        })
        .filter_map(|&p| model.project(image, &points.positions[p as usize]))
        .collect();
    let centre = uv.iter().fold(nalgebra::Point2::origin(), |a, p| {
        a + p.coords / uv.len() as f64
    });
    let (lo_y, hi_y) = uv
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), p| (a.min(p.y), b.max(p.y)));
    eprintln!(
        "segment {segment}: {} points, {} seen in view {view}",
        members.len(),
        uv.len()
    );
    // A vertical stroke through the segment's middle.
    let split = Command::SplitByStroke {
        image_id: image.id,
        stroke: vec![[centre.x, lo_y - 10.0], [centre.x, hi_y + 10.0]],
        closed: false,
    };
    let mut group = c.benchmark_group("edits_5k_point_segment");
    group.sample_size(20);
    group.bench_function("split_by_stroke", |b| {
        b.iter(|| {
            session.apply(split.clone()).expect("split");
            session.undo();
        })
    });
    session.apply(split.clone()).expect("split");
    // Click one point of each of the two parts the split made.
    // Click the middle of each of the two parts the split made (the visible point nearest to
    // the part's projected centroid, away from the stroke and the rim).
    let part_click = |session: &Session, target: i32, other: bool| {
        let part: Vec<(u32, nalgebra::Point2<f64>)> = members
            .iter()
            .filter(|&&p| {
                points.views[p as usize]
                    .binary_search(&(view as u32))
                    .is_ok()
                    && (session.segment_of()[p as usize] == target) != other
            })
            .filter_map(|&p| {
                model
                    .project(image, &points.positions[p as usize])
                    .map(|uv| (p, uv))
            })
            .collect();
        let centroid = part.iter().fold(nalgebra::Point2::origin(), |a, (_, uv)| {
            a + uv.coords / part.len() as f64
        });
        let (p, uv) = *part
            .iter()
            .min_by(|a, b| (a.1 - centroid).norm().total_cmp(&(b.1 - centroid).norm()))
            .expect("a visible point of each part");
        let click = PixelRef {
            image_id: image.id,
            pixel: [uv.x, uv.y],
        };
        assert_eq!(
            session
                .pick_segment(&click)
                .expect("a point under the click") as i32,
            session.segment_of()[p as usize],
            "the click lands on its part"
        );
        click
    };
    let merge = Command::MergeByClick {
        first: part_click(&session, segment as i32, false),
        second: part_click(&session, segment as i32, true),
    };
    group.bench_function("merge_by_click", |b| {
        b.iter(|| {
            session.apply(merge.clone()).expect("merge");
            session.undo();
        })
    });
    session.undo();
    group.finish();

    let mat = session.scene().load_image(image).expect("image");
    let mut group = c.benchmark_group("boundary_800x600");
    group.sample_size(10);
    group.bench_function("oversegmentation_watershed", |b| {
        b.iter(|| {
            black_box(
                Oversegmentation::compute(&mat, &BoundaryOptions::default()).expect("watershed"),
            )
        })
    });
    let superpixels =
        Oversegmentation::compute(&mat, &BoundaryOptions::default()).expect("watershed");
    eprintln!("{} superpixels", superpixels.len());
    let all: Vec<(u32, nalgebra::Point2<f64>)> = (0..points.len())
        .filter(|&p| points.views[p].binary_search(&(view as u32)).is_ok())
        .filter_map(|p| {
            model
                .project(image, &points.positions[p])
                .map(|uv| (p as u32, uv))
        })
        .collect();
    let foreground: Vec<_> = all
        .iter()
        .filter(|(p, _)| session.segment_of()[*p as usize] == segment as i32)
        .map(|x| x.1)
        .collect();
    let background: Vec<_> = all
        .iter()
        .filter(|(p, _)| session.segment_of()[*p as usize] != segment as i32)
        .map(|x| x.1)
        .collect();
    group.bench_function("segment_boundary", |b| {
        b.iter(|| {
            black_box(
                superpixels
                    .boundary(&foreground, &background, &BoundaryOptions::default())
                    .expect("boundary"),
            )
        })
    });
    group.finish();
}

criterion_group!(benches, maxflow, edits);
criterion_main!(benches);
