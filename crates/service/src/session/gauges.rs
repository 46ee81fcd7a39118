//! Per-session gauges for `/metrics`: each plot-fusion session's radar
//! registration (bias, σ, pairs, converged) and accuracy (each σ declared,
//! learnt and applied), as this replica last saw it.
//!
//! The `metrics` recorder cannot forget a label set, and a session's labels
//! must go when the session does; so these gauges are kept here and
//! rendered in Prometheus text format after the recorder's own. A session's
//! entry is set by every batch this replica applies to it, removed when it
//! is deleted here, and dropped once it has not changed for
//! [`RadarGauges::RETAIN`] (a session idle that long, deleted on another
//! replica, or now pushed through another replica). Behind a load balancer
//! each replica shows the sessions it served: `…_updated_timestamp_seconds`
//! tells a query which replica's copy is the newest.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::sync::Mutex;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use crate::plot_fusion::{RadarAccuracyView, RadarBiasView, SigmaView};

/// (tenant, session id).
type SessionKey = (String, String);

/// When a session's gauges were set (unix seconds), and its radars'
/// registration and accuracy.
type Entry = (f64, Vec<RadarBiasView>, Vec<RadarAccuracyView>);

/// The registration gauges of the sessions this replica pushed to.
#[derive(Debug, Default)]
pub struct RadarGauges {
    sessions: Mutex<HashMap<SessionKey, Entry>>,
}

/// One gauge family: its name, help, and the value of a radar's view (none:
/// not shown for that radar, an elevation of a 2D radar).
struct Family {
    name: &'static str,
    help: &'static str,
    value: fn(&RadarBiasView) -> Option<f64>,
}

const FAMILIES: &[Family] = &[
    Family {
        name: "fusion_session_radar_range_bias_metres",
        help: "Estimated range bias of a session's radar (measured minus true), as applied to its plots",
        value: |b| Some(b.range_m),
    },
    Family {
        name: "fusion_session_radar_range_bias_sigma_metres",
        help: "Standard deviation of the range bias estimate",
        value: |b| Some(b.sigma_range_m),
    },
    Family {
        name: "fusion_session_radar_azimuth_bias_degrees",
        help: "Estimated azimuth bias of a session's radar (measured minus true)",
        value: |b| Some(b.azimuth_deg),
    },
    Family {
        name: "fusion_session_radar_azimuth_bias_sigma_degrees",
        help: "Standard deviation of the azimuth bias estimate",
        value: |b| Some(b.sigma_azimuth_deg),
    },
    Family {
        name: "fusion_session_radar_elevation_bias_degrees",
        help: "Estimated elevation bias of a session's 3D radar (measured minus true)",
        value: |b| b.elevation_deg,
    },
    Family {
        name: "fusion_session_radar_elevation_bias_sigma_degrees",
        help: "Standard deviation of the elevation bias estimate",
        value: |b| b.sigma_elevation_deg,
    },
    Family {
        name: "fusion_session_radar_registration_pairs",
        help: "Common-target plot pairs behind the estimate (decayed count)",
        value: |b| Some(b.pairs),
    },
    Family {
        name: "fusion_session_radar_registration_converged",
        help: "1 when the estimate is applied (enough pairs), 0 while the prior is",
        value: |b| Some(if b.converged { 1.0 } else { 0.0 }),
    },
    Family {
        name: "fusion_session_radar_registration_reference",
        help: "1 when the radar is a reference (held at its prior)",
        value: |b| Some(if b.reference { 1.0 } else { 0.0 }),
    },
];

/// One accuracy gauge family (labelled by the σ's `component`): its name,
/// help and the value of a σ (none: not shown), and the same of the
/// detection probability (unlabelled).
struct SigmaFamily {
    name: &'static str,
    help: &'static str,
    value: fn(&SigmaView) -> Option<f64>,
    detection: (&'static str, &'static str),
}

const SIGMA_FAMILIES: &[SigmaFamily] = &[
    SigmaFamily {
        name: "fusion_session_radar_sigma_declared",
        help: "A session's radar's declared measurement σ (component: range_m, azimuth_deg, elevation_deg, radial_velocity_mps)",
        value: |s| Some(s.declared),
        detection: (
            "fusion_session_radar_detection_probability_declared",
            "A session's radar's declared detection probability per scan",
        ),
    },
    SigmaFamily {
        name: "fusion_session_radar_sigma_estimated",
        help: "The radar's measurement σ learnt online from its plots' innovations",
        value: |s| s.estimated,
        detection: (
            "fusion_session_radar_detection_probability_estimated",
            "The radar's detection probability learnt online from the scans between its hits of the confirmed tracks",
        ),
    },
    SigmaFamily {
        name: "fusion_session_radar_sigma_estimate_sigma",
        help: "Standard deviation of the learnt σ",
        value: |s| s.sigma,
        detection: (
            "fusion_session_radar_detection_probability_estimate_sigma",
            "Standard deviation of the learnt detection probability",
        ),
    },
    SigmaFamily {
        name: "fusion_session_radar_sigma_applied",
        help: "The measurement σ the tracker applies (the learnt one once converged, unless pinned)",
        value: |s| Some(s.applied),
        detection: (
            "fusion_session_radar_detection_probability_applied",
            "The detection probability the tracker applies (the learnt one once converged, unless pinned)",
        ),
    },
    SigmaFamily {
        name: "fusion_session_radar_sigma_converged",
        help: "1 when the learnt σ has converged",
        value: |s| Some(if s.converged { 1.0 } else { 0.0 }),
        detection: (
            "fusion_session_radar_detection_probability_converged",
            "1 when the learnt detection probability has converged",
        ),
    },
    SigmaFamily {
        name: "fusion_session_radar_sigma_plots",
        help: "Plots behind the learnt σ (decayed count)",
        value: |s| Some(s.plots),
        detection: (
            "fusion_session_radar_detection_probability_trials",
            "Scans (trials) behind the learnt detection probability (decayed count)",
        ),
    },
];

impl RadarGauges {
    /// How long a session's gauges stay without a batch applied here.
    pub const RETAIN: Duration = Duration::from_secs(15 * 60);

    /// Sets a session's gauges from a batch's update (its radars'
    /// registration and accuracy); a session with neither has none.
    pub fn record(
        &self,
        tenant: &str,
        id: &str,
        radars: &[RadarBiasView],
        accuracy: &[RadarAccuracyView],
    ) {
        self.record_at(tenant, id, radars, accuracy, unix_now());
    }

    fn record_at(
        &self,
        tenant: &str,
        id: &str,
        radars: &[RadarBiasView],
        accuracy: &[RadarAccuracyView],
        now: f64,
    ) {
        let mut sessions = self.sessions.lock().unwrap_or_else(|p| p.into_inner());
        if radars.is_empty() && accuracy.is_empty() {
            if !sessions.is_empty() {
                sessions.remove(&(tenant.to_string(), id.to_string()));
            }
        } else {
            sessions.insert(
                (tenant.to_string(), id.to_string()),
                (now, radars.to_vec(), accuracy.to_vec()),
            );
        }
    }

    /// Drops a deleted session's gauges.
    pub fn forget(&self, tenant: &str, id: &str) {
        let mut sessions = self.sessions.lock().unwrap_or_else(|p| p.into_inner());
        sessions.remove(&(tenant.to_string(), id.to_string()));
    }

    /// The gauges in Prometheus text format (0.0.4), after dropping the
    /// sessions unchanged for longer than [`RadarGauges::RETAIN`]. Empty
    /// when no session has any.
    pub fn render(&self) -> String {
        self.render_at(unix_now())
    }

    fn render_at(&self, now: f64) -> String {
        let mut sessions = self.sessions.lock().unwrap_or_else(|p| p.into_inner());
        sessions.retain(|_, (at, _, _)| now - *at <= Self::RETAIN.as_secs_f64());
        if sessions.is_empty() {
            return String::new();
        }
        let mut keys: Vec<_> = sessions.keys().collect();
        keys.sort();
        let mut out = String::new();
        for f in FAMILIES {
            let _ = writeln!(out, "# HELP {} {}", f.name, f.help);
            let _ = writeln!(out, "# TYPE {} gauge", f.name);
            for key in &keys {
                let (_, radars, _) = &sessions[*key];
                for b in radars {
                    if let Some(v) = (f.value)(b) {
                        let _ =
                            writeln!(out, "{}{{{}}} {}", f.name, labels(key, &b.radar), number(v));
                    }
                }
            }
        }
        let name = "fusion_session_radar_registration_updated_timestamp_seconds";
        let _ = writeln!(
            out,
            "# HELP {name} When this replica last applied a batch to the session (unix seconds)"
        );
        let _ = writeln!(out, "# TYPE {name} gauge");
        for key in &keys {
            let (at, radars, _) = &sessions[*key];
            for b in radars {
                let _ = writeln!(out, "{name}{{{}}} {}", labels(key, &b.radar), number(*at));
            }
        }
        for f in SIGMA_FAMILIES {
            let _ = writeln!(out, "# HELP {} {}", f.name, f.help);
            let _ = writeln!(out, "# TYPE {} gauge", f.name);
            for key in &keys {
                let (_, _, accuracy) = &sessions[*key];
                for a in accuracy {
                    for (component, s) in a.components() {
                        if let Some(v) = s.and_then(|s| (f.value)(s)) {
                            let _ = writeln!(
                                out,
                                "{}{{{},component=\"{component}\"}} {}",
                                f.name,
                                labels(key, &a.radar),
                                number(v)
                            );
                        }
                    }
                }
            }
        }
        for f in SIGMA_FAMILIES {
            let (name, help) = f.detection;
            let _ = writeln!(out, "# HELP {name} {help}");
            let _ = writeln!(out, "# TYPE {name} gauge");
            for key in &keys {
                let (_, _, accuracy) = &sessions[*key];
                for a in accuracy {
                    if let Some(v) = a.p_detection.as_ref().and_then(f.value) {
                        let _ = writeln!(out, "{name}{{{}}} {}", labels(key, &a.radar), number(v));
                    }
                }
            }
        }
        out
    }
}

fn labels((tenant, session): &SessionKey, radar: &str) -> String {
    format!(
        "tenant=\"{}\",session=\"{}\",radar=\"{}\"",
        escape(tenant),
        escape(session),
        escape(radar)
    )
}

/// A label value as the text format wants it: `\`, `"` and newlines escaped.
fn escape(v: &str) -> String {
    let mut s = String::with_capacity(v.len());
    for c in v.chars() {
        match c {
            '\\' => s.push_str("\\\\"),
            '"' => s.push_str("\\\""),
            '\n' => s.push_str("\\n"),
            c => s.push(c),
        }
    }
    s
}

/// A sample value: Rust's shortest round-trip form, and the text format's
/// spellings of the non-finite values.
fn number(v: f64) -> String {
    if v.is_nan() {
        "NaN".into()
    } else if v.is_infinite() {
        if v > 0.0 {
            "+Inf".into()
        } else {
            "-Inf".into()
        }
    } else {
        format!("{v}")
    }
}

fn unix_now() -> f64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bias(radar: &str, elevation: Option<f64>) -> RadarBiasView {
        RadarBiasView {
            radar: radar.into(),
            range_m: 301.5,
            azimuth_deg: -0.25,
            elevation_deg: elevation,
            sigma_range_m: 4.0,
            sigma_azimuth_deg: 0.01,
            sigma_elevation_deg: elevation.map(|_| 0.02),
            pairs: 42.5,
            converged: true,
            reference: false,
        }
    }

    #[test]
    fn renders_each_radar_under_its_session_and_tenant() {
        let g = RadarGauges::default();
        let sigma = |declared: f64, estimated: Option<f64>| SigmaView {
            declared,
            estimated,
            sigma: estimated.map(|e| e / 20.0),
            plots: 512.0,
            converged: estimated.is_some(),
            applied: estimated.unwrap_or(declared),
            clipped: 0,
        };
        let accuracy = RadarAccuracyView {
            radar: "r2".into(),
            range_m: sigma(50.0, Some(120.0)),
            azimuth_deg: sigma(0.1, None),
            elevation_deg: None,
            radial_velocity_mps: Some(sigma(1.0, Some(2.5))),
            p_detection: Some(sigma(0.9, Some(0.625))),
            pinned: false,
        };
        g.record_at(
            "acme",
            "s1",
            &[bias("r\"1", None), bias("r2", Some(0.1))],
            &[accuracy],
            1000.0,
        );
        let text = g.render_at(1000.0);
        assert!(text.contains(
            "fusion_session_radar_range_bias_metres{tenant=\"acme\",session=\"s1\",radar=\"r\\\"1\"} 301.5"
        ));
        assert!(text.contains(
            "fusion_session_radar_azimuth_bias_sigma_degrees{tenant=\"acme\",session=\"s1\",radar=\"r2\"} 0.01"
        ));
        // Each σ under its component; no estimate, no sample.
        for line in [
            "fusion_session_radar_sigma_estimated{tenant=\"acme\",session=\"s1\",radar=\"r2\",component=\"range_m\"} 120",
            "fusion_session_radar_sigma_applied{tenant=\"acme\",session=\"s1\",radar=\"r2\",component=\"radial_velocity_mps\"} 2.5",
            "fusion_session_radar_sigma_declared{tenant=\"acme\",session=\"s1\",radar=\"r2\",component=\"azimuth_deg\"} 0.1",
            "fusion_session_radar_sigma_converged{tenant=\"acme\",session=\"s1\",radar=\"r2\",component=\"azimuth_deg\"} 0",
            "fusion_session_radar_detection_probability_estimated{tenant=\"acme\",session=\"s1\",radar=\"r2\"} 0.625",
            "fusion_session_radar_detection_probability_trials{tenant=\"acme\",session=\"s1\",radar=\"r2\"} 512",
        ] {
            assert!(text.contains(line), "{line}");
        }
        assert!(!text.contains("component=\"elevation_deg\""));
        assert!(!text.contains(
            "fusion_session_radar_sigma_estimated{tenant=\"acme\",session=\"s1\",radar=\"r2\",component=\"azimuth_deg\"}"
        ));
        // A 2D radar has no elevation sample; the 3D one has.
        let elevation: Vec<_> = text
            .lines()
            .filter(|l| l.starts_with("fusion_session_radar_elevation_bias_degrees{"))
            .collect();
        assert_eq!(
            elevation,
            [
                "fusion_session_radar_elevation_bias_degrees{tenant=\"acme\",session=\"s1\",radar=\"r2\"} 0.1"
            ]
        );
        assert!(text.contains("fusion_session_radar_registration_converged{tenant=\"acme\",session=\"s1\",radar=\"r2\"} 1"));
        assert!(text.contains(
            "fusion_session_radar_registration_updated_timestamp_seconds{tenant=\"acme\",session=\"s1\",radar=\"r2\"} 1000"
        ));
        // Each family is declared once.
        assert_eq!(
            text.matches("# TYPE fusion_session_radar_range_bias_metres gauge")
                .count(),
            1
        );
    }

    #[test]
    fn a_deleted_idle_or_unregistered_session_shows_nothing() {
        let g = RadarGauges::default();
        g.record_at("t", "a", &[bias("r1", None)], &[], 0.0);
        g.record_at("t", "b", &[bias("r1", None)], &[], 0.0);
        g.record_at("t", "c", &[bias("r1", None)], &[], 100.0);
        g.forget("t", "a");
        g.record_at("t", "c", &[], &[], 200.0);
        assert!(!g.render_at(1.0).contains("session=\"a\""));
        assert!(g.render_at(1.0).contains("session=\"b\""));
        let retain = RadarGauges::RETAIN.as_secs_f64();
        assert_eq!(g.render_at(retain + 1.0), "");
    }
}
