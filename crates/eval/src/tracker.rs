//! Local trackers of the distributed experiments: one Kalman filter per
//! target per node, in Cartesian coordinates, as seed 000 §5.1 prescribes.
//!
//! Each plot is converted to a local position `[x, y]` with the covariance of
//! eqs. 27–28 ([`algo::polar::plot_to_local`], which calls
//! `polar_covariance_2d`); the first two plots initialise the track by eqs.
//! 29–30 ([`algo::polar::two_point_init`]); then every scan predicts
//! with the eq. 24 transition and the eq. 26 process noise built from the
//! *estimated* velocity (the paper: "the law of the process noise is known
//! and formed from the estimated velocity"), and updates with H of eq. 25
//! ([`algo::kalman::update_linear`], Joseph form). Plot-to-track
//! association is assumed correct, as in the paper.

use nalgebra::{DMatrix, DVector};

use super::SimError;
use super::sensor::{Plot, Radar};
use algo::kalman;
use algo::motion::{ConstantVelocity, MotionModel, ProcessNoise};
use algo::polar::{plot_to_local, two_point_init};

/// What a node reports for one track at one scan.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackEstimate {
    /// Time of the estimate (s).
    pub t: f64,
    /// State estimate `[x, vx, y, vy]` (m, m/s).
    pub x: DVector<f64>,
    /// Its covariance (4x4).
    pub p: DMatrix<f64>,
    /// The Kalman gain K (4x2) of the update that produced it, when the
    /// tracker was asked to keep gains; `None` at initialisation.
    pub gain: Option<DMatrix<f64>>,
}

/// A Kalman filter for one target seen by one 2D radar.
#[derive(Debug, Clone)]
pub struct LocalKalman {
    site: [f64; 3],
    sigma_range: f64,
    sigma_azimuth: f64,
    model: ConstantVelocity,
    keep_gain: bool,
    first: Option<(f64, [f64; 2])>,
    current: Option<TrackEstimate>,
}

/// Measurement matrix of seed 000 eq. 25: position from `[x, vx, y, vy]`.
pub fn position_h() -> DMatrix<f64> {
    DMatrix::from_row_slice(2, 4, &[1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0])
}

impl LocalKalman {
    /// A filter for plots of `radar` with process-noise factor `noise_factor`
    /// (eq. 26, 0.05 in the paper); `keep_gain` makes estimates carry K.
    pub fn new(radar: &Radar, noise_factor: f64, keep_gain: bool) -> Result<Self, SimError> {
        Ok(Self {
            site: radar.site,
            sigma_range: radar.sigma_range,
            sigma_azimuth: radar.sigma_azimuth,
            model: ConstantVelocity::new(
                2,
                ProcessNoise::VelocityProportional {
                    factor: noise_factor,
                },
            )?,
            keep_gain,
            first: None,
            current: None,
        })
    }

    /// The latest estimate, if the track is initialised.
    pub fn estimate(&self) -> Option<&TrackEstimate> {
        self.current.as_ref()
    }

    /// The motion model the filter predicts with.
    pub fn model(&self) -> &ConstantVelocity {
        &self.model
    }

    /// Processes the plot of this track's target: stores the first plot,
    /// initialises on the second (eqs. 29–30), then predicts and updates.
    /// Returns the estimate after the plot, `None` while not initialised.
    pub fn process(&mut self, plot: &Plot) -> Result<Option<&TrackEstimate>, SimError> {
        let meas = algo::PolarMeasurement {
            range: plot.range,
            azimuth: plot.azimuth,
            elevation: None,
            sigma_range: self.sigma_range,
            sigma_azimuth: self.sigma_azimuth,
            sigma_elevation: None,
        };
        let z = plot_to_local(self.site, &meas)?;
        let (zmean, r) = z.into_parts();
        let zxy = [zmean[0], zmean[1]];
        match (&self.current, self.first) {
            (None, None) => {
                self.first = Some((plot.t, zxy));
                return Ok(None);
            }
            (None, Some((t0, z0))) => {
                let g = two_point_init(z0, zxy, &r, plot.t - t0)?;
                let (x, p) = g.into_parts();
                self.current = Some(TrackEstimate {
                    t: plot.t,
                    x,
                    p,
                    gain: None,
                });
            }
            (Some(est), _) => {
                let dt = plot.t - est.t;
                let (xp, pp) = self.model.predict(&est.x, &est.p, dt)?;
                let u = kalman::update_linear(&xp, &pp, &zmean, &position_h(), &r)?;
                self.current = Some(TrackEstimate {
                    t: plot.t,
                    x: u.x,
                    p: u.p,
                    gain: self.keep_gain.then_some(u.gain),
                });
            }
        }
        Ok(self.current.as_ref())
    }

    /// Predicts the track to `t` without a plot (a missed detection).
    pub fn coast(&mut self, t: f64) -> Result<Option<&TrackEstimate>, SimError> {
        if let Some(est) = &self.current {
            let (x, p) = self.model.predict(&est.x, &est.p, t - est.t)?;
            self.current = Some(TrackEstimate {
                t,
                x,
                p,
                gain: None,
            });
        }
        Ok(self.current.as_ref())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::montecarlo::run_rng;
    use crate::sensor::Origin;

    fn plot(t: f64, range: f64, azimuth: f64) -> Plot {
        Plot {
            t,
            range,
            azimuth,
            elevation: None,
            radial_velocity: None,
            origin: Origin::Target(0),
        }
    }

    #[test]
    fn two_plots_initialise_by_eqs_29_30() {
        // Radar at the origin, σρ = 100 m, σθ = 0.01 rad; plots due north at
        // 10 km then 10.4 km, T = 4 s. Eq. 29: x̂ = [0, 0, 10400, 100].
        // Eq. 28 at θ = 0 (north, our convention): σx² = (ρσθ)² = 104² =
        // 10816, σy² = σρ² = 10000, σxy = 0. Eq. 30: P[vy,vy] = 2σy²/T² = 1250,
        // P[x,vx] = σx²/T = 2704.
        let radar = Radar::two_d([0.0; 3], 100.0, 0.01, 4.0);
        let mut kf = LocalKalman::new(&radar, 0.05, true).unwrap();
        assert!(kf.process(&plot(0.0, 10_000.0, 0.0)).unwrap().is_none());
        let est = kf
            .process(&plot(4.0, 10_400.0, 0.0))
            .unwrap()
            .unwrap()
            .clone();
        let want = [0.0, 0.0, 10_400.0, 100.0];
        for (got, want) in est.x.iter().zip(want) {
            assert!((got - want).abs() < 1e-9, "{}", est.x);
        }
        assert!((est.p[(3, 3)] - 1250.0).abs() < 1e-9);
        assert!((est.p[(0, 1)] - 2704.0).abs() < 1e-6);
        assert!(est.p[(0, 2)].abs() < 1e-6);
        assert!(est.gain.is_none());
        // Third plot: the update keeps the gain, 4x2.
        let est = kf.process(&plot(8.0, 10_800.0, 0.0)).unwrap().unwrap();
        assert_eq!(est.gain.as_ref().map(|k| k.shape()), Some((4, 2)));
        assert!((est.x[2] - 10_800.0).abs() < 1e-6);
    }

    #[test]
    fn filter_error_shrinks_below_the_measurement_error() {
        // A straight target measured 30 times: the filtered position error
        // must be well under the raw conversion error (σ ≈ ρσθ ≈ 1 km across).
        let radar = Radar::two_d([0.0; 3], 170.0, 1f64.to_radians(), 4.0);
        let mut rng = run_rng(9, 0);
        let mut kf = LocalKalman::new(&radar, 0.0, false).unwrap();
        let (mut se_f, mut n) = (0.0, 0);
        for k in 0..40 {
            let t = 4.0 * k as f64;
            let s = [20_000.0 + 150.0 * t, 150.0, 60_000.0, 0.0, 0.0, 0.0];
            let p = radar
                .measure(t, &s, Origin::Target(0), &mut rng)
                .unwrap()
                .unwrap();
            if let Some(e) = kf.process(&p).unwrap()
                && k >= 20
            {
                se_f += (e.x[0] - s[0]).powi(2) + (e.x[2] - s[2]).powi(2);
                n += 1;
            }
        }
        let rmse = (se_f / n as f64).sqrt();
        assert!(rmse < 500.0, "filtered rmse {rmse}");
    }
}
