//! Time alignment of local tracks to common instants. Seed 000 tests two
//! nodes' estimates of one target at the same time; radars are never
//! synchronised, so their reports must first be brought to shared instants.
//! The batch endpoint and the streaming sessions use this one module.
//!
//! The default is a **fusion-time grid**: instants `epoch + k·period`; at
//! each one, every track is brought from its latest sample at or before the
//! instant (predicted with F and Q over the gap), provided that sample is at
//! most `max_staleness` old. Tracks of radars with any scan phases then meet
//! at every instant. The period and the staleness bound are estimated from
//! the data when not given: a node's scan period is the median interval
//! between consecutive samples of its tracks (robust to dropped scans), the
//! grid period is the longest node period (so that every instant holds a
//! fresh sample of every node, not one sample counted twice), and a node's
//! staleness bound is one and a half of its period (one missed scan makes a
//! track absent instead of stretching a prediction).
//!
//! The older rules stay available: clusters of report times no wider than a
//! tolerance ([`clusters`]) and, for offline batches, linear interpolation.

use nalgebra::{DMatrix, DVector};

use super::scene::Track;
use crate::{AlgoError, motion::MotionModel, small};

/// Staleness bound as a multiple of a node's scan period.
pub const STALENESS_PERIODS: f64 = 1.5;

/// One reported estimate of a local track in canonical order.
#[derive(Debug, Clone, PartialEq)]
pub struct Estimate {
    /// Time of the estimate (s).
    pub t: f64,
    /// State vector.
    pub x: Vec<f64>,
    /// Row-major.
    pub p: Vec<f64>,
    /// The reported I − K H of the update that produced it, row-major.
    pub factor: Option<Vec<f64>>,
}

/// Clusters of sorted times no wider than `tolerance`: (start, end), the
/// instant being the end (the latest time in the cluster).
pub fn clusters(sorted: &[f64], tolerance: f64) -> Vec<(f64, f64)> {
    let mut out: Vec<(f64, f64)> = Vec::new();
    for &t in sorted {
        match out.last_mut() {
            Some((start, end)) if t - *start <= tolerance => *end = t,
            _ => out.push((t, t)),
        }
    }
    out
}

/// The median of positive intervals (the scan period of a node); `None`
/// without any. Reorders `intervals`.
pub fn median_interval(intervals: &mut [f64]) -> Option<f64> {
    if intervals.is_empty() {
        return None;
    }
    let mid = intervals.len() / 2;
    let (_, m, _) = intervals.select_nth_unstable_by(mid, f64::total_cmp);
    Some(*m)
}

/// The first grid point `epoch + k·period` at or after `t`.
pub fn grid_at_or_after(t: f64, period: f64, epoch: f64) -> f64 {
    let k = ((t - epoch) / period).ceil();
    let g = epoch + k * period;
    // Rounding can leave g a hair below t.
    if g < t { epoch + (k + 1.0) * period } else { g }
}

/// The next grid point after `g`, or `None` when the period is below the
/// resolution of the time values (no progress).
pub fn grid_after(g: f64, period: f64, epoch: f64) -> Option<f64> {
    let next = grid_at_or_after(g + period * 0.5, period, epoch);
    (next > g && next.is_finite()).then_some(next)
}

/// The grid instants over sorted sample times: `epoch + k·period` from the
/// first grid point at or after the earliest time to the first at or after
/// the latest, leaving out the stretches where no sample lies within
/// `max_staleness` before the instant (nothing could be present there).
/// `None` when there would be more than `limit` instants, or the period is
/// below the resolution of the times.
pub fn grid_instants(
    sorted: &[f64],
    period: f64,
    epoch: f64,
    max_staleness: f64,
    limit: usize,
) -> Option<Vec<f64>> {
    let (Some(&first), Some(&last)) = (sorted.first(), sorted.last()) else {
        return Some(Vec::new());
    };
    let end = grid_at_or_after(last, period, epoch);
    let mut out = Vec::new();
    let mut g = grid_at_or_after(first, period, epoch);
    let mut i = 0; // samples before index i are at or before g
    while g <= end {
        while i < sorted.len() && sorted[i] <= g {
            i += 1;
        }
        // sorted[i - 1] is the latest sample at or before g (i ≥ 1 here).
        if g - sorted[i - 1] <= max_staleness {
            if out.len() == limit {
                return None;
            }
            out.push(g);
            g = grid_after(g, period, epoch)?;
        } else {
            // Jump to the grid point at or after the next sample.
            g = grid_at_or_after(sorted[i], period, epoch);
        }
    }
    Some(out)
}

/// A state and its row-major covariance.
pub type StateCov = (Vec<f64>, Vec<f64>);

/// Brings `(x, p)` forward by `dt` > 0 with the model; `None` without one
/// (or without a gap): the estimate is used as reported.
pub fn bring(
    model: Option<&dyn MotionModel>,
    x: &[f64],
    p: &[f64],
    dt: f64,
) -> Result<Option<StateCov>, AlgoError> {
    let Some(model) = model.filter(|_| dt > 0.0) else {
        return Ok(None);
    };
    let dim = x.len();
    let (xp, pp) = model.predict(
        &DVector::from_column_slice(x),
        &DMatrix::from_row_slice(dim, dim, p),
        dt,
    )?;
    Ok(Some((xp.as_slice().to_vec(), small::row_major(&pp))))
}

/// I − K H in canonical order, from a gain K (row-major, state × H's rows)
/// whose rows follow the request's state layout (`from_request[i]` is the
/// request's index of canonical component i).
pub fn gain_factor(k_rows: &[f64], h: &DMatrix<f64>, from_request: &[usize]) -> Vec<f64> {
    let dim = from_request.len();
    let m = h.nrows();
    let mut k = DMatrix::zeros(dim, m);
    for (i, &ri) in from_request.iter().enumerate() {
        for j in 0..m {
            k[(i, j)] = k_rows[ri * m + j];
        }
    }
    small::row_major(&(DMatrix::<f64>::identity(dim, dim) - &k * h))
}

/// How an estimate reached an instant.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Placed {
    /// The sample's own time is the instant.
    OnTime,
    /// Predicted (or held, without a model) across a gap.
    Brought,
}

/// Puts `est` at instant `k` (time `t_k` ≥ `est.t`) of `track`, brought
/// forward with the model. `first_use` is false when the same estimate was
/// already placed at an earlier instant: its reported update factor then
/// does not apply again (no new update happened), and I is recorded
/// instead.
pub fn place(
    track: &mut Track,
    k: usize,
    t_k: f64,
    est: &Estimate,
    model: Option<&dyn MotionModel>,
    first_use: bool,
) -> Result<Placed, AlgoError> {
    let dt = t_k - est.t;
    let placed = match bring(model, &est.x, &est.p, dt)? {
        Some((x, p)) => {
            track.set(k, &x, &p);
            Placed::Brought
        }
        None => {
            track.set(k, &est.x, &est.p);
            if dt > 0.0 {
                Placed::Brought
            } else {
                Placed::OnTime
            }
        }
    };
    if let Some(f) = &est.factor {
        if first_use {
            track.set_gain_factor(k, f);
        } else {
            let dim = est.x.len();
            let mut eye = vec![0.0; dim * dim];
            for i in 0..dim {
                eye[i * dim + i] = 1.0;
            }
            track.set_gain_factor(k, &eye);
        }
    }
    Ok(placed)
}

/// What grid alignment did to one track.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct GridStats {
    /// Instants filled by prediction (or holding) across a gap.
    pub brought: usize,
    /// Samples never used (a later one of the same track came before the
    /// next instant).
    pub unused: usize,
    /// Instants after the track's first sample left empty because its
    /// latest sample was older than the staleness bound.
    pub stale: usize,
}

/// Fills `track` at each of `instants` (global indices from `first`) from
/// its time-ordered `samples`: the latest at or before the instant, at most
/// `max_staleness` old. On a prediction error, returns the sample's index.
pub fn fill_grid(
    track: &mut Track,
    samples: &[Estimate],
    instants: &[f64],
    first: usize,
    model: Option<&dyn MotionModel>,
    max_staleness: f64,
) -> Result<GridStats, (usize, AlgoError)> {
    let mut stats = GridStats::default();
    let mut next = 0; // samples before `next` are at or before the instant
    let mut last_used: Option<usize> = None;
    for (i, &t_k) in instants.iter().enumerate() {
        while next < samples.len() && samples[next].t <= t_k {
            next += 1;
        }
        let Some(s) = next.checked_sub(1) else {
            continue;
        };
        if t_k - samples[s].t > max_staleness {
            stats.stale += 1;
            continue;
        }
        let first_use = last_used != Some(s);
        if first_use {
            stats.unused += s - last_used.map_or(0, |u| u + 1);
        }
        let placed =
            place(track, first + i, t_k, &samples[s], model, first_use).map_err(|e| (s, e))?;
        if placed == Placed::Brought {
            stats.brought += 1;
        }
        last_used = Some(s);
    }
    stats.unused += samples.len() - last_used.map_or(0, |u| u + 1);
    Ok(stats)
}

/// Fills `out` at every instant that lies between two samples of the track
/// no more than `max_gap` apart (or on a sample): the state and covariance are
/// interpolated linearly, x = (1 − w) x_a + w x_b, P = (1 − w) P_a + w P_b
/// (a convex combination of positive definite matrices stays positive
/// definite). Never extrapolates. Returns the number of interpolated
/// estimates (those not on a sample).
pub fn interpolate(out: &mut Track, samples: &[Estimate], instants: &[f64], max_gap: f64) -> usize {
    let mut count = 0;
    for (k, &t) in instants.iter().enumerate() {
        // The first sample at or after t.
        let b = samples.partition_point(|s| s.t < t);
        if b < samples.len() && samples[b].t == t {
            out.set(k, &samples[b].x, &samples[b].p);
            continue;
        }
        if b == 0 || b == samples.len() || samples[b].t - samples[b - 1].t > max_gap {
            continue;
        }
        let (sa, sb) = (&samples[b - 1], &samples[b]);
        let w = (t - sa.t) / (sb.t - sa.t);
        let mix = |a: &[f64], b: &[f64]| -> Vec<f64> {
            a.iter()
                .zip(b)
                .map(|(a, b)| (1.0 - w) * a + w * b)
                .collect()
        };
        out.set(k, &mix(&sa.x, &sb.x), &mix(&sa.p, &sb.p));
        count += 1;
    }
    count
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::{ConstantVelocity, ProcessNoise};

    fn est(t: f64, x: f64) -> Estimate {
        Estimate {
            t,
            x: vec![x, 10.0],
            p: vec![1.0, 0.0, 0.0, 1.0],
            factor: None,
        }
    }

    #[test]
    fn the_grid_covers_the_data_and_skips_empty_stretches() {
        // Period 4, epoch 0: data from 1 to 9 → instants 4, 8, 12 (the first
        // grid point at or after the last sample, 9).
        let grid = |t: &[f64], p, e, s| grid_instants(t, p, e, s, 100).unwrap();
        assert_eq!(
            grid(&[1.0, 3.0, 5.0, 9.0], 4.0, 0.0, 6.0),
            vec![4.0, 8.0, 12.0]
        );
        // A gap: samples at 1 and 30 with staleness 6 → 4 (3 s after 1),
        // then nothing until 32 (2 s after 30); 8 … 28 are more than 6 s
        // after 1 and before 30.
        assert_eq!(grid(&[1.0, 30.0], 4.0, 0.0, 6.0), vec![4.0, 32.0]);
        // An epoch shifts the grid; a sample on a grid point is an instant.
        assert_eq!(grid(&[2.0, 6.0], 4.0, 2.0, 6.0), vec![2.0, 6.0]);
        assert_eq!(grid_at_or_after(8.000000000000002, 4.0, 0.0), 12.0);
        // Too many instants, or a period below the times' resolution (the
        // spacing of doubles near 1e15 is 0.125): refused, never a hang.
        let dense: Vec<f64> = (0..=100).map(f64::from).collect();
        assert_eq!(grid_instants(&dense, 1.0, 0.0, 2.0, 50), None);
        assert_eq!(
            grid_instants(&[1e15, 1e15 + 1.0], 0.01, 0.0, 2.0, 1000),
            None
        );
    }

    #[test]
    fn a_median_ignores_a_dropped_scan() {
        let mut v = vec![4.0, 4.1, 8.0, 3.9, 4.0];
        assert_eq!(median_interval(&mut v), Some(4.0));
        assert_eq!(median_interval(&mut []), None);
    }

    #[test]
    fn clusters_are_no_wider_than_the_tolerance() {
        assert_eq!(
            clusters(&[0.0, 0.3, 0.6, 2.0, 2.5], 0.5),
            vec![(0.0, 0.3), (0.6, 0.6), (2.0, 2.5)]
        );
    }

    #[test]
    fn grid_filling_predicts_from_the_latest_sample_within_staleness() {
        // Samples at 1, 5, 9 (x = 10 + 10 t, v = 10); instants 4, 8, 12, 16.
        let samples: Vec<_> = [1.0, 5.0, 9.0]
            .iter()
            .map(|&t| est(t, 10.0 + 10.0 * t))
            .collect();
        let cv = ConstantVelocity::new(1, ProcessNoise::Cwna { q: 0.0 }).unwrap();
        let instants = [4.0, 8.0, 12.0, 16.0];
        let mut track = Track::new(instants.len(), 2);
        let stats = fill_grid(&mut track, &samples, &instants, 0, Some(&cv), 6.0).unwrap();
        // At 4 from 1: x = 20 + 10·3 = 50; at 8 from 5: 60 + 30 = 90; at 12
        // from 9: 100 + 30 = 130; at 16 the sample at 9 is 7 s old > 6.
        assert_eq!(track.x(0, 2), &[50.0, 10.0]);
        assert_eq!(track.x(1, 2), &[90.0, 10.0]);
        assert_eq!(track.x(2, 2), &[130.0, 10.0]);
        assert!(!track.is_present(3));
        // P = F P F' with F = [[1, 3], [0, 1]] and P = I: [[10, 3], [3, 1]].
        assert_eq!(track.p(0, 2), &[10.0, 3.0, 3.0, 1.0]);
        assert_eq!(
            stats,
            GridStats {
                brought: 3,
                unused: 0,
                stale: 1
            }
        );
    }

    #[test]
    fn a_reused_sample_records_no_second_update() {
        let mut s = est(1.0, 0.0);
        s.factor = Some(vec![0.5, 0.0, 0.0, 0.5]);
        let instants = [2.0, 3.0];
        let mut track = Track::new(2, 2);
        let stats = fill_grid(&mut track, &[s], &instants, 0, None, 5.0).unwrap();
        assert_eq!(track.gain_factor(0, 2).unwrap(), &[0.5, 0.0, 0.0, 0.5]);
        assert_eq!(track.gain_factor(1, 2).unwrap(), &[1.0, 0.0, 0.0, 1.0]);
        // Held without a model.
        assert_eq!(track.x(1, 2), &[0.0, 10.0]);
        assert_eq!(stats.brought, 2);
    }

    #[test]
    fn samples_skipped_between_instants_are_counted() {
        // Three samples before the first instant: two are never used.
        let samples: Vec<_> = [1.0, 2.0, 3.0].iter().map(|&t| est(t, 0.0)).collect();
        let mut track = Track::new(1, 2);
        let stats = fill_grid(&mut track, &samples, &[4.0], 0, None, 5.0).unwrap();
        assert_eq!(stats.unused, 2);
    }

    #[test]
    fn gain_factors_follow_the_request_layout() {
        // Request layout [vx, x] (from_request = [1, 0]: canonical x is the
        // request's index 1). K in request rows: vx row 0.2, x row 0.6.
        // H picks x: [1, 0] in canonical order. I − K H with canonical
        // K = [0.6, 0.2]': [[0.4, 0], [-0.2, 1]].
        let h = DMatrix::from_row_slice(1, 2, &[1.0, 0.0]);
        let f = gain_factor(&[0.2, 0.6], &h, &[1, 0]);
        let want = [0.4, 0.0, -0.2, 1.0];
        for (a, b) in f.iter().zip(want) {
            assert!((a - b).abs() < 1e-15, "{f:?}");
        }
    }
}
