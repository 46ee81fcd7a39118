//! The association problem: the pairs' summaries and interpolation
//! brackets, the eq. 6 distance matrix, CA-CFAR credible pairs, the
//! distances under a bias and the gated optimal 2D assignment.

use std::cell::{OnceCell, RefCell};
use std::collections::HashMap;

use super::alignment::{Bracket, Sector, Summary, at, dist, time_groups, walk, walk_brackets};
use super::{AisPoint, Bias, BiasEstimate, Config, RadarSample, WIDEN_FACTOR};
use crate::assignment;
use crate::bias::cfar::{self, Thresholds};

/// Optimal gated assignment of `edges` (row < `rows`, column < `cols`):
/// the objective of `assignment::solve(edges, gate)` (the chosen costs plus
/// gate/2 for every row and column left alone), solved per connected
/// component on the smaller side only. With s rows and l columns in a
/// component that objective is Σ chosen w + gate/2 · (s + l − 2m) = Σ chosen
/// w + gate · (s − m) + const, so the smaller side's s entries each take a
/// column of the larger side at w or a dummy column of their own at the
/// gate: an s × (l + s) Hungarian instead of the (s + l)² square one (a
/// fifth of the work for the harbour's 43 × 32 block of moored ships). The
/// optimum is the same; only between assignments of equal total could the
/// choice differ.
pub(super) fn solve_gated(
    edges: &[(usize, usize, f64)],
    rows: usize,
    cols: usize,
    gate: f64,
) -> Vec<(usize, usize)> {
    fn find(parent: &mut [usize], mut x: usize) -> usize {
        while parent[x] != x {
            parent[x] = parent[parent[x]];
            x = parent[x];
        }
        x
    }
    let edges: Vec<(usize, usize, f64)> = edges
        .iter()
        .copied()
        .filter(|e| e.2.is_finite() && e.2 < gate)
        .collect();
    // Union-find over rows (0..rows) and columns (rows..rows + cols).
    let mut parent: Vec<usize> = (0..rows + cols).collect();
    for &(r, c, _) in &edges {
        let (a, b) = (find(&mut parent, r), find(&mut parent, rows + c));
        if a != b {
            parent[a] = b;
        }
    }
    let mut component_of = vec![usize::MAX; rows + cols];
    let mut components: Vec<Vec<usize>> = Vec::new();
    for (e, &(r, _, _)) in edges.iter().enumerate() {
        let root = find(&mut parent, r);
        if component_of[root] == usize::MAX {
            component_of[root] = components.len();
            components.push(Vec::new());
        }
        components[component_of[root]].push(e);
    }
    let big = gate.abs().max(1.0) * 1e6 + 1e6;
    // Local index of each row and column in its component.
    let mut local = vec![usize::MAX; rows + cols];
    let mut out = Vec::new();
    for component in &components {
        if let [e] = component[..] {
            out.push((edges[e].0, edges[e].1));
            continue;
        }
        let mut rs: Vec<usize> = component.iter().map(|&e| edges[e].0).collect();
        let mut cs: Vec<usize> = component.iter().map(|&e| rows + edges[e].1).collect();
        for v in [&mut rs, &mut cs] {
            v.sort_unstable();
            v.dedup();
        }
        // The smaller side are the Hungarian's rows.
        let (small, large) = if rs.len() <= cs.len() {
            (&rs, &cs)
        } else {
            (&cs, &rs)
        };
        for (k, &x) in small.iter().chain(large.iter()).enumerate() {
            local[x] = if k < small.len() { k } else { k - small.len() };
        }
        let (s, l) = (small.len(), large.len());
        let m = l + s;
        let mut cost = vec![big; s * m];
        let row_is_small = small[0] < rows;
        for &e in component {
            let (r, c, w) = edges[e];
            let (a, b) = if row_is_small {
                (local[r], local[rows + c])
            } else {
                (local[rows + c], local[r])
            };
            cost[a * m + b] = cost[a * m + b].min(w);
        }
        for a in 0..s {
            cost[a * m + l + a] = gate;
        }
        for (a, &b) in assignment::dense(&cost, s, m).iter().enumerate() {
            if b < l && cost[a * m + b] < big {
                let (x, y) = (small[a], large[b]);
                out.push(if row_is_small {
                    (x, y - rows)
                } else {
                    (y, x - rows)
                });
            }
        }
    }
    out.sort_unstable();
    out
}

/// A pair's (range, azimuth) residual at one common instant and the index
/// of its AIS report.
pub(super) type Residual = ([f64; 2], usize);

/// The sums over a pair's common instants (brackets `br` of `ship` in the
/// track at raw positions `pos`, AIS ranges `rho_a`): eq. 6 distance, range
/// residual and its square, ρ_a sin δ, ρ_a cos δ, the square of the first,
/// and the AIS range (δ = θ_p − θ_a, with ρ_a sin δ = (p × q)/|p|). Four
/// instants at a time, each lane with the same operations as one at a time
/// (so the square roots and divisions pack into vector instructions), the
/// sums taken in instant order: the same bits as a plain loop.
fn sums(pos: &[[f64; 2]], ship: &[AisPoint], rho_a: &[f64], br: &[Bracket]) -> [f64; 7] {
    const L: usize = 4;
    let mut acc = [0.0f64; 7];
    for chunk in br.chunks(L) {
        // Unused lanes hold a harmless point (1, 0) against itself.
        let (mut px, mut py, mut qx, mut qy, mut ra) =
            ([1.0; L], [0.0; L], [1.0; L], [0.0; L], [1.0; L]);
        for (l, b) in chunk.iter().enumerate() {
            let p = at(pos, b.a as usize, b.w);
            let k = b.k as usize;
            (px[l], py[l]) = (p[0], p[1]);
            (qx[l], qy[l]) = (ship[k].position[0], ship[k].position[1]);
            ra[l] = rho_a[k];
        }
        let (mut d, mut dr, mut x, mut y) = ([0.0; L], [0.0; L], [0.0; L], [0.0; L]);
        for l in 0..L {
            let rho_p = (px[l] * px[l] + py[l] * py[l]).sqrt();
            dr[l] = rho_p - ra[l];
            let inv = 1.0 / rho_p.max(1e-9);
            x[l] = (px[l] * qy[l] - py[l] * qx[l]) * inv;
            y[l] = (px[l] * qx[l] + py[l] * qy[l]) * inv;
            let (ex, ey) = (px[l] - qx[l], py[l] - qy[l]);
            d[l] = (ex * ex + ey * ey).sqrt();
        }
        for l in 0..chunk.len() {
            acc[0] += d[l];
            acc[1] += dr[l];
            acc[2] += dr[l] * dr[l];
            acc[3] += x[l];
            acc[4] += y[l];
            acc[5] += x[l] * x[l];
            acc[6] += ra[l];
        }
    }
    acc
}

/// The fixed geometry of a problem: tracks, ships and their time alignment.
pub(super) struct Problem<'a> {
    pub(super) radar: &'a [Vec<RadarSample>],
    pub(super) ais: &'a [Vec<AisPoint>],
    pub(super) cfg: &'a Config,
    pub(super) rows: usize,
    pub(super) cols: usize,
    /// Raw plane positions and (sin θ, cos θ) of every radar sample.
    pub(super) raw: Vec<Vec<[f64; 2]>>,
    pub(super) unit: Vec<Vec<[f64; 2]>>,
    /// AIS range and velocity (central differences) of every report.
    pub(super) ais_range: Vec<Vec<f64>>,
    pub(super) ais_velocity: Vec<Vec<[f64; 2]>>,
    /// Row-major nR × nA pair summaries.
    pub(super) summary: Vec<Summary>,
    /// Pairs never walked, since their bearings are further apart than any
    /// bias the search may reach plus the gate: (pair, lower bound of their
    /// eq. 6 distance from the sectors' boxes).
    lower_bounds: Vec<(usize, f64)>,
    /// Pairs with common instants, by implied range bias.
    by_range: Vec<usize>,
    /// The time group of each track: tracks whose sample times are equal
    /// bit for bit (a tracker stamping every plot with its scan time) place
    /// every AIS report at the same bracket, so each ship is walked once per
    /// group instead of once per track.
    pub(super) group: Vec<usize>,
    /// Brackets of every ship in each time group (groups × nA), built on
    /// first use; raw residuals (with the AIS report index) of each pair,
    /// built on first use.
    pub(super) brackets: Vec<OnceCell<Vec<Bracket>>>,
    pub(super) residuals: Vec<OnceCell<Vec<Residual>>>,
    /// Gated assignments by bias (bits of range, azimuth) and estimates by
    /// associated pairs: the search, the refinements and the ambiguity check
    /// meet the same biases and associations again.
    assigned: RefCell<HashMap<(u64, u64), Assigned>>,
    pub(super) estimates: RefCell<HashMap<Pairs, Option<BiasEstimate>>>,
}

/// The tracks' plane positions under one bias, each sample compensated
/// where it is read: the raw unit vector turned back by the azimuth bias,
/// times the corrected range (at no bias, the raw positions). A bias's
/// candidate pairs mostly pass or fail the gate within a few of their
/// common instants, so compensating whole tracks for them was most of the
/// work of an assignment.
pub(super) struct Positions<'p, 'a> {
    problem: &'p Problem<'a>,
    bias: Bias,
    sin_cos: (f64, f64),
}

impl Positions<'_, '_> {
    /// Sample `a` of track `i`.
    fn point(&self, i: usize, a: usize) -> [f64; 2] {
        let p = self.problem;
        if self.bias == Bias::default() {
            return p.raw[i][a];
        }
        let ((s, c), u) = (self.sin_cos, p.unit[i][a]);
        let r = p.radar[i][a].range - self.bias.range;
        [r * (u[0] * c - u[1] * s), r * (u[1] * c + u[0] * s)]
    }

    /// Track i's interpolated position at bracket (a, w): [`at`] of its
    /// compensated samples.
    pub(super) fn at(&self, i: usize, a: usize, w: f64) -> [f64; 2] {
        let p = self.point(i, a);
        if w == 0.0 {
            return p;
        }
        let q = self.point(i, a + 1);
        [p[0] + w * (q[0] - p[0]), p[1] + w * (q[1] - p[1])]
    }
}

/// Associated pairs (radar track, AIS ship).
pub(super) type Pairs = Vec<(usize, usize)>;
/// A gated assignment and its total distance.
type Assigned = (Pairs, f64);

/// Central-difference velocity of each report (one-sided at the ends).
fn velocities(ship: &[AisPoint]) -> Vec<[f64; 2]> {
    let n = ship.len();
    (0..n)
        .map(|k| {
            let (a, b) = (k.saturating_sub(1), (k + 1).min(n.saturating_sub(1)));
            let dt = ship[b].t - ship[a].t;
            if b == a || dt <= 0.0 {
                return [0.0, 0.0];
            }
            let (p, q) = (ship[a].position, ship[b].position);
            [(q[0] - p[0]) / dt, (q[1] - p[1]) / dt]
        })
        .collect()
}

impl<'a> Problem<'a> {
    pub(super) fn new(
        radar: &'a [Vec<RadarSample>],
        ais: &'a [Vec<AisPoint>],
        cfg: &'a Config,
    ) -> Self {
        let (rows, cols) = (radar.len(), ais.len());
        let unit: Vec<Vec<[f64; 2]>> = radar
            .iter()
            .map(|t| {
                t.iter()
                    .map(|s| {
                        let (sin, cos) = s.azimuth.sin_cos();
                        [sin, cos]
                    })
                    .collect()
            })
            .collect();
        let raw: Vec<Vec<[f64; 2]>> = radar
            .iter()
            .zip(&unit)
            .map(|(t, u)| {
                t.iter()
                    .zip(u)
                    .map(|(s, u)| [s.range * u[0], s.range * u[1]])
                    .collect()
            })
            .collect();
        let ais_range: Vec<Vec<f64>> = ais
            .iter()
            .map(|s| {
                s.iter()
                    .map(|r| r.position[0].hypot(r.position[1]))
                    .collect()
            })
            .collect();
        let min_common = cfg.min_common.max(1);
        let sectors_r: Vec<Sector> = raw.iter().map(|t| Sector::of(t)).collect();
        let sectors_a: Vec<Sector> = ais
            .iter()
            .map(|s| Sector::of(&s.iter().map(|r| r.position).collect::<Vec<_>>()))
            .collect();
        let reach = 1.1 * cfg.gate + 1.0;
        let outer = if cfg.widen {
            (WIDEN_FACTOR * cfg.max_azimuth_bias).min(std::f64::consts::PI)
        } else {
            cfg.max_azimuth_bias
        };
        let (group, sizes) = time_groups(radar);
        let brackets: Vec<OnceCell<Vec<Bracket>>> =
            (0..sizes.len() * cols).map(|_| OnceCell::new()).collect();
        let mut summary = Vec::with_capacity(rows * cols);
        let mut pruned = Vec::new();
        let mut scratch = Vec::new();
        for (i, track) in radar.iter().enumerate() {
            let g = group[i];
            for (j, ship) in ais.iter().enumerate() {
                if sectors_r[i].apart(&sectors_a[j], outer, reach) {
                    pruned.push(i * cols + j);
                    summary.push(Summary::default());
                    continue;
                }
                // A shared group keeps its brackets for the other tracks;
                // a track of its own walks into the scratch buffer (its
                // brackets are rebuilt only if the pair is used later).
                let br: &[Bracket] = if sizes[g] > 1 {
                    brackets[g * cols + j].get_or_init(|| walk_brackets(track, ship, cfg.max_gap))
                } else {
                    scratch.clear();
                    walk(track, ship, cfg.max_gap, |k, a, w| {
                        scratch.push(Bracket {
                            k: k as u32,
                            a: a as u32,
                            w,
                        })
                    });
                    &scratch
                };
                let n = br.len();
                if n < min_common {
                    summary.push(Summary::default());
                    continue;
                }
                let acc = sums(&raw[i], ship, &ais_range[j], br);
                let nf = n as f64;
                let m = acc.map(|s| s / nf);
                summary.push(Summary {
                    n,
                    distance: m[0],
                    range: m[1],
                    azimuth: m[3].atan2(m[4]),
                    sin: m[3],
                    cos: m[4],
                    rho: m[6],
                    spread: ((m[2] - m[1] * m[1]) + (m[5] - m[3] * m[3])).max(0.0),
                });
            }
        }
        let lower_bounds = pruned
            .iter()
            .map(|&ij| (ij, sectors_r[ij / cols].distance(&sectors_a[ij % cols])))
            .collect();
        let mut by_range: Vec<usize> = (0..summary.len()).filter(|&p| summary[p].n > 0).collect();
        by_range.sort_by(|&a, &b| summary[a].range.total_cmp(&summary[b].range));
        Self {
            radar,
            ais,
            cfg,
            rows,
            cols,
            raw,
            unit,
            ais_velocity: ais.iter().map(|s| velocities(s)).collect(),
            ais_range,
            summary,
            lower_bounds,
            by_range,
            group,
            brackets,
            residuals: (0..rows * cols).map(|_| OnceCell::new()).collect(),
            assigned: RefCell::new(HashMap::new()),
            estimates: RefCell::new(HashMap::new()),
        }
    }

    /// Brackets of pair ij (none when it has no summary: fewer than
    /// `min_common` common instants, or never walked).
    pub(super) fn brackets(&self, ij: usize) -> &[Bracket] {
        if self.summary[ij].n == 0 {
            return &[];
        }
        self.walked(ij)
    }

    /// Brackets of pair ij however few, shared by its track's time group.
    pub(super) fn walked(&self, ij: usize) -> &[Bracket] {
        let (i, j) = (ij / self.cols, ij % self.cols);
        self.brackets[self.group[i] * self.cols + j]
            .get_or_init(|| walk_brackets(&self.radar[i], &self.ais[j], self.cfg.max_gap))
    }

    /// Plane positions of the tracks compensated by `bias`, each sample
    /// where it is read ([`Positions::at`]): each assignment of the search
    /// and the refinements used to compensate all 34,632 samples of the
    /// harbour into a fresh 0.5 MB, though a bias's candidate pairs read
    /// few of them.
    pub(super) fn positions(&self, bias: Bias) -> Positions<'_, 'a> {
        Positions {
            problem: self,
            bias,
            sin_cos: bias.azimuth.sin_cos(),
        }
    }

    /// Eq. 6 for pair ij at positions `pos`.
    pub(super) fn distance(&self, pos: &Positions<'_, '_>, ij: usize) -> f64 {
        let br = self.brackets(ij);
        if br.is_empty() {
            return f64::INFINITY;
        }
        let (i, j) = (ij / self.cols, ij % self.cols);
        let sum: f64 = br
            .iter()
            .map(|b| {
                dist(
                    pos.at(i, b.a as usize, b.w),
                    self.ais[j][b.k as usize].position,
                )
            })
            .sum();
        sum / br.len() as f64
    }

    /// The eq. 6 matrix of the raw data (∞ without common instants); the
    /// pairs never walked hold their lower bound.
    pub(super) fn raw_matrix(&self) -> Vec<f64> {
        let mut m: Vec<f64> = self
            .summary
            .iter()
            .map(|s| if s.n == 0 { f64::INFINITY } else { s.distance })
            .collect();
        for &(ij, lb) in &self.lower_bounds {
            m[ij] = lb;
        }
        m
    }

    /// The exact eq. 6 distance of a pair never walked (∞ with fewer than
    /// `min_common` common instants).
    fn raw_distance(&self, ij: usize) -> f64 {
        let (i, j) = (ij / self.cols, ij % self.cols);
        let br = self.walked(ij);
        let n = br.len();
        if n < self.cfg.min_common.max(1) {
            return f64::INFINITY;
        }
        let sum: f64 = br
            .iter()
            .map(|b| {
                dist(
                    at(&self.raw[i], b.a as usize, b.w),
                    self.ais[j][b.k as usize].position,
                )
            })
            .sum();
        sum / n as f64
    }

    /// CA-CFAR thresholds and credible pairs exactly as on the full raw
    /// matrix: a pair held at its lower bound can change neither while the
    /// bound exceeds S2 and the (m′ + 1)-th smallest distance (the thresholds
    /// read only the smallest m′ + 1 distances, eq. 7 only asks whether the
    /// others exceed S2); otherwise its exact distance replaces it and the
    /// detector runs again.
    pub(super) fn cfar(&self) -> (Vec<f64>, Option<Thresholds>) {
        let mut m = self.raw_matrix();
        let mut open: Vec<(usize, f64)> = self.lower_bounds.clone();
        loop {
            let t = cfar::thresholds(&m, &self.cfg.cfar);
            let limit = match &t {
                Some(t) => {
                    let mut d: Vec<f64> = m.iter().copied().filter(|x| x.is_finite()).collect();
                    d.sort_by(f64::total_cmp);
                    t.s2.max(d.get(t.count).copied().unwrap_or(f64::INFINITY))
                }
                None => f64::INFINITY,
            };
            let (close, far): (Vec<_>, Vec<_>) = open.into_iter().partition(|e| e.1 <= limit);
            if close.is_empty() {
                return (m, t);
            }
            for (ij, _) in close {
                m[ij] = self.raw_distance(ij);
            }
            open = far;
        }
    }

    /// Pairs whose lower bounds under `bias` are within the gate (margin
    /// 10 % + 1 m).
    pub(super) fn candidates(&self, bias: Bias) -> impl Iterator<Item = usize> + '_ {
        let reach = 1.1 * self.cfg.gate + 1.0;
        let sc = bias.azimuth.sin_cos();
        let lo = self
            .by_range
            .partition_point(|&p| self.summary[p].range < bias.range - reach);
        self.by_range[lo..]
            .iter()
            .copied()
            .take_while(move |&p| self.summary[p].range <= bias.range + reach)
            .filter(move |&p| self.summary[p].offsets(bias, sc).1 <= reach)
    }

    /// Pairs under the gate at `bias`: (i, j, eq. 6 distance). A pair's sum
    /// stops once it reaches gate × n: its mean cannot fall below the gate.
    pub(super) fn edges(&self, bias: Bias) -> Vec<(usize, usize, f64)> {
        let pos = self.positions(bias);
        let gate = self.cfg.gate;
        self.candidates(bias)
            .filter_map(|ij| {
                let br = self.brackets(ij);
                let (i, j) = (ij / self.cols, ij % self.cols);
                let limit = gate * br.len() as f64;
                let mut sum = 0.0;
                for b in br {
                    sum += dist(
                        pos.at(i, b.a as usize, b.w),
                        self.ais[j][b.k as usize].position,
                    );
                    if sum >= limit {
                        return None;
                    }
                }
                let d = sum / br.len() as f64;
                (d < gate).then_some((i, j, d))
            })
            .collect()
    }

    /// Optimal gated assignment at `bias` and its total distance.
    pub(super) fn assign(&self, bias: Bias) -> Assigned {
        let key = (bias.range.to_bits(), bias.azimuth.to_bits());
        if let Some(a) = self.assigned.borrow().get(&key) {
            return a.clone();
        }
        let edges = self.edges(bias);
        let pairs = solve_gated(&edges, self.rows, self.cols, self.cfg.gate);
        let mut cost = HashMap::with_capacity(edges.len());
        cost.extend(edges.iter().map(|e| ((e.0, e.1), e.2)));
        let total = pairs
            .iter()
            .map(|p| cost.get(p).copied().unwrap_or(0.0))
            .sum();
        let a = (pairs, total);
        self.assigned.borrow_mut().insert(key, a.clone());
        a
    }
}
