//! Grouping and fusion: the correlated (and trial) pairs of every node pair
//! grouped consistently across nodes (`algo::correlation::grouping`), each
//! group fused into a system track at its latest well-covered instant.

use std::collections::HashMap;

use nalgebra::{DMatrix, DVector};

use algo::correlation::{
    engine::{Decision, PairReport},
    fusion,
    grouping::{self, Link},
    scene::Scene,
};

use super::{FusionKind, GroupOutput, Plan, TrackName};

/// Cross-covariance of each correlated pair ((node, track), (node, track)) at
/// its last common instant: (instant index, row-major P_ab).
pub(crate) type CrossCovariances = HashMap<((usize, usize), (usize, usize)), (usize, Vec<f64>)>;

/// The correlated and trial pairs of every node pair, as grouping links,
/// with the cross-covariances of the correlated ones for the fusion.
#[derive(Debug, Default)]
pub(crate) struct Links {
    pub(crate) correlated: Vec<Link>,
    /// Trial system tracks (eq. 21): undecided pairs provisionally paired.
    pub(crate) trial: Vec<Link>,
    pub(crate) cross: CrossCovariances,
}

impl Links {
    /// Records pair report `r` of nodes `na`, `nb`.
    pub(crate) fn collect(&mut self, r: &PairReport, na: usize, nb: usize) {
        let link = Link {
            a: (na, r.a),
            b: (nb, r.b),
            m: r.m,
            mean_statistic: r.mean_statistic,
        };
        if r.decision == Decision::Correlated {
            self.correlated.push(link);
            if let Some(c) = &r.cross_covariance {
                self.cross
                    .insert(((na, r.a), (nb, r.b)), (r.last_common, c.clone()));
            }
        } else if r.trial {
            self.trial.push(link);
        }
    }
}

/// The system tracks: the groups of correlated tracks, then the trial
/// groups (trial pairs among tracks in no correlated group, flagged
/// `trial`), each fused at its latest well-covered instant. Returns the
/// correlated grouping too (its conflicts), and every track in a group.
pub(crate) fn system_tracks(
    scene: &Scene,
    plan: &Plan,
    links: &Links,
    name: impl Fn(usize, usize) -> TrackName,
) -> (
    grouping::Grouping,
    std::collections::HashSet<(usize, usize)>,
    Vec<GroupOutput>,
) {
    let dim = plan.layout.dim;
    let grouping = grouping::group(&links.correlated);
    let mut grouped: std::collections::HashSet<(usize, usize)> =
        grouping.groups.iter().flatten().copied().collect();
    let free: Vec<Link> = links
        .trial
        .iter()
        .filter(|l| !grouped.contains(&l.a) && !grouped.contains(&l.b))
        .cloned()
        .collect();
    let trial = grouping::group(&free);
    grouped.extend(trial.groups.iter().flatten().copied());
    let all = grouping
        .groups
        .iter()
        .map(|g| (g, false))
        .chain(trial.groups.iter().map(|g| (g, true)));
    let groups = all
        .enumerate()
        .map(|(id, (members, is_trial))| {
            let fused = if plan.fuse {
                fuse_group(scene, members, &links.cross, dim)
            } else {
                None
            };
            let (t, state, covariance, fusion) = match fused {
                Some((k, f, kind)) => (
                    scene.time(k),
                    plan.layout.vector_to_request(f.x.as_slice()),
                    plan.layout.matrix_to_request(&f.p),
                    kind,
                ),
                None => (f64::NAN, Vec::new(), Vec::new(), FusionKind::None),
            };
            GroupOutput {
                id: id as u32,
                members: members.iter().map(|&(n, t)| name(n, t)).collect(),
                t,
                state,
                covariance,
                fusion,
                trial: is_trial,
            }
        })
        .collect();
    (grouping, grouped, groups)
}

/// Fuses a group at the latest instant where most of its members are present:
/// Bar-Shalom–Campo for two members with a known cross-covariance at that
/// instant, covariance intersection otherwise.
pub(crate) fn fuse_group(
    scene: &Scene,
    members: &[(usize, usize)],
    cross: &CrossCovariances,
    dim: usize,
) -> Option<(usize, fusion::Fused, FusionKind)> {
    let count = |k: usize| {
        members
            .iter()
            .filter(|&&(n, t)| scene.track(n, t).is_present(k))
            .count()
    };
    let best = (scene.first()..scene.end())
        .rev()
        .max_by_key(|&k| (count(k), k))?;
    let present: Vec<(usize, usize)> = members
        .iter()
        .copied()
        .filter(|&(n, t)| scene.track(n, t).is_present(best))
        .collect();
    let est = |&(n, t): &(usize, usize)| {
        let tr = scene.track(n, t);
        (
            DVector::from_column_slice(tr.x(best, dim)),
            DMatrix::from_row_slice(dim, dim, tr.p(best, dim)),
        )
    };
    match present.as_slice() {
        [] => None,
        [one] => {
            let (x, p) = est(one);
            Some((
                best,
                fusion::Fused {
                    x,
                    p,
                    weights: Vec::new(),
                },
                FusionKind::Single,
            ))
        }
        [a, b] => {
            let (xa, pa) = est(a);
            let (xb, pb) = est(b);
            if let Some((k, c)) = cross.get(&(*a, *b))
                && *k == best
            {
                let p12 = DMatrix::from_row_slice(dim, dim, c);
                if let Ok(f) = fusion::bar_shalom_campo(&xa, &pa, &xb, &pb, &p12) {
                    return Some((best, f, FusionKind::BarShalomCampo));
                }
            }
            fusion::covariance_intersection(&[(xa, pa), (xb, pb)])
                .ok()
                .map(|f| (best, f, FusionKind::CovarianceIntersection))
        }
        many => {
            let list: Vec<_> = many.iter().map(est).collect();
            fusion::covariance_intersection(&list)
                .ok()
                .map(|f| (best, f, FusionKind::CovarianceIntersection))
        }
    }
}
