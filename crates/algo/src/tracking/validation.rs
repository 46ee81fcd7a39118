//! Self-reported positions (ADS-B, AIS) checked against independent
//! evidence (radar plots, multilateration), per track.
//!
//! An aircraft's ADS-B position is what its own navigation says: faulty
//! avionics and spoofing make it wrong while its stated quality (NACp)
//! stays good. A radar's plot or a multilateration report of the same
//! Mode S address is measured by the ground, independently. The two meet
//! in a track:
//! - **An independent plot of the track's address outside its gate, while
//!   self-reported positions hold the track** (its last update was one):
//!   a disagreement.
//! - **A self-reported position of the track's address outside its gate,
//!   while independent evidence holds the track** (an independent update
//!   in the last [`INDEPENDENT_WINDOW_S`](super::identity::INDEPENDENT_WINDOW_S)): a disagreement; one inside the
//!   χ²₂ gate at 0.999 of the track's and the report's covariances (13.8)
//!   while distrusted, an agreement.
//!
//! After [`DISAGREEMENTS_TO_DISTRUST`](super::identity::DISAGREEMENTS_TO_DISTRUST) disagreements in a row the track
//! distrusts its self-reported positions: a self-reported report of its
//! address no longer pairs with it (the association rules the pairing
//! out), and when the disagreement was an independent plot the track is
//! set at that plot (its position and covariance; its velocity kept with
//! σ at least [`ANCHOR_SPEED_SIGMA`]): it follows the radar from then on.
//! After [`AGREEMENTS_TO_TRUST`](super::identity::AGREEMENTS_TO_TRUST) agreements in a row it trusts them again.
//! A plot taken up by a disagreement or an agreement starts no track: one
//! address, one track. Independent plots that gate the track while
//! self-reported positions hold it reset the count (they agree).
//!
//! What it cannot see: a self-reported position wrong by less than the
//! gate of the independent evidence (a radar's σ at range: hundreds of
//! metres) and a track no independent sensor holds (outside radar
//! coverage: the track is then marked unvalidated by the caller,
//! [`Validation::independently_held`]); a primary plot has no address, so
//! only secondary (Mode S) plots and multilateration check ADS-B.

use std::sync::Arc;

use super::identity::{Disagreement, Validation};
use super::{CartesianPlot, Motion, Track, Tracker, TrackerConfig};

/// χ²₂ at 0.999 (−2 ln 0.001): a self-reported position within it of an
/// independently held track agrees.
const AGREEMENT_CHI2: f64 = 13.815_510_557_964_274;
/// σ (m/s) at least given to the velocity of a track set at an
/// independent plot: the self-reported velocity it followed may be as
/// wrong as the positions.
pub(crate) const ANCHOR_SPEED_SIGMA: f64 = 50.0;

/// Whether plot `plot` is a self-reported position (ADS-B, AIS).
fn self_reported(plot: &CartesianPlot) -> bool {
    plot.measured
        .and_then(|m| m.report)
        .is_some_and(|r| r.kind.is_self_reported())
}

/// Whether the last update of `track` was a self-reported position.
fn held_by_self_reports(cfg: &TrackerConfig, track: &Track) -> bool {
    track.radars.iter().any(|&i| cfg.is_self_reported(i))
}

/// Whether an independent sensor (a radar, multilateration) has updated
/// `track` within [`INDEPENDENT_WINDOW_S`](super::identity::INDEPENDENT_WINDOW_S)
/// of `t` (its hits per sensor, or the time its check keeps).
fn independently_held(cfg: &TrackerConfig, track: &Track, t: f64) -> bool {
    track.identity.validation.independently_held(t)
        || track.detections.iter().any(|h| {
            !cfg.is_self_reported(h.radar) && t - h.last <= super::identity::INDEPENDENT_WINDOW_S
        })
}

/// Records the sensor of a plot that updated `track` (before the track
/// records the hit): the time of its last independent or self-reported
/// update; an independent plot updating a track its self-reported
/// positions held agrees with them.
pub(crate) fn note_hit(cfg: &TrackerConfig, track: &mut Track, plot: &CartesianPlot) {
    let t = plot.measured.map_or(plot.t, |m| m.t);
    let later = |s: Option<f64>| Some(s.map_or(t, |s| s.max(t)));
    let held = held_by_self_reports(cfg, track);
    let independent = |i: usize| !cfg.is_self_reported(i);
    let v = &mut track.identity.validation;
    if self_reported(plot) {
        if v.last_self_reported.is_none() {
            // The first self-reported position: the track's independent
            // hits so far (kept per sensor) date its independent evidence.
            v.last_independent = track
                .detections
                .iter()
                .filter(|h| independent(h.radar))
                .map(|h| h.last)
                .reduce(f64::max);
        }
        v.last_self_reported = later(v.last_self_reported);
    } else if v.last_self_reported.is_some() {
        // Kept only for tracks with self-reported positions: a radar-only
        // tracker's state is what it was before reports existed.
        v.last_independent = later(v.last_independent);
        if held && v.trusted() {
            v.disagreements = 0;
        }
    }
}

/// The squared Mahalanobis distance and the distance (m) between the
/// horizontal position of `plot` and `track`'s, extrapolated to the plot's
/// time at constant velocity, over the sum of their covariances and
/// `extra` (`[ee, en, nn]`).
fn horizontal_distance(track: &Track, plot: &CartesianPlot, extra: [f64; 3]) -> (f64, f64) {
    let dt = plot.t - track.t;
    let d = [
        plot.z[0] - (track.x[0] + track.x[1] * dt),
        plot.z[1] - (track.x[2] + track.x[3] * dt),
    ];
    let s = [
        track.p[(0, 0)] + plot.r[(0, 0)] + extra[0],
        track.p[(0, 2)] + plot.r[(0, 1)] + extra[1],
        track.p[(2, 2)] + plot.r[(1, 1)] + extra[2],
    ];
    let det = s[0] * s[2] - s[1] * s[1];
    let d2 = if det > 0.0 {
        (d[0] * d[0] * s[2] - 2.0 * d[0] * d[1] * s[1] + d[1] * d[1] * s[0]) / det
    } else {
        f64::INFINITY
    };
    (d2, d[0].hypot(d[1]))
}

impl Validation {
    /// Whether the track is validated at `t`: independent evidence holds
    /// it, or it has no self-reported position to validate.
    pub fn validated(&self, t: f64) -> bool {
        self.last_self_reported.is_none() || self.independently_held(t)
    }
}

impl Tracker {
    /// The frame's plots no track used that carry the Mode S address of a
    /// confirmed track, checked against it (module documentation): those
    /// taken up by the check are marked `used` (they start no track).
    pub(super) fn check_leftovers(&mut self, plots: &[CartesianPlot], used: &mut [bool]) {
        for (j, plot) in plots.iter().enumerate() {
            if used[j] {
                continue;
            }
            let Some(m) = plot.measured else { continue };
            let Some(address) = m.identity.address else {
                continue;
            };
            let Some(k) = self
                .tracks
                .iter()
                .position(|tr| tr.identity.address.is_some_and(|a| a.value == address))
            else {
                continue;
            };
            let track = &self.tracks[k];
            let v = track.identity.validation;
            if self_reported(plot) {
                // Against what the independent sensor could say: the
                // track's own covariance is the self-reports' (metres),
                // and a manoeuvre they follow would be a disagreement.
                let (d2, distance) =
                    horizontal_distance(track, plot, self.independent_covariance(track));
                if !independently_held(&self.config, track, m.t) {
                    if held_by_self_reports(&self.config, track) {
                        self.reacquire(k, plot, (d2, distance));
                        used[j] = true;
                    }
                    continue;
                }
                used[j] = true;
                let v = &mut Arc::make_mut(&mut self.tracks[k]).identity.validation;
                if d2 <= AGREEMENT_CHI2 {
                    v.agree();
                } else {
                    v.disagree(Disagreement {
                        t: m.t,
                        distance,
                        sigma: plot.r[(0, 0)].sqrt(),
                    });
                }
            } else {
                if !(v.trusted() && held_by_self_reports(&self.config, track)) {
                    continue;
                }
                let (_, distance) = horizontal_distance(track, plot, [0.0; 3]);
                used[j] = true;
                let sigma = (0.5 * (track.p[(0, 0)] + track.p[(2, 2)])).sqrt();
                let motion = self.config.motion.clone();
                let track = Arc::make_mut(&mut self.tracks[k]);
                let distrusted = track.identity.validation.disagree(Disagreement {
                    t: m.t,
                    distance,
                    sigma,
                });
                if distrusted {
                    track.anchor(plot, &motion);
                    note_hit(&self.config, track, plot);
                    track.record(Some(plot.radars.clone()));
                    track.last_plot = Some(m);
                    self.index.moved(k, track);
                }
            }
        }
    }
}

impl Tracker {
    /// The horizontal covariance (`[ee, en, nn]`, m²) of a plot of the
    /// radar that last updated `track`, at the track's position: σ_ρ² along
    /// the line of sight, (ρ σ_θ)² across; zero when no radar has.
    fn independent_covariance(&self, track: &Track) -> [f64; 3] {
        let Some(h) = track
            .detections
            .iter()
            .filter(|h| h.radar < self.applied.len())
            .max_by(|a, b| a.last.total_cmp(&b.last))
        else {
            return [0.0; 3];
        };
        let spec = &self.applied[h.radar];
        let (e, n) = (track.x[0] - spec.site[0], track.x[2] - spec.site[1]);
        let range = e.hypot(n).max(1.0);
        let (ue, un) = (e / range, n / range);
        let along = spec.sigma_range * spec.sigma_range;
        let across = (range * spec.sigma_azimuth).powi(2);
        [
            along * ue * ue + across * un * un,
            (along - across) * ue * un,
            along * un * un + across * ue * ue,
        ]
    }

    /// A self-reported position of the address of track `k`, which only
    /// self-reported positions hold, outside its gate (`d2`, distance
    /// `distance`): the same aircraft (one address, one track), not a new
    /// track. Two in a row, without a self-reported update between, set the
    /// track at the report (it lost the aircraft: a manoeuvre, or positions
    /// noisier than their stated quality).
    fn reacquire(&mut self, k: usize, plot: &CartesianPlot, (d2, distance): (f64, f64)) {
        let motion = self.config.motion.clone();
        let track = Arc::make_mut(&mut self.tracks[k]);
        let v = &mut track.identity.validation;
        if d2 <= AGREEMENT_CHI2 {
            return;
        }
        let t = plot.measured.map_or(plot.t, |m| m.t);
        let in_a_row = v
            .last_disagreement
            .is_some_and(|d| v.last_self_reported.is_none_or(|s| d.t >= s));
        v.disagreements = if in_a_row {
            v.disagreements.saturating_add(1)
        } else {
            1
        };
        v.last_disagreement = Some(Disagreement {
            t,
            distance,
            sigma: plot.r[(0, 0)].sqrt(),
        });
        if v.disagreements >= super::identity::DISAGREEMENTS_TO_DISTRUST {
            v.disagreements = 0;
            track.anchor(plot, &motion);
            note_hit(&self.config, track, plot);
            track.record(Some(plot.radars.clone()));
            self.index.moved(k, track);
        }
    }
}

impl Track {
    /// Sets the track at an independent plot (its position and covariance,
    /// the velocity kept with σ at least [`ANCHOR_SPEED_SIGMA`], no
    /// correlation), at the later of its time and the plot's; an IMM
    /// track's models start again.
    pub(crate) fn anchor(&mut self, plot: &CartesianPlot, motion: &Motion) {
        let n = self.x.len();
        let k = plot.z.len().min(n / 2);
        let mut p = nalgebra::DMatrix::zeros(n, n);
        for i in 0..n / 2 {
            p[(2 * i, 2 * i)] = self.p[(2 * i, 2 * i)];
            p[(2 * i + 1, 2 * i + 1)] =
                self.p[(2 * i + 1, 2 * i + 1)].max(ANCHOR_SPEED_SIGMA.powi(2));
        }
        for a in 0..k {
            self.x[2 * a] = plot.z[a];
            for b in 0..k {
                p[(2 * a, 2 * b)] = plot.r[(a, b)];
            }
        }
        self.p = p;
        self.t = self.t.max(plot.t);
        match motion {
            Motion::Imm(imm) => self.start_modes(imm),
            Motion::ConstantVelocity => self.modes.clear(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::identity::{
        AGREEMENTS_TO_TRUST, DISAGREEMENTS_TO_DISTRUST, INDEPENDENT_WINDOW_S,
    };
    use super::*;

    #[test]
    fn two_disagreements_distrust_and_five_agreements_trust_again() {
        let mut v = Validation::default();
        let d = Disagreement {
            t: 1.0,
            distance: 3000.0,
            sigma: 10.0,
        };
        assert!(!v.disagree(d));
        assert!(v.trusted());
        assert!(v.disagree(Disagreement { t: 5.0, ..d }));
        assert_eq!(v.distrusted_since, Some(5.0));
        // A third disagreement does not distrust again.
        assert!(!v.disagree(d));
        for _ in 0..AGREEMENTS_TO_TRUST - 1 {
            assert!(!v.agree());
        }
        assert!(v.agree());
        assert!(v.trusted());
        assert_eq!(DISAGREEMENTS_TO_DISTRUST, 2);
    }

    #[test]
    fn independently_held_within_its_window() {
        let v = Validation {
            last_independent: Some(10.0),
            last_self_reported: Some(50.0),
            ..Default::default()
        };
        assert!(v.independently_held(10.0 + INDEPENDENT_WINDOW_S));
        assert!(!v.independently_held(10.1 + INDEPENDENT_WINDOW_S));
        assert!(!v.validated(50.0));
        assert!(Validation::default().validated(50.0));
    }
}
