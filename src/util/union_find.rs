//! Disjoint sets with path halving (connected components of graphs and meshes).

/// Disjoint sets over `0..n`; the smallest index of a set is its representative.
pub struct UnionFind {
    parent: Vec<usize>,
}

impl UnionFind {
    pub fn new(n: usize) -> Self {
        Self {
            parent: (0..n).collect(),
        }
    }

    /// The representative of `i`'s set.
    pub fn find(&mut self, mut i: usize) -> usize {
        while self.parent[i] != i {
            self.parent[i] = self.parent[self.parent[i]];
            i = self.parent[i];
        }
        i
    }

    /// Joins the sets of `a` and `b`.
    pub fn union(&mut self, a: usize, b: usize) {
        let (a, b) = (self.find(a), self.find(b));
        if a != b {
            self.parent[a.max(b)] = a.min(b);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unions_join_sets_under_their_smallest_member() {
        let mut sets = UnionFind::new(6);
        sets.union(4, 2);
        sets.union(2, 5);
        sets.union(0, 1);
        assert_eq!(
            [sets.find(5), sets.find(4), sets.find(1), sets.find(3)],
            [2, 2, 0, 3]
        );
    }
}
