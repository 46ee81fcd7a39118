//! The stored form of a [`LagWindow`]: a tracker that takes late plots
//! within a lag (`algo::tracking::window`).
//!
//! Layout (after the magic `RFLW` and a `u32` format version):
//! - format 5 (this release): format 4 with plots that may be
//!   cooperative reports (tracker format 11's plots);
//! - format 4: format 3 followed by the limit of live
//!   tracks the window applies (optional `usize`): the picture's open
//!   frame is flushed under it, so a window decoded without it showed
//!   tracks the serving one had refused (formats 1–3 decode without a
//!   limit, as they were written);
//! - format 3: format 2 with, under auto, whether the
//!   window is past its bound (bool, after the bound) and then, past it,
//!   no base and no plots (as under retrodiction), the approximate time
//!   under reprocessing and auto either way; each plot with its identity
//!   (Mode S, Mode 3/A, Mode C, callsign: tracker format 6's plots);
//! - format 2: the policy (u8: 0 reprocessing, 1
//!   retrodiction, 2 auto followed by its bound of replayed plots, u32),
//!   then under reprocessing and auto format 1's fields and the time from
//!   which the head is approximate (optional f64), under retrodiction the
//!   lag, the head tracker, horizon, newest and late count (no base, no
//!   plots: a retrodicting window holds none);
//! - format 1 (earlier releases, decoded as reprocessing): the lag (f64),
//!   the base tracker and the head tracker (each as
//!   [`super::tracker::encode_tracker`] bytes), the window's plots, the
//!   horizon and the newest plot time (optional f64), and the count of
//!   plots dropped as late beyond the lag (u64).
//!
//! The in-memory snapshots are not stored: a reprocessing window decoded
//! elsewhere replays a late plot from its base. So the bytes grow with the
//! lag (two trackers and the plots of the window) under reprocessing and
//! auto within its bound, and are one tracker's under retrodiction and
//! auto past its bound.

use algo::tracking::{LagWindow, LagWindowParts, LatePolicy, Tracker};

use super::tracker::{
    FORMAT_VERSION as TRACKER_FORMAT_VERSION, decode_tracker, encode_tracker_as, plot_as, read_plot,
};
use wire_formats::wire::{FormatError, Reader, Writer, corrupt, invalid};

const MAGIC: &[u8; 4] = b"RFLW";
/// The format this release writes.
pub const FORMAT_VERSION: u32 = 5;

/// The bytes of `window` (see the module header).
pub fn encode_lag_window(window: &LagWindow) -> Vec<u8> {
    encode_lag_window_as(window, FORMAT_VERSION)
}

/// The bytes of `window` in format 3 to 5 (3: without the limit of live
/// tracks, 3 and 4: radar plots and tracker format 10, as earlier
/// releases wrote them; for the tests of older formats).
pub(crate) fn encode_lag_window_as(window: &LagWindow, version: u32) -> Vec<u8> {
    assert!((3..=FORMAT_VERSION).contains(&version));
    let tracker_format = if version >= 5 {
        TRACKER_FORMAT_VERSION
    } else {
        10
    };
    let s = window.state();
    let mut w = Writer::default();
    w.buf.extend_from_slice(MAGIC);
    w.u32(version);
    match s.policy {
        LatePolicy::Reprocess => w.u8(0),
        LatePolicy::Retrodict => w.u8(1),
        LatePolicy::Auto { max_replay } => {
            w.u8(2);
            w.u32(max_replay);
            w.bool(s.past_bound);
        }
    }
    let plots = s.policy != LatePolicy::Retrodict && !s.past_bound;
    w.f64(s.max_lag);
    if plots {
        w.bytes(&encode_tracker_as(s.base, tracker_format));
    }
    w.bytes(&encode_tracker_as(s.head, tracker_format));
    if plots {
        w.usize(s.window.len());
        for p in s.window {
            plot_as(&mut w, p, tracker_format);
        }
    }
    w.opt(s.horizon, Writer::f64);
    w.opt(s.newest, Writer::f64);
    w.u64(s.late);
    if s.policy != LatePolicy::Retrodict {
        w.opt(s.approximate_from, Writer::f64);
    }
    if version >= 4 {
        w.opt(s.max_tracks, Writer::usize);
    }
    w.buf
}

/// A window from [`encode_lag_window`]'s bytes (formats 1 to 4): bytes
/// that are not such an encoding are [`FormatError::Corrupt`], parts the
/// window rejects [`FormatError::Invalid`].
pub fn decode_lag_window(bytes: &[u8]) -> Result<LagWindow, FormatError> {
    if bytes.len() < 4 || &bytes[..4] != MAGIC {
        return Err(corrupt("not an encoded lag window"));
    }
    let mut r = Reader::new(&bytes[4..]);
    let version = r.u32()?;
    let (policy, past_bound) = match version {
        1 => (LatePolicy::Reprocess, false),
        2..=5 => match r.u8()? {
            0 => (LatePolicy::Reprocess, false),
            1 => (LatePolicy::Retrodict, false),
            2 => {
                let max_replay = r.u32()?;
                let past_bound = version >= 3 && r.bool()?;
                (LatePolicy::Auto { max_replay }, past_bound)
            }
            other => return Err(corrupt(&format!("unknown late-plot policy {other}"))),
        },
        _ => return Err(corrupt(&format!("unknown lag window format {version}"))),
    };
    // Format 3 stores plots with their identity (tracker format 6),
    // format 5 with their cooperative report (tracker format 11).
    let plot_format = match version {
        5.. => super::tracker::REPORT_FORMAT,
        3..=4 => 6,
        _ => 5,
    };
    let max_lag = r.f64()?;
    let plots = policy != LatePolicy::Retrodict && !past_bound;
    let (base, head, window) = if plots {
        let base = decode_tracker(&r.bytes()?)?;
        let head = decode_tracker(&r.bytes()?)?;
        let n = r.len(16)?;
        let window = (0..n)
            .map(|_| read_plot(&mut r, plot_format))
            .collect::<Result<Vec<_>, _>>()?;
        (base, head, window)
    } else {
        let head = decode_tracker(&r.bytes()?)?;
        let base = Tracker::new(head.config().clone()).map_err(invalid)?;
        (base, head, Vec::new())
    };
    let horizon = r.opt(Reader::f64)?;
    let newest = r.opt(Reader::f64)?;
    let late = r.u64()?;
    let approximate_from = match version {
        3.. if policy != LatePolicy::Retrodict => r.opt(Reader::f64)?,
        2 if plots => r.opt(Reader::f64)?,
        _ => None,
    };
    let max_tracks = if version >= 4 {
        r.opt(Reader::usize)?
    } else {
        None
    };
    if !r.is_empty() {
        return Err(corrupt("trailing bytes"));
    }
    LagWindow::from_parts(LagWindowParts {
        policy,
        past_bound,
        approximate_from,
        max_lag,
        base,
        window,
        head,
        horizon,
        newest,
        late,
        max_tracks,
    })
    .map_err(invalid)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::state::tracker::{encode_tracker_as, plot_as};
    use algo::tracking::{Plot, RadarSpec, Tracker, TrackerConfig};

    fn radar(site: [f64; 3]) -> RadarSpec {
        RadarSpec {
            site,
            sigma_range: 50.0,
            sigma_azimuth: 0.2f64.to_radians(),
            sigma_elevation: None,
            sigma_radial_velocity: None,
            scan_period: 4.0,
            detection_probability: 1.0,
            clutter_density: 1e-9,
        }
    }

    /// Two radars seeing three targets on straight lines, 40 s.
    fn plots() -> Vec<Plot> {
        let sites = [[0.0, 0.0, 0.0], [30_000.0, 0.0, 0.0]];
        let mut out = Vec::new();
        for (i, site) in sites.iter().enumerate() {
            let mut t = 0.7 * i as f64;
            while t < 40.0 {
                for k in 0..3 {
                    let x = 5_000.0 + 4_000.0 * k as f64 + 150.0 * t;
                    let y = 20_000.0 - 100.0 * t + 3_000.0 * k as f64;
                    let (e, n) = (x - site[0], y - site[1]);
                    out.push(Plot {
                        radar: i,
                        t,
                        range: e.hypot(n),
                        azimuth: e.atan2(n),
                        elevation: None,
                        radial_velocity: None,
                        identity: Default::default(),
                        report: None,
                    });
                }
                t += 4.0;
            }
        }
        out.sort_by(|a, b| a.t.total_cmp(&b.t));
        out
    }

    fn window() -> LagWindow {
        let config = TrackerConfig::new(2, vec![radar([0.0; 3]), radar([30_000.0, 0.0, 0.0])]);
        LagWindow::new(Tracker::new(config).unwrap(), 10.0).unwrap()
    }

    /// A retrodicting window stores its head alone and continues as the
    /// original; the policy round-trips.
    #[test]
    fn a_retrodicting_window_round_trips_and_continues_as_the_original() {
        let all = plots();
        let (first, rest) = all.split_at(all.len() / 2);
        let config = TrackerConfig::new(2, vec![radar([0.0; 3]), radar([30_000.0, 0.0, 0.0])]);
        let mut a =
            LagWindow::with_policy(Tracker::new(config).unwrap(), 10.0, LatePolicy::Retrodict)
                .unwrap();
        a.push(first).unwrap();
        let mut late = first[first.len() - 4];
        late.t -= 2.0;
        a.push(&[late]).unwrap();
        let b = round_trips_smaller_and_continues(a, first, late, rest);
        assert_eq!(b.policy(), LatePolicy::Retrodict);
    }

    /// `a` (fed `first`, then `late`) decodes to its parts and picture, in
    /// fewer bytes than a reprocessing window of the same plots (two
    /// trackers and the plots), and goes on with `rest` as the original;
    /// returns the decoded window.
    fn round_trips_smaller_and_continues(
        mut a: LagWindow,
        first: &[Plot],
        late: Plot,
        rest: &[Plot],
    ) -> LagWindow {
        let bytes = encode_lag_window(&a);
        let mut b = decode_lag_window(&bytes).unwrap();
        assert_eq!(a.to_parts(), b.to_parts());
        assert_eq!(a.picture(), b.picture());
        let mut c = window();
        c.push(first).unwrap();
        c.push(&[late]).unwrap();
        assert!(bytes.len() < encode_lag_window(&c).len());
        a.push(rest).unwrap();
        b.push(rest).unwrap();
        assert_eq!(a.picture(), b.picture());
        assert_eq!(a.counters(), b.counters());
        b
    }

    /// Auto past its bound stores no plots and no base, and decodes to a
    /// window that goes on as the original.
    #[test]
    fn an_auto_window_past_its_bound_round_trips_without_plots() {
        let all = plots();
        let (first, rest) = all.split_at(all.len() / 2);
        assert!(first.len() > 4);
        let config = TrackerConfig::new(2, vec![radar([0.0; 3]), radar([30_000.0, 0.0, 0.0])]);
        let auto = LatePolicy::Auto { max_replay: 4 };
        let mut a = LagWindow::with_policy(Tracker::new(config).unwrap(), 10.0, auto).unwrap();
        a.push(first).unwrap();
        assert!(a.past_bound());
        assert_eq!((a.window_len(), a.approximate_from()), (0, None));
        let mut late = first[first.len() - 4];
        late.t -= 2.0;
        a.push(&[late]).unwrap();
        assert_eq!(a.approximate_from(), Some(late.t));
        let b = round_trips_smaller_and_continues(a, first, late, rest);
        assert_eq!(b.policy(), auto);
        assert!(b.past_bound());
    }

    /// Format 1 (earlier releases): a reprocessing window.
    #[test]
    fn a_window_of_format_1_decodes_as_reprocessing() {
        let mut config = TrackerConfig::new(2, vec![radar([0.0; 3]), radar([30_000.0, 0.0, 0.0])]);
        // As that release: the declared σ (format 7 and earlier read the
        // accuracy estimator off).
        config.accuracy.enabled = false;
        let mut a =
            LagWindow::with_policy(Tracker::new(config).unwrap(), 10.0, LatePolicy::Reprocess)
                .unwrap();
        a.push(&plots()).unwrap();
        // Format 1: the lag, the two trackers (format 5 here: the release
        // before identities), the plots without identities, horizon,
        // newest, late count.
        let s = a.state();
        let mut w = Writer::default();
        w.buf.extend_from_slice(MAGIC);
        w.u32(1);
        w.f64(s.max_lag);
        w.bytes(&encode_tracker_as(s.base, 5));
        w.bytes(&encode_tracker_as(s.head, 5));
        w.usize(s.window.len());
        for p in s.window {
            plot_as(&mut w, p, 5);
        }
        w.opt(s.horizon, Writer::f64);
        w.opt(s.newest, Writer::f64);
        w.u64(s.late);
        let v1 = w.buf;
        let b = decode_lag_window(&v1).unwrap();
        assert_eq!(b.policy(), LatePolicy::Reprocess);
        // The same window, but for what format 5 trackers do not hold (the
        // tracks' hits per radar, format 9): the trackers equal as format 5
        // holds them.
        let (mut pa, mut pb) = (a.to_parts(), b.to_parts());
        for (x, y) in [(&pa.base, &pb.base), (&pa.head, &pb.head)] {
            assert_eq!(encode_tracker_as(x, 5), encode_tracker_as(y, 5));
        }
        for p in [&mut pa, &mut pb] {
            p.base = decode_tracker(&encode_tracker_as(&p.base, 5)).unwrap();
            p.head = decode_tracker(&encode_tracker_as(&p.head, 5)).unwrap();
        }
        assert_eq!(pa, pb);
    }

    #[test]
    fn a_window_round_trips_and_continues_as_the_original() {
        let all = plots();
        let (first, rest) = all.split_at(all.len() / 2);
        let mut a = window();
        a.push(first).unwrap();
        // A late plot within the lag and one beyond it.
        let mut late = first[first.len() - 4];
        late.t -= 0.1;
        let mut too_late = first[0];
        too_late.t = first[first.len() - 1].t - 30.0;
        a.push(&[late, too_late]).unwrap();
        let bytes = encode_lag_window(&a);
        let mut b = decode_lag_window(&bytes).unwrap();
        assert_eq!(a.to_parts(), b.to_parts());
        assert_eq!(a.picture(), b.picture());
        a.push(rest).unwrap();
        b.push(rest).unwrap();
        // The same tracks; where the window starts may differ (the
        // original could adopt an in-memory snapshot as its base).
        assert_eq!(a.picture(), b.picture());
        assert_eq!(a.counters(), b.counters());
    }

    /// The limit of live tracks is stored: a window at its limit, with an
    /// open frame whose plots would start more tracks, decodes to the
    /// same picture and goes on as the original. Format 3 (no limit)
    /// decodes without one.
    #[test]
    fn a_window_at_its_track_limit_round_trips_with_it() {
        let all = plots();
        // 3 targets: two scans of radar 0 and radar 1's first plots
        // open (its frame is the picture's open frame).
        let cut = all.iter().position(|p| p.t > 4.7).unwrap();
        let (first, rest) = all.split_at(cut);
        let mut a = window();
        a.set_max_tracks(Some(1));
        a.push(first).unwrap();
        assert!(a.pending() > 0);
        assert_eq!(a.picture().track_ids().count(), 1);
        let bytes = encode_lag_window(&a);
        let mut b = decode_lag_window(&bytes).unwrap();
        assert_eq!(a.to_parts(), b.to_parts());
        assert_eq!(a.to_parts().max_tracks, Some(1));
        assert_eq!(a.picture(), b.picture());
        a.push(rest).unwrap();
        b.push(rest).unwrap();
        assert_eq!(a.picture(), b.picture());
        assert_eq!(a.counters(), b.counters());
        assert_eq!(b.picture().track_ids().count(), 1);
        // Format 3: the same bytes without the limit (its `None` byte).
        let mut c = window();
        c.push(first).unwrap();
        let v3 = encode_lag_window_as(&c, 3);
        let d = decode_lag_window(&v3).unwrap();
        assert_eq!(d.to_parts(), c.to_parts());
        assert_eq!(d.to_parts().max_tracks, None);
    }

    #[test]
    fn corrupt_bytes_are_errors_never_panics() {
        let mut a = window();
        a.push(&plots()[..20]).unwrap();
        let bytes = encode_lag_window(&a);
        for n in 0..bytes.len() {
            assert!(
                matches!(decode_lag_window(&bytes[..n]), Err(FormatError::Corrupt(_))),
                "truncated at {n}"
            );
        }
        let mut longer = bytes.clone();
        longer.push(0);
        assert!(decode_lag_window(&longer).is_err());
        for i in (0..bytes.len()).step_by(7) {
            let mut flipped = bytes.clone();
            flipped[i] ^= 0x5a;
            let _ = decode_lag_window(&flipped);
        }
    }

    /// Valid encodings of a reprocessing window holding plots and of a
    /// retrodicting one (built once).
    fn valid_encodings() -> &'static [Vec<u8>] {
        static ENCODED: std::sync::OnceLock<Vec<Vec<u8>>> = std::sync::OnceLock::new();
        ENCODED.get_or_init(|| {
            let mut reprocessing = window();
            reprocessing.push(&plots()[..20]).unwrap();
            let config = TrackerConfig::new(2, vec![radar([0.0; 3]), radar([30_000.0, 0.0, 0.0])]);
            let mut retrodicting =
                LagWindow::with_policy(Tracker::new(config).unwrap(), 10.0, LatePolicy::Retrodict)
                    .unwrap();
            retrodicting.push(&plots()[..20]).unwrap();
            vec![
                encode_lag_window(&reprocessing),
                encode_lag_window(&retrodicting),
            ]
        })
    }

    proptest::proptest! {
        #![proptest_config(proptest::test_runner::Config::with_cases(256))]

        /// Several edits of a valid encoding decode to an error or to a
        /// window that encodes and decodes again: never a panic.
        #[test]
        fn mutated_windows_are_errors_or_windows_never_panics(
            which in 0..2usize,
            edits in wire_formats::mutation::edits(),
        ) {
            let bytes = wire_formats::mutation::apply(&valid_encodings()[which], &edits);
            if let Ok(window) = decode_lag_window(&bytes) {
                let again = encode_lag_window(&window);
                proptest::prop_assert!(decode_lag_window(&again).is_ok());
            }
        }
    }
}
