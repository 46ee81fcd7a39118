//! ADS-B quality indicators (I021/090) as numbers a tracker can use:
//! NACp → the 95 % horizontal position bound (EPU) and a σ per axis;
//! NACv (and NUCr, the same thresholds) → the 95 % horizontal velocity
//! bound and a σ per axis; NIC → the containment radius Rc.
//!
//! Tables: the NACp, NACv and NIC tables of RTCA DO-260B / EUROCAE
//! ED-102A (and of the MASPS, RTCA DO-242A, they implement); NUCr's HFOMr
//! table of DO-260 has NACv's thresholds.
//!
//! **From a 95 % radius to σ.** A horizontal error with independent
//! zero-mean Gaussian components of equal σ (a circular Gaussian) has a
//! Rayleigh-distributed radius: P(r ≤ R) = 1 − exp(−R² / (2σ²)). Setting
//! P = 0.95 gives R = σ·√(−2 ln 0.05) = 2.4477·σ, so σ = EPU / 2.4477
//! ([`K95`]). The categories give an upper bound ("EPU < 30 m"), so the σ
//! is an upper bound too: conservative, never optimistic, for the
//! category's best aircraft.
//!
//! **NIC is integrity, not accuracy.** Rc is the radius that contains the
//! true position with the integrity probability of the SIL (10⁻⁷ per
//! hour or sample, typically): a protection level for alerting, far
//! larger than the typical error. It is not a σ, and a tracker should
//! not use it as one; use NACp.

/// √(−2 ln 0.05): the 95 % radius of a circular Gaussian in units of its
/// per-axis σ.
pub const K95: f64 = 2.447_746_830_680_816_6;

/// NACp → EPU, the 95 % horizontal accuracy bound (m); `None` for 0
/// (EPU ≥ 10 NM or unknown) and 12–15 (reserved).
pub fn nacp_epu_m(nacp: u8) -> Option<f64> {
    Some(match nacp {
        11 => 3.0,
        10 => 10.0,
        9 => 30.0,
        8 => 92.6,    // 0.05 NM
        7 => 185.2,   // 0.1 NM
        6 => 555.6,   // 0.3 NM
        5 => 926.0,   // 0.5 NM
        4 => 1852.0,  // 1 NM
        3 => 3704.0,  // 2 NM
        2 => 7408.0,  // 4 NM
        1 => 18520.0, // 10 NM
        _ => return None,
    })
}

/// NACp → σ of the horizontal position per axis (m): EPU / [`K95`].
pub fn nacp_sigma_m(nacp: u8) -> Option<f64> {
    nacp_epu_m(nacp).map(|epu| epu / K95)
}

/// NACv (or NUCr, whose thresholds are the same) → the 95 % horizontal
/// velocity error bound (m/s); `None` for 0 (unknown or ≥ 10 m/s) and
/// 5–7 (reserved).
pub fn nacv_bound_mps(nacv: u8) -> Option<f64> {
    Some(match nacv {
        4 => 0.3,
        3 => 1.0,
        2 => 3.0,
        1 => 10.0,
        _ => return None,
    })
}

/// NACv → σ of the horizontal velocity per axis (m/s): bound / [`K95`].
pub fn nacv_sigma_mps(nacv: u8) -> Option<f64> {
    nacv_bound_mps(nacv).map(|b| b / K95)
}

/// NIC → Rc, the horizontal containment radius (m): an integrity bound,
/// not an accuracy (see the module header); `None` for 0 (unknown) and
/// 12–15. NIC 6 stands for Rc < 0.6 NM, 0.5 NM or 0.3 NM depending on
/// the NIC supplements, which I021/090 does not carry: the largest, 0.6
/// NM, is given.
pub fn nic_containment_m(nic: u8) -> Option<f64> {
    Some(match nic {
        11 => 7.5,
        10 => 25.0,
        9 => 75.0,
        8 => 185.2,   // 0.1 NM
        7 => 370.4,   // 0.2 NM
        6 => 1111.2,  // 0.6 NM (0.5 or 0.3 NM with supplements)
        5 => 1852.0,  // 1 NM
        4 => 3704.0,  // 2 NM
        3 => 7408.0,  // 4 NM
        2 => 14816.0, // 8 NM
        1 => 37040.0, // 20 NM
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol
    }

    #[test]
    fn k95_is_the_95_percent_radius_of_a_circular_gaussian() {
        // √(−2 ln 0.05) = √5.991464547… = 2.447746830…
        assert!(close(K95, (-2.0 * 0.05f64.ln()).sqrt(), 1e-15));
        // And back: P(r ≤ K95·σ) = 1 − exp(−K95²/2) = 0.95.
        assert!(close(1.0 - (-K95 * K95 / 2.0).exp(), 0.95, 1e-15));
    }

    #[test]
    fn nacp_gives_the_tables_epu_and_its_sigma() {
        // (NACp, EPU from DO-260B's table, σ = EPU / 2.447747 by hand).
        let table = [
            (11, 3.0, 1.2256),
            (10, 10.0, 4.0854),
            (9, 30.0, 12.2562),
            (8, 92.6, 37.8307),   // 0.05 NM
            (7, 185.2, 75.6614),  // 0.1 NM
            (6, 555.6, 226.9843), // 0.3 NM
            (5, 926.0, 378.3071), // 0.5 NM
            (4, 1852.0, 756.6142),
            (3, 3704.0, 1513.2284),
            (2, 7408.0, 3026.4568),
            (1, 18520.0, 7566.1420),
        ];
        for (nacp, epu, sigma) in table {
            assert_eq!(nacp_epu_m(nacp), Some(epu), "NACp {nacp}");
            let s = nacp_sigma_m(nacp).unwrap();
            assert!(close(s, sigma, 1e-4), "NACp {nacp}: σ {s}, by hand {sigma}");
        }
        for unknown in [0, 12, 15, 255] {
            assert_eq!(nacp_sigma_m(unknown), None);
        }
    }

    #[test]
    fn nacv_gives_the_tables_bound_and_its_sigma() {
        // (NACv, 95 % bound, σ = bound / 2.447747 by hand).
        let table = [
            (4, 0.3, 0.12256),
            (3, 1.0, 0.40854),
            (2, 3.0, 1.22562),
            (1, 10.0, 4.08539),
        ];
        for (nacv, bound, sigma) in table {
            assert_eq!(nacv_bound_mps(nacv), Some(bound));
            assert!(close(nacv_sigma_mps(nacv).unwrap(), sigma, 1e-5));
        }
        assert_eq!(nacv_bound_mps(0), None);
        assert_eq!(nacv_bound_mps(5), None);
    }

    #[test]
    fn nic_gives_the_containment_radius() {
        // DO-260B's NIC table: 11 < 7.5 m, 10 < 25 m, 9 < 75 m, 8 < 0.1 NM,
        // 7 < 0.2 NM, 6 < 0.6 NM, 5 < 1 NM, 4 < 2 NM, 3 < 4 NM, 2 < 8 NM,
        // 1 < 20 NM (1 NM = 1852 m).
        let nm = [
            (8, 0.1),
            (7, 0.2),
            (6, 0.6),
            (5, 1.0),
            (4, 2.0),
            (3, 4.0),
            (2, 8.0),
            (1, 20.0),
        ];
        for (nic, r) in nm {
            assert!(
                close(nic_containment_m(nic).unwrap(), r * 1852.0, 1e-9),
                "NIC {nic}"
            );
        }
        assert_eq!(nic_containment_m(11), Some(7.5));
        assert_eq!(nic_containment_m(10), Some(25.0));
        assert_eq!(nic_containment_m(9), Some(75.0));
        assert_eq!(nic_containment_m(0), None);
    }
}
