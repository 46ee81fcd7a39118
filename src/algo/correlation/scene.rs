//! The input of track-to-track correlation: local tracks of several nodes,
//! already aligned to common instants (the service does the alignment), in
//! flat row-major buffers so that the hot loops do not allocate.

use crate::algo::{AlgoError, small::MAX_DIM};

/// Aligned local tracks of every node.
#[derive(Debug, Clone)]
pub struct Scene {
    dim: usize,
    pos: Vec<usize>,
    times: Vec<f64>,
    nodes: Vec<Vec<Track>>,
}

/// One local track: its estimate and covariance at each instant where present.
#[derive(Debug, Clone)]
pub struct Track {
    present: Vec<bool>,
    x: Vec<f64>,
    p: Vec<f64>,
    gain_factor: Option<Vec<f64>>,
}

impl Scene {
    /// A scene of state dimension `dim` (≤ [`MAX_DIM`]) whose position
    /// components sit at `pos` (2 or 3 indices), over strictly increasing
    /// `times`.
    pub fn new(dim: usize, pos: Vec<usize>, times: Vec<f64>) -> Result<Self, AlgoError> {
        if dim == 0 || dim > MAX_DIM {
            return Err(AlgoError::InvalidParameter {
                what: "state_dim",
                reason: format!("must be between 1 and {MAX_DIM}"),
            });
        }
        if pos.is_empty() || pos.len() > 3 || pos.iter().any(|&i| i >= dim) {
            return Err(AlgoError::InvalidParameter {
                what: "position_indices",
                reason: "need 1 to 3 position components inside the state".into(),
            });
        }
        if times.iter().any(|t| !t.is_finite()) || times.windows(2).any(|w| w[1] <= w[0]) {
            return Err(AlgoError::InvalidParameter {
                what: "times",
                reason: "instants must be finite and strictly increasing".into(),
            });
        }
        Ok(Self {
            dim,
            pos,
            times,
            nodes: Vec::new(),
        })
    }

    /// Adds a node with its tracks; returns its index.
    pub fn add_node(&mut self, tracks: Vec<Track>) -> Result<usize, AlgoError> {
        for t in &tracks {
            if t.present.len() != self.times.len() {
                return Err(AlgoError::DimensionMismatch {
                    what: "track instants",
                    expected: self.times.len(),
                    found: t.present.len(),
                });
            }
            if t.x.len() != self.times.len() * self.dim {
                return Err(AlgoError::DimensionMismatch {
                    what: "track state",
                    expected: self.dim,
                    found: t.x.len() / self.times.len().max(1),
                });
            }
        }
        self.nodes.push(tracks);
        Ok(self.nodes.len() - 1)
    }

    pub fn dim(&self) -> usize {
        self.dim
    }

    pub fn position_indices(&self) -> &[usize] {
        &self.pos
    }

    pub fn times(&self) -> &[f64] {
        &self.times
    }

    pub fn nodes(&self) -> &[Vec<Track>] {
        &self.nodes
    }

    pub fn track(&self, node: usize, track: usize) -> &Track {
        &self.nodes[node][track]
    }
}

impl Track {
    /// A track absent at every one of `instants` instants.
    pub fn new(instants: usize, dim: usize) -> Self {
        Self {
            present: vec![false; instants],
            x: vec![0.0; instants * dim],
            p: vec![0.0; instants * dim * dim],
            gain_factor: None,
        }
    }

    /// Sets the estimate at instant `k`; `p` is row-major. The caller has
    /// checked finiteness and positive definiteness.
    pub fn set(&mut self, k: usize, x: &[f64], p: &[f64]) {
        let dim = x.len();
        self.present[k] = true;
        self.x[k * dim..(k + 1) * dim].copy_from_slice(x);
        self.p[k * dim * dim..(k + 1) * dim * dim].copy_from_slice(p);
    }

    /// Sets the reported filter factor I − K H at instant `k` (row-major),
    /// used by the cross-covariance recursion of seed 000 eq. 13.
    pub fn set_gain_factor(&mut self, k: usize, factor: &[f64]) {
        let n2 = factor.len();
        let instants = self.present.len();
        let g = self
            .gain_factor
            .get_or_insert_with(|| vec![f64::NAN; instants * n2]);
        g[k * n2..(k + 1) * n2].copy_from_slice(factor);
    }

    pub fn is_present(&self, k: usize) -> bool {
        self.present[k]
    }

    pub fn x(&self, k: usize, dim: usize) -> &[f64] {
        &self.x[k * dim..(k + 1) * dim]
    }

    pub fn p(&self, k: usize, dim: usize) -> &[f64] {
        &self.p[k * dim * dim..(k + 1) * dim * dim]
    }

    /// The reported I − K H at instant `k`, if the client sent gains for it.
    pub fn gain_factor(&self, k: usize, dim: usize) -> Option<&[f64]> {
        let g = self.gain_factor.as_ref()?;
        let s = &g[k * dim * dim..(k + 1) * dim * dim];
        s[0].is_finite().then_some(s)
    }

    /// The last instant before `k` where the track is present.
    pub fn previous(&self, k: usize) -> Option<usize> {
        (0..k).rev().find(|&j| self.present[j])
    }
}
