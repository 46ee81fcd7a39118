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

use nalgebra::{DMatrix, DVector, SMatrix, SVector};

use crate::error::AlgoError;
use crate::gaussian::moment_match;
use crate::jpda::Association;
use crate::kalman::{self, PositionLayout};
use crate::polar::{MIN_HORIZONTAL_RANGE, PolarMeasurement, azimuth_of, wrap_angle};
use crate::tracking::config::{Plot, RadarSpec};
use crate::tracking::conversion::{CartesianPlot, polar_measurement};
use crate::tracking::height::{HeightMeasurement, pressure_altitude_m, quantisation_variance_m2};
use crate::tracking::predictor::{MIN_PROBABILITY, ModeState};

/// An updater (Stone Soup's `Updater`): a frame's measurements of one
/// kind, with the update of a track's predicted modes (one mode for a
/// single-model track) by the associator's weights. A new measurement
/// model is one more type implementing it.
pub trait Updater {
    /// The Kalman update of (x, P) with measurement `j`, and its
    /// ln N(ν; 0, S).
    fn update_one(
        &self,
        x: &DVector<f64>,
        p: &DMatrix<f64>,
        j: usize,
    ) -> Result<Updated, AlgoError>;

    /// The (IMM) update of `modes` (predicted: probabilities c_j) with the
    /// association `assoc` of the track (module documentation); returns
    /// the combined estimate. With one mode it is the PDA update.
    fn update(
        &self,
        modes: &mut [ModeState],
        assoc: &Association,
    ) -> Result<(DVector<f64>, DMatrix<f64>), AlgoError> {
        update_imm_with(self, modes, assoc)
    }
}

/// One radar's plots, updated by the polar EKF at the radar's site, with
/// the range rate when the radar gives it (Doppler) and the plot has one.
#[derive(Debug, Clone, Copy)]
pub struct PolarUpdater<'a> {
    /// The radar.
    pub radar: &'a RadarSpec,
    /// Where the position lies in the state (a 2D radar measures the
    /// horizontal range).
    pub layout: PositionLayout,
    /// The plots, indexed as in the association.
    pub plots: &'a [Plot],
    /// σ_ṙ when the range rate is measured
    /// ([`crate::tracking::associator::range_rate_sigma`], as the
    /// association decided).
    pub range_rate: Option<f64>,
    /// The Mode C height measurement of a 3D tracker: a plot with a
    /// validated Mode C also updates the track's height, after its polar
    /// update, in every IMM model. Its likelihood does not weigh the
    /// models: they differ vertically only by the noise their horizontal
    /// manoeuvre brings along (the turns' √q = 3 against the straight
    /// model's 1), so a height known to metres would vote for the quietest
    /// vertical model at every update, also in a horizontal turn (seen on
    /// real flights: worse p90 horizontal errors, a track losing a turning
    /// aircraft). Climbs are followed by the state's vertical velocity.
    pub height: Option<HeightMeasurement>,
}

impl PolarUpdater<'_> {
    /// Plot `j`'s Mode C update of a state of `n` (6: a 3D tracker's) in
    /// place (x, P column-major); its likelihood is not used
    /// ([`PolarUpdater::height`]).
    fn height_update(
        &self,
        j: usize,
        n: usize,
        x: &mut [f64],
        p: &mut [f64],
    ) -> Result<(), AlgoError> {
        let Some(m) = &self.height else {
            return Ok(());
        };
        let identity = &self.plots[j].identity;
        if let (Some(h_p), 6) = (pressure_altitude_m(identity), n) {
            m.update(x, p, [0, 2, 4], h_p, quantisation_variance_m2(identity))?;
        }
        Ok(())
    }
}

/// Fused Cartesian plots with their own covariance (and the range rates of
/// the plots moved to the instant, [`CartesianPlot::linearise`]).
#[derive(Debug, Clone, Copy)]
pub struct CartesianUpdater<'a> {
    /// The plots, indexed as in the association.
    pub plots: &'a [CartesianPlot],
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

fn updated(u: kalman::Update) -> Updated {
    let k = u.s.nrows() as f64;
    Updated {
        ln_likelihood: -0.5 * (u.ln_det_s + k * (2.0 * std::f64::consts::PI).ln() + u.nis),
        x: u.x,
        p: u.p,
    }
}

impl Updater for PolarUpdater<'_> {
    fn update_one(
        &self,
        x: &DVector<f64>,
        p: &DMatrix<f64>,
        j: usize,
    ) -> Result<Updated, AlgoError> {
        let plot = &self.plots[j];
        let meas = polar_measurement(self.radar, plot);
        let range_rate = plot.radial_velocity.zip(self.range_rate);
        // The IMM's model states are positive definite by construction
        // (predicted from updated ones): no Cholesky checks of P and P⁺
        // per model and plot.
        let mut out = updated(kalman::update_polar_trusted(
            x,
            p,
            &meas,
            range_rate,
            self.layout,
            self.radar.site,
        )?);
        self.height_update(j, x.len(), out.x.as_mut_slice(), out.p.as_mut_slice())?;
        Ok(out)
    }

    /// On the stack for states of 4 and 6 ([`fixed`]), else on the heap.
    fn update(
        &self,
        modes: &mut [ModeState],
        assoc: &Association,
    ) -> Result<(DVector<f64>, DMatrix<f64>), AlgoError> {
        if let Some(out) = fixed::update_imm(modes, assoc, self)? {
            return Ok(out);
        }
        update_imm_with(self, modes, assoc)
    }
}

impl Updater for CartesianUpdater<'_> {
    fn update_one(
        &self,
        x: &DVector<f64>,
        p: &DMatrix<f64>,
        j: usize,
    ) -> Result<Updated, AlgoError> {
        Ok(updated(self.plots[j].update(x, p)?))
    }
}

/// [`Updater::update`] on heap matrices over [`Updater::update_one`]
/// (any state and measurement).
fn update_imm_with<U: Updater + ?Sized>(
    updater: &U,
    modes: &mut [ModeState],
    assoc: &Association,
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
                .map(|&(j, _)| updater.update_one(&mode.x, &mode.p, j))
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

/// The IMM update on the stack for the hot case: a radar's polar plots
/// (range, azimuth, elevation of a 3D radar, range rate of a Doppler
/// radar) and states of 4 or 6 in the interleaved layout. The arithmetic
/// of the heap path (the EKF of `kalman::update_polar_trusted`: Joseph
/// form, Cholesky of S; the same weights and moment matching), with the
/// sums of the matrix products in another order.
mod fixed {
    use super::*;

    /// The most detected plots a track's update holds on the stack before
    /// falling back to the heap path.
    const MAX_PLOTS: usize = 8;
    const MAX_MODES: usize = 8;

    use crate::gaussian::symmetrize_fixed as sym;

    type Upd<const N: usize> = (SVector<f64, N>, SMatrix<f64, N, N>, f64);

    /// The combined estimate, or `None` where the stack path does not
    /// apply.
    type Combined = Option<(DVector<f64>, DMatrix<f64>)>;

    pub(super) fn update_imm(
        modes: &mut [ModeState],
        assoc: &Association,
        measurements: &PolarUpdater<'_>,
    ) -> Result<Combined, AlgoError> {
        let PolarUpdater {
            radar,
            layout,
            range_rate,
            ..
        } = measurements;
        let n = modes.first().map_or(0, |m| m.x.len());
        let standard = layout.x == 0 && layout.y == 2 && layout.z.is_none_or(|z| z == 4);
        if !standard || modes.len() > MAX_MODES {
            return Ok(None);
        }
        let with_el = radar.sigma_elevation.is_some() && layout.z.is_some();
        let with_rr = range_rate.is_some();
        let m = 2 + usize::from(with_el) + usize::from(with_rr);
        match (n, m) {
            (4, 2) => run::<4, 2>(modes, assoc, measurements),
            (4, 3) => run::<4, 3>(modes, assoc, measurements),
            (6, 2) => run::<6, 2>(modes, assoc, measurements),
            (6, 3) => run::<6, 3>(modes, assoc, measurements),
            (6, 4) => run::<6, 4>(modes, assoc, measurements),
            _ => Ok(None),
        }
    }

    fn run<const N: usize, const M: usize>(
        modes: &mut [ModeState],
        assoc: &Association,
        measurements: &PolarUpdater<'_>,
    ) -> Result<Combined, AlgoError> {
        let PolarUpdater {
            radar,
            layout,
            plots,
            range_rate,
            ..
        } = measurements;
        if modes
            .iter()
            .any(|m| m.x.len() != N || m.p.shape() != (N, N))
        {
            return Ok(None);
        }
        let detected: Vec<(usize, f64)> = assoc
            .measurements
            .iter()
            .copied()
            .filter(|&(_, b)| b > 0.0)
            .collect();
        let with_el = M - 2 - usize::from(range_rate.is_some()) == 1;
        if detected.len() > MAX_PLOTS
            || detected
                .iter()
                .any(|&(j, _)| plots[j].elevation.is_some() != with_el)
        {
            return Ok(None);
        }
        let r = modes.len();
        let mut xs = [SVector::<f64, N>::zeros(); MAX_MODES];
        let mut ps = [SMatrix::<f64, N, N>::zeros(); MAX_MODES];
        for (i, m) in modes.iter().enumerate() {
            xs[i] = SVector::from_column_slice(m.x.as_slice());
            ps[i] = SMatrix::from_column_slice(m.p.as_slice());
        }
        // Per model, per detected plot: the update and ln L.
        let mut ups = [[(
            SVector::<f64, N>::zeros(),
            SMatrix::<f64, N, N>::zeros(),
            0.0,
        ); MAX_PLOTS]; MAX_MODES];
        for j in 0..r {
            for (k, &(plot, _)) in detected.iter().enumerate() {
                let meas = polar_measurement(radar, &plots[plot]);
                let rr = plots[plot].radial_velocity.zip(*range_rate);
                let mut up =
                    polar::<N, M>(&xs[j], &ps[j], &meas, rr, layout.z.is_some(), radar.site)?;
                measurements.height_update(plot, N, up.0.as_mut_slice(), up.1.as_mut_slice())?;
                ups[j][k] = up;
            }
        }
        // w_jm = β_m exp(ln c_j + ln L_jm − ln Σ_i c_i L_im).
        let mut w = [[0.0; MAX_PLOTS]; MAX_MODES];
        for (k, &(_, beta)) in detected.iter().enumerate() {
            let mut ln = [0.0; MAX_MODES];
            for j in 0..r {
                ln[j] = modes[j].probability.ln() + ups[j][k].2;
            }
            let top = ln[..r].iter().copied().fold(f64::NEG_INFINITY, f64::max);
            let sum: f64 = ln[..r].iter().map(|v| (v - top).exp()).sum();
            for j in 0..r {
                w[j][k] = beta * (ln[j] - top).exp() / sum;
            }
        }
        let d = detected.len();
        let beta0 = assoc.miss.max(0.0);
        let mut mu = [0.0; MAX_MODES];
        for j in 0..r {
            mu[j] =
                (beta0 * modes[j].probability + w[j][..d].iter().sum::<f64>()).max(MIN_PROBABILITY);
        }
        let total: f64 = mu[..r].iter().sum();
        for (j, mode) in modes.iter_mut().enumerate() {
            let own = beta0 * mode.probability;
            let scale = own + w[j][..d].iter().sum::<f64>();
            if scale > 0.0 && d > 0 {
                // Moment match of the prediction and the per-plot updates.
                let parts = || {
                    std::iter::once((own / scale, &xs[j], &ps[j])).chain(
                        ups[j][..d]
                            .iter()
                            .zip(&w[j][..d])
                            .map(move |(u, &wm)| (wm / scale, &u.0, &u.1)),
                    )
                };
                let mut x = SVector::<f64, N>::zeros();
                for (wt, xi, _) in parts() {
                    x.axpy(wt, xi, 1.0);
                }
                let mut p = SMatrix::<f64, N, N>::zeros();
                for (wt, xi, pi) in parts() {
                    let dv = xi - x;
                    p += pi * wt;
                    p.ger(wt, &dv, &dv, 1.0);
                }
                sym(&mut p);
                xs[j] = x;
                ps[j] = p;
            }
            mode.probability = mu[j] / total;
            if xs[j].iter().any(|v| !v.is_finite()) || !mode.probability.is_finite() {
                return Err(AlgoError::NonFinite {
                    what: "updated state",
                });
            }
            mode.x.as_mut_slice().copy_from_slice(xs[j].as_slice());
            mode.p.as_mut_slice().copy_from_slice(ps[j].as_slice());
        }
        let mut xb = SVector::<f64, N>::zeros();
        for (j, mode) in modes.iter().enumerate() {
            xb.axpy(mode.probability, &xs[j], 1.0);
        }
        let mut pb = SMatrix::<f64, N, N>::zeros();
        for (j, mode) in modes.iter().enumerate() {
            let dv = xs[j] - xb;
            pb += ps[j] * mode.probability;
            pb.ger(mode.probability, &dv, &dv, 1.0);
        }
        sym(&mut pb);
        Ok(Some((
            DVector::from_column_slice(xb.as_slice()),
            DMatrix::from_column_slice(N, N, pb.as_slice()),
        )))
    }

    /// The polar EKF update of (x, P) (`kalman::update_polar_trusted` on
    /// the stack) and its ln N(ν; 0, S).
    fn polar<const N: usize, const M: usize>(
        x: &SVector<f64, N>,
        p: &SMatrix<f64, N, N>,
        meas: &PolarMeasurement,
        range_rate: Option<(f64, f64)>,
        has_z: bool,
        site: [f64; 3],
    ) -> Result<Upd<N>, AlgoError> {
        meas.validate()?;
        let cols = [0usize, 2, 4];
        let axes = if has_z { 3 } else { 2 };
        let rel = [
            x[0] - site[0],
            x[2] - site[1],
            if has_z { x[4] - site[2] } else { 0.0 },
        ];
        let [e, n, u] = rel;
        let rho2 = e * e + n * n;
        let rho = rho2.sqrt();
        if rho.is_nan() || rho < MIN_HORIZONTAL_RANGE {
            return Err(AlgoError::DegenerateGeometry {
                what: "target position",
                reason: "target at or directly above/below the radar site, azimuth undefined",
            });
        }
        let r2 = rho2 + u * u;
        let rg = r2.sqrt();
        let mut h = SMatrix::<f64, M, N>::zeros();
        let mut nu = SVector::<f64, M>::zeros();
        let mut rd = SVector::<f64, M>::zeros();
        let jr = [e / rg, n / rg, u / rg];
        let ja = [n / rho2, -e / rho2, 0.0];
        for k in 0..axes {
            h[(0, cols[k])] = jr[k];
            h[(1, cols[k])] = ja[k];
        }
        nu[0] = meas.range - rg;
        nu[1] = wrap_angle(meas.azimuth - azimuth_of(e, n));
        rd[0] = meas.sigma_range * meas.sigma_range;
        rd[1] = meas.sigma_azimuth * meas.sigma_azimuth;
        let mut row = 2;
        if let (Some(el), Some(sel), true) = (meas.elevation, meas.sigma_elevation, has_z) {
            if row < M {
                let je = [-e * u / (r2 * rho), -n * u / (r2 * rho), rho / r2];
                for k in 0..3 {
                    h[(row, cols[k])] = je[k];
                }
                nu[row] = el - u.atan2(rho);
                rd[row] = sel * sel;
                row += 1;
            }
        }
        if let Some((v, sigma)) = range_rate {
            if row < M {
                let vel = [x[1], x[3], if has_z { x[5] } else { 0.0 }];
                let rdot = (0..3).map(|k| rel[k] * vel[k]).sum::<f64>() / rg;
                for k in 0..axes {
                    h[(row, cols[k])] = vel[k] / rg - rdot * rel[k] / r2;
                    h[(row, cols[k] + 1)] = rel[k] / rg;
                }
                nu[row] = v - rdot;
                rd[row] = sigma * sigma;
                row += 1;
            }
        }
        if row != M || nu.iter().any(|v| !v.is_finite()) {
            return Err(AlgoError::NonFinite { what: "innovation" });
        }
        let hp = h * p;
        let mut s = hp * h.transpose();
        for i in 0..M {
            s[(i, i)] += rd[i];
        }
        sym(&mut s);
        let chol = s.cholesky().ok_or(AlgoError::NotPositiveDefinite {
            what: "innovation covariance",
        })?;
        let gain = chol.solve(&hp).transpose();
        let x_new = x + gain * nu;
        let i_kh = SMatrix::<f64, N, N>::identity() - gain * h;
        let mut kr = gain;
        for j in 0..M {
            for i in 0..N {
                kr[(i, j)] *= rd[j];
            }
        }
        let mut p_new = i_kh * p * i_kh.transpose() + kr * gain.transpose();
        sym(&mut p_new);
        if x_new.iter().chain(p_new.iter()).any(|v| !v.is_finite()) {
            return Err(AlgoError::NonFinite {
                what: "updated state",
            });
        }
        let l = chol.l();
        let w = l
            .solve_lower_triangular(&nu)
            .ok_or(AlgoError::NotPositiveDefinite {
                what: "innovation covariance",
            })?;
        let nis = w.norm_squared();
        let ln_det: f64 = (0..M).map(|i| 2.0 * l[(i, i)].ln()).sum();
        let ln_likelihood = -0.5 * (ln_det + M as f64 * (2.0 * std::f64::consts::PI).ln() + nis);
        Ok((x_new, p_new, ln_likelihood))
    }

    #[cfg(test)]
    mod tests {
        use super::*;
        use crate::tracking::config::{Imm, NoiseModel, RadarSpec};
        use crate::tracking::predictor::predict_imm;

        /// The stack update equals the heap update to rounding: 2D and 3D
        /// radars, with and without range rate, one and two plots.
        #[test]
        fn the_stack_update_is_the_heap_update_to_rounding() {
            let imm = Imm::aircraft();
            for (axes, three_d, doppler) in [
                (2, false, false),
                (2, false, true),
                (3, false, false),
                (3, true, false),
                (3, true, true),
            ] {
                let n = 2 * axes;
                let radar = RadarSpec {
                    site: [1000.0, -2000.0, 50.0],
                    sigma_range: 50.0,
                    sigma_azimuth: 0.1f64.to_radians(),
                    sigma_elevation: three_d.then_some(0.2f64.to_radians()),
                    sigma_radial_velocity: doppler.then_some(1.5),
                    scan_period: 4.0,
                    detection_probability: 0.9,
                    clutter_density: 1e-9,
                };
                let x =
                    DVector::from_fn(n, |i, _| [30_000.0, -150.0, 40_000.0, 90.0, 8000.0, 2.0][i]);
                let p = DMatrix::from_fn(n, n, |i, k| {
                    if i == k {
                        [400.0, 100.0][i % 2]
                    } else if i / 2 == k / 2 {
                        60.0
                    } else {
                        0.0
                    }
                });
                let mut modes: Vec<ModeState> = imm
                    .initial_probabilities
                    .iter()
                    .map(|&probability| ModeState {
                        probability,
                        x: x.clone(),
                        p: p.clone(),
                    })
                    .collect();
                predict_imm(&imm, NoiseModel::Cwna, &mut modes, 3.0).unwrap();
                let plot = |dr: f64, daz: f64| Plot {
                    radar: 0,
                    t: 3.0,
                    range: 50_100.0 + dr,
                    azimuth: (29_000.0f64 - 1000.0).atan2(40_300.0 + 2000.0) + daz,
                    elevation: three_d.then_some(0.16),
                    radial_velocity: doppler.then_some(-30.0),
                    identity: Default::default(),
                    report: None,
                };
                let plots = [plot(0.0, 0.0), plot(80.0, 0.002)];
                let layout = if three_d && axes == 3 {
                    PositionLayout::CV_3D
                } else {
                    PositionLayout::CV_2D
                };
                let m = PolarUpdater {
                    radar: &radar,
                    layout,
                    plots: &plots,
                    range_rate: radar.sigma_radial_velocity,
                    height: None,
                };
                for assoc in [
                    Association {
                        miss: 0.2,
                        measurements: vec![(0, 0.8)],
                    },
                    Association {
                        miss: 0.1,
                        measurements: vec![(0, 0.6), (1, 0.3)],
                    },
                ] {
                    let (mut a, mut b) = (modes.clone(), modes.clone());
                    let (xa, pa) = update_imm(&mut a, &assoc, &m).unwrap().expect("stack path");
                    let (xb, pb) = update_imm_with(&m, &mut b, &assoc).unwrap();
                    let close = |u: &[f64], v: &[f64]| {
                        u.iter()
                            .zip(v)
                            .all(|(p, q)| (p - q).abs() <= 1e-9 * p.abs().max(q.abs()).max(1.0))
                    };
                    assert!(
                        close(xa.as_slice(), xb.as_slice()),
                        "{axes} {three_d} {doppler}"
                    );
                    assert!(
                        close(pa.as_slice(), pb.as_slice()),
                        "{axes} {three_d} {doppler}"
                    );
                    for (ma, mb) in a.iter().zip(&b) {
                        assert!((ma.probability - mb.probability).abs() < 1e-12);
                        assert!(close(ma.x.as_slice(), mb.x.as_slice()));
                    }
                }
            }
        }
    }
}
