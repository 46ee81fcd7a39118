//! Time alignment by interpolation (§2.2): where each AIS report falls in a
//! radar track (brackets, walked in one pass), what one pass over a pair's
//! common instants tells (`Summary`), and the bearing sectors that rule
//! pairs out before any distance is computed.

use std::collections::HashMap;

use super::{AisPoint, Bias, RadarSample};
use crate::polar::wrap_angle;

/// Where AIS report k of ship j falls in radar track i: samples a and a + 1
/// with weight w of a + 1 (w = 0 when the time is a sample's own).
#[derive(Debug, Clone, Copy)]
pub(super) struct Bracket {
    pub(super) k: u32,
    pub(super) a: u32,
    pub(super) w: f64,
}

/// What one pass over a pair's common instants tells (raw radar data).
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Summary {
    /// Common instants (0 when fewer than `min_common`).
    pub(super) n: usize,
    /// Eq. 6 mean distance.
    pub(super) distance: f64,
    /// Implied bias: mean range residual and circular mean azimuth residual.
    pub(super) range: f64,
    pub(super) azimuth: f64,
    /// Means of ρ_a sin δ and ρ_a cos δ over the instants (δ the azimuth
    /// residual, ρ_a the AIS range) and the mean AIS range.
    pub(super) sin: f64,
    pub(super) cos: f64,
    pub(super) rho: f64,
    /// Variance of the range plus cross-range residuals (m²).
    pub(super) spread: f64,
}

impl Summary {
    /// Lower bounds of the pair's mean distance under bias `h` (with
    /// `sc` = (sin, cos) of its azimuth): along range |mean range residual −
    /// Δρ| (up to the interpolation chord), and across it |mean ρ_a sin(δ −
    /// Δθ)|, since a point is at least ρ_a |sin| from the other's bearing
    /// line and compensation turns every sample, so every interpolated
    /// point, by Δθ.
    pub(super) fn offsets(&self, h: Bias, sc: (f64, f64)) -> (f64, f64) {
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
pub(super) struct Sector {
    centre: f64,
    pub(super) half: f64,
    min_range: f64,
    pub(super) lo: [f64; 2],
    hi: [f64; 2],
}

impl Sector {
    pub(super) fn of(points: &[[f64; 2]]) -> Self {
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
    pub(super) fn apart(&self, ais: &Sector, outer: f64, reach: f64) -> bool {
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
    pub(super) fn distance(&self, other: &Sector) -> f64 {
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
pub(super) fn walk(
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
pub(super) fn walk_brackets(
    track: &[RadarSample],
    ship: &[AisPoint],
    max_gap: f64,
) -> Vec<Bracket> {
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
pub(super) fn time_groups(radar: &[Vec<RadarSample>]) -> (Vec<usize>, Vec<usize>) {
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
pub(super) fn at(pos: &[[f64; 2]], a: usize, w: f64) -> [f64; 2] {
    let p = pos[a];
    if w == 0.0 {
        return p;
    }
    let q = pos[a + 1];
    [p[0] + w * (q[0] - p[0]), p[1] + w * (q[1] - p[1])]
}

pub(super) fn dist(p: [f64; 2], q: [f64; 2]) -> f64 {
    ((p[0] - q[0]) * (p[0] - q[0]) + (p[1] - q[1]) * (p[1] - q[1])).sqrt()
}
