//! Correlation across M ≥ 2 nodes: pairwise decisions of every node pair are
//! merged into groups, strongest first, so that no group holds two tracks of
//! one node and every track is in at most one group. A decision that would
//! break that is rejected and reported as a conflict.

use std::collections::BTreeMap;

/// A track named by (node index, track index).
pub type TrackRef = (usize, usize);

/// A correlated pair with its strength: larger m first, then smaller mean
/// statistic (the order of eqs. 18–20).
#[derive(Debug, Clone, PartialEq)]
pub struct Link {
    /// One track of the pair.
    pub a: TrackRef,
    /// The other track, of another node.
    pub b: TrackRef,
    /// Correlation quality m: samples passing the first threshold.
    pub m: u32,
    /// Mean test statistic over the pair's samples.
    pub mean_statistic: f64,
}

/// A rejected link and the track it collided with.
#[derive(Debug, Clone, PartialEq)]
pub struct Conflict {
    /// The rejected link.
    pub link: Link,
    /// The node that would hold two tracks in one group.
    pub node: usize,
    /// Its two tracks that the link would have joined.
    pub tracks: (usize, usize),
}

/// Groups of correlated tracks (each sorted, the groups sorted by their
/// first member) and the links rejected to keep them consistent.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Grouping {
    /// Groups of correlated tracks.
    pub groups: Vec<Vec<TrackRef>>,
    /// Links rejected because they would put two tracks of one node in a
    /// group.
    pub conflicts: Vec<Conflict>,
}

/// Merges links strongest first (Kruskal-like), refusing any merge that would
/// put two tracks of one node in a group.
pub fn group(links: &[Link]) -> Grouping {
    let mut order: Vec<usize> = (0..links.len()).collect();
    order.sort_by(|&i, &j| {
        let (x, y) = (&links[i], &links[j]);
        y.m.cmp(&x.m)
            .then(x.mean_statistic.total_cmp(&y.mean_statistic))
            .then(x.a.cmp(&y.a))
            .then(x.b.cmp(&y.b))
    });
    // Each group: node → track.
    let mut groups: Vec<BTreeMap<usize, usize>> = Vec::new();
    let mut group_of: BTreeMap<TrackRef, usize> = BTreeMap::new();
    let mut conflicts = Vec::new();
    for i in order {
        let link = &links[i];
        let ga = group_of.get(&link.a).copied();
        let gb = group_of.get(&link.b).copied();
        match (ga, gb) {
            (Some(x), Some(y)) if x == y => {}
            (Some(x), Some(y)) => {
                let clash = groups[x]
                    .iter()
                    .find_map(|(n, t)| groups[y].get(n).map(|u| (*n, (*t, *u))));
                if let Some((node, tracks)) = clash {
                    conflicts.push(Conflict {
                        link: link.clone(),
                        node,
                        tracks,
                    });
                } else {
                    let moved = std::mem::take(&mut groups[y]);
                    for (n, t) in moved {
                        groups[x].insert(n, t);
                        group_of.insert((n, t), x);
                    }
                }
            }
            (Some(x), None) | (None, Some(x)) => {
                let new = if ga.is_some() { link.b } else { link.a };
                if let Some(&t) = groups[x].get(&new.0) {
                    conflicts.push(Conflict {
                        link: link.clone(),
                        node: new.0,
                        tracks: (t, new.1),
                    });
                } else {
                    groups[x].insert(new.0, new.1);
                    group_of.insert(new, x);
                }
            }
            (None, None) => {
                if link.a.0 == link.b.0 {
                    conflicts.push(Conflict {
                        link: link.clone(),
                        node: link.a.0,
                        tracks: (link.a.1, link.b.1),
                    });
                    continue;
                }
                let mut g = BTreeMap::new();
                g.insert(link.a.0, link.a.1);
                g.insert(link.b.0, link.b.1);
                groups.push(g);
                group_of.insert(link.a, groups.len() - 1);
                group_of.insert(link.b, groups.len() - 1);
            }
        }
    }
    let mut out: Vec<Vec<TrackRef>> = groups
        .into_iter()
        .filter(|g| g.len() >= 2)
        .map(|g| g.into_iter().collect())
        .collect();
    out.sort();
    Grouping {
        groups: out,
        conflicts,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn link(a: TrackRef, b: TrackRef, m: u32, mean: f64) -> Link {
        Link {
            a,
            b,
            m,
            mean_statistic: mean,
        }
    }

    #[test]
    fn three_nodes_agreeing_form_one_group() {
        let g = group(&[
            link((0, 1), (1, 4), 8, 1.0),
            link((1, 4), (2, 0), 8, 1.0),
            link((0, 1), (2, 0), 7, 2.0),
        ]);
        assert_eq!(g.groups, vec![vec![(0, 1), (1, 4), (2, 0)]]);
        assert!(g.conflicts.is_empty());
    }

    #[test]
    fn a_weaker_link_that_would_double_a_node_is_a_conflict() {
        // A1–B4 and B4–C0 are strong; A2–C0 would put A1 and A2 together.
        let g = group(&[
            link((0, 1), (1, 4), 8, 1.0),
            link((1, 4), (2, 0), 8, 1.5),
            link((0, 2), (2, 0), 6, 0.5),
        ]);
        assert_eq!(g.groups, vec![vec![(0, 1), (1, 4), (2, 0)]]);
        assert_eq!(g.conflicts.len(), 1);
        assert_eq!(g.conflicts[0].node, 0);
        assert_eq!(g.conflicts[0].tracks, (1, 2));
    }

    #[test]
    fn merging_two_groups_is_refused_when_they_share_a_node() {
        // {A1, B1} and {A2, C1} exist; B1–C1 would join A1 and A2.
        let g = group(&[
            link((0, 1), (1, 1), 8, 1.0),
            link((0, 2), (2, 1), 8, 1.0),
            link((1, 1), (2, 1), 5, 1.0),
        ]);
        assert_eq!(g.groups.len(), 2);
        assert_eq!(g.conflicts.len(), 1);
        assert_eq!(g.conflicts[0].tracks, (1, 2));
    }
}
