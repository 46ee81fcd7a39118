//! Out-of-sequence plots by retrodiction: a plot older than a track's own
//! time updates the track where it stands, in the sense of Bar-Shalom
//! (Bar-Shalom, Chen and Mallick, "One-step solution for the multistep
//! out-of-sequence-measurement problem in tracking", IEEE TAES 40(1),
//! 2004; per IMM model as in Bar-Shalom and Chen, IEEE TAES 41(1), 2005).
//!
//! Per model j of a track at time k with estimate (x, P) (one model for a
//! single-model track), a plot at d < k, Δ = k − d, F = F_j(Δ) (every model
//! is linear: constant velocity or a turn at a known rate, so F_j(−Δ) =
//! F⁻¹), Q = Q_j(Δ):
//! - the state at d is x(d) = F⁻¹ (x(k) − w), w the process noise over
//!   (d, k]; taking w independent of the estimate's error (the
//!   approximation of Bl1/Cl1, exact when Q = 0), the retrodicted estimate
//!   is x_d = F⁻¹ x, P_d = F⁻¹ (P + Q) F⁻ᵀ, and the cross-covariance of
//!   x(k)'s error with x(d)'s is P F⁻ᵀ;
//! - x(k) given x(d) is then linear Gaussian with gain
//!   G = P F⁻ᵀ P_d⁻¹ = P (P + Q)⁻¹ F, so whatever the plot does to the
//!   retrodicted estimate (the usual update at d: PDA/JPDA weights, the
//!   polar EKF, the IMM's per-model likelihoods) carries to k as
//!   x⁺ = x + G (x_d⁺ − x_d), P⁺ = P − G (P_d − P_d⁺) Gᵀ (the smoother's
//!   identity, valid for any posterior of x(d), a mixture included).
//!
//! The mode probabilities are the update's at d (the plot's likelihood
//! under each model, with the current probabilities as the prior: no
//! mixing backwards). With Q = 0 this is the in-sequence result exactly
//! (a linear Kalman filter's estimate does not depend on the order of its
//! measurements; test below). The cost is one update of the tracks the
//! plot gates with, not a replay of everything after it.

use nalgebra::{DMatrix, DVector};

use crate::error::AlgoError;
use crate::gaussian::{moment_match_into, symmetrize};
use crate::tracking::config::{Motion, MotionModel, NoiseModel, TrackerConfig};
use crate::tracking::predictor::{ModeState, process_noise, transition};
use crate::tracking::track::{Prediction, Track};

/// What carries an update at the plot's time back to the track's time:
/// per model, the gain G and the retrodicted prior (x_d, P_d).
#[derive(Debug, Clone, Default)]
pub(crate) struct Retro {
    parts: Vec<RetroPart>,
}

#[derive(Debug, Clone)]
struct RetroPart {
    gain: DMatrix<f64>,
    x_d: DVector<f64>,
    p_d: DMatrix<f64>,
}

/// The models of a track's modes, in order (the CV model of the
/// configuration for a single-model track).
fn models(cfg: &TrackerConfig, track: &Track) -> Vec<MotionModel> {
    match (&cfg.motion, track.modes.is_empty()) {
        (Motion::Imm(imm), false) => imm.models.clone(),
        _ => vec![MotionModel::ConstantVelocity {
            sigma_a: cfg.sigma_a,
        }],
    }
}

fn sigma_of(model: &MotionModel) -> &[f64; 3] {
    match model {
        MotionModel::ConstantVelocity { sigma_a }
        | MotionModel::CoordinatedTurn { sigma_a, .. } => sigma_a,
    }
}

/// One model's retrodiction of (x, P) at k to d = k − `dt`.
fn retrodict_one(
    model: &MotionModel,
    noise: NoiseModel,
    axes: usize,
    dt: f64,
    x: &DVector<f64>,
    p: &DMatrix<f64>,
) -> Result<RetroPart, AlgoError> {
    let f = transition(model, axes, dt)?;
    let back = transition(model, axes, -dt)?;
    let q = process_noise(axes, dt, sigma_of(model), noise)?;
    let pq = p + &q;
    let mut p_d = &back * &pq * back.transpose();
    symmetrize(&mut p_d);
    // G = P (P + Q)⁻¹ F: (P + Q) Y = P gives Y = (P + Q)⁻¹ P = (P (P + Q)⁻¹)ᵀ.
    let chol = pq.cholesky().ok_or(AlgoError::NotPositiveDefinite {
        what: "retrodicted covariance",
    })?;
    let y = chol.solve(p);
    let gain = y.transpose() * f;
    Ok(RetroPart {
        gain,
        x_d: &back * x,
        p_d,
    })
}

/// `track` (at its time k > `t`) retrodicted to `t` into `out` (its modes
/// at `t` with the current probabilities, and their combination), with
/// what [`carry`] needs.
pub(crate) fn retrodict(
    cfg: &TrackerConfig,
    track: &Track,
    t: f64,
    out: &mut Prediction,
) -> Result<Retro, AlgoError> {
    let dt = track.t - t;
    let models = models(cfg, track);
    let mut parts = Vec::with_capacity(models.len());
    out.modes.clear();
    if track.modes.is_empty() {
        let part = retrodict_one(&models[0], cfg.noise, cfg.axes, dt, &track.x, &track.p)?;
        out.x = part.x_d.clone();
        out.p = part.p_d.clone();
        parts.push(part);
    } else {
        for (model, mode) in models.iter().zip(&track.modes) {
            let part = retrodict_one(model, cfg.noise, cfg.axes, dt, &mode.x, &mode.p)?;
            out.modes.push(ModeState {
                probability: mode.probability,
                x: part.x_d.clone(),
                p: part.p_d.clone(),
            });
            parts.push(part);
        }
        moment_match_into(
            out.modes.iter().map(|m| (m.probability, &m.x, &m.p)),
            &mut out.x,
            &mut out.p,
        );
    }
    Ok(Retro { parts })
}

/// Carries the update at d of the retrodicted modes (`updated`, one mode
/// for a single-model track) to the track at its own time: per model
/// x⁺ = x + G (x_d⁺ − x_d), P⁺ = P − G (P_d − P_d⁺) Gᵀ, the mode
/// probabilities the update's; the combined estimate recomputed.
pub(crate) fn carry(
    track: &mut Track,
    retro: &Retro,
    updated: &[ModeState],
) -> Result<(), AlgoError> {
    let step = |x: &mut DVector<f64>, p: &mut DMatrix<f64>, part: &RetroPart, up: &ModeState| {
        *x += &part.gain * (&up.x - &part.x_d);
        *p -= &part.gain * (&part.p_d - &up.p) * part.gain.transpose();
        symmetrize(p);
    };
    if track.modes.is_empty() {
        let (Some(part), Some(up)) = (retro.parts.first(), updated.first()) else {
            return Ok(());
        };
        step(&mut track.x, &mut track.p, part, up);
    } else {
        for ((mode, part), up) in track.modes.iter_mut().zip(&retro.parts).zip(updated) {
            step(&mut mode.x, &mut mode.p, part, up);
            mode.probability = up.probability;
        }
        let (mut x, mut p) = (DVector::zeros(0), DMatrix::zeros(0, 0));
        moment_match_into(
            track.modes.iter().map(|m| (m.probability, &m.x, &m.p)),
            &mut x,
            &mut p,
        );
        track.x = x;
        track.p = p;
    }
    let finite = track.x.iter().chain(track.p.iter()).all(|v| v.is_finite());
    if !finite || track.p.clone().cholesky().is_none() {
        return Err(AlgoError::NonFinite {
            what: "retrodicted update",
        });
    }
    Ok(())
}

impl Track {
    /// Records a hit older than the track's time (an out-of-sequence
    /// plot): when the plot is older than its radar's last judged sweep
    /// (`behind_sweep`), the miss that sweep judged, if there is one
    /// ([`Track::replace_miss`]), becomes the hit; else one more frame
    /// lived and hit, placed before the trailing misses; the time, last
    /// update and radars of the track kept.
    pub(crate) fn record_late_hit(&mut self, behind_sweep: bool) {
        if behind_sweep && self.replace_miss() {
            return;
        }
        let c = self.consecutive_misses.min(63);
        let low = self.history & ((1u64 << c) - 1);
        self.history = ((self.history >> c) << (c + 1)) | (1u64 << c) | low;
        self.age = self.age.saturating_add(1);
        self.hits = self.hits.saturating_add(1);
    }
}

impl Track {
    /// A hit from a plot older than its radar's last judged sweep: that
    /// sweep judged the track missed before the plot arrived, so the most
    /// recent miss among the last [`REPLACEABLE_FRAMES`] frames becomes
    /// the hit (no frame added). `false` when there is none.
    pub(crate) fn replace_miss(&mut self) -> bool {
        let lived = self.age.min(REPLACEABLE_FRAMES);
        let missed = !self.history & ((1u64 << lived) - 1);
        if missed == 0 {
            return false;
        }
        let bit = missed.trailing_zeros();
        self.history |= 1u64 << bit;
        self.misses = self.misses.saturating_sub(1);
        self.hits = self.hits.saturating_add(1);
        let trailing = self.history.trailing_zeros().min(self.age);
        self.consecutive_misses = self.consecutive_misses.min(trailing);
        true
    }
}

/// How far back (frames) a late hit looks for the miss its radar's sweep
/// judged: a scan of four radars with a few tracks' frames each.
const REPLACEABLE_FRAMES: u32 = 8;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kalman;
    use crate::tracking::track::position_selector;
    use nalgebra::{dmatrix, dvector};

    fn cfg_cv(sigma: f64) -> TrackerConfig {
        let mut cfg = crate::tracking::tests::fig5_config(false);
        cfg.motion = Motion::ConstantVelocity;
        cfg.sigma_a = [sigma, sigma, 0.0];
        cfg
    }

    /// Linear position plots of a CV target, filtered in order and with the
    /// second plot arriving after the third: with no process noise the
    /// Kalman filter's estimate does not depend on the order (information
    /// form: P⁻¹ = P₀⁻¹ + Σ Hᵢᵀ R⁻¹ Hᵢ mapped to k), so retrodiction must
    /// give the in-order result to rounding.
    #[test]
    fn with_no_process_noise_a_late_plot_gives_the_in_order_estimate() {
        let cfg = cfg_cv(0.0);
        let h = position_selector(2, 2);
        let r = dmatrix![100.0, 0.0; 0.0, 400.0];
        let plots = [
            (1.0, dvector![110.0, 48.0]),
            (2.0, dvector![205.0, 103.0]),
            (3.0, dvector![290.0, 152.0]),
        ];
        let start = || {
            Track::fresh(
                1,
                dvector![0.0, 100.0, 0.0, 50.0],
                DMatrix::from_diagonal(&dvector![1e4, 400.0, 1e4, 400.0]),
            )
        };
        let update = |tr: &mut Track, t: f64, z: &DVector<f64>| {
            tr.predict(t, &cfg.sigma_a, cfg.noise).unwrap();
            let u = kalman::update_linear(&tr.x, &tr.p, z, &h, &r).unwrap();
            tr.x = u.x;
            tr.p = u.p;
        };
        let mut in_order = start();
        for (t, z) in &plots {
            update(&mut in_order, *t, z);
        }
        let mut late = start();
        update(&mut late, plots[0].0, &plots[0].1);
        update(&mut late, plots[2].0, &plots[2].1);
        let mut pred = Prediction::default();
        let retro = retrodict(&cfg, &late, plots[1].0, &mut pred).unwrap();
        let u = kalman::update_linear(&pred.x, &pred.p, &plots[1].1, &h, &r).unwrap();
        let up = [ModeState {
            probability: 1.0,
            x: u.x,
            p: u.p,
        }];
        carry(&mut late, &retro, &up).unwrap();
        assert_eq!(late.t, 3.0);
        for i in 0..4 {
            assert!(
                (late.x[i] - in_order.x[i]).abs() < 1e-9,
                "x[{i}]: {} vs {}",
                late.x[i],
                in_order.x[i]
            );
            for j in 0..4 {
                let scale = in_order.p[(i, j)].abs().max(1.0);
                assert!((late.p[(i, j)] - in_order.p[(i, j)]).abs() < 1e-9 * scale);
            }
        }
    }

    /// With process noise the result is an approximation: close to the
    /// in-order one (a few per cent of σ here) and never more confident
    /// than an update that ignored the plot's age would be.
    #[test]
    fn with_process_noise_a_late_plot_is_close_to_the_in_order_estimate() {
        let cfg = cfg_cv(2.0);
        let h = position_selector(2, 2);
        let r = dmatrix![2500.0, 0.0; 0.0, 2500.0];
        let start = || {
            Track::fresh(
                1,
                dvector![0.0, 200.0, 0.0, 0.0],
                DMatrix::from_diagonal(&dvector![2500.0, 400.0, 2500.0, 400.0]),
            )
        };
        let update = |tr: &mut Track, t: f64, z: &DVector<f64>| {
            tr.predict(t, &cfg.sigma_a, cfg.noise).unwrap();
            let u = kalman::update_linear(&tr.x, &tr.p, z, &h, &r).unwrap();
            tr.x = u.x;
            tr.p = u.p;
        };
        let plots: Vec<(f64, DVector<f64>)> = (1..=8)
            .map(|i| {
                let t = i as f64;
                (
                    t,
                    dvector![200.0 * t + 30.0 * (t * 1.7).sin(), 25.0 * (t * 2.3).cos()],
                )
            })
            .collect();
        let mut in_order = start();
        for (t, z) in &plots {
            update(&mut in_order, *t, z);
        }
        // The plot at t = 5 arrives after the one at t = 8.
        let mut late = start();
        for (t, z) in plots.iter().filter(|(t, _)| *t != 5.0) {
            update(&mut late, *t, z);
        }
        let mut pred = Prediction::default();
        let retro = retrodict(&cfg, &late, 5.0, &mut pred).unwrap();
        let u = kalman::update_linear(&pred.x, &pred.p, &plots[4].1, &h, &r).unwrap();
        let up = [ModeState {
            probability: 1.0,
            x: u.x,
            p: u.p,
        }];
        let before = late.p.clone();
        carry(&mut late, &retro, &up).unwrap();
        let sigma = in_order.p[(0, 0)].sqrt();
        assert!(
            (late.x[0] - in_order.x[0]).abs() < 0.2 * sigma,
            "{} vs {} (σ {sigma})",
            late.x[0],
            in_order.x[0]
        );
        // The plot informs: the variance shrinks, and not below the
        // in-order one by more than rounding.
        assert!(late.p[(0, 0)] < before[(0, 0)]);
        assert!(late.p[(0, 0)] > 0.95 * in_order.p[(0, 0)]);
    }

    #[test]
    fn a_late_hit_takes_the_place_of_the_latest_miss() {
        let mut t = Track::fresh(1, dvector![0.0, 0.0], DMatrix::identity(2, 2));
        // hit, miss, miss → 0b100; a late hit replaces the latest miss →
        // 0b101: one consecutive miss... none (the latest frame is the hit).
        t.record(Some(vec![0]));
        t.record(None);
        t.record(None);
        t.record_late_hit(true);
        assert_eq!(t.history & 0b111, 0b101);
        assert_eq!(
            (t.hits, t.misses, t.age, t.consecutive_misses),
            (2, 1, 3, 0)
        );
        // Another: the remaining miss goes.
        t.record_late_hit(true);
        assert_eq!(t.history & 0b111, 0b111);
        assert_eq!(
            (t.hits, t.misses, t.age, t.consecutive_misses),
            (3, 0, 3, 0)
        );
        // None left: a frame is added, a hit.
        t.record_late_hit(true);
        assert_eq!(t.history & 0b1111, 0b1111);
        assert_eq!((t.hits, t.misses, t.age), (4, 0, 4));
    }
}
