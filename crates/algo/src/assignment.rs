//! Optimal 2D assignment (the "global optimal assignment" of seed 000's
//! introduction, after Chang and Youens' use of the Hungarian/Munkres method).
//!
//! Rows and columns may stay unassigned: a row left alone costs
//! `unassigned_cost`, and only the listed (row, column, cost) edges exist.
//! The sparse problem is split into connected components, and each component
//! is solved exactly by the shortest-augmenting-path Hungarian algorithm
//! (Kuhn–Munkres with potentials, O(n³) per component) on a square matrix
//! padded with dummy rows and columns.

use std::collections::HashMap;

/// An assignment: the chosen edges as (row, column) pairs, sorted by row.
pub type Assignment = Vec<(usize, usize)>;

/// Minimises the total cost of the chosen edges plus `unassigned_cost / 2`
/// for every row and every column left unmatched, so an edge is worth taking
/// exactly when its cost is below `unassigned_cost`. Edges with a non-finite
/// cost, or a cost not below `unassigned_cost`, are ignored.
pub fn solve(edges: &[(usize, usize, f64)], unassigned_cost: f64) -> Assignment {
    let edges: Vec<_> = edges
        .iter()
        .copied()
        .filter(|e| e.2.is_finite() && e.2 < unassigned_cost)
        .collect();
    let mut result = Vec::new();
    for component in components(&edges) {
        result.extend(solve_component(&edges, &component, unassigned_cost));
    }
    result.sort_unstable();
    result
}

/// Edge indices grouped by connected component of the bipartite graph.
fn components(edges: &[(usize, usize, f64)]) -> Vec<Vec<usize>> {
    // Union-find over rows (r) and columns (c) as distinct keys.
    let mut id: HashMap<(bool, usize), usize> = HashMap::new();
    let mut parent: Vec<usize> = Vec::new();
    fn find(parent: &mut [usize], mut x: usize) -> usize {
        while parent[x] != x {
            parent[x] = parent[parent[x]];
            x = parent[x];
        }
        x
    }
    let mut key = |k: (bool, usize), parent: &mut Vec<usize>| {
        *id.entry(k).or_insert_with(|| {
            parent.push(parent.len());
            parent.len() - 1
        })
    };
    for &(r, c, _) in edges {
        let a = key((false, r), &mut parent);
        let b = key((true, c), &mut parent);
        let (ra, rb) = (find(&mut parent, a), find(&mut parent, b));
        if ra != rb {
            parent[ra] = rb;
        }
    }
    let mut groups: HashMap<usize, Vec<usize>> = HashMap::new();
    for (i, &(r, _, _)) in edges.iter().enumerate() {
        let node = id[&(false, r)];
        let root = find(&mut parent, node);
        groups.entry(root).or_default().push(i);
    }
    let mut out: Vec<Vec<usize>> = groups.into_values().collect();
    out.sort_unstable_by_key(|g| g[0]);
    out
}

fn solve_component(
    edges: &[(usize, usize, f64)],
    component: &[usize],
    unassigned_cost: f64,
) -> Assignment {
    let mut rows: Vec<usize> = component.iter().map(|&e| edges[e].0).collect();
    let mut cols: Vec<usize> = component.iter().map(|&e| edges[e].1).collect();
    rows.sort_unstable();
    rows.dedup();
    cols.sort_unstable();
    cols.dedup();
    let (nr, nc) = (rows.len(), cols.len());
    // Square matrix of size nr + nc: real rows then dummy rows; real columns
    // then dummy columns. Row i may take its own dummy column (nc + i) at
    // half the unassigned cost; column j may be taken by its dummy row
    // (nr + j) at half the cost; dummy rows take dummy columns for free.
    let n = nr + nc;
    let big = unassigned_cost.abs().max(1.0) * 1e6 + 1e6;
    let half = unassigned_cost / 2.0;
    let mut cost = vec![big; n * n];
    for &e in component {
        let (r, c, w) = edges[e];
        let i = rows.binary_search(&r).expect("row of the component");
        let j = cols.binary_search(&c).expect("column of the component");
        cost[i * n + j] = cost[i * n + j].min(w);
    }
    for i in 0..nr {
        cost[i * n + nc + i] = half;
    }
    for j in 0..nc {
        cost[(nr + j) * n + j] = half;
    }
    for i in nr..n {
        for j in nc..n {
            cost[i * n + j] = 0.0;
        }
    }
    let col_of_row = dense(&cost, n, n);
    let mut out = Vec::new();
    for (i, &j) in col_of_row.iter().enumerate() {
        if i < nr && j < nc && cost[i * n + j] < big {
            out.push((rows[i], cols[j]));
        }
    }
    out
}

/// Minimum-cost assignment of every row of a dense `rows × cols` cost
/// matrix (row-major, rows ≤ cols) to a distinct column: the Hungarian method
/// with potentials and shortest augmenting paths, O(rows²·cols). Returns the
/// column of each row.
///
/// # Panics
/// If `rows > cols` (transpose first) or `cost.len() != rows·cols`.
pub fn dense(cost: &[f64], rows: usize, cols: usize) -> Vec<usize> {
    assert!(rows <= cols, "dense assignment needs rows <= cols");
    assert_eq!(cost.len(), rows * cols, "cost must be rows × cols");
    let (n, m) = (rows, cols);
    // 1-based potentials u (rows), v (cols); way[j] = previous column on the
    // augmenting path; p[j] = row matched to column j (0 = none).
    let mut u = vec![0.0; n + 1];
    let mut v = vec![0.0; m + 1];
    let mut p = vec![0usize; m + 1];
    let mut way = vec![0usize; m + 1];
    for i in 1..=n {
        p[0] = i;
        let mut j0 = 0;
        let mut minv = vec![f64::INFINITY; m + 1];
        let mut used = vec![false; m + 1];
        loop {
            used[j0] = true;
            let i0 = p[j0];
            let mut delta = f64::INFINITY;
            let mut j1 = 0;
            for j in 1..=m {
                if !used[j] {
                    let cur = cost[(i0 - 1) * m + (j - 1)] - u[i0] - v[j];
                    if cur < minv[j] {
                        minv[j] = cur;
                        way[j] = j0;
                    }
                    if minv[j] < delta {
                        delta = minv[j];
                        j1 = j;
                    }
                }
            }
            for j in 0..=m {
                if used[j] {
                    u[p[j]] += delta;
                    v[j] -= delta;
                } else {
                    minv[j] -= delta;
                }
            }
            j0 = j1;
            if p[j0] == 0 {
                break;
            }
        }
        loop {
            let j1 = way[j0];
            p[j0] = p[j1];
            j0 = j1;
            if j0 == 0 {
                break;
            }
        }
    }
    let mut out = vec![0usize; n];
    for j in 1..=m {
        if p[j] != 0 {
            out[p[j] - 1] = j - 1;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Total cost of an assignment under the solver's objective.
    fn objective(
        edges: &[(usize, usize, f64)],
        a: &Assignment,
        rows: usize,
        cols: usize,
        u: f64,
    ) -> f64 {
        let chosen: f64 = a
            .iter()
            .map(|&(r, c)| {
                edges
                    .iter()
                    .filter(|e| e.0 == r && e.1 == c)
                    .map(|e| e.2)
                    .fold(f64::INFINITY, f64::min)
            })
            .sum();
        chosen + (rows + cols - 2 * a.len()) as f64 * u / 2.0
    }

    /// Exhaustive search over all partial matchings (small cases only).
    fn brute(edges: &[(usize, usize, f64)], rows: usize, cols: usize, u: f64) -> f64 {
        #[allow(clippy::too_many_arguments)]
        fn go(
            r: usize,
            rows: usize,
            cols: usize,
            used: &mut Vec<bool>,
            edges: &[(usize, usize, f64)],
            acc: &mut Vec<(usize, usize)>,
            best: &mut f64,
            u: f64,
        ) {
            if r == rows {
                let v = super::tests::objective(edges, acc, rows, cols, u);
                if v < *best {
                    *best = v;
                }
                return;
            }
            go(r + 1, rows, cols, used, edges, acc, best, u);
            for c in 0..cols {
                if !used[c] && edges.iter().any(|e| e.0 == r && e.1 == c && e.2 < u) {
                    used[c] = true;
                    acc.push((r, c));
                    go(r + 1, rows, cols, used, edges, acc, best, u);
                    acc.pop();
                    used[c] = false;
                }
            }
        }
        let mut best = f64::INFINITY;
        go(
            0,
            rows,
            cols,
            &mut vec![false; cols],
            edges,
            &mut Vec::new(),
            &mut best,
            u,
        );
        best
    }

    #[test]
    fn hand_case_prefers_the_cheaper_total() {
        // Rows {0,1}, columns {0,1}: 0–0 = 1, 0–1 = 2, 1–0 = 2, 1–1 = 10.
        // Diagonal: 1 + 10 = 11; anti-diagonal: 2 + 2 = 4. With unassigned
        // cost 20 (10 per side), both matchings beat leaving anything.
        let edges = [(0, 0, 1.0), (0, 1, 2.0), (1, 0, 2.0), (1, 1, 10.0)];
        assert_eq!(solve(&edges, 20.0), vec![(0, 1), (1, 0)]);
        // With unassigned cost 5: an edge is worth it only below 5, so 1–1
        // (10) is out; best is 0–1 + 1–0 = 4 against 0–0 alone = 1 + 5 = 6.
        assert_eq!(solve(&edges, 5.0), vec![(0, 1), (1, 0)]);
        // With unassigned cost 1.5: only 0–0 (1) qualifies.
        assert_eq!(solve(&edges, 1.5), vec![(0, 0)]);
    }

    #[test]
    fn dense_rectangular_case_by_hand() {
        // Rows pick distinct columns; optimum 1 + 2 + 1 = 4 with columns 1, 0, 3.
        let c = [4.0, 1.0, 3.0, 9.0, 2.0, 0.5, 5.0, 9.0, 3.0, 2.0, 2.0, 1.0];
        assert_eq!(dense(&c, 3, 4), vec![1, 0, 3]);
        assert!(dense(&[], 0, 3).is_empty());
    }

    #[test]
    fn empty_and_disconnected_components() {
        assert!(solve(&[], 1.0).is_empty());
        let edges = [(0, 5, 1.0), (7, 9, 2.0), (7, 5, 0.5)];
        // Component {0,7}×{5,9}: 0–5 + 7–9 = 3 versus 7–5 alone = 0.5 + 2·(u/2)
        // with u = 10: 10.5. So the pair of edges wins.
        assert_eq!(solve(&edges, 10.0), vec![(0, 5), (7, 9)]);
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(128))]
        #[test]
        fn matches_brute_force_on_small_cases(
            rows in 1usize..5,
            cols in 1usize..5,
            weights in prop::collection::vec(prop::option::of(0.0f64..10.0), 16),
            u in 0.5f64..12.0,
        ) {
            let mut edges = Vec::new();
            for r in 0..rows {
                for c in 0..cols {
                    if let Some(w) = weights[r * 4 + c] {
                        edges.push((r, c, w));
                    }
                }
            }
            let a = solve(&edges, u);
            // A valid matching: no row or column twice.
            let mut rs: Vec<_> = a.iter().map(|x| x.0).collect();
            let mut cs: Vec<_> = a.iter().map(|x| x.1).collect();
            rs.sort_unstable(); rs.dedup(); cs.sort_unstable(); cs.dedup();
            prop_assert_eq!(rs.len(), a.len());
            prop_assert_eq!(cs.len(), a.len());
            let got = objective(&edges, &a, rows, cols, u);
            let best = brute(&edges, rows, cols, u);
            prop_assert!((got - best).abs() < 1e-9, "got {} best {}", got, best);
        }
    }
}
