//! The persisted state of a [`PairCorrelator`]: [`CorrelatorState`], laid
//! open through its parts so that a codec outside this crate (the `formats`
//! crate) can store it for streaming sessions.

use super::{Pair, PairStatus, Side};
use crate::AlgoError;

/// The evolving state of a [`PairCorrelator`] (its candidate pairs with
/// their counters, history windows and cross-covariances, the decided
/// partners and the next instant), detached from the scene so that a
/// streaming session can keep it between batches and persist it.
#[derive(Debug, Clone, Default)]
pub struct CorrelatorState {
    pub(super) pairs: Vec<Pair>,
    pub(super) partner_a: Vec<Option<u32>>,
    pub(super) partner_b: Vec<Option<u32>>,
    pub(super) next: usize,
    pub(super) singular_tests: usize,
}

pub(super) fn bad(reason: &str) -> AlgoError {
    AlgoError::InvalidParameter {
        what: "state",
        reason: format!("corrupt correlator state: {reason}"),
    }
}

impl CorrelatorState {
    /// The next instant (global index) the correlator will process.
    pub fn next(&self) -> usize {
        self.next
    }

    /// Every candidate pair as (track in a, track in b, decided correlated,
    /// trial system track), in the order held.
    pub fn links(&self) -> impl Iterator<Item = (usize, usize, bool, bool)> + '_ {
        self.pairs.iter().map(|p| {
            (
                p.a as usize,
                p.b as usize,
                p.status == PairStatus::Decided,
                p.trial,
            )
        })
    }

    /// Candidate pairs held.
    pub fn pair_count(&self) -> usize {
        self.pairs.len()
    }

    /// Forgets every pair of track `t` on `side` (a retired track): its
    /// decided partner, if any, becomes free.
    pub fn release(&mut self, side: Side, t: usize) {
        let t = t as u32;
        let gone = |p: &Pair| match side {
            Side::A => p.a == t,
            Side::B => p.b == t,
        };
        if !self.pairs.iter().any(gone) {
            return;
        }
        let mut remap = vec![None; self.pairs.len()];
        let mut kept = Vec::with_capacity(self.pairs.len());
        for (i, p) in std::mem::take(&mut self.pairs).into_iter().enumerate() {
            if !gone(&p) {
                remap[i] = Some(kept.len() as u32);
                kept.push(p);
            }
        }
        self.pairs = kept;
        for slot in self.partner_a.iter_mut().chain(self.partner_b.iter_mut()) {
            *slot = slot.and_then(|pi| remap[pi as usize]);
        }
    }

    /// The candidate pairs, in the order held.
    pub fn pairs(&self) -> &[Pair] {
        &self.pairs
    }

    /// Each track's decided pair (an index into [`CorrelatorState::pairs`])
    /// in the first node and in the second.
    pub fn partners(&self) -> (&[Option<u32>], &[Option<u32>]) {
        (&self.partner_a, &self.partner_b)
    }

    /// Tests whose modified S was not positive definite so far.
    pub fn singular_tests(&self) -> usize {
        self.singular_tests
    }

    /// A state from its parts (as [`CorrelatorState::pairs`],
    /// [`CorrelatorState::partners`], [`CorrelatorState::next`] and
    /// [`CorrelatorState::singular_tests`] gave them). Every index is
    /// checked, and every cross-covariance's size against `dim`, so that
    /// parts read from corrupt bytes cannot make the engine panic later.
    pub fn from_parts(
        pairs: Vec<Pair>,
        partners: (Vec<Option<u32>>, Vec<Option<u32>>),
        next: usize,
        singular_tests: usize,
        dim: usize,
    ) -> Result<Self, AlgoError> {
        let (partner_a, partner_b) = partners;
        for p in &pairs {
            if p.a as usize >= partner_a.len() || p.b as usize >= partner_b.len() {
                return Err(bad("pair names an unknown track"));
            }
            if p.cross.as_ref().is_some_and(|c| c.len() != dim * dim) {
                return Err(bad("cross-covariance size"));
            }
        }
        let n_pairs = pairs.len();
        if partner_a
            .iter()
            .chain(&partner_b)
            .flatten()
            .any(|&pi| pi as usize >= n_pairs)
        {
            return Err(bad("partner names an unknown pair"));
        }
        Ok(Self {
            pairs,
            partner_a,
            partner_b,
            next,
            singular_tests,
        })
    }
}
