//! Gaussian densities and covariance hygiene.
//!
//! Checks that a matrix is a usable covariance (square, finite, symmetric,
//! positive definite), a validated [`Gaussian`] (mean and covariance), and the
//! squared Mahalanobis distance `d' S⁻¹ d` computed by a Cholesky
//! triangular solve, which is the test statistic of seed 000 (He You et al.,
//! double-threshold track correlation), eqs. 10 and 12, compared with the
//! threshold of eq. 14.

use nalgebra::{Cholesky, DMatrix, DVector, Dyn};

use crate::error::{AlgoError, check_vector, finite_slice};

/// Relative tolerance of the symmetry check: `|p_ij - p_ji| <= SYMMETRY_RTOL * max|p|`.
pub const SYMMETRY_RTOL: f64 = 1e-9;

/// Checks that `p` is a covariance: square, non-empty, finite, symmetric within
/// `SYMMETRY_RTOL * max|p_ij|`, and positive definite (the Cholesky
/// factorisation exists and its diagonal is strictly positive and finite).
pub fn check_covariance(what: &'static str, p: &DMatrix<f64>) -> Result<(), AlgoError> {
    cholesky(what, p).map(|_| ())
}

/// Checks `p` like [`check_covariance`] and returns its Cholesky factor.
pub fn cholesky(what: &'static str, p: &DMatrix<f64>) -> Result<Cholesky<f64, Dyn>, AlgoError> {
    if p.is_empty() {
        return Err(AlgoError::InvalidParameter {
            what,
            reason: "must not be empty".to_owned(),
        });
    }
    check_symmetric(what, p)?;
    let chol = Cholesky::new(p.clone()).ok_or(AlgoError::NotPositiveDefinite { what })?;
    let l = chol.l_dirty();
    if (0..l.nrows()).all(|i| l[(i, i)] > 0.0 && l[(i, i)].is_finite()) {
        Ok(chol)
    } else {
        Err(AlgoError::NotPositiveDefinite { what })
    }
}

/// Checks that `p` is square, finite and symmetric within
/// `SYMMETRY_RTOL * max|p_ij|`, without requiring definiteness (for process
/// noise `G Q G'`, which is only positive semi-definite).
pub fn check_symmetric(what: &'static str, p: &DMatrix<f64>) -> Result<(), AlgoError> {
    if !p.is_square() {
        return Err(AlgoError::NotSquare {
            what,
            rows: p.nrows(),
            cols: p.ncols(),
        });
    }
    finite_slice(what, p.as_slice())?;
    let scale = p.amax();
    let n = p.nrows();
    let mut worst = 0.0_f64;
    for j in 0..n {
        for i in (j + 1)..n {
            worst = worst.max((p[(i, j)] - p[(j, i)]).abs());
        }
    }
    if worst <= SYMMETRY_RTOL * scale {
        Ok(())
    } else {
        Err(AlgoError::NotSymmetric {
            what,
            max_abs_asymmetry: worst,
        })
    }
}

/// The moment-matched Gaussian of a mixture with weights w summing to 1:
/// x̄ = Σ w x, P̄ = Σ w (P + d d′), d = x − x̄ (symmetrised).
pub fn moment_match<'a>(
    parts: impl Iterator<Item = (f64, &'a DVector<f64>, &'a DMatrix<f64>)> + Clone,
) -> (DVector<f64>, DMatrix<f64>) {
    let (_, x0, p0) = parts.clone().next().expect("a mixture has a component");
    let mut x = DVector::zeros(x0.len());
    let mut p = DMatrix::zeros(p0.nrows(), p0.ncols());
    moment_match_into(parts, &mut x, &mut p);
    (x, p)
}

/// [`moment_match`] into `x` and `p` (resized to the components' shape
/// when they differ), the same arithmetic without the allocations: the
/// IMM's mixing and output run it per track and frame.
pub fn moment_match_into<'a>(
    parts: impl Iterator<Item = (f64, &'a DVector<f64>, &'a DMatrix<f64>)> + Clone,
    x: &mut DVector<f64>,
    p: &mut DMatrix<f64>,
) {
    let (_, x0, p0) = parts.clone().next().expect("a mixture has a component");
    if x.len() != x0.len() {
        *x = DVector::zeros(x0.len());
    }
    if p.shape() != p0.shape() {
        *p = DMatrix::zeros(p0.nrows(), p0.ncols());
    }
    x.fill(0.0);
    for (w, xi, _) in parts.clone() {
        x.axpy(w, xi, 1.0);
    }
    p.fill(0.0);
    let mut d = DVector::zeros(x.len());
    for (w, xi, pi) in parts {
        d.copy_from(xi);
        d -= &*x;
        p.zip_apply(pi, |a, b| *a += b * w);
        p.ger(w, &d, &d, 1.0);
    }
    symmetrize(p);
}

/// [`symmetrize`] of a fixed-size square matrix.
pub fn symmetrize_fixed<const N: usize>(p: &mut nalgebra::SMatrix<f64, N, N>) {
    for j in 0..N {
        for i in (j + 1)..N {
            let m = 0.5 * (p[(i, j)] + p[(j, i)]);
            p[(i, j)] = m;
            p[(j, i)] = m;
        }
    }
}

/// Replaces a square `p` by `(p + p') / 2`. Non-square matrices are left unchanged.
pub fn symmetrize(p: &mut DMatrix<f64>) {
    if !p.is_square() {
        return;
    }
    let n = p.nrows();
    for j in 0..n {
        for i in (j + 1)..n {
            let m = 0.5 * (p[(i, j)] + p[(j, i)]);
            p[(i, j)] = m;
            p[(j, i)] = m;
        }
    }
}

/// A multivariate normal density N(mean, cov) with a validated covariance.
#[derive(Debug, Clone, PartialEq)]
pub struct Gaussian {
    mean: DVector<f64>,
    cov: DMatrix<f64>,
}

impl Gaussian {
    /// Builds N(mean, cov) after checking that the mean is finite and `cov`
    /// is an `n x n` symmetric positive-definite matrix with `n = mean.len()`.
    pub fn new(mean: DVector<f64>, cov: DMatrix<f64>) -> Result<Self, AlgoError> {
        check_vector("mean", &mean, mean.len())?;
        if cov.nrows() != mean.len() {
            return Err(AlgoError::DimensionMismatch {
                what: "covariance",
                expected: mean.len(),
                found: cov.nrows(),
            });
        }
        check_covariance("covariance", &cov)?;
        Ok(Self { mean, cov })
    }

    /// The mean vector.
    pub fn mean(&self) -> &DVector<f64> {
        &self.mean
    }

    /// The covariance matrix.
    pub fn cov(&self) -> &DMatrix<f64> {
        &self.cov
    }

    /// The dimension `n`.
    pub fn dim(&self) -> usize {
        self.mean.len()
    }

    /// Consumes the density, returning `(mean, cov)`.
    pub fn into_parts(self) -> (DVector<f64>, DMatrix<f64>) {
        (self.mean, self.cov)
    }
}

/// Squared Mahalanobis distance `d' S⁻¹ d`, computed as `‖L⁻¹ d‖²` with
/// `S = L L'` (Cholesky). This is the statistic α_ij / β_ij of seed 000
/// eqs. 10 and 12, compared with the χ² threshold of eq. 14.
pub fn mahalanobis_sq(d: &DVector<f64>, s: &DMatrix<f64>) -> Result<f64, AlgoError> {
    let chol = cholesky("difference covariance", s)?;
    mahalanobis_sq_chol(d, &chol)
}

/// [`mahalanobis_sq`] with a Cholesky factor computed once (for hot loops
/// over many candidate pairs sharing the same `S`).
pub fn mahalanobis_sq_chol(d: &DVector<f64>, chol: &Cholesky<f64, Dyn>) -> Result<f64, AlgoError> {
    let l = chol.l_dirty();
    check_vector("difference vector", d, l.nrows())?;
    let w = l
        .solve_lower_triangular(d)
        .ok_or(AlgoError::NotPositiveDefinite {
            what: "difference covariance",
        })?;
    let m = w.norm_squared();
    if m.is_finite() {
        Ok(m)
    } else {
        Err(AlgoError::NonFinite {
            what: "mahalanobis distance",
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::dmatrix;
    use nalgebra::dvector;
    use proptest::prelude::*;

    #[test]
    fn accepts_spd_and_rejects_the_rest() {
        assert!(check_covariance("p", &dmatrix![4.0, 1.0; 1.0, 3.0]).is_ok());
        assert!(matches!(
            check_covariance("p", &dmatrix![1.0, 2.0, 3.0; 4.0, 5.0, 6.0]),
            Err(AlgoError::NotSquare {
                rows: 2,
                cols: 3,
                ..
            })
        ));
        assert!(matches!(
            check_covariance("p", &dmatrix![1.0, f64::NAN; f64::NAN, 1.0]),
            Err(AlgoError::NonFinite { what: "p" })
        ));
        match check_covariance("p", &dmatrix![4.0, 1.0; 1.5, 3.0]) {
            Err(AlgoError::NotSymmetric {
                max_abs_asymmetry, ..
            }) => assert_eq!(max_abs_asymmetry, 0.5),
            other => panic!("{other:?}"),
        }
        // Eigenvalues of [[1,2],[2,1]] are 3 and -1: indefinite.
        assert!(matches!(
            check_covariance("p", &dmatrix![1.0, 2.0; 2.0, 1.0]),
            Err(AlgoError::NotPositiveDefinite { what: "p" })
        ));
        // Singular (rank 1) and zero matrices are not positive definite.
        assert!(check_covariance("p", &dmatrix![1.0, 1.0; 1.0, 1.0]).is_err());
        assert!(check_covariance("p", &DMatrix::zeros(2, 2)).is_err());
        assert!(check_covariance("p", &DMatrix::zeros(0, 0)).is_err());
    }

    #[test]
    fn symmetry_tolerance_is_relative() {
        // Entries ~1e6: an asymmetry of 1e-4 is 1e-10 relative, accepted.
        let p = dmatrix![1e6, 1.0 + 1e-4; 1.0, 1e6];
        assert!(check_covariance("p", &p).is_ok());
        // Entries ~1e-6: an asymmetry of 1e-12 is 1e-6 relative, rejected.
        let p = dmatrix![1e-6, 1e-12; 0.0, 1e-6];
        assert!(check_covariance("p", &p).is_err());
    }

    #[test]
    fn symmetrize_averages_mirrored_entries() {
        let mut p = dmatrix![1.0, 2.0; 4.0, 5.0];
        symmetrize(&mut p);
        assert_eq!(p, dmatrix![1.0, 3.0; 3.0, 5.0]);
    }

    #[test]
    fn gaussian_validates() {
        let g = Gaussian::new(dvector![1.0, 2.0], dmatrix![2.0, 0.0; 0.0, 3.0]).unwrap();
        assert_eq!(g.dim(), 2);
        assert_eq!(g.mean()[1], 2.0);
        assert_eq!(g.cov()[(1, 1)], 3.0);
        let (m, c) = g.into_parts();
        assert_eq!((m.len(), c.nrows()), (2, 2));
        assert!(matches!(
            Gaussian::new(dvector![1.0, 2.0, 3.0], dmatrix![2.0, 0.0; 0.0, 3.0]),
            Err(AlgoError::DimensionMismatch {
                expected: 3,
                found: 2,
                ..
            })
        ));
        assert!(Gaussian::new(dvector![f64::INFINITY], dmatrix![1.0]).is_err());
    }

    #[test]
    fn mahalanobis_by_hand() {
        // S = [[4, 2], [2, 3]], det S = 12 - 4 = 8, S⁻¹ = [[3, -2], [-2, 4]] / 8.
        // d = [1, 2]: d'S⁻¹d = (3·1 - 2·2·1·2 + 4·4) / 8 = (3 - 8 + 16) / 8 = 11/8.
        let s = dmatrix![4.0, 2.0; 2.0, 3.0];
        let d = dvector![1.0, 2.0];
        assert!((mahalanobis_sq(&d, &s).unwrap() - 11.0 / 8.0).abs() < 1e-15);
        let chol = cholesky("s", &s).unwrap();
        assert!((mahalanobis_sq_chol(&d, &chol).unwrap() - 11.0 / 8.0).abs() < 1e-15);
        assert!(matches!(
            mahalanobis_sq_chol(&dvector![1.0], &chol),
            Err(AlgoError::DimensionMismatch { .. })
        ));
        assert!(mahalanobis_sq(&dvector![f64::NAN, 0.0], &s).is_err());
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(128))]

        /// For diagonal S the distance is Σ d_i² / s_i (closed form).
        #[test]
        fn mahalanobis_diagonal_closed_form(
            d in proptest::collection::vec(-1e3..1e3f64, 1..6),
            s in proptest::collection::vec(1e-3..1e3f64, 6),
        ) {
            let n = d.len();
            let sm = DMatrix::from_diagonal(&DVector::from_column_slice(&s[..n]));
            let expected: f64 = d.iter().zip(&s).map(|(di, si)| di * di / si).sum();
            let got = mahalanobis_sq(&DVector::from_column_slice(&d), &sm).unwrap();
            prop_assert!((got - expected).abs() <= 1e-12 * expected.max(1.0));
        }
    }
}
