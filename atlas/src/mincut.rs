//! Two-label energies minimised exactly by a minimum s–t cut: the labelling that
//! [`crate::injective`] uses to tell the two sides of a thin wall apart, and to cut an island in
//! two where the cut across its middle is shortest.
//!
//! The energy is `Σ_i cost_i(label_i) + Σ_(i,j) w_ij · [label_i ≠ label_j]` over labels in
//! `{false, true}`, with non-negative costs and weights (a submodular energy, so the cut is a
//! global minimum; Boykov & Kolmogorov, "An Experimental Comparison of Min-Cut/Max-Flow
//! Algorithms for Energy Minimization in Vision", 2004). Node `i` hangs from the source by an
//! arc of capacity `cost_i(true)` and to the sink by one of `cost_i(false)`; each pair is an arc
//! both ways of capacity `w_ij`. After a maximum flow, the nodes the source still reaches in the
//! residual graph are labelled `false`, the rest `true` (between labellings of equal energy the
//! flow chooses, the same way every time).
//!
//! The flow is Dinic's algorithm (levels by breadth-first search, blocking flows by depth-first
//! search with the current-arc rule, iteratively: no recursion however long a path) on integer
//! capacities: the costs scaled so that their total is [`TOTAL`], which keeps sums exact and the
//! result independent of summation order. Not petgraph's `dinics`: it clears an array over all
//! nodes for every augmenting path, and on these graphs, where most nodes carry a short path of
//! their own, its time grows with the square of the node count.

/// What the scaled capacities of all arcs from the source and to the sink sum to at most: far
/// below `i64::MAX`, so no flow overflows, and fine enough that a cost a 1e-9 share of the total
/// still counts.
const TOTAL: f64 = 1e15;

/// Labels minimising the energy of the module docs. `unary[i]` is `(cost_i(false),
/// cost_i(true))`; `pairs` are `(i, j, w_ij)` with `i ≠ j` (several pairs of the same nodes
/// add up). Costs and weights must be finite and non-negative (others count as 0).
pub(crate) fn two_labels(unary: &[(f64, f64)], pairs: &[(u32, u32, f64)]) -> Vec<bool> {
    let n = unary.len();
    let clean = |x: f64| if x.is_finite() && x > 0.0 { x } else { 0.0 };
    let total: f64 = unary.iter().map(|&(a, b)| clean(a) + clean(b)).sum::<f64>()
        + pairs.iter().map(|&(_, _, w)| 2.0 * clean(w)).sum::<f64>();
    if total <= 0.0 {
        return vec![false; n];
    }
    let scale = TOTAL / total;
    let cap = |x: f64| (clean(x) * scale).round() as i64;
    let (source, sink) = (n as u32, n as u32 + 1);
    let mut net = Network::new(n + 2);
    for (i, &(if_false, if_true)) in unary.iter().enumerate() {
        // Labelling i `true` cuts source → i; labelling it `false` cuts i → sink.
        net.arc(source, i as u32, cap(if_true), 0);
        net.arc(i as u32, sink, cap(if_false), 0);
    }
    for &(i, j, w) in pairs {
        net.arc(i, j, cap(w), cap(w));
    }
    net.max_flow(source, sink);
    let reached = net.reached_from(source);
    (0..n).map(|i| !reached[i]).collect()
}

/// A flow network: arcs in pairs (`a`, `a ^ 1` its reverse), residual capacities, and the arcs
/// leaving each node in one array (compressed rows, built by [`Network::seal`]).
struct Network {
    nodes: usize,
    head: Vec<u32>,
    residual: Vec<i64>,
    /// The first index into `out` of each node's arcs, and one past the last node's.
    start: Vec<usize>,
    out: Vec<u32>,
}

impl Network {
    fn new(nodes: usize) -> Self {
        Network { nodes, head: Vec::new(), residual: Vec::new(), start: Vec::new(), out: Vec::new() }
    }

    /// An arc `from → to` of capacity `forward` and its reverse of capacity `backward`.
    fn arc(&mut self, from: u32, to: u32, forward: i64, backward: i64) {
        if forward == 0 && backward == 0 {
            return;
        }
        self.head.extend([to, from]);
        self.residual.extend([forward, backward]);
    }

    /// The arc of index `a` leaves the node its reverse enters.
    fn tail(&self, a: usize) -> u32 {
        self.head[a ^ 1]
    }

    fn seal(&mut self) {
        let mut count = vec![0usize; self.nodes + 1];
        for a in 0..self.head.len() {
            count[self.tail(a) as usize + 1] += 1;
        }
        for v in 0..self.nodes {
            count[v + 1] += count[v];
        }
        self.start = count.clone();
        self.out = vec![0; self.head.len()];
        for a in 0..self.head.len() {
            let v = self.tail(a) as usize;
            self.out[count[v]] = a as u32;
            count[v] += 1;
        }
    }

    /// Breadth-first levels from `source` over arcs with residual capacity (`u32::MAX`: not
    /// reached).
    fn levels(&self, source: u32) -> Vec<u32> {
        let mut level = vec![u32::MAX; self.nodes];
        let mut queue = std::collections::VecDeque::from([source]);
        level[source as usize] = 0;
        while let Some(v) = queue.pop_front() {
            for &a in &self.out[self.start[v as usize]..self.start[v as usize + 1]] {
                let w = self.head[a as usize];
                if self.residual[a as usize] > 0 && level[w as usize] == u32::MAX {
                    level[w as usize] = level[v as usize] + 1;
                    queue.push_back(w);
                }
            }
        }
        level
    }

    fn reached_from(&self, source: u32) -> Vec<bool> {
        self.levels(source).into_iter().map(|l| l != u32::MAX).collect()
    }

    /// Saturates the network from `source` to `sink` (Dinic).
    fn max_flow(&mut self, source: u32, sink: u32) {
        self.seal();
        loop {
            let mut level = self.levels(source);
            if level[sink as usize] == u32::MAX {
                return;
            }
            // The next arc to try out of each node (current-arc rule).
            let mut next = self.start[..self.nodes].to_vec();
            let mut path: Vec<u32> = Vec::new();
            let mut v = source;
            loop {
                if v == sink {
                    let pushed = path.iter().map(|&a| self.residual[a as usize]).min().unwrap_or(0);
                    for &a in &path {
                        self.residual[a as usize] -= pushed;
                        self.residual[a as usize ^ 1] += pushed;
                    }
                    // Back to the tail of the first arc the push saturated.
                    let k = path.iter().position(|&a| self.residual[a as usize] == 0).unwrap_or(0);
                    path.truncate(k);
                    v = path.last().map_or(source, |&a| self.head[a as usize]);
                    continue;
                }
                let end = self.start[v as usize + 1];
                let mut advanced = false;
                while next[v as usize] < end {
                    let a = self.out[next[v as usize]];
                    let w = self.head[a as usize];
                    if self.residual[a as usize] > 0 && level[w as usize] == level[v as usize] + 1 {
                        path.push(a);
                        v = w;
                        advanced = true;
                        break;
                    }
                    next[v as usize] += 1;
                }
                if advanced {
                    continue;
                }
                // A dead end: no path to the sink goes through `v` in this phase.
                match path.pop() {
                    None => break,
                    Some(a) => {
                        level[v as usize] = u32::MAX;
                        v = self.tail(a as usize);
                        next[v as usize] += 1;
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The energy of `labels` (module docs).
    fn energy(unary: &[(f64, f64)], pairs: &[(u32, u32, f64)], labels: &[bool]) -> f64 {
        let u: f64 = unary.iter().zip(labels).map(|(&(f, t), &l)| if l { t } else { f }).sum();
        u + pairs
            .iter()
            .filter(|&&(i, j, _)| labels[i as usize] != labels[j as usize])
            .map(|p| p.2)
            .sum::<f64>()
    }

    #[test]
    fn the_labelling_is_the_least_energy_of_all_on_small_random_problems() {
        // Every labelling of 8 nodes tried against the cut's, on random costs and pairs.
        let mut state = 0x2545F4914F6CDD1Du64;
        let mut rand = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..200 {
            let n = 8;
            let unary: Vec<(f64, f64)> = (0..n).map(|_| (rand(), rand())).collect();
            let mut pairs = Vec::new();
            for i in 0..n as u32 {
                for j in i + 1..n as u32 {
                    if rand() < 0.4 {
                        pairs.push((i, j, 0.6 * rand()));
                    }
                }
            }
            let labels = two_labels(&unary, &pairs);
            let best = (0..1u32 << n)
                .map(|m| {
                    let l: Vec<bool> = (0..n).map(|i| m >> i & 1 == 1).collect();
                    energy(&unary, &pairs, &l)
                })
                .fold(f64::INFINITY, f64::min);
            let ours = energy(&unary, &pairs, &labels);
            assert!(ours <= best + 1e-9, "{ours} > {best}");
        }
    }

    #[test]
    fn smoothing_relabels_a_lone_node_and_keeps_a_large_block() {
        // A path of 40 nodes: the first 25 prefer `false`, the rest `true`, node 10 prefers
        // `true` alone. With pair weights above a node's preference the lone node follows its
        // neighbours, and the two blocks keep their labels (one cut, between nodes 24 and 25).
        let mut unary: Vec<(f64, f64)> =
            (0..40).map(|i| if i < 25 { (0.0, 1.0) } else { (1.0, 0.0) }).collect();
        unary[10] = (1.0, 0.0);
        let pairs: Vec<(u32, u32, f64)> = (0..39).map(|i| (i, i + 1, 1.5)).collect();
        let labels = two_labels(&unary, &pairs);
        let expected: Vec<bool> = (0..40).map(|i| i >= 25).collect();
        assert_eq!(labels, expected);
        // Without smoothing every node takes its own preference.
        let alone = two_labels(&unary, &[]);
        assert!(alone[10] && !alone[9] && alone[30]);
    }

    #[test]
    fn empty_problems_and_invalid_costs() {
        // NaN and negative costs count as 0: nothing to pay, everything `false`.
        assert!(two_labels(&[], &[]).is_empty());
        assert_eq!(two_labels(&[(f64::NAN, -1.0)], &[]), vec![false]);
    }
}
