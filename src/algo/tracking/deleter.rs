//! Deletion of confirmed tracks (seed 001 step 7c "delete the tracks that
//! keep finding no plot in their gate", step 8): any configured rule
//! deletes — K consecutive missed frames, M_d misses among the last N_d
//! frames (MATLAB `trackHistoryLogic`'s deletion threshold), or a
//! horizontal position standard deviation √(P_xx + P_yy) above a bound
//! (the height is left out so that a 3D tracker fed by 2D radars, whose
//! height is never measured, is not deleted for it).

use crate::algo::tracking::config::Deletion;
use crate::algo::tracking::track::Track;

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

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, dvector};

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
}
