//! Boykov–Kolmogorov against petgraph's Dinic on random graphs: same flow value, and the
//! cut it reports has exactly that capacity.

use frond::graph::maxflow::{CutSide, MaxFlow};
use frond::util::rng::Rng;
use petgraph::Graph;
use petgraph::algo::dinics;

#[test]
fn same_flow_as_dinics_and_a_valid_cut() {
    for seed in 0..200 {
        let mut rng = Rng::seed_from(1000 + seed);
        let n = 2 + rng.below(60);
        let mut graph = Graph::<(), f64>::new();
        let nodes: Vec<_> = (0..n + 2).map(|_| graph.add_node(())).collect();
        let (source, sink) = (nodes[n], nodes[n + 1]);
        let mut flow = MaxFlow::new(n);
        let mut edges: Vec<(usize, usize, f64)> = Vec::new();
        for (v, &node) in nodes.iter().enumerate().take(n) {
            if rng.chance(0.35) {
                let c = rng.range(0.1, 10.0);
                graph.add_edge(source, node, c);
                flow.add_terminal_weights(v, c, 0.0).unwrap();
                edges.push((n, v, c));
            }
            if rng.chance(0.35) {
                let c = rng.range(0.1, 10.0);
                graph.add_edge(node, sink, c);
                flow.add_terminal_weights(v, 0.0, c).unwrap();
                edges.push((v, n + 1, c));
            }
        }
        for _ in 0..rng.below(5 * n + 1) {
            let (a, b) = (rng.below(n), rng.below(n));
            if a == b {
                continue;
            }
            let (forward, backward) = (rng.range(0.0, 6.0), rng.range(0.0, 6.0));
            graph.add_edge(nodes[a], nodes[b], forward);
            graph.add_edge(nodes[b], nodes[a], backward);
            flow.add_edge(a, b, forward, backward).unwrap();
            edges.push((a, b, forward));
            edges.push((b, a, backward));
        }
        let (expected, _) = dinics(&graph, source, sink);
        let value = flow.solve();
        assert!(
            (value - expected).abs() < 1e-9 * expected.max(1.0),
            "seed {seed}: {value} vs {expected}"
        );
        let on_source = |v: usize| v == n || (v < n && flow.side(v) == CutSide::Source);
        let cut: f64 = edges
            .iter()
            .filter(|(a, b, _)| on_source(*a) && !on_source(*b))
            .map(|(_, _, c)| c)
            .sum();
        assert!(
            (cut - expected).abs() < 1e-9 * expected.max(1.0),
            "seed {seed}: cut {cut} vs {expected}"
        );
    }
}
