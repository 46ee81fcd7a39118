//! The persisted state of a [`PairCorrelator`]: [`CorrelatorState`] and its
//! byte encoding (stored by streaming sessions; the format is fixed).

use std::collections::VecDeque;

use super::{Pair, REASONS, Sample, Side, Status};
use crate::{
    AlgoError,
    wire::{Reader, Writer},
};

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

const STATUSES: [Status; 3] = [Status::Testing, Status::Stopped, Status::Decided];

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
                p.status == Status::Decided,
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

    /// Appends the state to `w` (the format of [`CorrelatorState::decode`]);
    /// matrices hold `dim` × `dim` values.
    pub fn encode(&self, w: &mut Writer, dim: usize) {
        w.usize(self.next);
        w.usize(self.singular_tests);
        for partners in [&self.partner_a, &self.partner_b] {
            w.usize(partners.len());
            for p in partners {
                w.opt(*p, |w, v| w.u32(v));
            }
        }
        w.usize(self.pairs.len());
        for p in &self.pairs {
            w.u32(p.a);
            w.u32(p.b);
            w.u8(STATUSES
                .iter()
                .position(|&s| s == p.status)
                .expect("listed") as u8);
            w.u8(REASONS.iter().position(|&r| r == p.reason).expect("listed") as u8);
            w.bool(p.trial);
            w.u32(p.l);
            w.u32(p.m);
            w.u32(p.c);
            w.f64(p.sum_stat);
            w.f64(p.sum_posdiff);
            w.bool(p.cycle_done);
            w.opt(p.decided_at, Writer::usize);
            w.opt(p.decided_time, Writer::f64);
            w.usize(p.hist.len());
            for h in &p.hist {
                w.u32(h.k);
                w.f64(h.stat);
                w.f64(h.posdiff);
                w.bool(h.hit);
            }
            w.opt(p.cross.as_deref(), |w, c| {
                for &v in &c[..dim * dim] {
                    w.f64(v);
                }
            });
            w.opt(p.last_common, Writer::usize);
        }
    }

    /// Reads a state written by [`CorrelatorState::encode`], checking every
    /// index so that a corrupt buffer cannot make the engine panic later.
    pub fn decode(r: &mut Reader<'_>, dim: usize) -> Result<Self, AlgoError> {
        let next = r.usize()?;
        let singular_tests = r.usize()?;
        let mut partners = [Vec::new(), Vec::new()];
        for list in &mut partners {
            let n = r.len(1)?;
            *list = (0..n)
                .map(|_| r.opt(Reader::u32))
                .collect::<Result<_, _>>()?;
        }
        let [partner_a, partner_b] = partners;
        let n = r.len(40)?;
        let mut pairs = Vec::with_capacity(n);
        for _ in 0..n {
            let a = r.u32()?;
            let b = r.u32()?;
            let status = *STATUSES
                .get(r.u8()? as usize)
                .ok_or_else(|| bad("status"))?;
            let reason = *REASONS.get(r.u8()? as usize).ok_or_else(|| bad("reason"))?;
            let trial = r.bool()?;
            let (l, m, c) = (r.u32()?, r.u32()?, r.u32()?);
            let (sum_stat, sum_posdiff) = (r.f64()?, r.f64()?);
            let cycle_done = r.bool()?;
            let decided_at = r.opt(Reader::usize)?;
            let decided_time = r.opt(Reader::f64)?;
            let h = r.len(21)?;
            let mut hist = VecDeque::with_capacity(h);
            for _ in 0..h {
                hist.push_back(Sample {
                    k: r.u32()?,
                    stat: r.f64()?,
                    posdiff: r.f64()?,
                    hit: r.bool()?,
                });
            }
            let cross = r.opt(|r| (0..dim * dim).map(|_| r.f64()).collect())?;
            let last_common = r.opt(Reader::usize)?;
            if a as usize >= partner_a.len() || b as usize >= partner_b.len() {
                return Err(bad("pair names an unknown track"));
            }
            pairs.push(Pair {
                a,
                b,
                status,
                reason,
                trial,
                l,
                m,
                c,
                sum_stat,
                sum_posdiff,
                cycle_done,
                decided_at,
                decided_time,
                hist,
                cross,
                last_common,
            });
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
