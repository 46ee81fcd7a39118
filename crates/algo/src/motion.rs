//! Constant-velocity motion models for the interleaved state layout.
//!
//! States are `[x, vx]` per axis, interleaved: 2D `[x, vx, y, vy]`, 3D
//! `[x, vx, y, vy, z, vz]` (x east, y north, z up). Provides the transition
//! matrix, three process-noise forms (discrete and continuous white-noise
//! acceleration, and the velocity-proportional noise of seed 000, He You et
//! al., eqs. 24 and 26) and a [`MotionModel`] trait whose `predict` calls
//! [`crate::kalman::predict`]. `dt` may be negative (retrodiction) or
//! zero but must be finite.

use nalgebra::{DMatrix, DVector};

use crate::error::{AlgoError, check_vector, finite, finite_slice, non_negative};
use crate::gaussian::{check_symmetric, symmetrize};
use crate::kalman;

/// A motion model: transition matrix and process noise for a time step.
pub trait MotionModel {
    /// Dimension of the state vector.
    fn state_dim(&self) -> usize;

    /// Transition matrix F(dt).
    fn transition(&self, dt: f64) -> Result<DMatrix<f64>, AlgoError>;

    /// Process noise in state space for a step `dt` from `state` (the state
    /// is needed by state-dependent noise such as seed 000 eq. 26).
    fn process_noise(&self, dt: f64, state: &DVector<f64>) -> Result<DMatrix<f64>, AlgoError>;

    /// Whether [`MotionModel::process_noise`] ignores the state, so that a
    /// caller may compute Q once per step length (the default says no).
    fn process_noise_ignores_state(&self) -> bool {
        false
    }

    /// Kalman prediction over `dt`: x⁺ = F x, P⁺ = F P F' + Q.
    fn predict(
        &self,
        x: &DVector<f64>,
        p: &DMatrix<f64>,
        dt: f64,
    ) -> Result<(DVector<f64>, DMatrix<f64>), AlgoError> {
        check_vector("state", x, self.state_dim())?;
        let f = self.transition(dt)?;
        let q = self.process_noise(dt, x)?;
        kalman::predict(x, p, &f, &q)
    }
}

/// Process-noise choice for [`ConstantVelocity`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ProcessNoise {
    /// Discrete white-noise acceleration with standard deviation `sigma_a` (m/s²),
    /// see [`dwna_process_noise`].
    Dwna {
        /// Acceleration standard deviation (m/s²), ≥ 0.
        sigma_a: f64,
    },
    /// Continuous white-noise acceleration with power spectral density `q`
    /// (m²/s³), see [`cwna_process_noise`].
    Cwna {
        /// Power spectral density (m²/s³), ≥ 0.
        q: f64,
    },
    /// Seed 000 eqs. 24 and 26: `G Q G'` with √q_ii = `factor` · v_i
    /// (the paper uses 0.05), velocities taken from the state.
    VelocityProportional {
        /// Ratio of the velocity-noise standard deviation to the speed, ≥ 0.
        factor: f64,
    },
}

/// Constant-velocity model with `axes` interleaved `[position, velocity]` pairs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConstantVelocity {
    axes: usize,
    noise: ProcessNoise,
}

impl ConstantVelocity {
    /// A model with `axes >= 1` (2 or 3 in practice) and a valid noise parameter.
    pub fn new(axes: usize, noise: ProcessNoise) -> Result<Self, AlgoError> {
        check_axes(axes)?;
        match noise {
            ProcessNoise::Dwna { sigma_a } => non_negative("sigma_a", sigma_a)?,
            ProcessNoise::Cwna { q } => non_negative("q", q)?,
            ProcessNoise::VelocityProportional { factor } => non_negative("factor", factor)?,
        };
        Ok(Self { axes, noise })
    }

    /// Number of spatial axes.
    pub fn axes(&self) -> usize {
        self.axes
    }

    /// The process-noise choice.
    pub fn noise(&self) -> ProcessNoise {
        self.noise
    }
}

impl MotionModel for ConstantVelocity {
    fn state_dim(&self) -> usize {
        2 * self.axes
    }

    fn transition(&self, dt: f64) -> Result<DMatrix<f64>, AlgoError> {
        cv_transition(self.axes, dt)
    }

    fn process_noise_ignores_state(&self) -> bool {
        !matches!(self.noise, ProcessNoise::VelocityProportional { .. })
    }

    fn process_noise(&self, dt: f64, state: &DVector<f64>) -> Result<DMatrix<f64>, AlgoError> {
        check_vector("state", state, self.state_dim())?;
        match self.noise {
            ProcessNoise::Dwna { sigma_a } => dwna_process_noise(self.axes, dt, sigma_a),
            ProcessNoise::Cwna { q } => cwna_process_noise(self.axes, dt, q),
            ProcessNoise::VelocityProportional { factor } => {
                let v: Vec<f64> = (0..self.axes).map(|i| state[2 * i + 1]).collect();
                let q = seed000_velocity_proportional_q(&v, factor)?;
                gqg(&seed000_noise_gain(self.axes, dt)?, &q)
            }
        }
    }
}

/// Constant-velocity transition, block diagonal of `[[1, dt], [0, 1]]`
/// (seed 000 eq. 24, Φ with T = `dt`).
pub fn cv_transition(axes: usize, dt: f64) -> Result<DMatrix<f64>, AlgoError> {
    check_axes(axes)?;
    finite("dt", dt)?;
    Ok(per_axis(axes, [[1.0, dt], [0.0, 1.0]]))
}

/// [`cv_transition`] at a size known at compile time: `N / 2` interleaved
/// `[position, velocity]` components (the α-β filter's fixed-size path).
pub fn cv_transition_fixed<const N: usize>(dt: f64) -> nalgebra::SMatrix<f64, N, N> {
    let mut f = nalgebra::SMatrix::identity();
    for i in 0..N / 2 {
        f[(2 * i, 2 * i + 1)] = dt;
    }
    f
}

/// The per-axis factor of the discrete white-noise acceleration over `dt`:
/// `[dt⁴/4, dt³/2, dt²]`, the entries of `Γ Γ'` with `Γ = [dt²/2, dt]'`
/// (the noise of one axis is σ_a² times it, [`dwna_process_noise`]).
pub fn dwna_factor(dt: f64) -> [f64; 3] {
    [dt.powi(4) / 4.0, dt.powi(3) / 2.0, dt * dt]
}

/// Discrete white-noise acceleration: per axis `Γ σ_a² Γ'` with
/// `Γ = [dt²/2, dt]'`, i.e. `σ_a² [[dt⁴/4, dt³/2], [dt³/2, dt²]]`
/// (Bar-Shalom, Li & Kirubarajan 2001, ch. 6). Positive semi-definite
/// (rank one per axis).
pub fn dwna_process_noise(axes: usize, dt: f64, sigma_a: f64) -> Result<DMatrix<f64>, AlgoError> {
    check_axes(axes)?;
    finite("dt", dt)?;
    let s2 = non_negative("sigma_a", sigma_a)?.powi(2);
    let [c11, c12, c22] = dwna_factor(dt);
    Ok(per_axis(axes, [[s2 * c11, s2 * c12], [s2 * c12, s2 * c22]]))
}

/// Continuous white-noise acceleration with spectral density `q`: per axis
/// `q [[|dt|³/3, dt|dt|/2], [dt|dt|/2, |dt|]]` (Bar-Shalom et al. 2001,
/// ch. 6). For `dt > 0` this is the textbook `q [[dt³/3, dt²/2], [dt²/2, dt]]`;
/// for a retrodiction step (`dt < 0`) the noise accumulated over |dt| is used,
/// with the sign of the position–velocity correlation following dt, so the
/// matrix stays positive semi-definite.
pub fn cwna_process_noise(axes: usize, dt: f64, q: f64) -> Result<DMatrix<f64>, AlgoError> {
    check_axes(axes)?;
    finite("dt", dt)?;
    non_negative("q", q)?;
    let a = dt.abs();
    let c = q * dt * a / 2.0;
    Ok(per_axis(axes, [[q * a * a * a / 3.0, c], [c, q * a]]))
}

/// Noise gain G of seed 000 eq. 24: per axis `[T/2, 1]'`, an `2·axes × axes`
/// matrix with T = `dt`.
///
/// Printed as T/2, not the T²/2 of an acceleration input: in eq. 26 the
/// noise V is a velocity perturbation (√q11 = 0.05·ẋ, in m/s), which moves
/// the velocity by V and the position by the average V·T/2 over the
/// interval, so `[T/2, 1]'` is dimensionally consistent (m/s → m, m/s).
pub fn seed000_noise_gain(axes: usize, dt: f64) -> Result<DMatrix<f64>, AlgoError> {
    check_axes(axes)?;
    finite("dt", dt)?;
    let mut g = DMatrix::zeros(2 * axes, axes);
    for i in 0..axes {
        g[(2 * i, i)] = dt / 2.0;
        g[(2 * i + 1, i)] = 1.0;
    }
    Ok(g)
}

/// Seed 000 eq. 26: `Q = diag((factor · v_i)²)` for the per-axis velocities
/// `v` (m/s); the paper uses `factor = 0.05`.
pub fn seed000_velocity_proportional_q(
    velocity: &[f64],
    factor: f64,
) -> Result<DMatrix<f64>, AlgoError> {
    if velocity.is_empty() {
        return Err(AlgoError::InvalidParameter {
            what: "velocity",
            reason: "must not be empty".to_owned(),
        });
    }
    finite_slice("velocity", velocity)?;
    non_negative("factor", factor)?;
    let d: Vec<f64> = velocity.iter().map(|v| (factor * v).powi(2)).collect();
    Ok(DMatrix::from_diagonal(&DVector::from_vec(d)))
}

/// `G Q G'`, symmetrized (the process-noise term of seed 000 eq. 13).
/// `Q` must be square, finite and symmetric; the result is only positive
/// semi-definite, which is enough for prediction since P is definite.
pub fn gqg(g: &DMatrix<f64>, q: &DMatrix<f64>) -> Result<DMatrix<f64>, AlgoError> {
    finite_slice("noise gain", g.as_slice())?;
    check_symmetric("noise covariance", q)?;
    if q.nrows() != g.ncols() {
        return Err(AlgoError::DimensionMismatch {
            what: "noise covariance",
            expected: g.ncols(),
            found: q.nrows(),
        });
    }
    let mut out = g * q * g.transpose();
    symmetrize(&mut out);
    finite_slice("process noise", out.as_slice())?;
    Ok(out)
}

fn check_axes(axes: usize) -> Result<(), AlgoError> {
    if axes == 0 {
        Err(AlgoError::InvalidParameter {
            what: "axes",
            reason: "must be >= 1".to_owned(),
        })
    } else {
        Ok(())
    }
}

/// Block diagonal matrix repeating the 2x2 `block` for each axis.
fn per_axis(axes: usize, block: [[f64; 2]; 2]) -> DMatrix<f64> {
    let mut m = DMatrix::zeros(2 * axes, 2 * axes);
    for i in 0..axes {
        for r in 0..2 {
            for c in 0..2 {
                m[(2 * i + r, 2 * i + c)] = block[r][c];
            }
        }
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gaussian::check_covariance;
    use nalgebra::{dmatrix, dvector};
    use proptest::prelude::*;

    /// The paper's T = 4 s.
    const T: f64 = 4.0;

    #[test]
    fn transition_dt4() {
        #[rustfmt::skip]
        let expected = dmatrix![
            1.0, 4.0, 0.0, 0.0;
            0.0, 1.0, 0.0, 0.0;
            0.0, 0.0, 1.0, 4.0;
            0.0, 0.0, 0.0, 1.0
        ];
        assert_eq!(cv_transition(2, T).unwrap(), expected);
        assert_eq!(cv_transition(3, 0.0).unwrap(), DMatrix::identity(6, 6));
        assert!(cv_transition(2, f64::NAN).is_err());
        assert!(cv_transition(0, 1.0).is_err());
    }

    #[test]
    fn dwna_dt4() {
        // σ_a = 1, Γ = [16/2, 4]' = [8, 4]': Γ Γ' = [[64, 32], [32, 16]].
        let q = dwna_process_noise(2, T, 1.0).unwrap();
        assert_eq!(q.view((0, 0), (2, 2)), dmatrix![64.0, 32.0; 32.0, 16.0]);
        assert_eq!(q.view((2, 2), (2, 2)), dmatrix![64.0, 32.0; 32.0, 16.0]);
        assert_eq!(q[(0, 2)], 0.0);
        // σ_a = 0.5 scales by 0.25.
        let q = dwna_process_noise(1, T, 0.5).unwrap();
        assert_eq!(q, dmatrix![16.0, 8.0; 8.0, 4.0]);
    }

    #[test]
    fn cwna_dt4() {
        // q = 3, dt = 4: [[3·64/3, 3·16/2], [3·16/2, 3·4]] = [[64, 24], [24, 12]].
        assert_eq!(
            cwna_process_noise(1, T, 3.0).unwrap(),
            dmatrix![64.0, 24.0; 24.0, 12.0]
        );
        // dt = −4: same variances, negative correlation.
        assert_eq!(
            cwna_process_noise(1, -T, 3.0).unwrap(),
            dmatrix![64.0, -24.0; -24.0, 12.0]
        );
    }

    #[test]
    fn seed000_dt4() {
        // v = 100 m/s, factor 0.05: √q = 5, q = 25; G = [4/2, 1]' = [2, 1]';
        // G q G' = 25 [[4, 2], [2, 1]] = [[100, 50], [50, 25]].
        let g = seed000_noise_gain(2, T).unwrap();
        assert_eq!(g, dmatrix![2.0, 0.0; 1.0, 0.0; 0.0, 2.0; 0.0, 1.0]);
        let q = seed000_velocity_proportional_q(&[100.0, -40.0], 0.05).unwrap();
        // √q22 = 0.05 · (−40) = −2, q22 = 4.
        assert!((q.clone() - dmatrix![25.0, 0.0; 0.0, 4.0]).amax() < 1e-12);
        let gq = gqg(&g, &q).unwrap();
        #[rustfmt::skip]
        let expected = dmatrix![
            100.0, 50.0, 0.0, 0.0;
            50.0, 25.0, 0.0, 0.0;
            0.0, 0.0, 16.0, 8.0;
            0.0, 0.0, 8.0, 4.0
        ];
        assert!((gq - expected).amax() < 1e-12);
        assert!(gqg(&g, &dmatrix![1.0]).is_err());
        assert!(seed000_velocity_proportional_q(&[], 0.05).is_err());
    }

    #[test]
    fn model_uses_state_velocity() {
        let m =
            ConstantVelocity::new(2, ProcessNoise::VelocityProportional { factor: 0.05 }).unwrap();
        let x = dvector![0.0, 100.0, 0.0, 0.0];
        let q = m.process_noise(T, &x).unwrap();
        assert!((q[(0, 0)] - 100.0).abs() < 1e-12 && (q[(1, 1)] - 25.0).abs() < 1e-12);
        assert_eq!(q[(2, 2)], 0.0);
        assert!(m.process_noise(T, &dvector![0.0, 1.0]).is_err());
        assert!(ConstantVelocity::new(2, ProcessNoise::Dwna { sigma_a: -1.0 }).is_err());
        assert!(!m.process_noise_ignores_state());
    }

    #[test]
    fn white_noise_models_ignore_the_state() {
        // DWNA and CWNA Q depend on dt only: the same Q at two states.
        for noise in [
            ProcessNoise::Dwna { sigma_a: 2.0 },
            ProcessNoise::Cwna { q: 3.0 },
        ] {
            let m = ConstantVelocity::new(2, noise).unwrap();
            assert!(m.process_noise_ignores_state());
            let q1 = m.process_noise(T, &dvector![0.0, 100.0, 0.0, 0.0]).unwrap();
            let q2 = m
                .process_noise(T, &dvector![5.0, -7.0, 1.0, 300.0])
                .unwrap();
            assert_eq!(q1, q2);
        }
    }

    #[test]
    fn model_predict_by_hand() {
        // 1 axis, dt = 4, σ_a = 1, x = [0, 10], P = I:
        // x⁺ = [0 + 4·10, 10] = [40, 10];
        // F P F' = [[1 + 16, 4], [4, 1]] = [[17, 4], [4, 1]]; Q = [[64, 32], [32, 16]] (Γ = [8, 4]');
        // P⁺ = [[81, 36], [36, 17]].
        let m = ConstantVelocity::new(1, ProcessNoise::Dwna { sigma_a: 1.0 }).unwrap();
        let (x, p) = m
            .predict(&dvector![0.0, 10.0], &DMatrix::identity(2, 2), T)
            .unwrap();
        assert_eq!(x, dvector![40.0, 10.0]);
        assert_eq!(p, dmatrix![81.0, 36.0; 36.0, 17.0]);
        assert!(
            m.predict(&dvector![0.0], &DMatrix::identity(1, 1), T)
                .is_err()
        );
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(128))]

        /// Predicting with every noise form keeps P symmetric positive definite,
        /// for forward, zero and backward steps.
        #[test]
        fn predict_keeps_spd(
            dt in -10.0..10.0f64,
            axes in 1usize..4,
            kind in 0usize..3,
            level in 0.0..5.0f64,
            diag in proptest::collection::vec(0.1..1e4f64, 6),
            x in proptest::collection::vec(-300.0..300.0f64, 6),
        ) {
            let noise = match kind {
                0 => ProcessNoise::Dwna { sigma_a: level },
                1 => ProcessNoise::Cwna { q: level },
                _ => ProcessNoise::VelocityProportional { factor: level / 50.0 },
            };
            let m = ConstantVelocity::new(axes, noise).unwrap();
            let n = 2 * axes;
            let xv = DVector::from_column_slice(&x[..n]);
            let p = DMatrix::from_diagonal(&DVector::from_column_slice(&diag[..n]));
            let (_, pp) = m.predict(&xv, &p, dt).unwrap();
            prop_assert!(check_covariance("p", &pp).is_ok());
            let q = m.process_noise(dt, &xv).unwrap();
            prop_assert!(check_symmetric("q", &q).is_ok());
        }
    }
}
