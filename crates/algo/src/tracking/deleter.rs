//! Deletion of confirmed tracks (seed 001 step 7c "delete the tracks that
//! keep finding no plot in their gate", step 8): any configured rule
//! deletes — K consecutive missed frames, M_d misses among the last N_d
//! frames (MATLAB `trackHistoryLogic`'s deletion threshold), or a
//! horizontal position standard deviation √(P_xx + P_yy) above a bound
//! (the height is left out so that a 3D tracker fed by 2D radars, whose
//! height is never measured, is not deleted for it); and [`duplicates`],
//! the tracks that follow the same target as an older one.

use crate::error::AlgoError;
use crate::gating::chi2_threshold;
use crate::gaussian::mahalanobis_sq;
use crate::tracking::config::Deletion;
use crate::tracking::track::Track;

/// `true` when `track` must be deleted under `rule`.
pub(crate) fn should_delete(track: &Track, rule: &Deletion) -> bool {
    let consecutive = rule
        .max_consecutive_misses
        .is_some_and(|k| track.consecutive_misses >= k);
    let m_of_n = rule
        .misses_m_of_n
        .is_some_and(|(m, n)| track.misses_in_last(n) >= m);
    let sigma = rule
        .max_position_sigma
        .is_some_and(|s| horizontal_sigma(track) > s);
    consecutive || m_of_n || sigma
}

/// √(P_xx + P_yy) of an interleaved state.
pub(crate) fn horizontal_sigma(track: &Track) -> f64 {
    (track.p[(0, 0)] + track.p[(2, 2)]).sqrt()
}

/// Which confirmed tracks duplicate another: two tracks whose best plot of
/// this frame (`hits`: (track index, plot index)) is the same plot and
/// whose states are statistically indistinguishable, (x₁ − x₂)′(P₁ +
/// P₂)⁻¹(x₁ − x₂) below the χ²_n quantile at `probability` (n the state
/// size; P₁ + P₂ ignores the correlation of two tracks fed the same plots,
/// so the test is conservative). Of such a pair the track with fewer hits
/// (then the higher id) is the duplicate. JPDA feeds both tracks of a
/// target from its plots, so neither would ever miss; without this they
/// live on side by side. Two tracks that share their best plot and carry
/// the same Mode S address are duplicates whatever their states (one
/// aircraft); two that carry different Mode S addresses or different AIS
/// MMSIs never are (two transponders: ships moored side by side, aircraft
/// in formation, whose plots the tracks share). `probability` 0 disables
/// the rule. Returns the duplicates' indices.
pub(super) fn duplicates<T: std::borrow::Borrow<Track>>(
    tracks: &[T],
    hits: &[(usize, usize)],
    probability: f64,
) -> Result<Vec<usize>, AlgoError> {
    let tracks = |i: usize| -> &Track { tracks[i].borrow() };
    let mut out = Vec::new();
    if probability <= 0.0 || hits.len() < 2 {
        return Ok(out);
    }
    let n = tracks(0).x.len();
    let threshold = chi2_threshold(n, 1.0 - probability)?;
    // Tracks by their best plot; only tracks sharing one are compared.
    let mut by_plot: Vec<(usize, usize)> = hits.iter().map(|&(i, j)| (j, i)).collect();
    by_plot.sort_unstable();
    for group in by_plot.chunk_by(|a, b| a.0 == b.0) {
        if group.len() < 2 {
            continue;
        }
        let mut members: Vec<usize> = group.iter().map(|&(_, i)| i).collect();
        members.sort_by(|&a, &b| {
            tracks(b)
                .hits
                .cmp(&tracks(a).hits)
                .then(tracks(a).id.cmp(&tracks(b).id))
        });
        let mut duplicate = vec![false; members.len()];
        for k in 0..members.len() {
            let i = members[k];
            for (m, &keeper) in members[..k].iter().enumerate() {
                if duplicate[m] {
                    continue;
                }
                // One Mode S address: one aircraft, whatever the states.
                let (a, b) = (&tracks(i).identity, &tracks(keeper).identity);
                let same_address = matches!(
                    (a.address, b.address),
                    (Some(a), Some(b)) if a.value == b.value
                );
                let differ =
                    |x: Option<u32>, y: Option<u32>| matches!((x, y), (Some(x), Some(y)) if x != y);
                if differ(a.address.map(|e| e.value), b.address.map(|e| e.value))
                    || differ(a.mmsi.map(|e| e.value), b.mmsi.map(|e| e.value))
                {
                    continue;
                }
                let d = &tracks(i).x - &tracks(keeper).x;
                let s = &tracks(i).p + &tracks(keeper).p;
                if same_address || mahalanobis_sq(&d, &s)? <= threshold {
                    duplicate[k] = true;
                    out.push(i);
                    break;
                }
            }
        }
    }
    out.sort_unstable();
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, dvector};

    /// An identity value seen in five plots.
    fn evidence(value: u32) -> Option<crate::tracking::identity::Evidence<u32>> {
        Some(crate::tracking::identity::Evidence {
            value,
            plots: 5,
            first_t: 0.0,
            last_t: 1.0,
        })
    }

    fn track(frames: &[bool], var: f64) -> Track {
        let mut t = Track::fresh(
            0,
            dvector![0.0, 0.0, 0.0, 0.0],
            DMatrix::identity(4, 4) * var,
        );
        for &h in frames {
            t.record(h.then(Vec::new));
        }
        t
    }

    #[test]
    fn two_tracks_of_one_mode_s_address_on_one_plot_are_one_aircraft() {
        // States 2 km apart (d² = 4·10⁶/200 = 20,000: never alike), the
        // same best plot: duplicates only when they carry one address.
        let p = DMatrix::<f64>::identity(4, 4) * 100.0;
        let mut a = Track::fresh(1, dvector![0.0, 100.0, 0.0, 0.0], p.clone());
        a.hits = 10;
        let mut b = Track::fresh(2, dvector![2000.0, 100.0, 0.0, 0.0], p);
        b.hits = 4;
        let none: Vec<usize> = Vec::new();
        let hits = [(0, 3), (1, 3)];
        assert_eq!(
            duplicates(&[a.clone(), b.clone()], &hits, 0.99).unwrap(),
            none
        );
        a.identity.address = evidence(0x4CA2D1);
        b.identity.address = evidence(0x4CA2D1);
        assert_eq!(
            duplicates(&[a.clone(), b.clone()], &hits, 0.99).unwrap(),
            vec![1]
        );
        b.identity.address = evidence(0x4CA2D2);
        assert_eq!(duplicates(&[a, b], &hits, 0.99).unwrap(), none);
    }

    #[test]
    fn alike_tracks_of_two_transponders_are_not_duplicates() {
        // Two ships moored 20 m apart, σ 100 m: alike (d² = 400/20,000 =
        // 0.02 ≪ the χ²₄ quantile), sharing their best plot: a duplicate,
        // unless their MMSIs (or Mode S addresses) differ.
        let p = DMatrix::<f64>::identity(4, 4) * 10_000.0;
        let mut a = Track::fresh(1, dvector![0.0, 0.0, 0.0, 0.0], p.clone());
        a.hits = 10;
        let mut b = Track::fresh(2, dvector![20.0, 0.0, 0.0, 0.0], p);
        b.hits = 4;
        let hits = [(0, 3), (1, 3)];
        assert_eq!(
            duplicates(&[a.clone(), b.clone()], &hits, 0.99).unwrap(),
            vec![1]
        );
        a.identity.mmsi = evidence(235_070_762);
        b.identity.mmsi = evidence(235_070_763);
        let none: Vec<usize> = Vec::new();
        assert_eq!(
            duplicates(&[a.clone(), b.clone()], &hits, 0.99).unwrap(),
            none
        );
        // The same MMSI: alike, so one ship.
        b.identity.mmsi = evidence(235_070_762);
        assert_eq!(
            duplicates(&[a.clone(), b.clone()], &hits, 0.99).unwrap(),
            vec![1]
        );
        // One MMSI and one unknown: alike, a duplicate.
        b.identity.mmsi = None;
        assert_eq!(
            duplicates(&[a.clone(), b.clone()], &hits, 0.99).unwrap(),
            vec![1]
        );
        a.identity.mmsi = None;
        a.identity.address = evidence(0x4CA2D1);
        b.identity.address = evidence(0x4CA2D2);
        assert_eq!(duplicates(&[a, b], &hits, 0.99).unwrap(), none);
    }

    #[test]
    fn each_rule_deletes_on_its_own() {
        let none = Deletion {
            max_consecutive_misses: None,
            misses_m_of_n: None,
            max_position_sigma: None,
        };
        let k3 = Deletion {
            max_consecutive_misses: Some(3),
            ..none
        };
        let m_of_n = Deletion {
            misses_m_of_n: Some((3, 5)),
            ..none
        };
        let sigma = Deletion {
            max_position_sigma: Some(100.0),
            ..none
        };
        // hit, miss, miss, hit, miss, miss: 2 consecutive, 4 misses of the last 5.
        let t = track(&[true, false, false, true, false, false], 1.0);
        assert!(!should_delete(&t, &none));
        assert!(!should_delete(&t, &k3));
        assert!(should_delete(&t, &m_of_n));
        assert!(!should_delete(&t, &sigma));
        let t = track(&[true, false, false, false], 1.0);
        assert!(should_delete(&t, &k3));
        // √(5001 + 5001) = 100.005 > 100; √(4999·2) = 99.99 ≤ 100.
        assert!(should_delete(&track(&[true], 5001.0), &sigma));
        assert!(!should_delete(&track(&[true], 4999.0), &sigma));
    }

    #[test]
    fn the_younger_of_two_tracks_on_one_plot_with_one_state_is_the_duplicate() {
        // P = 100 I per track: S = 200 I; states 20 m apart in x only give
        // d²= 400/200 = 2, below χ²_4 at 0.95 (7.779... is the 0.05 upper
        // quantile; the 0.05 lower quantile is 0.7107) → not a duplicate at
        // p = 0.05, a duplicate at p = 0.5 (χ²_4 median 3.357).
        let p = DMatrix::<f64>::identity(4, 4) * 100.0;
        let mut a = Track::fresh(1, dvector![0.0, 100.0, 0.0, 0.0], p.clone());
        a.hits = 10;
        let mut b = Track::fresh(2, dvector![20.0, 100.0, 0.0, 0.0], p.clone());
        b.hits = 4;
        let c = Track::fresh(3, dvector![5.0, 100.0, 0.0, 0.0], p.clone());
        let tracks = vec![b.clone(), a.clone()];
        let none: Vec<usize> = Vec::new();
        assert_eq!(duplicates(&tracks, &[(0, 7), (1, 7)], 0.05).unwrap(), none);
        assert_eq!(
            duplicates(&tracks, &[(0, 7), (1, 7)], 0.5).unwrap(),
            vec![0]
        );
        // Different best plots: never duplicates; 0 disables the rule.
        assert_eq!(duplicates(&tracks, &[(0, 7), (1, 8)], 0.5).unwrap(), none);
        assert_eq!(duplicates(&tracks, &[(0, 7), (1, 7)], 0.0).unwrap(), none);
        // 5 m apart: d² = 25/200 = 0.125 < 0.7107 → the one with fewer hits
        // (c, 0 hits) goes at p = 0.05.
        let tracks = vec![a, c];
        assert_eq!(
            duplicates(&tracks, &[(0, 1), (1, 1)], 0.05).unwrap(),
            vec![1]
        );
    }
}
