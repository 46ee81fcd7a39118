//! Seed 004 §2.3–2.4: cell-averaging CFAR over the sorted differences of the
//! track distance matrix (eqs. 8–10), and the credible pairs of eq. 7.

use crate::error::AlgoError;

/// CA-CFAR parameters (seed 004 fig. 1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CfarConfig {
    /// Reference window N: at most this many leading cells are averaged.
    pub window: usize,
    /// Guard cells between the cell under test and its reference window.
    pub guard: usize,
    /// Weighting K of eq. 8.
    pub k: f64,
    /// Ratio h of eq. 10, S2 = h S1.
    pub h: f64,
}

impl Default for CfarConfig {
    fn default() -> Self {
        Self {
            window: 5,
            guard: 1,
            k: 5.0,
            h: 3.0,
        }
    }
}

impl CfarConfig {
    /// Checks the parameters' ranges: N from 1 to 1000, at most 100 guard
    /// cells, K finite and > 0, h finite and ≥ 1.
    pub fn validate(&self) -> Result<(), AlgoError> {
        let bad = |what, reason: &str| {
            Err(AlgoError::InvalidParameter {
                what,
                reason: reason.into(),
            })
        };
        if self.window == 0 || self.window > 1000 {
            return bad("window", "must be between 1 and 1000");
        }
        if self.guard > 100 {
            return bad("guard", "must be at most 100");
        }
        if !(self.k.is_finite() && self.k > 0.0) {
            return bad("k", "must be a finite number > 0");
        }
        if !(self.h.is_finite() && self.h >= 1.0) {
            return bad("h", "must be a finite number >= 1");
        }
        Ok(())
    }
}

/// The thresholds found by the detector.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Thresholds {
    /// m′ of eq. 8 (1-based): the number of distances attributed to the bias.
    pub count: usize,
    /// Same-source threshold S1 = d_m′ (eq. 9).
    pub s1: f64,
    /// Different-source threshold S2 = h S1 (eq. 10).
    pub s2: f64,
}

/// Eq. 8 over `diffs` = ΔD (Δd_m = d_{m+1} − d_m, index 0 is m = 1): the
/// first m′ (1-based) with Δd_m′ ≥ K · mean of the up to N cells
/// Δd_{m′−G−N} … Δd_{m′−G−1} before the guard cells (at least one cell must
/// exist). A zero mean detects any positive difference.
pub fn ca_cfar(diffs: &[f64], cfg: &CfarConfig) -> Option<usize> {
    for m in 0..diffs.len() {
        // Reference cells are indices [m − G − N, m − G − 1] clipped at 0.
        let Some(end) = m.checked_sub(cfg.guard) else {
            continue;
        };
        if end == 0 {
            continue;
        }
        let start = end.saturating_sub(cfg.window);
        let reference = &diffs[start..end];
        let mean = reference.iter().sum::<f64>() / reference.len() as f64;
        let hit = if mean > 0.0 {
            diffs[m] / (cfg.k * mean) >= 1.0
        } else {
            diffs[m] > 0.0
        };
        if hit {
            return Some(m + 1);
        }
    }
    None
}

/// S1 and S2 from the finite entries of the distance matrix (eqs. 8–10).
pub fn thresholds(distances: &[f64], cfg: &CfarConfig) -> Option<Thresholds> {
    let mut d: Vec<f64> = distances
        .iter()
        .copied()
        .filter(|x| x.is_finite())
        .collect();
    d.sort_by(f64::total_cmp);
    let diffs: Vec<f64> = d.windows(2).map(|w| w[1] - w[0]).collect();
    let m = ca_cfar(&diffs, cfg)?;
    let s1 = d[m - 1];
    Some(Thresholds {
        count: m,
        s1,
        s2: cfg.h * s1,
    })
}

/// Credible pairs (eq. 7) of a `rows` × `cols` row-major matrix whose
/// missing entries are infinite: r_i′j′ ≤ S1 while every other entry of row
/// i′ and of column j′ exceeds S2. (The paper writes r < S1; with S1 = d_m′
/// by eq. 9 the strict form would drop the m′-th pair itself.)
pub fn credible_pairs(
    matrix: &[f64],
    rows: usize,
    cols: usize,
    t: &Thresholds,
) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    for i in 0..rows {
        for j in 0..cols {
            if matrix[i * cols + j] > t.s1 {
                continue;
            }
            let row_clear = (0..cols).all(|c| c == j || matrix[i * cols + c] > t.s2);
            let col_clear = (0..rows).all(|r| r == i || matrix[r * cols + j] > t.s2);
            if row_clear && col_clear {
                out.push((i, j));
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Hand-built sequence: five same-source distances 500, 510, 530, 535, 560
    /// (differences 10, 20, 5, 25), then a jump to 2000 (difference 1440),
    /// then 2100, 2400.
    /// With N = 3, G = 1, K = 4: m = 3 (Δ=5) averages cell 1 (10) → 5/40 < 1;
    /// m = 4 (Δ=25) averages cells 1–2 (mean 15) → 25/60 < 1; m = 5 (Δ=1440)
    /// averages cells 1–3 (mean 35/3) → 1440/46.7 ≥ 1: m′ = 5, S1 = d_5 = 560,
    /// S2 = 3 · 560 = 1680.
    #[test]
    fn ca_cfar_on_a_hand_built_sequence() {
        let d = [2400.0, 500.0, 510.0, 2000.0, 530.0, 535.0, 560.0, 2100.0];
        let cfg = CfarConfig {
            window: 3,
            guard: 1,
            k: 4.0,
            h: 3.0,
        };
        let t = thresholds(&d, &cfg).unwrap();
        assert_eq!(t.count, 5);
        assert_eq!(t.s1, 560.0);
        assert_eq!(t.s2, 1680.0);
        // With K = 0.4: m = 2 has no reference cell (the guard cell is
        // m = 1), m = 3 has Δ = 5 against the mean 10 of cell 1: 5/4 ≥ 1, so m′ = 3.
        let loose = CfarConfig { k: 0.4, ..cfg };
        assert_eq!(thresholds(&d, &loose).unwrap().count, 3);
        // Too few distances: no reference cell ever exists.
        assert_eq!(thresholds(&[1.0, 2.0], &cfg), None);
    }

    #[test]
    fn credible_pairs_need_isolation() {
        // 3 radar × 3 AIS. Pair (0,0) at 500 is isolated; (1,1) at 520 has a
        // rival (2,1) at 1200 < S2 = 1500; (2,2) at 900 exceeds S1 = 560.
        let inf = f64::INFINITY;
        let m = [
            500.0, 4000.0, inf, 3000.0, 520.0, 5000.0, 6000.0, 1200.0, 900.0,
        ];
        let t = Thresholds {
            count: 2,
            s1: 560.0,
            s2: 1500.0,
        };
        assert_eq!(credible_pairs(&m, 3, 3, &t), vec![(0, 0)]);
    }
}
