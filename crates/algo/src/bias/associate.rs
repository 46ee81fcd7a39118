//! AIS–radar association with joint estimation of the radar's range and
//! azimuth bias (seed 004): time alignment by interpolation (§2.2), the
//! mean-distance matrix (eq. 6), credible pairs by CA-CFAR (eqs. 7–10),
//! least-squares bias estimation, compensation, and re-association by
//! optimal 2D assignment with a gate until the association is stable.
//!
//! Robust seeding where the paper fails (its table 4: 64 % correct at 2–3 km
//! range bias): every radar–AIS pair with common times implies a bias (its
//! mean range and azimuth residuals). A common bias leaves every true pair
//! implying the same bias, so the true hypothesis gathers all true pairs
//! whatever the bias's size, which the distance-ordering argument of CA-CFAR
//! cannot promise.
//!
//! Cost. One pass over every pair's common instants gives the eq. 6 matrix
//! and each pair's implied bias with two lower bounds of its mean distance
//! under any bias h: the mean range residual minus h's range, and the mean
//! cross-range residual (AIS range × azimuth residual) minus h's (a point's
//! distance from another is at least their range difference, and at least
//! its distance from the other's bearing line). Only pairs whose bounds are
//! within the gate (with a 10 % margin for the sine and the interpolation
//! chord) can be gated, so the distances under h are computed for those
//! alone, from interpolation brackets built on first use. Hypotheses are
//! ranked by how many distinct radar tracks and AIS ships imply a bias
//! within a tenth of the gate of them (a true bias gathers every true pair),
//! near-duplicates are skipped, and at most `max_evaluations` are scored
//! exactly (gated pairs, then total distance), as the exhaustive search
//! scored every one; a hypothesis whose upper bound (distinct rows and
//! columns within the gate's bounds) cannot beat the best is never scored.
//!
//! Never silently wrong: when `widen` is set, pair-implied biases beyond the
//! bounds (up to four times them) are scored too, and one that gates more
//! pairs than the best within the bounds wins (`widened`). The result says
//! when its bias lies on or beyond a bound (`at_bound`), when a distinct
//! bias associates as many pairs nearly as well (`ambiguous`), and when the
//! residuals after compensation are far larger than the stated radar and
//! AIS errors (`inconsistent`, `residual_ratio`).
//!
//! Bias model: measured range ρ_m = ρ + Δρ, measured azimuth θ_m = θ + Δθ
//! (clockwise from north); compensation subtracts both. The plane is x east,
//! y north, so eq. 1 reads x = ρ sin θ, y = ρ cos θ.

use std::cell::{OnceCell, RefCell};
use std::collections::HashMap;

use crate::assignment;
use crate::bias::cfar::{self, CfarConfig, Thresholds};
use crate::error::AlgoError;
use crate::polar::wrap_angle;

/// A raw radar plot of a track: time, range (m), azimuth (rad, from north).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RadarSample {
    /// Time of the plot (s).
    pub t: f64,
    /// Measured range (m).
    pub range: f64,
    /// Measured azimuth (rad, clockwise from north).
    pub azimuth: f64,
}

/// An AIS report in the radar's local plane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AisPoint {
    /// Time of the report (s).
    pub t: f64,
    /// Position (east, north) in the radar's local plane (m).
    pub position: [f64; 2],
    /// Standard deviation of the report's time (s): a whole-second time
    /// stamp taken at the middle of its second is uniform within ±0.5 s,
    /// σ = 1/√12 s; 0 when the time is exact. Times speed enters the
    /// report's position variance along its course.
    pub time_sigma: f64,
}

impl AisPoint {
    /// A report with an exact time.
    pub fn exact(t: f64, position: [f64; 2]) -> Self {
        Self {
            t,
            position,
            time_sigma: 0.0,
        }
    }
}

/// Standard deviation of a time uniformly distributed over a `resolution`
/// interval (the time stamp at its middle): resolution / √12.
pub fn quantisation_sigma(resolution: f64) -> f64 {
    resolution / 12f64.sqrt()
}

/// A range and azimuth bias (m, rad).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Bias {
    /// Range bias Δρ (m).
    pub range: f64,
    /// Azimuth bias Δθ (rad).
    pub azimuth: f64,
}

/// How the initial bias is found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Seeding {
    /// The paper: credible pairs from CA-CFAR thresholds.
    Cfar,
    /// The bias search over pair-implied hypotheses.
    Search,
    /// Both; the result that gates more pairs (then the smaller mean
    /// distance) wins, CA-CFAR on a tie.
    Auto,
}

/// The path that produced the reported result.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Path {
    /// Seeded by the CA-CFAR credible pairs (the paper's path).
    Cfar,
    /// Seeded by the bias search over pair-implied hypotheses.
    BiasSearch,
    /// Nothing could be associated; no bias was estimated.
    None,
}

/// Residuals after compensation above this many stated standard deviations
/// (root mean square over both axes) flag the result as inconsistent.
pub const INCONSISTENT_RATIO: f64 = 3.0;
/// A distinct bias whose association gates as many pairs with a mean
/// distance at most this many times the chosen one's makes it ambiguous.
pub const AMBIGUOUS_DISTANCE_RATIO: f64 = 1.5;
/// The widened search looks this many times past the bounds.
pub const WIDEN_FACTOR: f64 = 4.0;

/// Parameters of [`associate`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Config {
    /// Longest gap between two radar samples interpolated across (s); no
    /// extrapolation beyond a track's first or last sample.
    pub max_gap: f64,
    /// The CA-CFAR detector of the credible pairs (eqs. 7–10).
    pub cfar: CfarConfig,
    /// Gate on the mean distance of an associated pair (m).
    pub gate: f64,
    /// How the initial bias is found.
    pub seeding: Seeding,
    /// Most rounds of compensation, assignment and re-estimation in a
    /// refinement (1 to 1000).
    pub max_iterations: usize,
    /// Bounds of the bias search.
    pub max_range_bias: f64,
    /// Largest azimuth bias searched (rad).
    pub max_azimuth_bias: f64,
    /// Most hypotheses ranked (the most time-consistent pairs first).
    pub max_hypotheses: usize,
    /// Most hypotheses scored exactly (gated assignment) on each side of
    /// the bounds.
    pub max_evaluations: usize,
    /// Score pair-implied biases up to `WIDEN_FACTOR` times past the bounds
    /// and take one that gates more pairs than any within them.
    pub widen: bool,
    /// The radar's stated errors (m, rad) and the AIS position error per
    /// axis (m): the model of the residuals' spread.
    pub sigma_range: f64,
    /// The radar's stated azimuth error, one standard deviation (rad).
    pub sigma_azimuth: f64,
    /// The AIS position error per axis, one standard deviation (m).
    pub sigma_ais: f64,
    /// Fewest common instants for a pair to enter the distance matrix
    /// (at least 2: one instant implies any bias exactly).
    pub min_common: usize,
}

impl Default for Config {
    fn default() -> Self {
        Self {
            max_gap: 30.0,
            cfar: CfarConfig::default(),
            gate: 500.0,
            seeding: Seeding::Auto,
            max_iterations: 20,
            max_range_bias: 5000.0,
            max_azimuth_bias: 5f64.to_radians(),
            max_hypotheses: 2000,
            max_evaluations: 4,
            widen: true,
            sigma_range: 50.0,
            sigma_azimuth: 0.2f64.to_radians(),
            sigma_ais: 10.0,
            min_common: 2,
        }
    }
}

/// A bias estimate with its covariance (rows/cols: range m, azimuth rad).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BiasEstimate {
    /// The estimated bias: the mean range and azimuth residuals over all
    /// samples.
    pub bias: Bias,
    /// The reported covariance: cluster-robust CR2 over pairs scaled to the
    /// small-sample 95 % quantile (Hotelling T² with the effective number of
    /// pairs − 1 degrees of freedom), at least the model covariance of the
    /// stated errors on each axis.
    pub covariance: [[f64; 2]; 2],
    /// The plain cluster-robust (CR1) covariance, for comparison.
    pub covariance_cr1: [[f64; 2]; 2],
    /// (Σ n_k)² / Σ n_k² over the pairs' sample counts n_k.
    pub effective_pairs: f64,
    /// Root mean square of the residuals after compensation in units of
    /// their stated standard deviations (1 when the stated errors hold).
    pub residual_ratio: f64,
    /// Pairs with residuals in the estimate.
    pub pairs: usize,
    /// Residual samples in the estimate (N: the pairs' common instants).
    pub samples: usize,
}

/// One associated pair: radar track index, AIS ship index, eq. 6 distances.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Association {
    /// Radar track index.
    pub radar: usize,
    /// AIS ship index.
    pub ais: usize,
    /// Eq. 6 mean distance before compensation (m).
    pub distance_before: f64,
    /// Eq. 6 mean distance after compensation by the estimated bias (m).
    pub distance_after: f64,
    /// Common instants of the pair (AIS report times within the track).
    pub common: usize,
}

/// A distinct bias that associates as many pairs nearly as well.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Alternative {
    /// The alternative bias, refined.
    pub bias: Bias,
    /// Pairs it gates.
    pub pairs: usize,
    /// Mean eq. 6 distance of those pairs after compensation by it (m).
    pub mean_distance: f64,
}

/// The result of [`associate`]: the path taken, the bias estimate, the
/// associated pairs and the diagnostics.
#[derive(Debug, Clone, PartialEq)]
pub struct Outcome {
    /// The path that produced the result.
    pub path: Path,
    /// CA-CFAR thresholds S1 and S2, when the detector ran and found them.
    pub thresholds: Option<Thresholds>,
    /// Credible pairs of eq. 7 (radar, AIS, raw eq. 6 distance).
    pub credible_pairs: Vec<(usize, usize, f64)>,
    /// The bias estimate; `None` when nothing could be associated.
    pub estimate: Option<BiasEstimate>,
    /// Refinement rounds of the chosen path.
    pub iterations: usize,
    /// Whether the refinement ended with an unchanged association.
    pub converged: bool,
    /// The associated pairs after refinement with the estimated bias.
    pub associations: Vec<Association>,
    /// Mean distance radar–AIS over the associated pairs' common instants,
    /// before and after compensation.
    pub mean_error_before: Option<f64>,
    /// Mean distance radar–AIS over the associated pairs' common instants
    /// after compensation (m).
    pub mean_error_after: Option<f64>,
    /// Gated pairs reached from each seed, when it ran: (CA-CFAR, search).
    pub gated_by_seed: (Option<usize>, Option<usize>),
    /// Pair-implied biases ranked, and scored exactly, by the search.
    pub hypotheses: usize,
    /// Pair-implied biases scored exactly by the search.
    pub evaluated: usize,
    /// The search went past the bounds: (gated pairs there, best within).
    pub widened: Option<(usize, usize)>,
    /// The estimate lies on or beyond a search bound.
    pub at_bound: bool,
    /// A distinct bias associating as many pairs nearly as well.
    pub ambiguous: Option<Alternative>,
    /// Residuals after compensation above `INCONSISTENT_RATIO` stated σ.
    pub inconsistent: bool,
    /// AIS ships sharing fewer than `min_common` instants with every track:
    /// they can never be associated.
    pub unassociable_ais: Vec<usize>,
}

/// Eq. 1 with azimuth from north: (east, north) of (range, azimuth).
pub fn polar_to_plane(range: f64, azimuth: f64) -> [f64; 2] {
    [range * azimuth.sin(), range * azimuth.cos()]
}

/// (range, azimuth in [0, 2π)) of a plane point.
pub fn plane_to_polar(p: [f64; 2]) -> (f64, f64) {
    (
        p[0].hypot(p[1]),
        p[0].atan2(p[1]).rem_euclid(std::f64::consts::TAU),
    )
}

/// A sample with `bias` removed.
pub fn compensate(s: &RadarSample, bias: Bias) -> RadarSample {
    RadarSample {
        t: s.t,
        range: s.range - bias.range,
        azimuth: (s.azimuth - bias.azimuth).rem_euclid(std::f64::consts::TAU),
    }
}

/// Where AIS report k of ship j falls in radar track i: samples a and a + 1
/// with weight w of a + 1 (w = 0 when the time is a sample's own).
#[derive(Debug, Clone, Copy)]
struct Bracket {
    k: u32,
    a: u32,
    w: f64,
}

/// What one pass over a pair's common instants tells (raw radar data).
#[derive(Debug, Clone, Copy, Default)]
struct Summary {
    /// Common instants (0 when fewer than `min_common`).
    n: usize,
    /// Eq. 6 mean distance.
    distance: f64,
    /// Implied bias: mean range residual and circular mean azimuth residual.
    range: f64,
    azimuth: f64,
    /// Means of ρ_a sin δ and ρ_a cos δ over the instants (δ the azimuth
    /// residual, ρ_a the AIS range) and the mean AIS range.
    sin: f64,
    cos: f64,
    rho: f64,
    /// Variance of the range plus cross-range residuals (m²).
    spread: f64,
}

impl Summary {
    /// Lower bounds of the pair's mean distance under bias `h` (with
    /// `sc` = (sin, cos) of its azimuth): along range |mean range residual −
    /// Δρ| (up to the interpolation chord), and across it |mean ρ_a sin(δ −
    /// Δθ)|, since a point is at least ρ_a |sin| from the other's bearing
    /// line and compensation turns every sample, so every interpolated
    /// point, by Δθ.
    fn offsets(&self, h: Bias, sc: (f64, f64)) -> (f64, f64) {
        (
            (self.range - h.range).abs(),
            (sc.1 * self.sin - sc.0 * self.cos).abs(),
        )
    }
}

/// The bearings and extent of a set of plane points: the circular mean
/// bearing, the largest deviation from it, the smallest range and the
/// bounding box.
#[derive(Debug, Clone, Copy)]
struct Sector {
    centre: f64,
    half: f64,
    min_range: f64,
    lo: [f64; 2],
    hi: [f64; 2],
}

impl Sector {
    fn of(points: &[[f64; 2]]) -> Self {
        let (sx, sy) = points.iter().fold((0.0, 0.0), |a, p| {
            let r = (p[0] * p[0] + p[1] * p[1]).sqrt().max(1e-9);
            (a.0 + p[0] / r, a.1 + p[1] / r)
        });
        let centre = sx.atan2(sy);
        let mut s = Self {
            centre,
            half: 0.0,
            min_range: f64::INFINITY,
            lo: [f64::INFINITY; 2],
            hi: [f64::NEG_INFINITY; 2],
        };
        // The widest point: largest angle atan2(|c|, d) from the centre,
        // compared without trigonometry (sign of the sine of the difference).
        let (uc, ud) = centre.sin_cos();
        let mut widest = (0.0f64, 1.0f64);
        for p in points {
            let (c, d) = ((p[0] * ud - p[1] * uc).abs(), p[0] * uc + p[1] * ud);
            if c * widest.1 - widest.0 * d > 0.0 {
                widest = (c, d);
            }
            s.min_range = s.min_range.min((p[0] * p[0] + p[1] * p[1]).sqrt());
            for (d, &x) in p.iter().enumerate() {
                s.lo[d] = s.lo[d].min(x);
                s.hi[d] = s.hi[d].max(x);
            }
        }
        s.half = widest.0.atan2(widest.1);
        s
    }

    /// Whether every azimuth residual of a radar track in `self` against a
    /// ship in `ais` stays so far from every bias up to `outer` that each
    /// AIS point is more than `reach` from the compensated bearing line:
    /// ρ_a |sin(δ − h)| > reach with |δ − h| between g and π − g.
    fn apart(&self, ais: &Sector, outer: f64, reach: f64) -> bool {
        let gap = wrap_angle(self.centre - ais.centre).abs();
        let (lo, hi) = (
            gap - self.half - ais.half - outer,
            gap + self.half + ais.half + outer,
        );
        let need = (reach / ais.min_range.max(1e-9)).min(1.0).asin();
        ais.min_range > reach && lo > need && hi < std::f64::consts::PI - need
    }

    /// Distance between the two bounding boxes (a lower bound of any
    /// distance between their points and of any interpolated point).
    fn distance(&self, other: &Sector) -> f64 {
        let g = |d: usize| {
            (other.lo[d] - self.hi[d])
                .max(self.lo[d] - other.hi[d])
                .max(0.0)
        };
        g(0).hypot(g(1))
    }
}

/// Brackets of every report of `ship` inside `track` (times ascending), as
/// `bracket` would find them one by one.
fn walk(
    track: &[RadarSample],
    ship: &[AisPoint],
    max_gap: f64,
    mut f: impl FnMut(usize, usize, f64),
) {
    let (Some(first), Some(last)) = (track.first(), track.last()) else {
        return;
    };
    let start = ship.partition_point(|r| r.t < first.t);
    let Some(r0) = ship.get(start) else {
        return;
    };
    // Invariant: track[b − 1].t ≤ t < track[b].t, or b = len at the end.
    let len = track.len();
    let mut b = track.partition_point(|s| s.t <= r0.t);
    // A radar revisits at a nearly constant period: the sample after t is
    // guessed from it and then moved to the exact one, the same b a scan
    // from the previous one finds (times strictly increase), without a
    // branch per skipped sample that the random AIS intervals mispredict.
    let period = (last.t - first.t) / (len.max(2) - 1) as f64;
    for (k, rep) in ship.iter().enumerate().skip(start) {
        let t = rep.t;
        if t > last.t {
            break;
        }
        if period > 0.0 {
            let guess = ((t - first.t) / period) as usize + 1;
            b = guess.clamp(b, len);
            while track[b - 1].t > t {
                b -= 1;
            }
        }
        while b < len && track[b].t <= t {
            b += 1;
        }
        let a = b - 1;
        if track[a].t == t {
            f(k, a, 0.0);
            continue;
        }
        let (ta, tb) = (track[a].t, track[b].t);
        if tb - ta <= max_gap {
            f(k, a, (t - ta) / (tb - ta));
        }
    }
}

/// `walk`'s brackets collected.
fn walk_brackets(track: &[RadarSample], ship: &[AisPoint], max_gap: f64) -> Vec<Bracket> {
    let mut b = Vec::new();
    walk(track, ship, max_gap, |k, a, w| {
        b.push(Bracket {
            k: k as u32,
            a: a as u32,
            w,
        })
    });
    b
}

/// Tracks grouped by sample times equal bit for bit: each track's group
/// index (groups numbered in order of their first track) and each group's
/// size. Candidates are found by (length, first and last time), then
/// compared in full, so distinct tracks cost one lookup each.
fn time_groups(radar: &[Vec<RadarSample>]) -> (Vec<usize>, Vec<usize>) {
    let bits = |t: &[RadarSample]| {
        (
            t.len(),
            t.first().map_or(0, |s| s.t.to_bits()),
            t.last().map_or(0, |s| s.t.to_bits()),
        )
    };
    let same = |a: &[RadarSample], b: &[RadarSample]| {
        a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.t.to_bits() == y.t.to_bits())
    };
    let mut by_key: HashMap<(usize, u64, u64), Vec<usize>> = HashMap::new();
    let mut leaders: Vec<usize> = Vec::new();
    let mut sizes: Vec<usize> = Vec::new();
    let group = radar
        .iter()
        .enumerate()
        .map(|(i, t)| {
            let candidates = by_key.entry(bits(t)).or_default();
            match candidates.iter().find(|&&g| same(&radar[leaders[g]], t)) {
                Some(&g) => {
                    sizes[g] += 1;
                    g
                }
                None => {
                    let g = leaders.len();
                    leaders.push(i);
                    sizes.push(1);
                    candidates.push(g);
                    g
                }
            }
        })
        .collect();
    (group, sizes)
}

/// The interpolated position at bracket (a, w).
fn at(pos: &[[f64; 2]], a: usize, w: f64) -> [f64; 2] {
    let p = pos[a];
    if w == 0.0 {
        return p;
    }
    let q = pos[a + 1];
    [p[0] + w * (q[0] - p[0]), p[1] + w * (q[1] - p[1])]
}

fn dist(p: [f64; 2], q: [f64; 2]) -> f64 {
    ((p[0] - q[0]) * (p[0] - q[0]) + (p[1] - q[1]) * (p[1] - q[1])).sqrt()
}

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
fn solve_gated(
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
type Residual = ([f64; 2], usize);

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
struct Problem<'a> {
    radar: &'a [Vec<RadarSample>],
    ais: &'a [Vec<AisPoint>],
    cfg: &'a Config,
    rows: usize,
    cols: usize,
    /// Raw plane positions and (sin θ, cos θ) of every radar sample.
    raw: Vec<Vec<[f64; 2]>>,
    unit: Vec<Vec<[f64; 2]>>,
    /// AIS range and velocity (central differences) of every report.
    ais_range: Vec<Vec<f64>>,
    ais_velocity: Vec<Vec<[f64; 2]>>,
    /// Row-major nR × nA pair summaries.
    summary: Vec<Summary>,
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
    group: Vec<usize>,
    /// Brackets of every ship in each time group (groups × nA), built on
    /// first use; raw residuals (with the AIS report index) of each pair,
    /// built on first use.
    brackets: Vec<OnceCell<Vec<Bracket>>>,
    residuals: Vec<OnceCell<Vec<Residual>>>,
    /// Gated assignments by bias (bits of range, azimuth) and estimates by
    /// associated pairs: the search, the refinements and the ambiguity check
    /// meet the same biases and associations again.
    assigned: RefCell<HashMap<(u64, u64), Assigned>>,
    estimates: RefCell<HashMap<Pairs, Option<BiasEstimate>>>,
}

/// Associated pairs (radar track, AIS ship).
type Pairs = Vec<(usize, usize)>;
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
    fn new(radar: &'a [Vec<RadarSample>], ais: &'a [Vec<AisPoint>], cfg: &'a Config) -> Self {
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
    fn brackets(&self, ij: usize) -> &[Bracket] {
        if self.summary[ij].n == 0 {
            return &[];
        }
        self.walked(ij)
    }

    /// Brackets of pair ij however few, shared by its track's time group.
    fn walked(&self, ij: usize) -> &[Bracket] {
        let (i, j) = (ij / self.cols, ij % self.cols);
        self.brackets[self.group[i] * self.cols + j]
            .get_or_init(|| walk_brackets(&self.radar[i], &self.ais[j], self.cfg.max_gap))
    }

    /// Plane positions of every track compensated by `bias`: the raw unit
    /// vector turned back by the azimuth bias, times the corrected range.
    fn positions(&self, bias: Bias) -> Vec<Vec<[f64; 2]>> {
        if bias == Bias::default() {
            return self.raw.clone();
        }
        let (s, c) = bias.azimuth.sin_cos();
        self.radar
            .iter()
            .zip(&self.unit)
            .map(|(t, u)| {
                t.iter()
                    .zip(u)
                    .map(|(x, u)| {
                        let r = x.range - bias.range;
                        [r * (u[0] * c - u[1] * s), r * (u[1] * c + u[0] * s)]
                    })
                    .collect()
            })
            .collect()
    }

    /// Eq. 6 for pair ij at positions `pos`.
    fn distance(&self, pos: &[Vec<[f64; 2]>], ij: usize) -> f64 {
        let br = self.brackets(ij);
        if br.is_empty() {
            return f64::INFINITY;
        }
        let (i, j) = (ij / self.cols, ij % self.cols);
        let sum: f64 = br
            .iter()
            .map(|b| {
                dist(
                    at(&pos[i], b.a as usize, b.w),
                    self.ais[j][b.k as usize].position,
                )
            })
            .sum();
        sum / br.len() as f64
    }

    /// The eq. 6 matrix of the raw data (∞ without common instants); the
    /// pairs never walked hold their lower bound.
    fn raw_matrix(&self) -> Vec<f64> {
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
    fn cfar(&self) -> (Vec<f64>, Option<Thresholds>) {
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
    fn candidates(&self, bias: Bias) -> impl Iterator<Item = usize> + '_ {
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
    fn edges(&self, bias: Bias) -> Vec<(usize, usize, f64)> {
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
                        at(&pos[i], b.a as usize, b.w),
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
    fn assign(&self, bias: Bias) -> Assigned {
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

    /// Range and azimuth residuals (measured − AIS) of pair (i, j) at its
    /// common instants, with the raw track interpolated in the plane, and
    /// each report's index.
    fn residuals(&self, i: usize, j: usize) -> &[Residual] {
        let ij = i * self.cols + j;
        self.residuals[ij].get_or_init(|| {
            self.brackets(ij)
                .iter()
                .map(|b| {
                    let (rm, am) = plane_to_polar(at(&self.raw[i], b.a as usize, b.w));
                    let (ra, aa) = plane_to_polar(self.ais[j][b.k as usize].position);
                    ([rm - ra, wrap_angle(am - aa)], b.k as usize)
                })
                .collect()
        })
    }

    /// Stated variances (range m², cross-range m²) of the residual of AIS
    /// report k of ship j: radar errors, AIS position error, and the time
    /// uncertainty times the ship's speed across each axis.
    fn stated_variances(&self, j: usize, k: usize) -> [f64; 2] {
        let c = self.cfg;
        let p = self.ais[j][k].position;
        let rho = self.ais_range[j][k].max(1e-9);
        let (ur, uc) = ([p[0] / rho, p[1] / rho], [p[1] / rho, -p[0] / rho]);
        let v = self.ais_velocity[j][k];
        let st = self.ais[j][k].time_sigma;
        let vr = (v[0] * ur[0] + v[1] * ur[1]) * st;
        let vc = (v[0] * uc[0] + v[1] * uc[1]) * st;
        let ais = c.sigma_ais * c.sigma_ais;
        [
            c.sigma_range * c.sigma_range + ais + vr * vr,
            (rho * c.sigma_azimuth).powi(2) + ais + vc * vc,
        ]
    }

    /// Least squares over the pairs' residuals. Under the bias model the
    /// range and azimuth residuals are Δρ and Δθ plus noise, so the estimate
    /// is their mean over all samples. Samples of one pair share the ship's
    /// own errors (antenna offset, a filtered track's lag), so the
    /// covariance is cluster-robust over pairs. With few pairs the plain
    /// CR1 form Σ_k n_k² (m_k − b)(m_k − b)ᵀ / N² · P/(P − 1) (m_k the pair
    /// means) is too small: the CR2 form divides each term by 1 − n_k/N
    /// (Bell and McCaffrey 2002: unbiased for equicorrelated clusters), and
    /// the 95 % ellipse of a covariance estimated from G = (Σ n_k)²/Σ n_k²
    /// effective pairs is Hotelling's T²(2, G − 1), not χ²₂: the covariance
    /// is scaled by their ratio so a client's χ²₂ ellipse keeps 95 %. Each
    /// axis is at least the model variance of the stated errors (with the
    /// AIS time quantisation) over the N samples. A single pair uses the
    /// sample covariance / n.
    fn estimate(&self, pairs: &[(usize, usize)]) -> Option<BiasEstimate> {
        if let Some(e) = self.estimates.borrow().get(pairs) {
            return *e;
        }
        let e = self.estimate_uncached(pairs);
        self.estimates.borrow_mut().insert(pairs.to_vec(), e);
        e
    }

    /// `estimate` computed.
    fn estimate_uncached(&self, pairs: &[(usize, usize)]) -> Option<BiasEstimate> {
        let per_pair: Vec<(usize, &[Residual])> = pairs
            .iter()
            .map(|&(i, j)| (j, self.residuals(i, j)))
            .filter(|r| !r.1.is_empty())
            .collect();
        let n: usize = per_pair.iter().map(|p| p.1.len()).sum();
        if n == 0 {
            return None;
        }
        let nf = n as f64;
        let mut mean = [0.0; 2];
        for (r, _) in per_pair.iter().flat_map(|p| p.1) {
            mean[0] += r[0] / nf;
            mean[1] += r[1] / nf;
        }
        let p = per_pair.len();
        let mut cr1 = [[0.0; 2]; 2];
        let mut cr2 = [[0.0; 2]; 2];
        let mut sum_n2 = 0.0;
        if p >= 2 {
            for (_, r) in &per_pair {
                let nk = r.len() as f64;
                sum_n2 += nk * nk;
                let mk = [
                    r.iter().map(|x| x.0[0]).sum::<f64>() / nk - mean[0],
                    r.iter().map(|x| x.0[1]).sum::<f64>() / nk - mean[1],
                ];
                for a in 0..2 {
                    for b in 0..2 {
                        cr1[a][b] += nk * nk * mk[a] * mk[b];
                        cr2[a][b] += nk * nk * mk[a] * mk[b] / (1.0 - nk / nf);
                    }
                }
            }
            let scale = p as f64 / (p as f64 - 1.0) / (nf * nf);
            cr1.iter_mut().flatten().for_each(|c| *c *= scale);
            cr2.iter_mut().flatten().for_each(|c| *c /= nf * nf);
        } else if n >= 2 {
            sum_n2 = nf * nf;
            for (r, _) in per_pair.iter().flat_map(|p| p.1) {
                let d = [r[0] - mean[0], r[1] - mean[1]];
                for a in 0..2 {
                    for b in 0..2 {
                        cr1[a][b] += d[a] * d[b] / ((nf - 1.0) * nf);
                    }
                }
            }
            cr2 = cr1;
        } else {
            sum_n2 = 1.0;
            cr1 = [[f64::INFINITY, 0.0], [0.0, f64::INFINITY]];
            cr2 = cr1;
        }
        let effective_pairs = nf * nf / sum_n2;
        let factor = if p >= 2 {
            small_sample_factor(effective_pairs - 1.0)
        } else {
            1.0
        };
        // Model variances and normalised residuals of the stated errors.
        let (mut model, mut nis) = ([0.0; 2], 0.0);
        for (j, r) in &per_pair {
            for &(x, k) in r.iter() {
                let v = self.stated_variances(*j, k);
                let rho = self.ais_range[*j][k];
                model[0] += v[0] / (nf * nf);
                model[1] += v[1] / (rho * rho).max(1e-18) / (nf * nf);
                let e = [x[0] - mean[0], rho * wrap_angle(x[1] - mean[1])];
                nis += e[0] * e[0] / v[0] + e[1] * e[1] / v[1];
            }
        }
        let mut cov = cr2;
        cov.iter_mut().flatten().for_each(|c| *c *= factor);
        for d in 0..2 {
            if cov[d][d].is_finite() {
                cov[d][d] = cov[d][d].max(model[d]);
            }
        }
        Some(BiasEstimate {
            bias: Bias {
                range: mean[0],
                azimuth: mean[1],
            },
            covariance: cov,
            covariance_cr1: cr1,
            effective_pairs,
            residual_ratio: (nis / (2.0 * nf)).sqrt(),
            pairs: p,
            samples: n,
        })
    }

    /// Compensate, assign, re-estimate until the assignment repeats.
    fn refine(&self, seed: Bias) -> Refined {
        let mut bias = seed;
        let mut last: Option<Vec<(usize, usize)>> = None;
        let mut estimate = None;
        let mut iterations = 0;
        let mut converged = false;
        while iterations < self.cfg.max_iterations {
            iterations += 1;
            let (pairs, _) = self.assign(bias);
            if last.as_ref() == Some(&pairs) {
                converged = true;
                break;
            }
            match self.estimate(&pairs) {
                Some(e) => {
                    bias = e.bias;
                    estimate = Some(e);
                }
                None => {
                    estimate = None;
                    last = Some(pairs);
                    converged = true;
                    break;
                }
            }
            last = Some(pairs);
        }
        let pairs = last.unwrap_or_default();
        let pos = self.positions(bias);
        let total: f64 = pairs
            .iter()
            .map(|&(i, j)| self.distance(&pos, i * self.cols + j))
            .sum();
        Refined {
            estimate,
            pairs,
            total,
            iterations,
            converged,
        }
    }
}

/// Hotelling's T²(2, ν) 95 % quantile over χ²₂'s: with F(2, m) in closed
/// form (its CDF is 1 − (1 + 2x/m)^(−m/2)), T² = 2ν/(ν − 1) F(2, ν − 1) =
/// ν (0.05^(−2/(ν − 1)) − 1), and χ²₂ = −2 ln 0.05. ν is clamped to 2 (the
/// fewest for a finite quantile): 133 there, 1.25 at ν = 19, → 1.
pub fn small_sample_factor(nu: f64) -> f64 {
    let nu = nu.max(2.0);
    let alpha: f64 = 0.05;
    let t2 = nu * (alpha.powf(-2.0 / (nu - 1.0)) - 1.0);
    t2 / (-2.0 * alpha.ln())
}

struct Refined {
    estimate: Option<BiasEstimate>,
    pairs: Vec<(usize, usize)>,
    total: f64,
    iterations: usize,
    converged: bool,
}

impl Refined {
    fn mean(&self) -> f64 {
        self.total / self.pairs.len().max(1) as f64
    }

    /// Better: more gated pairs, then a smaller mean distance.
    fn better_than(&self, other: &Refined) -> bool {
        self.pairs.len() > other.pairs.len()
            || (self.pairs.len() == other.pairs.len() && self.mean() < other.mean() * (1.0 - 1e-9))
    }
}

/// Checks the configuration's ranges.
pub fn validate_config(cfg: &Config) -> Result<(), AlgoError> {
    cfg.cfar.validate()?;
    let bad = |what, reason: &str| {
        Err(AlgoError::InvalidParameter {
            what,
            reason: reason.into(),
        })
    };
    if !(cfg.max_gap.is_finite() && cfg.max_gap > 0.0) {
        return bad("max_gap_s", "must be a finite number > 0");
    }
    if !(cfg.gate.is_finite() && cfg.gate > 0.0) {
        return bad("gate_m", "must be a finite number > 0");
    }
    if cfg.max_iterations == 0 || cfg.max_iterations > 1000 {
        return bad("max_iterations", "must be between 1 and 1000");
    }
    if !(cfg.max_range_bias.is_finite() && cfg.max_range_bias >= 0.0) {
        return bad("max_range_bias_m", "must be a finite number >= 0");
    }
    if !(cfg.max_azimuth_bias.is_finite()
        && (0.0..=std::f64::consts::PI).contains(&cfg.max_azimuth_bias))
    {
        return bad("max_azimuth_bias_deg", "must be between 0 and 180");
    }
    if cfg.max_hypotheses == 0 {
        return bad("max_hypotheses", "must be at least 1");
    }
    if cfg.max_evaluations == 0 || cfg.max_evaluations > 1000 {
        return bad("max_evaluations", "must be between 1 and 1000");
    }
    if !(cfg.sigma_range.is_finite() && cfg.sigma_range > 0.0) {
        return bad("radar_sigma_range_m", "must be a finite number > 0");
    }
    if !(cfg.sigma_azimuth.is_finite() && cfg.sigma_azimuth > 0.0) {
        return bad("radar_sigma_azimuth_deg", "must be a finite number > 0");
    }
    if !(cfg.sigma_ais.is_finite() && cfg.sigma_ais >= 0.0) {
        return bad("ais_sigma_m", "must be a finite number >= 0");
    }
    if cfg.min_common < 2 {
        return bad(
            "min_common",
            "must be at least 2: one common instant fits any bias exactly",
        );
    }
    Ok(())
}

/// Associates radar tracks (raw polar samples in time order) with AIS ships
/// (plane positions in time order) and estimates the radar bias.
pub fn associate(radar: &[Vec<RadarSample>], ais: &[Vec<AisPoint>], cfg: &Config) -> Outcome {
    let problem = Problem::new(radar, ais, cfg);
    let mut raw_matrix = problem.raw_matrix();
    let cols = problem.cols;
    let unassociable_ais: Vec<usize> = (0..cols)
        .filter(|&j| (0..problem.rows).all(|i| problem.summary[i * cols + j].n == 0))
        .collect();

    // The paper's path: CA-CFAR thresholds, credible pairs, estimate.
    let mut thresholds = None;
    let mut credible = Vec::new();
    let mut from_cfar = None;
    if matches!(cfg.seeding, Seeding::Cfar | Seeding::Auto) {
        let (m, t) = problem.cfar();
        raw_matrix = m;
        thresholds = t;
        if let Some(t) = &thresholds {
            credible = cfar::credible_pairs(&raw_matrix, radar.len(), cols, t);
            if let Some(e) = problem.estimate(&credible) {
                from_cfar = Some(problem.refine(e.bias));
            }
        }
    }
    let searched = matches!(cfg.seeding, Seeding::Search | Seeding::Auto).then(|| search(&problem));
    let from_search = searched
        .as_ref()
        .and_then(|s| s.best)
        .map(|b| problem.refine(b.bias));
    let gated_by_seed = (
        from_cfar.as_ref().map(|r| r.pairs.len()),
        from_search.as_ref().map(|r| r.pairs.len()),
    );
    let (path, chosen) = match (from_cfar, from_search) {
        (Some(c), Some(s)) if s.better_than(&c) => (Path::BiasSearch, Some(s)),
        (Some(c), _) => (Path::Cfar, Some(c)),
        (None, Some(s)) => (Path::BiasSearch, Some(s)),
        (None, None) => (Path::None, None),
    };
    let (path, chosen) = match chosen {
        Some(r) if r.estimate.is_some() && !r.pairs.is_empty() => (path, Some(r)),
        _ => (Path::None, None),
    };
    let credible_pairs = credible
        .iter()
        .map(|&(i, j)| (i, j, raw_matrix[i * cols + j]))
        .collect();
    let (hypotheses, evaluated) = searched
        .as_ref()
        .map_or((0, 0), |s| (s.hypotheses, s.evaluated));
    let widened = searched
        .as_ref()
        .and_then(|s| s.widened)
        .filter(|_| path == Path::BiasSearch);
    let Some(r) = chosen else {
        return Outcome {
            path,
            thresholds,
            credible_pairs,
            estimate: None,
            iterations: 0,
            converged: true,
            associations: Vec::new(),
            mean_error_before: None,
            mean_error_after: None,
            gated_by_seed,
            hypotheses,
            evaluated,
            widened: None,
            at_bound: false,
            ambiguous: None,
            inconsistent: false,
            unassociable_ais,
        };
    };
    let estimate = r.estimate.expect("checked above");
    // A distinct bias that gated as many pairs: refine it and compare.
    let ambiguous = searched
        .as_ref()
        .and_then(|s| s.runner_up)
        .map(|alt| problem.refine(alt.bias))
        .and_then(|alt| {
            let b = alt.estimate?.bias;
            let distinct = distinct(
                b,
                estimate.bias,
                median_rho(&problem, &r.pairs),
                cfg.gate / 2.0,
            );
            (distinct
                && alt.pairs.len() >= r.pairs.len()
                && alt.pairs != r.pairs
                && alt.mean() <= AMBIGUOUS_DISTANCE_RATIO * r.mean() + 1e-3)
                .then(|| Alternative {
                    bias: b,
                    pairs: alt.pairs.len(),
                    mean_distance: alt.mean(),
                })
        });
    let comp = problem.positions(estimate.bias);
    let associations: Vec<Association> = r
        .pairs
        .iter()
        .map(|&(i, j)| Association {
            radar: i,
            ais: j,
            distance_before: raw_matrix[i * cols + j],
            distance_after: problem.distance(&comp, i * cols + j),
            common: problem.summary[i * cols + j].n,
        })
        .collect();
    let n: usize = associations.iter().map(|a| a.common).sum();
    let weighted = |f: fn(&Association) -> f64| {
        associations
            .iter()
            .map(|a| f(a) * a.common as f64)
            .sum::<f64>()
            / n as f64
    };
    Outcome {
        path,
        thresholds,
        credible_pairs,
        estimate: Some(estimate),
        iterations: r.iterations,
        converged: r.converged,
        mean_error_before: (n > 0).then(|| weighted(|a| a.distance_before)),
        mean_error_after: (n > 0).then(|| weighted(|a| a.distance_after)),
        associations,
        gated_by_seed,
        hypotheses,
        evaluated,
        widened,
        at_bound: estimate.bias.range.abs() >= cfg.max_range_bias
            || estimate.bias.azimuth.abs() >= cfg.max_azimuth_bias,
        ambiguous,
        inconsistent: estimate.residual_ratio > INCONSISTENT_RATIO,
        unassociable_ais,
    }
}

/// Median mean AIS range of the pairs (m).
fn median_rho(problem: &Problem, pairs: &[(usize, usize)]) -> f64 {
    let mut r: Vec<f64> = pairs
        .iter()
        .map(|&(i, j)| problem.summary[i * problem.cols + j].rho)
        .collect();
    r.sort_by(f64::total_cmp);
    r.get(r.len() / 2).copied().unwrap_or(0.0)
}

/// Whether two biases differ by more than `by` metres in range or across
/// it at range `rho`.
fn distinct(a: Bias, b: Bias, rho: f64, by: f64) -> bool {
    (a.range - b.range).abs() > by || (wrap_angle(a.azimuth - b.azimuth) * rho).abs() > by
}

/// A hypothesis scored exactly.
#[derive(Debug, Clone, Copy)]
struct Scored {
    bias: Bias,
    rho: f64,
    count: usize,
    total: f64,
}

impl Scored {
    fn beats(&self, other: &Scored) -> bool {
        self.count > other.count || (self.count == other.count && self.total < other.total)
    }
}

struct SearchResult {
    best: Option<Scored>,
    /// The best scored hypothesis distinct from `best` with as many pairs.
    runner_up: Option<Scored>,
    hypotheses: usize,
    evaluated: usize,
    widened: Option<(usize, usize)>,
}

/// A hypothesis: the implied bias of a pair, its spread and AIS range.
#[derive(Debug, Clone, Copy)]
struct Hypothesis {
    spread: f64,
    bias: Bias,
    rho: f64,
}

/// The bias search: pair-implied biases within the bounds ranked by their
/// agreement with other pairs, the best few scored by gated assignments
/// then total distance; beyond the bounds when `widen` is set and a
/// hypothesis there could gate more pairs.
fn search(problem: &Problem) -> SearchResult {
    let cfg = problem.cfg;
    let outer_range = WIDEN_FACTOR * cfg.max_range_bias.max(cfg.gate);
    let outer_azimuth = (WIDEN_FACTOR * cfg.max_azimuth_bias).min(std::f64::consts::PI);
    let (mut inside, mut outside) = (Vec::new(), Vec::new());
    for s in problem.summary.iter().filter(|s| s.n > 0) {
        let h = Hypothesis {
            spread: s.spread,
            bias: Bias {
                range: s.range,
                azimuth: s.azimuth,
            },
            rho: s.rho,
        };
        let (r, a) = (s.range.abs(), s.azimuth.abs());
        if r <= cfg.max_range_bias && a <= cfg.max_azimuth_bias {
            inside.push(h);
        } else if cfg.widen && r <= outer_range && a <= outer_azimuth {
            outside.push(h);
        }
    }
    let mut voter = Voter::new(problem);
    let within = voter.best_of(&mut inside, None);
    let mut result = SearchResult {
        best: within.best,
        runner_up: within.runner_up,
        hypotheses: inside.len(),
        evaluated: within.evaluated,
        widened: None,
    };
    let count_within = within.best.map_or(0, |b| b.count);
    // No bias can gate more pairs than there are tracks or ships with any.
    let rows_with = (0..problem.rows)
        .filter(|&i| (0..problem.cols).any(|j| problem.summary[i * problem.cols + j].n > 0))
        .count();
    let cols_with = (0..problem.cols)
        .filter(|&j| (0..problem.rows).any(|i| problem.summary[i * problem.cols + j].n > 0))
        .count();
    if cfg.widen && !outside.is_empty() && count_within < rows_with.min(cols_with) {
        let beyond = voter.best_of(&mut outside, Some(count_within));
        result.hypotheses += outside.len();
        result.evaluated += beyond.evaluated;
        if let Some(b) = beyond.best.filter(|b| b.count > count_within) {
            result.best = Some(b);
            result.runner_up = beyond.runner_up;
            result.widened = Some((b.count, count_within));
        }
    }
    result.best = result.best.filter(|b| b.count > 0);
    result
}

struct Ranked {
    best: Option<Scored>,
    runner_up: Option<Scored>,
    evaluated: usize,
}

/// Counts distinct rows and columns of the pairs near a hypothesis.
struct Voter<'p, 'a> {
    problem: &'p Problem<'a>,
    stamp: Vec<usize>,
    generation: usize,
}

impl<'p, 'a> Voter<'p, 'a> {
    fn new(problem: &'p Problem<'a>) -> Self {
        Self {
            problem,
            stamp: vec![0; 2 * (problem.rows + problem.cols)],
            generation: 0,
        }
    }

    /// (upper bound of the gated pairs, agreeing rows/columns within a
    /// tenth of the gate) of hypothesis `h`.
    fn vote(&mut self, h: Bias) -> (usize, usize) {
        let p = self.problem;
        let tight = 0.1 * p.cfg.gate;
        self.generation += 1;
        let g = self.generation;
        let (rows, cols) = (p.rows, p.cols);
        let mut counts = [0usize; 4];
        let sc = h.azimuth.sin_cos();
        for ij in p.candidates(h) {
            let (i, j) = (ij / cols, ij % cols);
            let (dr, dx) = p.summary[ij].offsets(h, sc);
            let near = dr <= tight && dx <= tight;
            let slots = [i, rows + j, rows + cols + i, 2 * rows + cols + j];
            for (s, &slot) in slots.iter().enumerate() {
                if (s < 2 || near) && self.stamp[slot] != g {
                    self.stamp[slot] = g;
                    counts[s] += 1;
                }
            }
        }
        (counts[0].min(counts[1]), counts[2].min(counts[3]))
    }

    /// Ranks `hyps` (most agreeing first, then the least spread) and scores
    /// up to `max_evaluations` distinct ones whose bound can reach the best
    /// (and exceed `must_beat`).
    fn best_of(&mut self, hyps: &mut [Hypothesis], must_beat: Option<usize>) -> Ranked {
        let cfg = self.problem.cfg;
        hyps.sort_by(|a, b| a.spread.total_cmp(&b.spread));
        let hyps = &hyps[..hyps.len().min(cfg.max_hypotheses)];
        // One hypothesis (the least spread) per cell of a tenth of the gate
        // in range and cross-range: the rest would seed the same result.
        let tight = 0.1 * cfg.gate;
        let mut cells = std::collections::HashSet::new();
        let hyps: Vec<Hypothesis> = hyps
            .iter()
            .filter(|h| {
                cells.insert((
                    (h.bias.range / tight).floor() as i64,
                    (h.bias.azimuth * h.rho / tight).floor() as i64,
                ))
            })
            .copied()
            .collect();
        let votes: Vec<(usize, usize)> = hyps.iter().map(|h| self.vote(h.bias)).collect();
        let mut order: Vec<usize> = (0..hyps.len()).collect();
        order.sort_by_key(|&k| std::cmp::Reverse(votes[k].1));
        let mut scored: Vec<Scored> = Vec::new();
        let mut best: Option<Scored> = None;
        for k in order {
            if scored.len() >= cfg.max_evaluations {
                break;
            }
            let (h, ub) = (hyps[k], votes[k].0);
            let floor = best
                .map_or(0, |b| b.count)
                .max(must_beat.map_or(0, |m| m + 1));
            if ub < floor.max(1)
                || scored
                    .iter()
                    .any(|s| !distinct(s.bias, h.bias, h.rho, tight))
            {
                continue;
            }
            let (pairs, total) = self.problem.assign(h.bias);
            let s = Scored {
                bias: h.bias,
                rho: h.rho,
                count: pairs.len(),
                total,
            };
            if best.is_none_or(|b| s.beats(&b)) {
                best = Some(s);
            }
            scored.push(s);
        }
        let runner_up = best.and_then(|b| {
            scored
                .iter()
                .filter(|s| s.count >= b.count && distinct(s.bias, b.bias, b.rho, cfg.gate / 2.0))
                .copied()
                .reduce(|x, y| if y.beats(&x) { y } else { x })
        });
        Ranked {
            best,
            runner_up,
            evaluated: scored.len(),
        }
    }
}

/// Samples a and a + 1 of `track` around `t` and the weight of a + 1; `None`
/// outside the track or across a gap longer than `max_gap`.
#[cfg(test)]
fn bracket(track: &[RadarSample], t: f64, max_gap: f64) -> Option<(usize, f64)> {
    let first = track.first()?;
    let last = track.last()?;
    if t < first.t || t > last.t {
        return None;
    }
    let b = track.partition_point(|s| s.t <= t);
    // track[b − 1].t ≤ t < track[b].t (or b = len when t is the last time).
    let a = b - 1;
    if track[a].t == t {
        return Some((a, 0.0));
    }
    let (ta, tb) = (track[a].t, track[b].t);
    if tb - ta > max_gap {
        return None;
    }
    Some((a, (t - ta) / (tb - ta)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Ships on straight lines; radar samples at the AIS times with a pure
    /// bias, so the interpolation is exact and the estimate must equal the
    /// bias to rounding.
    fn scene(
        ships: &[([f64; 2], [f64; 2])],
        with_ais: &[bool],
        bias: Bias,
    ) -> (Vec<Vec<RadarSample>>, Vec<Vec<AisPoint>>) {
        let times: Vec<f64> = (0..20).map(|k| 10.0 * k as f64).collect();
        let mut radar = Vec::new();
        let mut ais = Vec::new();
        for (s, (p0, v)) in ships.iter().enumerate() {
            let pos = |t: f64| [p0[0] + v[0] * t, p0[1] + v[1] * t];
            radar.push(
                times
                    .iter()
                    .map(|&t| {
                        let (r, a) = plane_to_polar(pos(t));
                        RadarSample {
                            t,
                            range: r + bias.range,
                            azimuth: (a + bias.azimuth).rem_euclid(std::f64::consts::TAU),
                        }
                    })
                    .collect(),
            );
            if with_ais[s] {
                ais.push(times.iter().map(|&t| AisPoint::exact(t, pos(t))).collect());
            }
        }
        (radar, ais)
    }

    fn grid_ships(n: usize) -> Vec<([f64; 2], [f64; 2])> {
        (0..n)
            .map(|k| {
                let (a, b) = ((k % 5) as f64, (k / 5) as f64);
                (
                    [2000.0 + 4000.0 * a + 300.0 * b, 3000.0 + 4000.0 * b],
                    [5.0 - a, 3.0 + b],
                )
            })
            .collect()
    }

    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Stream `run` of the ChaCha8 generator keyed by `seed` (the key
    /// layout of the simulator's `eval::montecarlo::run_rng`).
    fn run_rng(seed: u64, run: u64) -> ChaCha8Rng {
        let mut key = [0u8; 32];
        key[..8].copy_from_slice(&seed.to_le_bytes());
        let mut rng = ChaCha8Rng::from_seed(key);
        rng.set_stream(run);
        rng
    }

    /// A standard normal draw (Box–Muller).
    fn gauss(rng: &mut ChaCha8Rng) -> f64 {
        let u1: f64 = 1.0 - rng.random::<f64>();
        let u2: f64 = rng.random::<f64>();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }

    /// A small AIS–radar scene generator for these tests (the simulator is
    /// the `eval` crate's, which the numerical core does not depend on): a
    /// harbour (`moored` ships 10–70 m apart in rows of 12 about (3, 5) km,
    /// `moving` ships at 2–10 m/s, the last quarter of each kind without
    /// AIS, 20 min, radar every 2.5 s with σρ 10 m, σθ 0.1°, AIS every 2–10
    /// s under way and 3 min moored with GNSS σ 3 m and antenna offset σ 5
    /// m) or, with `open_sea`, ships at 30–80 m/s in 20 × 20 km, all with
    /// exact AIS every 2–10 s, radar every 5 s for 145 s with σρ 50 m, σθ
    /// 0.2°. The same scene kinds as `eval::ais::AisSceneConfig`.
    struct AisSceneConfig {
        ships: usize,
        open_sea: bool,
        bias: Bias,
    }

    /// A generated scene: radar track i is ship i, AIS ship j is ship `owner[j]`.
    struct AisScene {
        radar: Vec<Vec<RadarSample>>,
        ais: Vec<Vec<AisPoint>>,
        owner: Vec<usize>,
    }

    impl AisSceneConfig {
        fn harbour(ships: usize, range: f64, azimuth: f64) -> Self {
            let bias = Bias { range, azimuth };
            Self {
                ships,
                open_sea: false,
                bias,
            }
        }

        fn open_sea(ships: usize, range: f64, azimuth: f64) -> Self {
            let bias = Bias { range, azimuth };
            Self {
                ships,
                open_sea: true,
                bias,
            }
        }

        fn generate(&self, rng: &mut ChaCha8Rng) -> Result<AisScene, std::convert::Infallible> {
            Ok(generated(self.ships, self.open_sea, self.bias, rng))
        }
    }

    fn generated(ships: usize, open_sea: bool, bias: Bias, rng: &mut ChaCha8Rng) -> AisScene {
        let (moored, moving) = if open_sea {
            (0, ships)
        } else {
            (ships * 3 / 5, ships - ships * 3 / 5)
        };
        let (duration, period, sr, sa): (f64, f64, f64, f64) = if open_sea {
            (145.0, 5.0, 50.0, 0.2f64.to_radians())
        } else {
            (1200.0, 2.5, 10.0, 0.1f64.to_radians())
        };
        let (ais_sigma, offset_sigma, without) = if open_sea {
            (0.0, 0.0, 0.0)
        } else {
            (3.0, 5.0, 0.25)
        };
        let no_ais =
            |count: usize, k: usize| k >= count - (count as f64 * without).round() as usize;
        // (start, velocity, carries AIS, moored)
        let mut fleet: Vec<([f64; 2], [f64; 2], bool, bool)> = Vec::new();
        let mut along = 0.0;
        for k in 0..moored {
            along = if k % 12 == 0 {
                0.0
            } else {
                along + rng.random_range(10.0..70.0)
            };
            let p = [3000.0 - 400.0 + along, 5000.0 + 300.0 * (k / 12) as f64];
            fleet.push((p, [0.0, 0.0], !no_ais(moored, k), true));
        }
        let (sea, speed) = if open_sea {
            ([0.0, 20_000.0, 0.0, 20_000.0], (30.0, 80.0))
        } else {
            ([-2000.0, 8000.0, 3000.0, 12_000.0], (2.0, 10.0))
        };
        for k in 0..moving {
            let p = [
                rng.random_range(sea[0]..sea[1]),
                rng.random_range(sea[2]..sea[3]),
            ];
            let v = rng.random_range(speed.0..speed.1);
            let course: f64 = rng.random_range(0.0..std::f64::consts::TAU);
            fleet.push((
                p,
                [v * course.sin(), v * course.cos()],
                !no_ais(moving, k),
                false,
            ));
        }
        let (mut radar, mut ais, mut owner) = (Vec::new(), Vec::new(), Vec::new());
        let scans = (duration / period).floor() as usize;
        for (s, &(p0, v, with_ais, moored)) in fleet.iter().enumerate() {
            let at = |t: f64| [p0[0] + v[0] * t, p0[1] + v[1] * t];
            radar.push(
                (0..=scans)
                    .map(|k| {
                        let t = k as f64 * period;
                        let (r, a) = plane_to_polar(at(t));
                        RadarSample {
                            t,
                            range: r + bias.range + sr * gauss(rng),
                            azimuth: (a + bias.azimuth + sa * gauss(rng))
                                .rem_euclid(std::f64::consts::TAU),
                        }
                    })
                    .collect(),
            );
            if with_ais {
                let interval = if moored { (180.0, 180.0) } else { (2.0, 10.0) };
                let draw = |rng: &mut ChaCha8Rng| {
                    if interval.0 < interval.1 {
                        rng.random_range(interval.0..interval.1)
                    } else {
                        interval.0
                    }
                };
                let offset = [offset_sigma * gauss(rng), offset_sigma * gauss(rng)];
                let mut reports = Vec::new();
                let mut t = rng.random::<f64>() * draw(rng);
                while t <= duration {
                    let p = at(t);
                    reports.push(AisPoint::exact(
                        t,
                        [
                            p[0] + offset[0] + ais_sigma * gauss(rng),
                            p[1] + offset[1] + ais_sigma * gauss(rng),
                        ],
                    ));
                    t += draw(rng);
                }
                ais.push(reports);
                owner.push(s);
            }
        }
        AisScene { radar, ais, owner }
    }

    /// (correct, false, missed) of an outcome against the scene's owners.
    fn score(out: &Outcome, owner: &[usize]) -> (usize, usize, usize) {
        let mut s = (0, 0, 0);
        for (j, &o) in owner.iter().enumerate() {
            match out.associations.iter().find(|a| a.ais == j) {
                Some(a) if a.radar == o => s.0 += 1,
                Some(_) => s.1 += 1,
                None => s.2 += 1,
            }
        }
        s
    }

    /// The search as it was before the ranking (issue 17's "before"):
    /// every in-bound pair-implied bias scored on the full eq. 6 matrix
    /// (sin/cos compensation, `hypot` distances, no screening), the best by
    /// gated pairs then total distance refined. Independent of the
    /// summaries, screens, votes and caps of `search`.
    fn exhaustive(radar: &[Vec<RadarSample>], ais: &[Vec<AisPoint>], cfg: &Config) -> Refined {
        let problem = Problem::new(radar, ais, cfg);
        let cols = ais.len();
        let full = |b: Bias| -> Vec<(usize, usize, f64)> {
            let pos: Vec<Vec<[f64; 2]>> = radar
                .iter()
                .map(|t| {
                    t.iter()
                        .map(|s| {
                            let c = compensate(s, b);
                            polar_to_plane(c.range, c.azimuth)
                        })
                        .collect()
                })
                .collect();
            let mut edges = Vec::new();
            for (i, track) in radar.iter().enumerate() {
                for (j, ship) in ais.iter().enumerate() {
                    let d: Vec<f64> = ship
                        .iter()
                        .filter_map(|r| bracket(track, r.t, cfg.max_gap).map(|bw| (r, bw)))
                        .map(|(r, (a, w))| {
                            let p = at(&pos[i], a, w);
                            (p[0] - r.position[0]).hypot(p[1] - r.position[1])
                        })
                        .collect();
                    if d.len() >= cfg.min_common {
                        let m = d.iter().sum::<f64>() / d.len() as f64;
                        if m < cfg.gate {
                            edges.push((i, j, m));
                        }
                    }
                }
            }
            edges
        };
        let mut best: Option<(usize, f64, Bias)> = None;
        for i in 0..radar.len() {
            for j in 0..cols {
                let r = problem.residuals(i, j);
                if r.len() < cfg.min_common {
                    continue;
                }
                let n = r.len() as f64;
                let b = Bias {
                    range: r.iter().map(|x| x.0[0]).sum::<f64>() / n,
                    azimuth: r.iter().map(|x| x.0[1]).sum::<f64>() / n,
                };
                if b.range.abs() > cfg.max_range_bias || b.azimuth.abs() > cfg.max_azimuth_bias {
                    continue;
                }
                let edges = full(b);
                let pairs = assignment::solve(&edges, cfg.gate);
                let total: f64 = pairs
                    .iter()
                    .map(|p| edges.iter().find(|e| (e.0, e.1) == *p).unwrap().2)
                    .sum();
                if best.is_none_or(|(c, t, _)| pairs.len() > c || (pairs.len() == c && total < t)) {
                    best = Some((pairs.len(), total, b));
                }
            }
        }
        problem.refine(best.unwrap().2)
    }

    /// Issue 17: the ranked search must decide as the exhaustive one on
    /// scenes where that was right (harbour and open sea, several seeds,
    /// small and large biases).
    #[test]
    fn ranked_search_matches_the_exhaustive_search() {
        let cfg = Config {
            seeding: Seeding::Search,
            ..Config::default()
        };
        let mut compared = 0;
        for seed in 0..3u64 {
            for (make, bias) in [
                (
                    AisSceneConfig::harbour(20, 500.0, 0.5f64.to_radians()),
                    500.0,
                ),
                (
                    AisSceneConfig::harbour(20, 3000.0, -1f64.to_radians()),
                    3000.0,
                ),
                (
                    AisSceneConfig::open_sea(12, 2000.0, 1f64.to_radians()),
                    2000.0,
                ),
            ] {
                let scene = make.generate(&mut run_rng(seed, bias as u64)).unwrap();
                let reference = exhaustive(&scene.radar, &scene.ais, &cfg);
                let out = associate(&scene.radar, &scene.ais, &cfg);
                let pairs: Vec<(usize, usize)> =
                    out.associations.iter().map(|a| (a.radar, a.ais)).collect();
                assert_eq!(pairs, reference.pairs, "seed {seed} bias {bias}");
                let (e, r) = (out.estimate.unwrap().bias, reference.estimate.unwrap().bias);
                assert!((e.range - r.range).abs() < 1e-6, "{e:?} {r:?}");
                assert!((e.azimuth - r.azimuth).abs() < 1e-9, "{e:?} {r:?}");
                assert!(out.evaluated <= cfg.max_evaluations);
                compared += 1;
            }
        }
        assert_eq!(compared, 9);
    }

    /// The smaller-side formulation against `assignment::solve` (the square
    /// (s + l)² formulation, itself checked against brute force): on random
    /// sparse problems with continuous costs (a unique optimum) both choose
    /// the same pairs, with the same objective.
    #[test]
    fn gated_solver_matches_the_square_formulation() {
        let mut rng = run_rng(170, 0);
        for case in 0..300 {
            let (rows, cols) = (rng.random_range(1..30), rng.random_range(1..30));
            let density = rng.random_range(0.02..0.9);
            let gate = 100.0;
            let mut edges = Vec::new();
            for i in 0..rows {
                for j in 0..cols {
                    if rng.random_bool(density) {
                        edges.push((i, j, rng.random_range(0.0..1.2 * gate)));
                    }
                }
            }
            let reference = assignment::solve(&edges, gate);
            let got = solve_gated(&edges, rows, cols, gate);
            assert_eq!(got, reference, "case {case}: {rows}x{cols}");
        }
    }

    /// Issue 17's silent failure: a 6 km range bias, past the 5 km bound.
    /// The widened search finds it (and says so); without widening the
    /// result is flagged, never returned as a clean answer.
    #[test]
    fn bias_past_the_bound_is_found_by_widening_or_flagged() {
        let cfg = AisSceneConfig::harbour(48, 6000.0, 1f64.to_radians());
        let scene = cfg.generate(&mut run_rng(17, 6000)).unwrap();
        let out = associate(&scene.radar, &scene.ais, &Config::default());
        let (c, f, m) = score(&out, &scene.owner);
        assert!(out.widened.is_some(), "{:?}", out.widened);
        assert!(c >= 33 && f == 0, "{c}/{f}/{m}");
        let e = out.estimate.unwrap();
        assert!((e.bias.range - 6000.0).abs() < 10.0, "{:?}", e.bias);
        assert!(out.at_bound && !out.inconsistent);

        let fixed = Config {
            widen: false,
            ..Config::default()
        };
        let out = associate(&scene.radar, &scene.ais, &fixed);
        assert!(out.widened.is_none());
        let flagged = out.at_bound || out.inconsistent || out.estimate.is_none();
        assert!(flagged, "{:?} {}", out.estimate, out.inconsistent);
    }

    /// A row of moored ships 300 m apart along one bearing, AIS on the
    /// first three: a bias 300 m larger pairs every AIS ship with the next
    /// track exactly as well, so the result must say it is ambiguous.
    #[test]
    fn periodic_row_is_ambiguous() {
        let ships: Vec<([f64; 2], [f64; 2])> = (0..6)
            .map(|k| ([0.0, 5000.0 + 300.0 * k as f64], [0.0, 0.0]))
            .collect();
        let bias = Bias {
            range: 200.0,
            azimuth: 0.0,
        };
        let (radar, ais) = scene(&ships, &[true, true, true, false, false, false], bias);
        let out = associate(&radar, &ais, &Config::default());
        let alt = out.ambiguous.expect("ambiguous");
        let e = out.estimate.unwrap().bias;
        let shift = (alt.bias.range - e.range).abs();
        assert!((shift / 300.0 - (shift / 300.0).round()).abs() < 1e-6 && shift > 1.0);
        assert_eq!(alt.pairs, 3);
    }

    /// Residuals of σρ = 50 m and σθ = 0.2° against stated errors ten times
    /// smaller are inconsistent; against the true ones they are not (ratio
    /// near 1: each axis's residual over its stated σ has unit variance;
    /// here about 0.82, see below).
    #[test]
    fn residuals_beyond_the_stated_errors_are_inconsistent() {
        // With this crate's own scene generator (the workspace split moved
        // the simulator out), the ratio over seeds 0–29 of this scene is
        // 0.785–0.859 (mean 0.82; one outlier at 2.6, seed 13): the radar
        // track interpolated between scans has less variance than its
        // stated σ. Seed 1 (0.821) is a typical run; the simulator's seed 4
        // was the typical run of the old generator.
        let scene = AisSceneConfig::open_sea(20, 500.0, 0.5f64.to_radians())
            .generate(&mut run_rng(1, 0))
            .unwrap();
        let stated = Config {
            sigma_ais: 0.0001,
            ..Config::default()
        };
        let out = associate(&scene.radar, &scene.ais, &stated);
        let ratio = out.estimate.unwrap().residual_ratio;
        assert!(!out.inconsistent && (0.8..1.25).contains(&ratio), "{ratio}");
        let small = Config {
            sigma_range: 5.0,
            sigma_azimuth: 0.02f64.to_radians(),
            sigma_ais: 1.0,
            ..Config::default()
        };
        let out = associate(&scene.radar, &scene.ais, &small);
        assert!(out.inconsistent, "{:?}", out.estimate);
        assert_eq!(score(&out, &scene.owner), (20, 0, 0));
    }

    #[test]
    fn a_single_ais_report_is_never_associable() {
        let bias = Bias {
            range: 300.0,
            azimuth: 0.0,
        };
        let (radar, mut ais) = scene(&grid_ships(5), &[true; 5], bias);
        ais[2].truncate(1);
        let out = associate(&radar, &ais, &Config::default());
        assert_eq!(out.unassociable_ais, vec![2]);
        assert!(out.associations.iter().all(|a| a.ais != 2));
        assert_eq!(out.associations.len(), 4);
    }

    /// T²(2, ν) in closed form against tabulated F quantiles:
    /// F₀.₉₅(2, 18) = 3.5546 (tables), T² = 2·19/18 · 3.5546 = 7.5041,
    /// over χ²₂ = 5.9915 gives 1.2525; F₀.₉₅(2, 1) = 199.5 gives
    /// 4 · 199.5 / 5.9915 = 133.19.
    #[test]
    fn small_sample_factor_matches_f_tables() {
        assert!((small_sample_factor(19.0) - 1.2525).abs() < 1e-3);
        assert!((small_sample_factor(2.0) - 133.19).abs() < 0.05);
        assert!((small_sample_factor(1e6) - 1.0).abs() < 1e-4);
    }

    /// Whole-second AIS times (NMEA tag blocks truncate): taken at the
    /// middle of their second with σ = 1/√12 s, the bias covariance must
    /// cover the truth over Monte Carlo runs (95 % ellipse, χ²₂ = 5.991);
    /// taken as exact, the azimuth is biased by the fleet's along-track
    /// offsets (½ s × 30–80 m/s).
    #[test]
    fn quantised_ais_times_are_covered_by_the_covariance() {
        let runs = 100;
        let (mut inside, mut nees_sum) = (0, 0.0);
        for run in 0..runs {
            let truth = [500.0, 0.5f64.to_radians()];
            let mut scene = AisSceneConfig::open_sea(20, truth[0], truth[1])
                .generate(&mut run_rng(40, run))
                .unwrap();
            for ship in &mut scene.ais {
                for r in ship.iter_mut() {
                    r.t = r.t.floor() + 0.5;
                    r.time_sigma = quantisation_sigma(1.0);
                }
            }
            let e = associate(&scene.radar, &scene.ais, &Config::default())
                .estimate
                .unwrap();
            let d = [e.bias.range - truth[0], e.bias.azimuth - truth[1]];
            let c = e.covariance;
            let det = c[0][0] * c[1][1] - c[0][1] * c[1][0];
            let nees =
                (c[1][1] * d[0] * d[0] - 2.0 * c[0][1] * d[0] * d[1] + c[0][0] * d[1] * d[1]) / det;
            nees_sum += nees;
            inside += usize::from(nees <= 5.991);
        }
        // Binomial(100, 0.95): 3 standard deviations (2.2 %) below is 88.5 %.
        assert!(inside >= 88, "{inside}/{runs}");
        assert!(nees_sum / runs as f64 <= 2.6, "{}", nees_sum / runs as f64);
    }

    #[test]
    fn noise_free_bias_is_recovered_to_1e_9() {
        let bias = Bias {
            range: 500.0,
            azimuth: 0.5f64.to_radians(),
        };
        let ships = grid_ships(12);
        let (radar, ais) = scene(&ships, &[true; 12], bias);
        for seeding in [Seeding::Cfar, Seeding::Search, Seeding::Auto] {
            let cfg = Config {
                seeding,
                ..Config::default()
            };
            let out = associate(&radar, &ais, &cfg);
            let e = out.estimate.unwrap();
            assert!(
                (e.bias.range - 500.0).abs() < 1e-9,
                "{seeding:?} {:?}",
                e.bias
            );
            assert!((e.bias.azimuth - bias.azimuth).abs() < 1e-12);
            assert_eq!(out.associations.len(), 12);
            assert!(out.associations.iter().all(|a| a.radar == a.ais));
            assert!(out.mean_error_after.unwrap() < 1e-6);
        }
    }

    #[test]
    fn large_range_bias_needs_the_search() {
        // 3 km range bias and 1°: the biased tracks sit closer to their
        // neighbours' AIS than to their own.
        let bias = Bias {
            range: 3000.0,
            azimuth: 1f64.to_radians(),
        };
        let ships = grid_ships(10);
        let mut with = [true; 10];
        with[3] = false;
        with[7] = false;
        let (radar, ais) = scene(&ships, &with, bias);
        let out = associate(&radar, &ais, &Config::default());
        let e = out.estimate.unwrap();
        assert!((e.bias.range - 3000.0).abs() < 1e-9);
        assert_eq!(out.associations.len(), 8);
        // AIS index j belongs to ship with[..] position j.
        let owners: Vec<usize> = (0..10).filter(|&s| with[s]).collect();
        assert!(out.associations.iter().all(|a| owners[a.ais] == a.radar));
    }

    #[test]
    fn one_ship_no_ships_and_ships_without_ais() {
        let bias = Bias {
            range: 200.0,
            azimuth: -0.3f64.to_radians(),
        };
        let one = grid_ships(1);
        let (radar, ais) = scene(&one, &[true], bias);
        let out = associate(&radar, &ais, &Config::default());
        assert_eq!(out.path, Path::BiasSearch);
        assert!((out.estimate.unwrap().bias.range - 200.0).abs() < 1e-9);
        assert_eq!(out.associations.len(), 1);

        let out = associate(&[], &[], &Config::default());
        assert_eq!(out.path, Path::None);
        assert!(out.associations.is_empty() && out.estimate.is_none());

        let (radar, _) = scene(&grid_ships(4), &[false; 4], bias);
        let out = associate(&radar, &[], &Config::default());
        assert_eq!(out.path, Path::None);
        assert!(out.associations.is_empty());
    }

    #[test]
    fn interpolation_never_crosses_long_gaps_or_extrapolates() {
        let s = |t| RadarSample {
            t,
            range: 1.0,
            azimuth: 0.0,
        };
        let track = [s(0.0), s(10.0), s(50.0)];
        assert_eq!(bracket(&track, 5.0, 30.0), Some((0, 0.5)));
        assert_eq!(bracket(&track, 10.0, 30.0), Some((1, 0.0)));
        assert_eq!(bracket(&track, 50.0, 30.0), Some((2, 0.0)));
        assert_eq!(bracket(&track, 20.0, 30.0), None);
        assert_eq!(bracket(&track, 60.0, 30.0), None);
        assert_eq!(bracket(&track, -1.0, 30.0), None);
    }

    /// Tracks share brackets only with tracks whose times are equal bit for
    /// bit (+0 and −0 differ), and every pair's shared brackets are the ones
    /// its own track gives (`walk` run on that track alone), on a harbour
    /// where half the tracks keep the scan times and the rest are moved
    /// by a per-track offset (a plot timed by its azimuth).
    #[test]
    fn time_groups_share_only_identical_brackets() {
        let mut scene = AisSceneConfig::harbour(24, 500.0, 0.5f64.to_radians())
            .generate(&mut run_rng(3, 0))
            .unwrap();
        for (i, track) in scene.radar.iter_mut().enumerate() {
            if i % 2 == 1 {
                let offset = 0.1 * (i % 6) as f64;
                track.iter_mut().for_each(|s| s.t += offset);
            }
        }
        // The first sample at −0: a group of its own (tracks 2 and 4 keep
        // +0; track 6 is moved to −0 and so is track 8, which joins it).
        for i in [6, 8] {
            scene.radar[i][0].t = -0.0;
        }
        let (group, sizes) = time_groups(&scene.radar);
        for a in 0..scene.radar.len() {
            for b in 0..scene.radar.len() {
                let same = scene.radar[a].len() == scene.radar[b].len()
                    && scene.radar[a]
                        .iter()
                        .zip(&scene.radar[b])
                        .all(|(x, y)| x.t.to_bits() == y.t.to_bits());
                assert_eq!(group[a] == group[b], same, "tracks {a} and {b}");
            }
        }
        assert_eq!(sizes.iter().sum::<usize>(), scene.radar.len());
        assert!(sizes.iter().any(|&n| n > 2) && group[6] == group[8] && group[6] != group[2]);

        let cfg = Config::default();
        let problem = Problem::new(&scene.radar, &scene.ais, &cfg);
        let key = |b: &[Bracket]| -> Vec<(u32, u32, u64)> {
            b.iter().map(|b| (b.k, b.a, b.w.to_bits())).collect()
        };
        let mut walked = 0;
        for i in 0..scene.radar.len() {
            for j in 0..scene.ais.len() {
                let own = walk_brackets(&scene.radar[i], &scene.ais[j], cfg.max_gap);
                let ij = i * problem.cols + j;
                assert_eq!(key(problem.walked(ij)), key(&own), "pair {i}, {j}");
                if problem.summary[ij].n > 0 {
                    assert_eq!(problem.summary[ij].n, own.len());
                    assert_eq!(key(problem.brackets(ij)), key(&own));
                    walked += 1;
                }
            }
        }
        assert!(walked > scene.ais.len());
    }
}
