//! Binary encoding of a track-to-track correlator's state
//! ([`CorrelatorState`]: its candidate pairs with their counters, history
//! windows and cross-covariances, and the decided partners), with
//! [`wire_formats::wire`]. The layout is fixed: stored sessions of every earlier
//! version use it.

use std::collections::VecDeque;

use algo::correlation::engine::{CorrelatorState, PAIR_STATUSES, Pair, REASONS, Sample};

use wire_formats::wire::{FormatError, Reader, Writer, corrupt, invalid};

/// Appends `state` to `w` (the format of [`decode_correlator`]); matrices
/// hold `dim` × `dim` values.
pub fn encode_correlator(state: &CorrelatorState, w: &mut Writer, dim: usize) {
    w.usize(state.next());
    w.usize(state.singular_tests());
    let (partner_a, partner_b) = state.partners();
    for partners in [partner_a, partner_b] {
        w.usize(partners.len());
        for p in partners {
            w.opt(*p, |w, v| w.u32(v));
        }
    }
    w.usize(state.pairs().len());
    for p in state.pairs() {
        w.u32(p.a);
        w.u32(p.b);
        w.u8(PAIR_STATUSES
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

/// Reads a state written by [`encode_correlator`]; every index is checked
/// ([`CorrelatorState::from_parts`]) so that a corrupt buffer cannot make
/// the engine panic later.
pub fn decode_correlator(r: &mut Reader<'_>, dim: usize) -> Result<CorrelatorState, FormatError> {
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
        let status = *PAIR_STATUSES
            .get(r.u8()? as usize)
            .ok_or_else(|| corrupt("correlator pair status"))?;
        let reason = *REASONS
            .get(r.u8()? as usize)
            .ok_or_else(|| corrupt("correlator pair reason"))?;
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
    CorrelatorState::from_parts(pairs, (partner_a, partner_b), next, singular_tests, dim)
        .map_err(invalid)
}
