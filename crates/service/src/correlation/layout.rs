//! The request's state layout and its permutation to the canonical
//! interleaved order.

use nalgebra::DMatrix;

use crate::Rows;

/// The request's state layout and its permutation to the canonical
/// interleaved order `[x, vx, y, vy(, z, vz)]` or `[x, y(, z)]`.
#[derive(Debug, Clone)]
pub(crate) struct Layout {
    /// canonical[i] = index in the request's layout.
    pub(crate) from_request: Vec<usize>,
    pub(crate) dim: usize,
    pub(crate) axes: usize,
    pub(crate) has_velocity: bool,
}

impl Layout {
    pub(super) fn parse(names: &[String]) -> Result<Self, String> {
        let canon_cv: &[&[&str]] = &[&["x", "vx", "y", "vy"], &["x", "vx", "y", "vy", "z", "vz"]];
        let canon_pos: &[&[&str]] = &[&["x", "y"], &["x", "y", "z"]];
        let mut sorted: Vec<&str> = names.iter().map(String::as_str).collect();
        sorted.sort_unstable();
        let mut dedup = sorted.clone();
        dedup.dedup();
        if dedup.len() != sorted.len() {
            return Err("names a component twice".into());
        }
        for (canon, has_velocity) in [(canon_cv, true), (canon_pos, false)] {
            for c in canon {
                let mut want: Vec<&str> = c.to_vec();
                want.sort_unstable();
                if want == sorted {
                    let from_request = c
                        .iter()
                        .map(|n| names.iter().position(|m| m == n).expect("same set"))
                        .collect();
                    let axes = if has_velocity { c.len() / 2 } else { c.len() };
                    return Ok(Self {
                        from_request,
                        dim: c.len(),
                        axes,
                        has_velocity,
                    });
                }
            }
        }
        Err(
            "must be a permutation of [x, vx, y, vy], [x, vx, y, vy, z, vz], [x, y] or [x, y, z]"
                .into(),
        )
    }

    /// Position indices in the canonical order.
    pub(crate) fn positions(&self) -> Vec<usize> {
        if self.has_velocity {
            (0..self.axes).map(|a| 2 * a).collect()
        } else {
            (0..self.axes).collect()
        }
    }

    pub(crate) fn vector_to_canonical(&self, v: &[f64]) -> Vec<f64> {
        self.from_request.iter().map(|&i| v[i]).collect()
    }

    pub(crate) fn matrix_to_canonical(&self, m: &Rows) -> Vec<f64> {
        let n = self.dim;
        let m = m.values();
        let mut out = vec![0.0; n * n];
        for (i, &ri) in self.from_request.iter().enumerate() {
            for (j, &rj) in self.from_request.iter().enumerate() {
                out[i * n + j] = m[ri * n + rj];
            }
        }
        out
    }

    pub(crate) fn vector_to_request(&self, v: &[f64]) -> Vec<f64> {
        let mut out = vec![0.0; self.dim];
        for (i, &ri) in self.from_request.iter().enumerate() {
            out[ri] = v[i];
        }
        out
    }

    pub(crate) fn matrix_to_request(&self, m: &DMatrix<f64>) -> Vec<Vec<f64>> {
        let mut out = vec![vec![0.0; self.dim]; self.dim];
        for (i, &ri) in self.from_request.iter().enumerate() {
            for (j, &rj) in self.from_request.iter().enumerate() {
                out[ri][rj] = m[(i, j)];
            }
        }
        out
    }
}
