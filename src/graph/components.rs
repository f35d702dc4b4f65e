//! Weighted adjacency in compressed rows, connected components and induced subgraphs.

/// Symmetric weighted adjacency in CSR form.
#[derive(Clone, Debug, Default)]
pub struct Adjacency {
    pub offsets: Vec<usize>,
    pub neighbours: Vec<u32>,
    pub weights: Vec<f64>,
}

/// A labelling of the nodes into connected components `0..count`.
#[derive(Clone, Debug)]
pub struct Components {
    pub labels: Vec<u32>,
    pub count: usize,
}

impl Components {
    /// The members of each component.
    pub fn groups(&self) -> Vec<Vec<u32>> {
        let mut groups = vec![Vec::new(); self.count];
        for (node, &label) in self.labels.iter().enumerate() {
            groups[label as usize].push(node as u32);
        }
        groups
    }
}

impl Adjacency {
    /// Builds the adjacency of `n` nodes from undirected edges `(a, b, w)`.
    pub fn from_edges(n: usize, edges: impl Iterator<Item = (u32, u32, f64)> + Clone) -> Self {
        let mut degree = vec![0usize; n + 1];
        for (a, b, _) in edges.clone() {
            degree[a as usize] += 1;
            degree[b as usize] += 1;
        }
        let mut offsets = Vec::with_capacity(n + 1);
        let mut total = 0;
        for d in &degree[..n] {
            offsets.push(total);
            total += d;
        }
        offsets.push(total);
        let mut fill = offsets.clone();
        let mut neighbours = vec![0u32; total];
        let mut weights = vec![0f64; total];
        for (a, b, w) in edges {
            for (from, to) in [(a, b), (b, a)] {
                let slot = fill[from as usize];
                neighbours[slot] = to;
                weights[slot] = w;
                fill[from as usize] += 1;
            }
        }
        Self {
            offsets,
            neighbours,
            weights,
        }
    }

    pub fn num_nodes(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }

    /// Neighbours and weights of `node`.
    pub fn row(&self, node: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        let range = self.offsets[node]..self.offsets[node + 1];
        self.neighbours[range.clone()]
            .iter()
            .zip(&self.weights[range])
            .map(|(&j, &w)| (j as usize, w))
    }

    /// Weighted degree of every node.
    pub fn degrees(&self) -> Vec<f64> {
        (0..self.num_nodes())
            .map(|i| self.row(i).map(|(_, w)| w).sum())
            .collect()
    }

    /// Connected components (breadth-first).
    pub fn components(&self) -> Components {
        let n = self.num_nodes();
        let mut labels = vec![u32::MAX; n];
        let mut count = 0u32;
        let mut queue = Vec::new();
        for start in 0..n {
            if labels[start] != u32::MAX {
                continue;
            }
            labels[start] = count;
            queue.push(start);
            while let Some(node) = queue.pop() {
                for (next, _) in self.row(node) {
                    if labels[next] == u32::MAX {
                        labels[next] = count;
                        queue.push(next);
                    }
                }
            }
            count += 1;
        }
        Components {
            labels,
            count: count as usize,
        }
    }

    /// The subgraph induced by `nodes` (renumbered in the given order).
    pub fn induced(&self, nodes: &[u32]) -> Adjacency {
        let mut local = std::collections::HashMap::with_capacity(nodes.len());
        for (i, &node) in nodes.iter().enumerate() {
            local.insert(node, i as u32);
        }
        let mut edges = Vec::new();
        for (i, &node) in nodes.iter().enumerate() {
            for (j, w) in self.row(node as usize) {
                if let Some(&lj) = local.get(&(j as u32))
                    && (i as u32) < lj
                {
                    edges.push((i as u32, lj, w));
                }
            }
        }
        Adjacency::from_edges(nodes.len(), edges.into_iter())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn components_and_induced_subgraphs() {
        let edges = vec![(0u32, 1u32, 1.0), (1, 2, 0.5), (3, 4, 2.0)];
        let adjacency = Adjacency::from_edges(6, edges.into_iter());
        let components = adjacency.components();
        assert_eq!(components.count, 3);
        assert_eq!(components.labels[0], components.labels[2]);
        assert_ne!(components.labels[0], components.labels[3]);
        assert_eq!(adjacency.degrees(), vec![1.0, 1.5, 0.5, 2.0, 2.0, 0.0]);
        let sub = adjacency.induced(&[2, 1]);
        assert_eq!(sub.num_nodes(), 2);
        assert_eq!(sub.row(0).collect::<Vec<_>>(), vec![(1, 0.5)]);
        let groups = components.groups();
        assert_eq!(groups.iter().map(Vec::len).sum::<usize>(), 6);
    }
}
