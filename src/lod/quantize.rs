//! Approximate instancing by vector quantization (seed 003 §6): plants (or leaves) are
//! described by parameter vectors, clustered by variance-minimising hyperbox splits (Wan et
//! al.) with a per-vector importance weight, and every member of a cluster is replaced by an
//! instance of the cluster's representative.

/// A code book: which cluster each vector fell in and each cluster's representative.
#[derive(Clone, Debug, PartialEq)]
pub struct Codebook {
    /// Cluster of each input vector.
    pub assignment: Vec<usize>,
    /// Per cluster, the index of the member nearest its weighted mean.
    pub representatives: Vec<usize>,
    /// Weighted RMS distance of the vectors to their cluster's weighted mean.
    pub rms_to_mean: f64,
    /// Weighted RMS distance of the vectors to their cluster's representative (what
    /// instancing actually substitutes).
    pub rms_to_representative: f64,
}

fn distance2(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum()
}

/// Weighted mean and weighted sum of squared deviations of `members`.
fn moments(members: &[usize], vectors: &[Vec<f64>], weights: &[f64]) -> (Vec<f64>, f64) {
    let dims = vectors.first().map_or(0, Vec::len);
    let total: f64 = members.iter().map(|&i| weights[i]).sum();
    let mut mean = vec![0.0; dims];
    if total <= 0.0 {
        return (mean, 0.0);
    }
    for &i in members {
        for (m, x) in mean.iter_mut().zip(&vectors[i]) {
            *m += weights[i] * x / total;
        }
    }
    let sse = members
        .iter()
        .map(|&i| weights[i] * distance2(&vectors[i], &mean))
        .sum();
    (mean, sse)
}

/// The best axis-aligned split of `members`: (total SSE after the split, the two halves).
fn best_split(
    members: &[usize],
    vectors: &[Vec<f64>],
    weights: &[f64],
) -> Option<(f64, Vec<usize>, Vec<usize>)> {
    let dims = vectors.first().map_or(0, Vec::len);
    let mut best: Option<(f64, usize, usize, Vec<usize>)> = None;
    for axis in 0..dims {
        let mut sorted = members.to_vec();
        sorted.sort_by(|&a, &b| {
            vectors[a][axis]
                .total_cmp(&vectors[b][axis])
                .then(a.cmp(&b))
        });
        // Prefix sums of w, w·x and w·|x|² give each half's SSE in O(dims).
        let mut prefix_w = vec![0.0; sorted.len() + 1];
        let mut prefix_wx = vec![vec![0.0; dims]; sorted.len() + 1];
        let mut prefix_wxx = vec![0.0; sorted.len() + 1];
        for (k, &i) in sorted.iter().enumerate() {
            let w = weights[i];
            prefix_w[k + 1] = prefix_w[k] + w;
            for d in 0..dims {
                prefix_wx[k + 1][d] = prefix_wx[k][d] + w * vectors[i][d];
            }
            prefix_wxx[k + 1] = prefix_wxx[k] + w * vectors[i].iter().map(|x| x * x).sum::<f64>();
        }
        let n = sorted.len();
        let sse = |from: usize, to: usize| {
            let w = prefix_w[to] - prefix_w[from];
            if w <= 0.0 {
                return 0.0;
            }
            let norm2: f64 = (0..dims)
                .map(|d| {
                    let s = prefix_wx[to][d] - prefix_wx[from][d];
                    s * s
                })
                .sum();
            (prefix_wxx[to] - prefix_wxx[from] - norm2 / w).max(0.0)
        };
        for cut in 1..n {
            if vectors[sorted[cut - 1]][axis] == vectors[sorted[cut]][axis] {
                continue;
            }
            let total = sse(0, cut) + sse(cut, n);
            if best.as_ref().is_none_or(|(b, ..)| total < *b) {
                best = Some((total, axis, cut, sorted.clone()));
            }
        }
    }
    best.map(|(total, _, cut, sorted)| (total, sorted[..cut].to_vec(), sorted[cut..].to_vec()))
}

/// Clusters `vectors` (all of one dimension) into at most `clusters` hyperboxes, splitting
/// the cluster of largest weighted variance at the axis-aligned plane that leaves the least
/// total variance, until there are `clusters` or nothing can be split. Weights are importance
/// (e.g. instance count × screen area): heavier vectors attract more representatives.
pub fn quantize(vectors: &[Vec<f64>], weights: &[f64], clusters: usize) -> Codebook {
    let n = vectors.len().min(weights.len());
    let vectors = &vectors[..n];
    let weights: Vec<f64> = weights[..n].iter().map(|w| w.max(0.0)).collect();
    let mut groups: Vec<Vec<usize>> = if n == 0 {
        Vec::new()
    } else {
        vec![(0..n).collect()]
    };
    while groups.len() < clusters.max(1) {
        // The group whose split removes the most variance… approximated, as in Wan et al., by
        // the group of largest variance that can be split at all.
        let mut order: Vec<(f64, usize)> = groups
            .iter()
            .enumerate()
            .map(|(g, members)| (moments(members, vectors, &weights).1, g))
            .collect();
        order.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
        let Some((g, (_, left, right))) = order
            .iter()
            .filter(|(sse, _)| *sse > 0.0)
            .find_map(|&(_, g)| best_split(&groups[g], vectors, &weights).map(|s| (g, s)))
        else {
            break;
        };
        groups[g] = left;
        groups.push(right);
    }
    let mut assignment = vec![0; n];
    let mut representatives = Vec::with_capacity(groups.len());
    let (mut to_mean, mut to_rep, mut total) = (0.0, 0.0, 0.0);
    for (g, members) in groups.iter().enumerate() {
        let (mean, sse) = moments(members, vectors, &weights);
        let representative = members
            .iter()
            .copied()
            .min_by(|&a, &b| {
                distance2(&vectors[a], &mean)
                    .total_cmp(&distance2(&vectors[b], &mean))
                    .then(a.cmp(&b))
            })
            .unwrap_or(0);
        for &i in members {
            assignment[i] = g;
            to_rep += weights[i] * distance2(&vectors[i], &vectors[representative]);
            total += weights[i];
        }
        to_mean += sse;
        representatives.push(representative);
    }
    let rms = |sum: f64| {
        if total > 0.0 {
            (sum / total).sqrt()
        } else {
            0.0
        }
    };
    Codebook {
        assignment,
        representatives,
        rms_to_mean: rms(to_mean),
        rms_to_representative: rms(to_rep),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::util::rng::Rng;

    fn cloud(n: usize, seed: u64) -> Vec<Vec<f64>> {
        let mut rng = Rng::seed_from(seed);
        (0..n)
            .map(|_| vec![rng.normal(), 0.5 * rng.normal(), rng.range(-1.0, 1.0)])
            .collect()
    }

    #[test]
    fn error_falls_monotonically_with_code_book_size() {
        let vectors = cloud(200, 4);
        let weights = vec![1.0; vectors.len()];
        let mut previous = f64::INFINITY;
        for k in 1..=24 {
            let book = quantize(&vectors, &weights, k);
            assert_eq!(book.representatives.len(), k);
            assert!(book.rms_to_mean <= previous + 1e-12, "k = {k}");
            assert!(book.rms_to_representative >= book.rms_to_mean - 1e-12);
            previous = book.rms_to_mean;
            // Every representative is a member of its own cluster.
            for (g, &r) in book.representatives.iter().enumerate() {
                assert_eq!(book.assignment[r], g);
            }
        }
        let all = quantize(&vectors, &weights, vectors.len());
        assert!(all.rms_to_representative < 1e-12);
    }

    #[test]
    fn heavily_weighted_plants_get_more_representatives() {
        // Two equal, well-separated groups; the first weighs 20× more.
        let mut vectors = cloud(60, 5);
        for v in vectors.iter_mut().skip(30) {
            v[0] += 20.0;
        }
        let weights: Vec<f64> = (0..60).map(|i| if i < 30 { 20.0 } else { 1.0 }).collect();
        let book = quantize(&vectors, &weights, 10);
        let heavy = book.representatives.iter().filter(|&&r| r < 30).count();
        assert!(
            heavy >= 7,
            "{heavy} of 10 representatives for the heavy group"
        );
        // Identical vectors cannot be split further than one cluster.
        let same = vec![vec![1.0, 2.0]; 5];
        assert_eq!(quantize(&same, &[1.0; 5], 3).representatives.len(), 1);
        assert!(quantize(&[], &[], 3).representatives.is_empty());
    }
}
