//! The input of track-to-track correlation: local tracks of several nodes,
//! already aligned to common instants (the service does the alignment), in
//! flat row-major buffers so that the hot loops do not allocate.
//!
//! Instants have global indices. A batch scene holds instants 0..n; a
//! streaming session appends instants with [`Scene::push_instant`] and drops
//! old ones with [`Scene::trim_before`], so it holds the window
//! [`Scene::first`]..[`Scene::end`]; a track is absent outside the window.

use crate::{AlgoError, small::MAX_DIM};

/// Aligned local tracks of every node.
#[derive(Debug, Clone)]
pub struct Scene {
    dim: usize,
    pos: Vec<usize>,
    /// Global index of `times[0]`.
    first: usize,
    times: Vec<f64>,
    nodes: Vec<Vec<Track>>,
}

/// One local track: its estimate and covariance at each instant where present.
#[derive(Debug, Clone)]
pub struct Track {
    /// Global index of `present[0]`.
    first: usize,
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
            first: 0,
            times,
            nodes: Vec::new(),
        })
    }

    /// A scene like [`Scene::new`]'s whose first held instant has global
    /// index `first` (a streaming scene rebuilt from storage); add its
    /// nodes with [`Scene::push_node`] and [`Scene::push_track`].
    pub fn held_from(
        dim: usize,
        pos: Vec<usize>,
        first: usize,
        times: Vec<f64>,
    ) -> Result<Self, AlgoError> {
        if first.checked_add(times.len()).is_none() {
            return Err(AlgoError::InvalidParameter {
                what: "first",
                reason: format!("instant index {first} overflows"),
            });
        }
        let mut scene = Self::new(dim, pos, times)?;
        scene.first = first;
        Ok(scene)
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

    /// State dimension of every track.
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// Indices of the position components in the state (2 or 3).
    pub fn position_indices(&self) -> &[usize] {
        &self.pos
    }

    /// The instants held, from [`Scene::first`] on.
    pub fn times(&self) -> &[f64] {
        &self.times
    }

    /// Global index of the first instant held.
    pub fn first(&self) -> usize {
        self.first
    }

    /// One past the global index of the last instant held.
    pub fn end(&self) -> usize {
        self.first + self.times.len()
    }

    /// Time of the held instant `k` (global index).
    pub fn time(&self, k: usize) -> f64 {
        self.times[k - self.first]
    }

    /// Appends an instant after the last one (every track absent there);
    /// returns its global index.
    pub fn push_instant(&mut self, t: f64) -> Result<usize, AlgoError> {
        if !t.is_finite() || self.times.last().is_some_and(|&last| t <= last) {
            return Err(AlgoError::InvalidParameter {
                what: "times",
                reason: "instants must be finite and strictly increasing".into(),
            });
        }
        self.times.push(t);
        let dim = self.dim;
        for track in self.nodes.iter_mut().flatten() {
            track.grow(dim);
        }
        Ok(self.end() - 1)
    }

    /// Drops every instant before global index `k`.
    pub fn trim_before(&mut self, k: usize) {
        let k = k.min(self.end());
        if k <= self.first {
            return;
        }
        let n = k - self.first;
        self.times.drain(..n);
        let dim = self.dim;
        for track in self.nodes.iter_mut().flatten() {
            track.drop_front(n, dim);
        }
        self.first = k;
    }

    /// Appends an empty node (streaming); returns its index.
    pub fn push_node(&mut self) -> usize {
        self.nodes.push(Vec::new());
        self.nodes.len() - 1
    }

    /// Appends a track absent everywhere to `node`; returns its index.
    pub fn push_track(&mut self, node: usize) -> usize {
        let mut track = Track::new(self.times.len(), self.dim);
        track.first = self.first;
        self.nodes[node].push(track);
        self.nodes[node].len() - 1
    }

    /// Marks a track absent at every held instant (its slot can be reused).
    pub fn clear_track(&mut self, node: usize, track: usize) {
        let t = &mut self.nodes[node][track];
        t.present.fill(false);
        t.gain_factor = None;
    }

    /// Track `track` of node `node`, to set its estimates.
    pub fn track_mut(&mut self, node: usize, track: usize) -> &mut Track {
        &mut self.nodes[node][track]
    }

    /// The tracks of every node, by node index.
    pub fn nodes(&self) -> &[Vec<Track>] {
        &self.nodes
    }

    /// Track `track` of node `node`.
    pub fn track(&self, node: usize, track: usize) -> &Track {
        &self.nodes[node][track]
    }
}

impl Track {
    /// A track absent at every one of `instants` instants.
    pub fn new(instants: usize, dim: usize) -> Self {
        Self {
            first: 0,
            present: vec![false; instants],
            x: vec![0.0; instants * dim],
            p: vec![0.0; instants * dim * dim],
            gain_factor: None,
        }
    }

    fn grow(&mut self, dim: usize) {
        self.present.push(false);
        self.x.extend(std::iter::repeat_n(0.0, dim));
        self.p.extend(std::iter::repeat_n(0.0, dim * dim));
        if let Some(g) = &mut self.gain_factor {
            g.extend(std::iter::repeat_n(f64::NAN, dim * dim));
        }
    }

    fn drop_front(&mut self, n: usize, dim: usize) {
        self.present.drain(..n);
        self.x.drain(..n * dim);
        self.p.drain(..n * dim * dim);
        if let Some(g) = &mut self.gain_factor {
            g.drain(..n * dim * dim);
        }
        self.first += n;
    }

    /// Sets the estimate at instant `k`; `p` is row-major. The caller has
    /// checked finiteness and positive definiteness.
    pub fn set(&mut self, k: usize, x: &[f64], p: &[f64]) {
        let dim = x.len();
        let k = k - self.first;
        self.present[k] = true;
        self.x[k * dim..(k + 1) * dim].copy_from_slice(x);
        self.p[k * dim * dim..(k + 1) * dim * dim].copy_from_slice(p);
    }

    /// Sets the reported filter factor I − K H at instant `k` (row-major),
    /// used by the cross-covariance recursion of seed 000 eq. 13.
    pub fn set_gain_factor(&mut self, k: usize, factor: &[f64]) {
        let n2 = factor.len();
        let k = k - self.first;
        let instants = self.present.len();
        let g = self
            .gain_factor
            .get_or_insert_with(|| vec![f64::NAN; instants * n2]);
        g[k * n2..(k + 1) * n2].copy_from_slice(factor);
    }

    /// Whether the track has an estimate at global instant `k` (false
    /// outside the held window).
    pub fn is_present(&self, k: usize) -> bool {
        k >= self.first && self.present.get(k - self.first).copied().unwrap_or(false)
    }

    /// The state at global instant `k` (present there), `dim` values.
    pub fn x(&self, k: usize, dim: usize) -> &[f64] {
        let k = k - self.first;
        &self.x[k * dim..(k + 1) * dim]
    }

    /// The covariance at global instant `k` (present there), `dim` × `dim`
    /// values row-major.
    pub fn p(&self, k: usize, dim: usize) -> &[f64] {
        let k = k - self.first;
        &self.p[k * dim * dim..(k + 1) * dim * dim]
    }

    /// The reported I − K H at instant `k`, if the client sent gains for it.
    pub fn gain_factor(&self, k: usize, dim: usize) -> Option<&[f64]> {
        let g = self.gain_factor.as_ref()?;
        let k = k - self.first;
        let s = &g[k * dim * dim..(k + 1) * dim * dim];
        s[0].is_finite().then_some(s)
    }

    /// The last instant before `k` where the track is present.
    pub fn previous(&self, k: usize) -> Option<usize> {
        (self.first..k).rev().find(|&j| self.is_present(j))
    }
}
