//! What a serial frame looked at. A radar's plots carry the time the beam
//! crossed the target, so a scan's plots arrive at different times and,
//! with `time_tolerance` 0, each is a frame of its own. A frame must then
//! count a miss only for the tracks the beam has just swept, or every
//! other track would miss at every plot of every radar (tracks deleted
//! after a few plots, tentative tracks never confirmed).
//!
//! A radar's beam is taken to rotate at one turn per `scan_period`. A frame
//! at time t whose last plot has azimuth θ, after the radar's previous
//! frame at (t₀, θ₀), swept the sector from θ₀ to θ: clockwise when that
//! angle fits the time (at most 1.5 × the expected 2π (t − t₀)/period +
//! 0.2 rad), else anticlockwise when that fits. A track is *judged* by the
//! frame when its predicted azimuth lies in that sector moved back (against
//! the rotation) by a margin (3 σ_θ + 0.5°), so that its own plot,
//! wherever the noise put it, has arrived before; it then gets a miss only
//! if no plot updated it since halfway between the beam's previous pass
//! over it (at the latest t − period) and this one (at the earliest t₀):
//! since (t − period + t₀)/2, which is half a scan before t when the
//! frames are dense and almost a whole one when the beam swept a wide
//! empty sector before this frame (a plot of the sector's beginning
//! arrived then, more than half a scan ago). A plot that
//! updates a track is a hit in whatever frame it comes. Frames that swept
//! a whole turn (t − t₀ ≥ 0.95 period, or a radar's first frame) judge
//! every track, as do sweeps that fit neither way.

use std::f64::consts::TAU;

use nalgebra::DVector;

use crate::tracking::config::RadarSpec;

/// The sector a serial frame judges, or every track.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum View {
    /// Every track (a whole turn, or parallel mode).
    All,
    /// Tracks whose azimuth from `site` lies clockwise from `start`
    /// within `width` (rad); a miss needs no update since `quiet_since`,
    /// the time between the beam's previous pass over the sector and this
    /// one.
    Sector {
        site: [f64; 3],
        start: f64,
        width: f64,
        quiet_since: f64,
    },
}

impl View {
    /// The view of a frame of `radar` at time `t` whose last plot has
    /// azimuth `azimuth`, after the radar's previous frame `previous`
    /// (time, azimuth).
    pub(crate) fn of_frame(
        radar: &RadarSpec,
        previous: Option<(f64, f64)>,
        t: f64,
        azimuth: f64,
    ) -> Self {
        let Some((t0, az0)) = previous else {
            return View::All;
        };
        let period = radar.scan_period;
        let dt = t - t0;
        if !(dt >= 0.0 && dt < 0.95 * period) {
            return View::All;
        }
        let fits = |w: f64| w <= 1.5 * TAU * dt / period + 0.2;
        let margin = 3.0 * radar.sigma_azimuth + 0.5_f64.to_radians();
        let clockwise = (azimuth - az0).rem_euclid(TAU);
        let anticlockwise = (az0 - azimuth).rem_euclid(TAU);
        // The judged sector lags the beam by the margin, whichever way it
        // turns.
        let (start, width) = if fits(clockwise) {
            (az0 - margin, clockwise)
        } else if fits(anticlockwise) {
            (azimuth + margin, anticlockwise)
        } else {
            return View::All;
        };
        View::Sector {
            site: radar.site,
            start,
            width,
            quiet_since: 0.5 * (t - period + t0),
        }
    }

    /// Whether a track without a plot in this frame gets a miss.
    pub(crate) fn misses(&self, x: &DVector<f64>, last_update: f64) -> bool {
        self.misses_at(x[0], x[2], last_update)
    }

    /// [`View::misses`] of a track at (e, n).
    pub(crate) fn misses_at(&self, e: f64, n: f64, last_update: f64) -> bool {
        match *self {
            View::All => true,
            View::Sector { quiet_since, .. } => last_update < quiet_since && self.swept(e, n),
        }
    }

    /// Whether a target at (e, n) lies in the swept sector (never in a
    /// whole-turn view, which knows no sweep).
    pub(crate) fn swept(&self, e: f64, n: f64) -> bool {
        match *self {
            View::All => false,
            View::Sector {
                site, start, width, ..
            } => {
                let az = (e - site[0]).atan2(n - site[1]);
                (az - start).rem_euclid(TAU) <= width
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::dvector;

    fn radar() -> RadarSpec {
        RadarSpec {
            site: [0.0; 3],
            sigma_range: 50.0,
            sigma_azimuth: 0.1_f64.to_radians(),
            sigma_elevation: None,
            sigma_radial_velocity: None,
            scan_period: 4.0,
            detection_probability: 0.9,
            clutter_density: 1e-7,
        }
    }

    #[test]
    fn a_sweep_judges_the_tracks_it_passed_by_the_margin() {
        let r = radar();
        // From 10° at t = 0 to 55° at t = 0.5 s (45°: one eighth of a 4-s
        // turn). The margin is 3 × 0.1° + 0.5° = 0.8°, so the sector judged
        // is [9.2°, 54.2°].
        let v = View::of_frame(&r, Some((0.0, 10f64.to_radians())), 0.5, 55f64.to_radians());
        let at = |deg: f64| {
            let a = deg.to_radians();
            dvector![50_000.0 * a.sin(), 0.0, 50_000.0 * a.cos(), 0.0]
        };
        for (deg, judged) in [
            (9.0, false),
            (9.3, true),
            (30.0, true),
            (54.1, true),
            (54.3, false),
            (200.0, false),
        ] {
            assert_eq!(v.misses(&at(deg), -10.0), judged, "{deg}°");
        }
        // Updated since halfway between the previous pass (at the latest
        // t − period = −3.5 s) and this one (at the earliest t₀ = 0):
        // after −1.75 s, no miss.
        assert!(!v.misses(&at(30.0), -1.7));
        assert!(v.misses(&at(30.0), -1.8));
        // Across north: from 350° to 20°.
        let v = View::of_frame(
            &r,
            Some((0.0, 350f64.to_radians())),
            1.0 / 3.0,
            20f64.to_radians(),
        );
        assert!(v.misses(&at(5.0), -10.0) && v.misses(&at(355.0), -10.0));
        assert!(!v.misses(&at(100.0), -10.0));
        // An anticlockwise beam from 55° to 10° in 0.5 s: judged
        // [10.8°, 55.8°].
        let v = View::of_frame(&r, Some((0.0, 55f64.to_radians())), 0.5, 10f64.to_radians());
        for (deg, judged) in [(10.5, false), (11.0, true), (55.5, true), (56.0, false)] {
            assert_eq!(v.misses(&at(deg), -10.0), judged, "anticlockwise {deg}°");
        }
        // A whole turn, a first frame, and a sweep too wide for the time
        // either way.
        assert_eq!(View::of_frame(&r, Some((0.0, 0.0)), 4.0, 0.1), View::All);
        assert_eq!(View::of_frame(&r, None, 4.0, 0.1), View::All);
        assert_eq!(View::of_frame(&r, Some((0.0, 0.0)), 0.1, 3.0), View::All);
    }
}
