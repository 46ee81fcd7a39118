//! The input of track-to-track correlation: local tracks of several nodes,
//! already aligned to common instants (the service does the alignment), in
//! flat row-major buffers so that the hot loops do not allocate.
//!
//! Instants have global indices. A batch scene holds instants 0..n; a
//! streaming session appends instants with [`Scene::push_instant`] and drops
//! old ones with [`Scene::trim_before`], so it holds the window
//! [`Scene::first`]..[`Scene::end`]; a track is absent outside the window.

use crate::{
    AlgoError,
    small::MAX_DIM,
    wire::{self, Reader, Writer},
};

/// The scene's encoding written by [`Scene::encode`].
pub const SCENE_FORMAT: u8 = 2;
/// Instant tag bits of scene format 2.
const TAG_PRESENT: u8 = 1;
const TAG_SYMMETRIC: u8 = 2;
const TAG_GAIN: u8 = 4;

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

    /// Appends the scene to `w` (the current format, [`SCENE_FORMAT`]).
    /// Each held instant of a track takes one tag byte: 0 when absent, else
    /// [`TAG_PRESENT`], plus [`TAG_SYMMETRIC`] when the covariance is
    /// bit-for-bit symmetric (then only its upper triangle, row by row, is
    /// written) and [`TAG_GAIN`] when a filter factor follows. Lossless:
    /// decoding gives back the same bits.
    pub fn encode(&self, w: &mut Writer) {
        let dim = self.dim;
        w.usize(dim);
        w.usize(self.pos.len());
        for &i in &self.pos {
            w.usize(i);
        }
        w.usize(self.first);
        w.f64s(&self.times);
        w.usize(self.nodes.len());
        // One reservation for the whole scene instead of the buffer doubling
        // and copying itself as it grows: a tag per instant, and for each
        // present one at most the state, a full covariance and the gain.
        let bytes: usize = self
            .nodes
            .iter()
            .flatten()
            .map(|t| {
                let present = t.present.iter().filter(|&&p| p).count();
                let per = dim + dim * dim + t.gain_factor.as_ref().map_or(0, |_| dim * dim);
                8 + t.present.len() + present * 8 * per
            })
            .sum();
        w.buf.reserve(bytes);
        for node in &self.nodes {
            w.usize(node.len());
            for t in node {
                for k in 0..t.present.len() {
                    if !t.present[k] {
                        w.u8(0);
                        continue;
                    }
                    let p = &t.p[k * dim * dim..(k + 1) * dim * dim];
                    let symmetric = (0..dim).all(|i| {
                        (i + 1..dim).all(|j| p[i * dim + j].to_bits() == p[j * dim + i].to_bits())
                    });
                    let g = t
                        .gain_factor
                        .as_ref()
                        .map(|g| &g[k * dim * dim..(k + 1) * dim * dim])
                        .filter(|g| g[0].is_finite());
                    let mut tag = TAG_PRESENT;
                    if symmetric {
                        tag |= TAG_SYMMETRIC;
                    }
                    if g.is_some() {
                        tag |= TAG_GAIN;
                    }
                    w.u8(tag);
                    w.f64_run(&t.x[k * dim..(k + 1) * dim]);
                    if symmetric {
                        for i in 0..dim {
                            w.f64_run(&p[i * dim + i..(i + 1) * dim]);
                        }
                    } else {
                        w.f64_run(p);
                    }
                    if let Some(g) = g {
                        w.f64_run(g);
                    }
                }
            }
        }
    }

    /// Reads a scene written by [`Scene::encode`] in scene format `format`:
    /// 1 (one presence byte, full covariances, an optional filter factor) or
    /// 2 ([`SCENE_FORMAT`], tagged instants).
    pub fn decode(r: &mut Reader<'_>, format: u8) -> Result<Self, AlgoError> {
        if !(1..=SCENE_FORMAT).contains(&format) {
            return Err(wire::corrupt(&format!("scene format {format} is unknown")));
        }
        let dim = r.usize()?;
        let npos = r.len(8)?;
        let pos = (0..npos)
            .map(|_| r.usize())
            .collect::<Result<Vec<_>, _>>()?;
        let first = r.usize()?;
        let times = r.f64s()?;
        let mut scene = Scene::new(dim, pos, times)?;
        scene.first = first;
        let floats = |r: &mut Reader<'_>, n: usize| -> Result<Vec<f64>, AlgoError> {
            (0..n).map(|_| r.f64()).collect()
        };
        let n_nodes = r.len(8)?;
        let mut p = vec![0.0; dim * dim];
        for _ in 0..n_nodes {
            let node = scene.push_node();
            let n_tracks = r.len(scene.times.len())?;
            for _ in 0..n_tracks {
                let ti = scene.push_track(node);
                for k in first..scene.end() {
                    let tag = if format == 1 {
                        u8::from(r.bool()?)
                    } else {
                        r.u8()?
                    };
                    if tag == 0 {
                        continue;
                    }
                    if tag & !(TAG_PRESENT | TAG_SYMMETRIC | TAG_GAIN) != 0
                        || tag & TAG_PRESENT == 0
                    {
                        return Err(wire::corrupt(&format!("unknown instant tag {tag:#04x}")));
                    }
                    let x = floats(r, dim)?;
                    if tag & TAG_SYMMETRIC != 0 {
                        for i in 0..dim {
                            for j in i..dim {
                                let v = r.f64()?;
                                p[i * dim + j] = v;
                                p[j * dim + i] = v;
                            }
                        }
                    } else {
                        p = floats(r, dim * dim)?;
                    }
                    let g = if format == 1 {
                        r.opt(|r| floats(r, dim * dim))?
                    } else if tag & TAG_GAIN != 0 {
                        Some(floats(r, dim * dim)?)
                    } else {
                        None
                    };
                    let track = scene.track_mut(node, ti);
                    track.set(k, &x, &p);
                    if let Some(g) = g {
                        track.set_gain_factor(k, &g);
                    }
                }
            }
        }
        Ok(scene)
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Every held value of two scenes, as bits (so that -0.0 ≠ 0.0).
    fn bits(s: &Scene) -> Vec<u64> {
        let dim = s.dim();
        let mut out: Vec<u64> = s.times().iter().map(|t| t.to_bits()).collect();
        for node in s.nodes() {
            for t in node {
                for k in s.first()..s.end() {
                    out.push(u64::from(t.is_present(k)));
                    if t.is_present(k) {
                        out.extend(t.x(k, dim).iter().map(|v| v.to_bits()));
                        out.extend(t.p(k, dim).iter().map(|v| v.to_bits()));
                        out.extend(
                            t.gain_factor(k, dim)
                                .into_iter()
                                .flatten()
                                .map(|v| v.to_bits()),
                        );
                    }
                }
            }
        }
        out
    }

    #[test]
    fn the_encoding_is_lossless_and_stores_symmetric_covariances_as_triangles() {
        let mut s = Scene::new(2, vec![0], vec![]).unwrap();
        for t in [0.0, 1.0, 2.0] {
            s.push_instant(t).unwrap();
        }
        let node = s.push_node();
        let (a, b) = (s.push_track(node), s.push_track(node));
        // Symmetric, with a -0.0 off the diagonal mirrored exactly.
        s.track_mut(node, a)
            .set(0, &[1.0, 2.0], &[4.0, -0.0, -0.0, 9.0]);
        // Asymmetric in the last bit, and 0.0 against -0.0: kept whole.
        let off = 0.1_f64;
        let off2 = f64::from_bits(off.to_bits() + 1);
        s.track_mut(node, a)
            .set(2, &[3.0, 4.0], &[4.0, off, off2, 9.0]);
        s.track_mut(node, b)
            .set(1, &[5.0, 6.0], &[1.0, 0.0, -0.0, 1.0]);
        s.track_mut(node, b)
            .set_gain_factor(1, &[0.5, 0.25, 0.125, 0.75]);
        let mut w = Writer::default();
        s.encode(&mut w);
        let back = Scene::decode(&mut Reader::new(&w.buf), SCENE_FORMAT).unwrap();
        assert_eq!(bits(&back), bits(&s));
        // Re-encoding gives the same bytes.
        let mut w2 = Writer::default();
        back.encode(&mut w2);
        assert_eq!(w2.buf, w.buf);
        // Size: the header is 7 counts and indices (dim, position count, the
        // position, first, time count, node count, track count) and 3 times:
        // (7 + 3) × 8 bytes; then 6 tag bytes, and 3 states of 2 values, the
        // symmetric covariance's 3 values, the two others' 4 each and the
        // gain factor's 4: (6 + 3 + 8 + 4) × 8 bytes.
        assert_eq!(w.buf.len(), (7 + 3) * 8 + 6 + (6 + 3 + 8 + 4) * 8);
        // A bad tag, and an unknown format, are errors.
        let mut bad = w.buf.clone();
        bad[(7 + 3) * 8] = 0x80;
        assert!(Scene::decode(&mut Reader::new(&bad), SCENE_FORMAT).is_err());
        assert!(Scene::decode(&mut Reader::new(&w.buf), SCENE_FORMAT + 1).is_err());
    }
}
