//! Least-squares bias estimation from the associated pairs' residuals, with
//! its covariance, and the refinement loop (estimate, compensate,
//! re-associate until the association is stable).

use super::alignment::at;
use super::problem::{Problem, Residual};
use super::{Bias, BiasEstimate, plane_to_polar, small_sample_factor};
use crate::polar::wrap_angle;

impl<'a> Problem<'a> {
    /// Range and azimuth residuals (measured − AIS) of pair (i, j) at its
    /// common instants, with the raw track interpolated in the plane, and
    /// each report's index.
    pub(super) fn residuals(&self, i: usize, j: usize) -> &[Residual] {
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
    pub(super) fn estimate(&self, pairs: &[(usize, usize)]) -> Option<BiasEstimate> {
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
    pub(super) fn refine(&self, seed: Bias) -> Refined {
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

pub(super) struct Refined {
    pub(super) estimate: Option<BiasEstimate>,
    pub(super) pairs: Vec<(usize, usize)>,
    pub(super) total: f64,
    pub(super) iterations: usize,
    pub(super) converged: bool,
}

impl Refined {
    pub(super) fn mean(&self) -> f64 {
        self.total / self.pairs.len().max(1) as f64
    }

    /// Better: more gated pairs, then a smaller mean distance.
    pub(super) fn better_than(&self, other: &Refined) -> bool {
        self.pairs.len() > other.pairs.len()
            || (self.pairs.len() == other.pairs.len() && self.mean() < other.mean() * (1.0 - 1e-9))
    }
}
