//! The updater of the tracker: per-measurement Kalman updates of a track's
//! Gaussian (the polar EKF of a radar's plots, or the linear update of a
//! fused Cartesian plot) with each measurement's likelihood, and the IMM
//! update that combines them with the association's weights.
//!
//! The association decides β_0 (no plot is the target's) and β_m for the
//! gated plots m of a track from its combined prediction (the moment-matched
//! Gaussian of the IMM mixture: one Gaussian per track keeps exact JPDA,
//! its cluster guard, AMSJPDA, NN and GNN unchanged, and its gate covers
//! every model's spread). Each model j then weighs the association events
//! with its own likelihood L_jm = N(ν_jm; 0, S_jm) and its predicted mode
//! probability c_j: the joint weight of (model j, plot m) is
//! w_jm = β_m c_j L_jm / Σ_i c_i L_im, of (model j, no plot) w_j0 = β_0 c_j.
//! So the updated mode probability is μ_j = w_j0 + Σ_m w_jm (Σ_j μ_j = 1),
//! and model j's state is the mixture of its prediction and its
//! per-plot updates with weights w_j·/μ_j, moment matched. With β from a
//! hard assignment (NN, GNN) this is the standard IMM update, μ_j ∝ c_j
//! L_jm; with one model it is the PDA update of eqs. 6–7.

use nalgebra::{DMatrix, DVector};

use crate::error::AlgoError;
use crate::gaussian::moment_match;
use crate::jpda::Association;
use crate::kalman::{self, PositionLayout};
use crate::tracking::config::{Plot, RadarSpec};
use crate::tracking::conversion::{CartesianPlot, polar_measurement};
use crate::tracking::predictor::{MIN_PROBABILITY, ModeState};

/// The measurements of one frame as the updater sees them.
#[derive(Debug, Clone, Copy)]
pub enum Measurements<'a> {
    /// One radar's plots, updated by the polar EKF at the radar's site,
    /// with the range rate when the radar gives it (Doppler) and the plot
    /// has one.
    Polar {
        /// The radar.
        radar: &'a RadarSpec,
        /// Where the position lies in the state (a 2D radar measures the
        /// horizontal range).
        layout: PositionLayout,
        /// The plots, indexed as in the association.
        plots: &'a [Plot],
        /// σ_ṙ when the range rate is measured
        /// ([`crate::tracking::associator::range_rate_sigma`], as the
        /// association decided).
        range_rate: Option<f64>,
    },
    /// Fused Cartesian plots with their own covariance (and the range rates
    /// of the plots moved to the instant, [`CartesianPlot::linearise`]).
    Cartesian {
        /// The plots, indexed as in the association.
        plots: &'a [CartesianPlot],
    },
}

/// A per-measurement update and its log-likelihood ln N(ν; 0, S).
#[derive(Debug, Clone)]
pub struct Updated {
    /// Updated state.
    pub x: DVector<f64>,
    /// Updated covariance.
    pub p: DMatrix<f64>,
    /// ln N(ν; 0, S).
    pub ln_likelihood: f64,
}

impl Measurements<'_> {
    /// The Kalman update of (x, P) with measurement `j`.
    pub fn update(
        &self,
        x: &DVector<f64>,
        p: &DMatrix<f64>,
        j: usize,
    ) -> Result<Updated, AlgoError> {
        let u = match self {
            Measurements::Polar {
                radar,
                layout,
                plots,
                range_rate,
            } => {
                let plot = &plots[j];
                let meas = polar_measurement(radar, plot);
                let range_rate = plot.radial_velocity.zip(*range_rate);
                // The IMM's model states are positive definite by
                // construction (predicted from updated ones): no Cholesky
                // checks of P and P⁺ per model and plot.
                kalman::update_polar_trusted(x, p, &meas, range_rate, *layout, radar.site)?
            }
            Measurements::Cartesian { plots } => plots[j].update(x, p)?,
        };
        let k = u.s.nrows() as f64;
        let ln_det = u.ln_det_s;
        Ok(Updated {
            x: u.x,
            p: u.p,
            ln_likelihood: -0.5 * (ln_det + k * (2.0 * std::f64::consts::PI).ln() + u.nis),
        })
    }
}

/// The IMM update of `modes` (predicted: probabilities c_j) with the
/// association `assoc` of the track (module documentation); returns the
/// combined estimate.
pub fn update_imm(
    modes: &mut [ModeState],
    assoc: &Association,
    measurements: &Measurements<'_>,
) -> Result<(DVector<f64>, DMatrix<f64>), AlgoError> {
    let detected: Vec<(usize, f64)> = assoc
        .measurements
        .iter()
        .copied()
        .filter(|&(_, b)| b > 0.0)
        .collect();
    let r = modes.len();
    // Per model, per detected plot: the update and ln(c_j L_jm).
    let mut updates: Vec<Vec<Updated>> = Vec::with_capacity(r);
    for mode in modes.iter() {
        updates.push(
            detected
                .iter()
                .map(|&(j, _)| measurements.update(&mode.x, &mode.p, j))
                .collect::<Result<_, _>>()?,
        );
    }
    // w_jm = β_m exp(ln c_j + ln L_jm − ln Σ_i c_i L_im), by log-sum-exp.
    let mut w = vec![vec![0.0; detected.len()]; r];
    for (m, &(_, beta)) in detected.iter().enumerate() {
        let ln: Vec<f64> = (0..r)
            .map(|j| modes[j].probability.ln() + updates[j][m].ln_likelihood)
            .collect();
        let top = ln.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let sum: f64 = ln.iter().map(|v| (v - top).exp()).sum();
        for j in 0..r {
            w[j][m] = beta * (ln[j] - top).exp() / sum;
        }
    }
    let beta0 = assoc.miss.max(0.0);
    let mut mu: Vec<f64> = (0..r)
        .map(|j| beta0 * modes[j].probability + w[j].iter().sum::<f64>())
        .collect();
    for v in &mut mu {
        *v = v.max(MIN_PROBABILITY);
    }
    let total: f64 = mu.iter().sum();
    for (j, mode) in modes.iter_mut().enumerate() {
        let mu_j = mu[j] / total;
        let own = beta0 * mode.probability;
        let scale = own + w[j].iter().sum::<f64>();
        if scale > 0.0 && !detected.is_empty() {
            let parts = std::iter::once((own / scale, &mode.x, &mode.p)).chain(
                updates[j]
                    .iter()
                    .zip(&w[j])
                    .map(|(u, &wm)| (wm / scale, &u.x, &u.p)),
            );
            let (x, p) = moment_match(parts);
            mode.x = x;
            mode.p = p;
        }
        mode.probability = mu_j;
    }
    if modes
        .iter()
        .any(|m| m.x.iter().any(|v| !v.is_finite()) || !m.probability.is_finite())
    {
        return Err(AlgoError::NonFinite {
            what: "updated state",
        });
    }
    Ok(moment_match(
        modes.iter().map(|m| (m.probability, &m.x, &m.p)),
    ))
}
