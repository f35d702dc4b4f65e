//! Boykov–Kolmogorov max-flow / min-cut (Boykov & Kolmogorov, "An experimental comparison of
//! min-cut/max-flow algorithms for energy minimization in vision", PAMI 2004), for the
//! two-label graph cuts of the interactive edits (seed 004 §5.3) and image boundaries (§5.4).
//!
//! Two search trees grow from the source and the sink; when they touch, the path is
//! augmented; orphaned nodes are re-adopted (with the distance/timestamp heuristic) or freed.
//! Trees are reused between augmentations, which is what makes the algorithm fast on the
//! short-path, grid-like graphs of vision.

use std::collections::VecDeque;

/// Which side of the minimum cut a node is on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CutSide {
    Source,
    Sink,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Tree {
    Free,
    Source,
    Sink,
}

const NO_PARENT: u32 = u32::MAX;
const TERMINAL: u32 = u32::MAX - 1;
const ORPHAN: u32 = u32::MAX - 2;

/// A flow network with terminal links, solved by Boykov–Kolmogorov.
#[derive(Clone, Debug)]
pub struct MaxFlow {
    /// Residual terminal capacity: > 0 from the source, < 0 to the sink.
    terminal: Vec<f64>,
    arcs_of: Vec<Vec<u32>>,
    head: Vec<u32>,
    residual: Vec<f64>,
    tree: Vec<Tree>,
    /// Arc from the node to its parent in its tree (or a marker).
    parent: Vec<u32>,
    timestamp: Vec<u64>,
    distance: Vec<u32>,
    flow: f64,
    solved: bool,
}

/// Invalid network input.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MaxFlowError {
    #[error("node {node} is out of range ({nodes} nodes)")]
    NodeOutOfRange { node: usize, nodes: usize },
    #[error("capacity {0} is negative or not finite")]
    BadCapacity(f64),
}

impl MaxFlow {
    /// A network of `nodes` nodes without arcs.
    pub fn new(nodes: usize) -> Self {
        Self {
            terminal: vec![0.0; nodes],
            arcs_of: vec![Vec::new(); nodes],
            head: Vec::new(),
            residual: Vec::new(),
            tree: vec![Tree::Free; nodes],
            parent: vec![NO_PARENT; nodes],
            timestamp: vec![0; nodes],
            distance: vec![0; nodes],
            flow: 0.0,
            solved: false,
        }
    }

    pub fn num_nodes(&self) -> usize {
        self.terminal.len()
    }

    fn check(&self, node: usize) -> Result<(), MaxFlowError> {
        if node >= self.num_nodes() {
            return Err(MaxFlowError::NodeOutOfRange {
                node,
                nodes: self.num_nodes(),
            });
        }
        Ok(())
    }

    fn check_capacity(capacity: f64) -> Result<(), MaxFlowError> {
        if capacity.is_finite() && capacity >= 0.0 || capacity == f64::INFINITY {
            Ok(())
        } else {
            Err(MaxFlowError::BadCapacity(capacity))
        }
    }

    /// Adds terminal capacities: source → node and node → sink. Called several times for a
    /// node, the capacities add up. Infinite capacities make hard constraints.
    pub fn add_terminal_weights(
        &mut self,
        node: usize,
        from_source: f64,
        to_sink: f64,
    ) -> Result<(), MaxFlowError> {
        self.check(node)?;
        Self::check_capacity(from_source)?;
        Self::check_capacity(to_sink)?;
        // Fold in what the node already has, then push the common part straight through:
        // only the difference remains as a terminal capacity.
        let existing = self.terminal[node];
        let (mut from_source, mut to_sink) = (from_source, to_sink);
        if existing > 0.0 {
            from_source += existing;
        } else {
            to_sink -= existing;
        }
        let common = from_source.min(to_sink);
        if from_source.is_infinite() && to_sink.is_infinite() {
            self.flow = f64::INFINITY;
            self.terminal[node] = 0.0;
        } else if from_source.is_infinite() {
            self.flow += to_sink;
            self.terminal[node] = f64::INFINITY;
        } else if to_sink.is_infinite() {
            self.flow += from_source;
            self.terminal[node] = f64::NEG_INFINITY;
        } else {
            self.flow += common;
            self.terminal[node] = from_source - to_sink;
        }
        self.solved = false;
        Ok(())
    }

    /// Adds an edge with capacity `forward` from `a` to `b` and `backward` from `b` to `a`.
    pub fn add_edge(
        &mut self,
        a: usize,
        b: usize,
        forward: f64,
        backward: f64,
    ) -> Result<(), MaxFlowError> {
        self.check(a)?;
        self.check(b)?;
        Self::check_capacity(forward)?;
        Self::check_capacity(backward)?;
        if a == b {
            return Ok(());
        }
        let index = self.head.len() as u32;
        self.head.push(b as u32);
        self.residual.push(forward);
        self.head.push(a as u32);
        self.residual.push(backward);
        self.arcs_of[a].push(index);
        self.arcs_of[b].push(index + 1);
        self.solved = false;
        Ok(())
    }

    /// Computes the maximum flow (the minimum cut's capacity).
    #[allow(clippy::needless_range_loop)] // node indexes several parallel arrays
    pub fn solve(&mut self) -> f64 {
        if self.solved {
            return self.flow;
        }
        let n = self.num_nodes();
        let mut active: VecDeque<u32> = VecDeque::new();
        let mut in_queue = vec![false; n];
        let mut orphans: Vec<u32> = Vec::new();
        let mut time: u64 = 1;
        for node in 0..n {
            self.tree[node] = Tree::Free;
            self.parent[node] = NO_PARENT;
            self.timestamp[node] = 0;
            if self.terminal[node] > 0.0 {
                self.tree[node] = Tree::Source;
            } else if self.terminal[node] < 0.0 {
                self.tree[node] = Tree::Sink;
            } else {
                continue;
            }
            self.parent[node] = TERMINAL;
            self.timestamp[node] = time;
            self.distance[node] = 1;
            active.push_back(node as u32);
            in_queue[node] = true;
        }
        while let Some(p) = active.front().copied() {
            let p = p as usize;
            if self.parent[p] == NO_PARENT {
                active.pop_front();
                in_queue[p] = false;
                continue;
            }
            // Grow from p until it reaches the other tree.
            let mut bridge: Option<u32> = None;
            let arcs = std::mem::take(&mut self.arcs_of[p]);
            for &arc in &arcs {
                let q = self.head[arc as usize] as usize;
                let (forward, sister) = (arc as usize, (arc ^ 1) as usize);
                match self.tree[p] {
                    Tree::Source if self.residual[forward] > 0.0 => match self.tree[q] {
                        Tree::Free => {
                            self.tree[q] = Tree::Source;
                            self.parent[q] = sister as u32;
                            self.timestamp[q] = self.timestamp[p];
                            self.distance[q] = self.distance[p] + 1;
                            if !in_queue[q] {
                                active.push_back(q as u32);
                                in_queue[q] = true;
                            }
                        }
                        Tree::Sink => {
                            bridge = Some(arc);
                            break;
                        }
                        Tree::Source => {
                            if self.timestamp[q] <= self.timestamp[p]
                                && self.distance[q] > self.distance[p]
                            {
                                self.parent[q] = sister as u32;
                                self.timestamp[q] = self.timestamp[p];
                                self.distance[q] = self.distance[p] + 1;
                            }
                        }
                    },
                    Tree::Sink if self.residual[sister] > 0.0 => match self.tree[q] {
                        Tree::Free => {
                            self.tree[q] = Tree::Sink;
                            self.parent[q] = sister as u32;
                            self.timestamp[q] = self.timestamp[p];
                            self.distance[q] = self.distance[p] + 1;
                            if !in_queue[q] {
                                active.push_back(q as u32);
                                in_queue[q] = true;
                            }
                        }
                        Tree::Source => {
                            bridge = Some(sister as u32);
                            break;
                        }
                        Tree::Sink => {
                            if self.timestamp[q] <= self.timestamp[p]
                                && self.distance[q] > self.distance[p]
                            {
                                self.parent[q] = sister as u32;
                                self.timestamp[q] = self.timestamp[p];
                                self.distance[q] = self.distance[p] + 1;
                            }
                        }
                    },
                    _ => {}
                }
            }
            self.arcs_of[p] = arcs;
            time += 1;
            match bridge {
                None => {
                    active.pop_front();
                    in_queue[p] = false;
                }
                Some(middle) => {
                    self.augment(middle as usize, &mut orphans);
                    if self.flow.is_infinite() {
                        break;
                    }
                    self.adopt(&mut orphans, &mut active, &mut in_queue, time);
                    // p stays at the front: it may still reach the other tree.
                }
            }
        }
        self.solved = true;
        self.flow
    }

    /// Pushes the bottleneck flow along source → … → tail(middle) → head(middle) → … → sink.
    fn augment(&mut self, middle: usize, orphans: &mut Vec<u32>) {
        let mut bottleneck = self.residual[middle];
        // Source side: from the tail of the middle arc up to the source.
        let mut node = self.head[middle ^ 1] as usize;
        while self.parent[node] != TERMINAL {
            let arc = self.parent[node] as usize;
            bottleneck = bottleneck.min(self.residual[arc ^ 1]);
            node = self.head[arc] as usize;
        }
        bottleneck = bottleneck.min(self.terminal[node]);
        // Sink side.
        let mut node = self.head[middle] as usize;
        while self.parent[node] != TERMINAL {
            let arc = self.parent[node] as usize;
            bottleneck = bottleneck.min(self.residual[arc]);
            node = self.head[arc] as usize;
        }
        bottleneck = bottleneck.min(-self.terminal[node]);
        if bottleneck.is_infinite() {
            // An infinite-capacity path from source to sink: no finite cut exists.
            self.flow = f64::INFINITY;
            return;
        }
        if bottleneck <= 0.0 || bottleneck.is_nan() {
            return;
        }

        self.residual[middle] -= bottleneck;
        self.residual[middle ^ 1] += bottleneck;
        let mut node = self.head[middle ^ 1] as usize;
        while self.parent[node] != TERMINAL {
            let arc = self.parent[node] as usize;
            self.residual[arc] += bottleneck;
            self.residual[arc ^ 1] -= bottleneck;
            if self.residual[arc ^ 1] <= 0.0 {
                self.parent[node] = ORPHAN;
                orphans.push(node as u32);
            }
            node = self.head[arc] as usize;
        }
        self.terminal[node] -= bottleneck;
        if self.terminal[node] <= 0.0 {
            self.terminal[node] = 0.0;
            self.parent[node] = ORPHAN;
            orphans.push(node as u32);
        }
        let mut node = self.head[middle] as usize;
        while self.parent[node] != TERMINAL {
            let arc = self.parent[node] as usize;
            self.residual[arc ^ 1] += bottleneck;
            self.residual[arc] -= bottleneck;
            if self.residual[arc] <= 0.0 {
                self.parent[node] = ORPHAN;
                orphans.push(node as u32);
            }
            node = self.head[arc] as usize;
        }
        self.terminal[node] += bottleneck;
        if self.terminal[node] >= 0.0 {
            self.terminal[node] = 0.0;
            self.parent[node] = ORPHAN;
            orphans.push(node as u32);
        }
        self.flow += bottleneck;
    }

    /// Whether the residual arc that would make `q` the parent of `p` has capacity.
    fn can_parent(&self, tree: Tree, arc_p_to_q: usize) -> bool {
        match tree {
            // Source tree: flow goes q → p.
            Tree::Source => self.residual[arc_p_to_q ^ 1] > 0.0,
            Tree::Sink => self.residual[arc_p_to_q] > 0.0,
            Tree::Free => false,
        }
    }

    /// Distance of `q` to its terminal if its path is still rooted there, else `None`.
    fn rooted_distance(&mut self, q: usize, time: u64) -> Option<u32> {
        let mut steps = 0u32;
        let mut node = q;
        let found = loop {
            if self.timestamp[node] == time {
                break Some(steps + self.distance[node]);
            }
            match self.parent[node] {
                TERMINAL => {
                    self.timestamp[node] = time;
                    self.distance[node] = 1;
                    break Some(steps + 1);
                }
                ORPHAN | NO_PARENT => break None,
                arc => {
                    steps += 1;
                    node = self.head[arc as usize] as usize;
                }
            }
        }?;
        // Mark the path so later checks stop early.
        let mut node = q;
        let mut d = found;
        while self.timestamp[node] != time {
            self.timestamp[node] = time;
            self.distance[node] = d;
            d = d.saturating_sub(1);
            let arc = self.parent[node];
            if arc == TERMINAL || arc == ORPHAN || arc == NO_PARENT {
                break;
            }
            node = self.head[arc as usize] as usize;
        }
        Some(found)
    }

    fn adopt(
        &mut self,
        orphans: &mut Vec<u32>,
        active: &mut VecDeque<u32>,
        in_queue: &mut [bool],
        time: u64,
    ) {
        while let Some(p) = orphans.pop() {
            let p = p as usize;
            let tree = self.tree[p];
            let arcs = std::mem::take(&mut self.arcs_of[p]);
            let mut best: Option<(u32, u32)> = None;
            for &arc in &arcs {
                let q = self.head[arc as usize] as usize;
                if self.tree[q] != tree || !self.can_parent(tree, arc as usize) {
                    continue;
                }
                if let Some(d) = self.rooted_distance(q, time)
                    && best.is_none_or(|(_, bd)| d < bd)
                {
                    best = Some((arc, d));
                }
            }
            match best {
                Some((arc, d)) => {
                    self.parent[p] = arc;
                    self.timestamp[p] = time;
                    self.distance[p] = d + 1;
                }
                None => {
                    for &arc in &arcs {
                        let q = self.head[arc as usize] as usize;
                        if self.tree[q] != tree {
                            continue;
                        }
                        if self.can_parent(tree, arc as usize) && !in_queue[q] {
                            active.push_back(q as u32);
                            in_queue[q] = true;
                        }
                        let parent_arc = self.parent[q];
                        if parent_arc != TERMINAL
                            && parent_arc != ORPHAN
                            && parent_arc != NO_PARENT
                            && self.head[parent_arc as usize] as usize == p
                        {
                            self.parent[q] = ORPHAN;
                            orphans.push(q as u32);
                        }
                    }
                    self.tree[p] = Tree::Free;
                    self.parent[p] = NO_PARENT;
                }
            }
            self.arcs_of[p] = arcs;
        }
    }

    /// The side of the minimum cut of a node (after [`MaxFlow::solve`]): the source side is
    /// what the source still reaches through residual capacity.
    pub fn side(&self, node: usize) -> CutSide {
        match self.tree.get(node) {
            Some(Tree::Source) => CutSide::Source,
            _ => CutSide::Sink,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::util::rng::Rng;

    #[test]
    fn textbook_network() {
        // CLRS figure 26.1: max flow 23 from s=0 to t=5; here s and t are terminals.
        let mut g = MaxFlow::new(4);
        // Nodes v1..v4 = 0..3.
        g.add_terminal_weights(0, 16.0, 0.0).unwrap();
        g.add_terminal_weights(1, 13.0, 0.0).unwrap();
        g.add_terminal_weights(2, 0.0, 20.0).unwrap();
        g.add_terminal_weights(3, 0.0, 4.0).unwrap();
        g.add_edge(0, 2, 12.0, 0.0).unwrap();
        g.add_edge(1, 0, 4.0, 0.0).unwrap();
        g.add_edge(2, 1, 9.0, 0.0).unwrap();
        g.add_edge(1, 3, 14.0, 0.0).unwrap();
        g.add_edge(3, 2, 7.0, 0.0).unwrap();
        assert!((g.solve() - 23.0).abs() < 1e-12);
    }

    #[test]
    fn hard_constraints_and_bad_input() {
        let mut g = MaxFlow::new(3);
        g.add_terminal_weights(0, f64::INFINITY, 0.0).unwrap();
        g.add_terminal_weights(2, 0.0, f64::INFINITY).unwrap();
        g.add_edge(0, 1, 2.0, 2.0).unwrap();
        g.add_edge(1, 2, 5.0, 5.0).unwrap();
        assert_eq!(g.solve(), 2.0);
        assert_eq!(g.side(0), CutSide::Source);
        assert_eq!(g.side(1), CutSide::Sink);
        assert_eq!(g.side(2), CutSide::Sink);
        assert!(g.add_edge(0, 3, 1.0, 1.0).is_err());
        assert!(g.add_edge(0, 1, -1.0, 1.0).is_err());
        assert!(g.add_terminal_weights(1, f64::NAN, 0.0).is_err());
    }

    /// Max flow by Edmonds–Karp on a dense matrix (an independent reference).
    fn reference_flow(n: usize, capacity: &[Vec<f64>], s: usize, t: usize) -> f64 {
        let mut residual = capacity.to_vec();
        let mut flow = 0.0;
        loop {
            let mut parent = vec![usize::MAX; n];
            parent[s] = s;
            let mut queue = std::collections::VecDeque::from([s]);
            while let Some(u) = queue.pop_front() {
                for v in 0..n {
                    if parent[v] == usize::MAX && residual[u][v] > 1e-12 {
                        parent[v] = u;
                        queue.push_back(v);
                    }
                }
            }
            if parent[t] == usize::MAX {
                return flow;
            }
            let mut bottleneck = f64::INFINITY;
            let mut v = t;
            while v != s {
                bottleneck = bottleneck.min(residual[parent[v]][v]);
                v = parent[v];
            }
            let mut v = t;
            while v != s {
                residual[parent[v]][v] -= bottleneck;
                residual[v][parent[v]] += bottleneck;
                v = parent[v];
            }
            flow += bottleneck;
        }
    }

    #[test]
    #[allow(clippy::needless_range_loop)] // dense capacity matrix indexed by node pairs
    fn random_graphs_match_edmonds_karp_and_the_cut_is_valid() {
        for seed in 0..60 {
            let mut rng = Rng::seed_from(seed);
            let n = 2 + rng.below(25);
            let (s, t) = (n, n + 1);
            let mut capacity = vec![vec![0.0; n + 2]; n + 2];
            let mut g = MaxFlow::new(n);
            for node in 0..n {
                let (a, b) = (
                    if rng.chance(0.4) {
                        rng.range(0.0, 5.0)
                    } else {
                        0.0
                    },
                    if rng.chance(0.4) {
                        rng.range(0.0, 5.0)
                    } else {
                        0.0
                    },
                );
                capacity[s][node] += a;
                capacity[node][t] += b;
                g.add_terminal_weights(node, a, b).unwrap();
            }
            for _ in 0..rng.below(4 * n) {
                let (a, b) = (rng.below(n), rng.below(n));
                let (f, r) = (rng.range(0.0, 3.0), rng.range(0.0, 3.0));
                if a != b {
                    capacity[a][b] += f;
                    capacity[b][a] += r;
                }
                g.add_edge(a, b, f, r).unwrap();
            }
            let expected = reference_flow(n + 2, &capacity, s, t);
            let flow = g.solve();
            assert!(
                (flow - expected).abs() < 1e-9,
                "seed {seed}: {flow} vs {expected}"
            );
            // The cut induced by the segments has exactly the flow's capacity.
            let side: Vec<bool> = (0..n).map(|i| g.side(i) == CutSide::Source).collect();
            let mut cut = 0.0;
            for i in 0..n {
                if side[i] {
                    cut += capacity[i][t];
                    for j in 0..n {
                        if !side[j] {
                            cut += capacity[i][j];
                        }
                    }
                } else {
                    cut += capacity[s][i];
                }
            }
            assert!(
                (cut - expected).abs() < 1e-9,
                "seed {seed}: cut {cut} vs flow {expected}"
            );
        }
    }
}
