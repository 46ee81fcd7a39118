//! Tests of the correlation kind: batches against the batch endpoint,
//! history, late reports, sequences, limits, stored formats and replay.

use super::*;
use crate::{
    Rows,
    correlation::{
        AlignmentInput, MethodInput, MotionModelInput, NodeInput, RuleInput, TrackInput, correlate,
    },
    session::{Admission, Batch, DecodeError, ENVELOPE_FORMAT, Spec, Update},
};
use algo::correlation::engine::Decision;

/// A correlation session in its envelope, as the store holds it.
type Session = Envelope<CorrelationSession>;

/// A batch as the tests write it: the envelope's sequence and the kind's
/// reports in one literal.
#[derive(Default)]
struct TestBatch {
    sequence: Option<u64>,
    reports: Vec<ReportInput>,
    flush: bool,
}

trait Push {
    fn push(
        &mut self,
        id: &str,
        b: TestBatch,
        limits: &Limits,
    ) -> Result<Update<BatchUpdate>, ServiceError>;
    /// Whether the envelope takes the sequence number for a duplicate.
    fn check_sequence(&self, sequence: Option<u64>) -> Result<bool, ServiceError>;
}

impl Push for Session {
    fn push(
        &mut self,
        id: &str,
        b: TestBatch,
        limits: &Limits,
    ) -> Result<Update<BatchUpdate>, ServiceError> {
        let batch = Batch {
            sequence: b.sequence,
            body: BatchInput {
                reports: b.reports,
                flush: b.flush,
            },
        };
        self.apply(id, &batch, limits)
    }

    fn check_sequence(&self, sequence: Option<u64>) -> Result<bool, ServiceError> {
        Ok(matches!(
            self.admit("s", sequence, None, 0)?,
            Admission::Duplicate(_)
        ))
    }
}

/// Applies the sequenced batch `sequence` of `reports`, which must succeed.
fn push_sequenced(s: &mut Session, sequence: u64, reports: &[ReportInput]) {
    s.push(
        "s",
        TestBatch {
            sequence: Some(sequence),
            reports: reports.to_vec(),
            flush: false,
        },
        &LIMITS,
    )
    .unwrap();
}

fn decode(bytes: &[u8]) -> Result<Session, DecodeError> {
    Session::decode(bytes)
}

/// A small deterministic generator (xorshift) for test noise.
struct Noise(u64);

impl Noise {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    }
}

/// Two radars, eight targets (two pairs of them crossing, so that some
/// pairs enter the gate late), radar b reporting 0.2 s after radar a,
/// with one track of b starting late and one of a ending early.
///
/// The cluster alignment (`predict`, tolerance 0.5 s) the stored fixtures
/// were written with; [`grid_scenario`] is the default grid alignment.
fn scenario() -> CorrelateInput {
    scenario_with("predict", 0.2)
}

/// The scenario with the default grid alignment, radar b reporting
/// `offset` s after radar a.
fn grid_scenario(offset: f64) -> CorrelateInput {
    let mut input = scenario_with("grid", offset);
    input.alignment.as_mut().unwrap().mode = None;
    input
}

fn scenario_with(mode: &str, offset_b: f64) -> CorrelateInput {
    let mut noise = Noise(0x9e37_79b9_7f4a_7c15);
    let mut nodes = Vec::new();
    for (ni, (node, offset)) in [("a", 0.0), ("b", offset_b)].into_iter().enumerate() {
        let mut tracks = Vec::new();
        for target in 0..8 {
            let (x0, y0, vx, vy) = match target {
                0 => (0.0, 0.0, 100.0, 0.0),
                1 => (3000.0, 0.0, -100.0, 0.0),
                2 => (0.0, 2000.0, 50.0, 50.0),
                3 => (0.0, 2600.0, 50.0, -50.0),
                t => (t as f64 * 4000.0, 9000.0, 0.0, 80.0),
            };
            let mut samples = Vec::new();
            for scan in 0..30 {
                if (ni == 1 && target == 5 && scan < 12) || (ni == 0 && target == 6 && scan > 20) {
                    continue;
                }
                let t = scan as f64 * 2.0 + offset;
                let e = 30.0;
                samples.push(SampleInput {
                    t: Some(t),
                    state: vec![
                        x0 + vx * t + e * noise.next(),
                        vx + noise.next(),
                        y0 + vy * t + e * noise.next(),
                        vy + noise.next(),
                    ],
                    covariance: Rows::from_nested(&[
                        [400.0, 10.0, 0.0, 0.0],
                        [10.0, 25.0, 0.0, 0.0],
                        [0.0, 0.0, 400.0, 10.0],
                        [0.0, 0.0, 10.0, 25.0],
                    ]),
                    gain: None,
                });
            }
            tracks.push(TrackInput {
                id: Some(format!("{node}{target}")),
                samples,
            });
        }
        nodes.push(NodeInput {
            id: Some(node.into()),
            tracks,
        });
    }
    CorrelateInput {
        state_layout: ["x", "vx", "y", "vy"].map(String::from).to_vec(),
        method: Some(MethodInput {
            kind: Some("dependent_double_threshold".into()),
            rule: Some(RuleInput {
                l: Some(3),
                r: Some(4),
            }),
            ..Default::default()
        }),
        motion_model: Some(MotionModelInput {
            process_noise: Some("dwna".into()),
            sigma_a_mps2: Some(1.0),
            ..Default::default()
        }),
        alignment: Some(AlignmentInput {
            mode: Some(mode.into()),
            tolerance_s: Some(0.5),
            ..Default::default()
        }),
        nodes,
        ..Default::default()
    }
}

fn reports_of(input: &CorrelateInput) -> Vec<ReportInput> {
    let mut out: Vec<ReportInput> = input
        .nodes
        .iter()
        .flat_map(|n| {
            n.tracks.iter().flat_map(move |t| {
                t.samples.iter().map(move |s| ReportInput {
                    node: n.id.clone(),
                    track: t.id.clone(),
                    sample: s.clone(),
                })
            })
        })
        .collect();
    out.sort_by(|a, b| a.sample.t.unwrap().total_cmp(&b.sample.t.unwrap()));
    out
}

fn session_of(input: &CorrelateInput, history: u32) -> Session {
    let mut config = input.clone();
    for n in &mut config.nodes {
        n.tracks.clear();
    }
    Session::create(
        Spec {
            idle_expiry_s: None,
            body: SessionSpec {
                config,
                history_instants: Some(history),
                retire_after_s: Some(1e6),
            },
        },
        0,
        &mut Vec::new(),
    )
    .unwrap()
}

const LIMITS: Limits = Limits {
    max_tracks: 1000,
    max_batch_reports: 10_000,
};

/// Pushes the reports in batches of `size`, through an encode/decode
/// round trip between batches (as the store does), then flushes.
fn run_session(input: &CorrelateInput, size: usize, history: u32) -> SessionView {
    let reports = reports_of(input);
    let mut bytes = session_of(input, history).encode();
    for (i, chunk) in reports.chunks(size).enumerate() {
        let mut s = decode(&bytes).unwrap();
        push_sequenced(&mut s, i as u64 + 1, chunk);
        bytes = s.encode();
    }
    let mut s = decode(&bytes).unwrap();
    s.push(
        "s",
        TestBatch {
            flush: true,
            ..Default::default()
        },
        &LIMITS,
    )
    .unwrap();
    s.view("s", 0, 0).unwrap().body
}

#[test]
fn batches_give_the_decisions_of_the_batch_endpoint() {
    let input = scenario();
    let batch = correlate(input.clone()).unwrap();
    assert!(
        batch
            .pairs
            .iter()
            .filter(|p| p.decision == Decision::Correlated)
            .count()
            >= 6,
        "the scenario must correlate most targets: {:?}",
        batch.pairs
    );
    // History 64 covers the 30 instants: exact whatever the batching.
    for size in [1, 7, 16, 1000] {
        let view = run_session(&input, size, 64);
        assert_eq!(view.instants_processed as usize, batch.instants.len());
        assert_eq!(view.pairs, batch.pairs, "batches of {size}");
        assert_eq!(view.system_tracks, batch.groups, "batches of {size}");
    }
}

/// Radar b reports half a scan (1 s of 2 s) after radar a: the cluster
/// alignment finds no common instant, the default grid finds them all, and
/// a session in batches of any size gives the batch endpoint's decisions.
#[test]
fn unsynchronised_radars_correlate_on_the_grid_in_batches_as_in_one_call() {
    let correlated = |pairs: &[PairOutput]| {
        pairs
            .iter()
            .filter(|p| p.decision == Decision::Correlated)
            .count()
    };
    let clustered = correlate(scenario_with("predict", 1.0)).unwrap();
    assert_eq!(correlated(&clustered.pairs), 0);
    assert_eq!(clustered.alignment.node_pairs_without_common_instant, 1);
    assert!(
        clustered
            .warnings
            .iter()
            .any(|w| w.contains("share no instant") && w.contains("grid")),
        "{:?}",
        clustered.warnings
    );
    let input = grid_scenario(1.0);
    let batch = correlate(input.clone()).unwrap();
    // Both nodes report every 2 s: the grid is 0, 2, 4, … 60 (the first grid
    // point at or after b's last report at 59), staleness 3 s.
    assert_eq!(batch.alignment.period_s, Some(2.0));
    assert!(batch.alignment.period_estimated);
    assert_eq!(batch.instants.len(), 31);
    assert_eq!(batch.instants[1], 2.0);
    assert_eq!(batch.alignment.node_pairs_without_common_instant, 0);
    // Every target seen by both radars is correlated, and nothing else.
    let pairs: Vec<(String, String)> = batch
        .pairs
        .iter()
        .filter(|p| p.decision == Decision::Correlated)
        .map(|p| (p.a.track.clone(), p.b.track.clone()))
        .collect();
    let want: Vec<(String, String)> = (0..8).map(|t| (format!("a{t}"), format!("b{t}"))).collect();
    assert_eq!(pairs, want);
    for size in [1, 7, 16, 1000] {
        let view = run_session(&input, size, 64);
        assert_eq!(view.instants_processed as usize, batch.instants.len());
        assert_eq!(view.pairs, batch.pairs, "batches of {size}");
        assert_eq!(view.system_tracks, batch.groups, "batches of {size}");
    }
}

/// Before any pair reaches its rule, the provisionally paired tracks (trial
/// system tracks, eq. 21) are output as system tracks flagged `trial`, and
/// are not listed as unpaired.
#[test]
fn trial_system_tracks_are_output_flagged() {
    let mut input = scenario();
    // Three scans of the 3/4 rule: m ≤ 3 … and 2 scans: m ≤ 2 < L = 3.
    for n in &mut input.nodes {
        for t in &mut n.tracks {
            t.samples.retain(|s| s.t.unwrap() < 4.0);
        }
        n.tracks.retain(|t| !t.samples.is_empty());
    }
    let out = correlate(input).unwrap();
    assert!(
        out.pairs.iter().all(|p| p.decision != Decision::Correlated),
        "{:?}",
        out.pairs
    );
    let trials: Vec<(String, String)> = out
        .groups
        .iter()
        .map(|g| {
            assert!(g.trial, "{g:?}");
            (g.members[0].track.clone(), g.members[1].track.clone())
        })
        .collect();
    let flagged = out.pairs.iter().filter(|p| p.trial).count();
    assert_eq!(trials.len(), flagged);
    assert!(trials.len() >= 5, "{trials:?}");
    for (a, b) in &trials {
        assert_eq!(a[1..], b[1..], "same target: {a} {b}");
        assert!(
            out.unpaired
                .iter()
                .all(|(_, ids)| !ids.contains(a) && !ids.contains(b))
        );
    }
}

/// A session whose cluster alignment keeps the nodes apart says so.
#[test]
fn a_session_says_when_its_nodes_never_meet() {
    let input = scenario_with("predict", 1.0);
    let mut s = session_of(&input, 64);
    let u = s
        .push(
            "s",
            TestBatch {
                reports: reports_of(&input),
                flush: true,
                sequence: None,
            },
            &LIMITS,
        )
        .unwrap();
    assert!(u.body.changes.is_empty());
    assert!(
        u.warnings
            .iter()
            .any(|w| w.contains("share no instant") && w.contains("(a–b)") && w.contains("grid")),
        "{:?}",
        u.warnings
    );
}

/// On the grid a report that arrives after its instant closed is not lost:
/// it becomes its track's latest and serves the next instants.
#[test]
fn on_the_grid_a_late_report_serves_the_later_instants() {
    let input = grid_scenario(1.0);
    let mut s = session_of(&input, 64);
    let reports = reports_of(&input);
    let (early, rest): (Vec<_>, Vec<_>) = reports
        .iter()
        .cloned()
        .partition(|r| r.sample.t.unwrap() < 20.0);
    // Radar b's reports at 17 s arrive late, after instant 18 closed; its
    // reports at 19 s are lost.
    let (late, early): (Vec<_>, Vec<_>) = early
        .into_iter()
        .filter(|r| !(r.node.as_deref() == Some("b") && r.sample.t == Some(19.0)))
        .partition(|r| r.node.as_deref() == Some("b") && r.sample.t == Some(17.0));
    assert_eq!(late.len(), 7);
    let batch = |reports: Vec<ReportInput>, flush| TestBatch {
        reports,
        flush,
        sequence: None,
    };
    let first = s.push("s", batch(early, true), &LIMITS).unwrap();
    // The last report is a's at 18 s: the flush closes the grid up to 18.
    assert_eq!(first.body.instants.last(), Some(&18.0));
    let u = s.push("s", batch(late, false), &LIMITS).unwrap();
    assert!(
        u.warnings
            .iter()
            .any(|w| w.contains("serve the later instants")),
        "{u:?}"
    );
    assert_eq!(s.state.reports_late, 7);
    // At 20 s the late reports are b's latest, 3 s old: within the 3 s
    // staleness bound, so b's tracks are present there (without them, the
    // reports at 15 s would be 5 s old and b absent).
    let u = s.push("s", batch(rest, true), &LIMITS).unwrap();
    assert_eq!(u.body.instants.first(), Some(&20.0));
    let scene = &s.state.scene;
    let k20 = scene.first() + scene.times().iter().position(|&t| t == 20.0).unwrap();
    let present = scene.nodes()[1]
        .iter()
        .filter(|t| t.is_present(k20))
        .count();
    assert_eq!(present, 7, "b's seven tracks alive at 17 s");
}

#[test]
fn a_short_history_keeps_the_decided_pairs_of_well_separated_targets() {
    let input = scenario();
    let batch = correlate(input.clone()).unwrap();
    let view = run_session(&input, 5, 4);
    let decided = |pairs: &[PairOutput]| -> Vec<(String, String)> {
        pairs
            .iter()
            .filter(|p| p.decision == Decision::Correlated)
            .map(|p| (p.a.track.clone(), p.b.track.clone()))
            .collect()
    };
    assert_eq!(decided(&view.pairs), decided(&batch.pairs));
}

#[test]
fn late_reports_are_dropped_and_silent_tracks_retire() {
    let input = scenario();
    let mut s = session_of(&input, 8);
    s.state.retire_after_s = 5.0;
    let reports = reports_of(&input);
    let early: Vec<_> = reports
        .iter()
        .filter(|r| r.sample.t.unwrap() < 20.0)
        .cloned()
        .collect();
    s.push(
        "s",
        TestBatch {
            reports: early.clone(),
            flush: true,
            sequence: None,
        },
        &LIMITS,
    )
    .unwrap();
    let again = s
        .push(
            "s",
            TestBatch {
                reports: early[..3].to_vec(),
                ..Default::default()
            },
            &LIMITS,
        )
        .unwrap();
    assert!(
        again.warnings.iter().any(|w| w.contains("dropped")),
        "{again:?}"
    );
    assert_eq!(s.state.reports_late, 3);
    // Node a's track 6 stops after scan 20 (t = 40): retired once an
    // instant more than 5 s later is closed.
    let rest: Vec<_> = reports
        .iter()
        .filter(|r| r.sample.t.unwrap() >= 20.0)
        .cloned()
        .collect();
    let u = s
        .push(
            "s",
            TestBatch {
                reports: rest,
                flush: true,
                sequence: None,
            },
            &LIMITS,
        )
        .unwrap();
    assert!(
        u.body
            .retired
            .iter()
            .any(|t| t.node == "a" && t.track == "a6"),
        "{:?}",
        u.body.retired
    );
    let view = s.view("s", 0, 0).unwrap();
    assert!(view.body.nodes[0].tracks.iter().all(|t| t.id != "a6"));
    assert!(view.body.pairs.iter().all(|p| p.a.track != "a6"));
}

#[test]
fn sequences_are_checked() {
    let mut s = session_of(&scenario(), 8);
    // A new session expects 1: a later number is a gap, 0 is invalid.
    assert!(matches!(
        s.check_sequence(Some(2)),
        Err(ServiceError::Conflict(_))
    ));
    assert!(matches!(
        s.check_sequence(Some(0)),
        Err(ServiceError::InvalidInput(ref v)) if v[0].field == "sequence"
    ));
    assert!(!s.check_sequence(Some(1)).unwrap());
    assert!(!s.check_sequence(None).unwrap());
    for sequence in 1..=10 {
        s.push(
            "s",
            TestBatch {
                sequence: Some(sequence),
                ..Default::default()
            },
            &LIMITS,
        )
        .unwrap();
    }
    assert!(s.check_sequence(Some(10)).unwrap());
    assert!(s.check_sequence(Some(3)).unwrap());
    assert!(!s.check_sequence(Some(11)).unwrap());
    assert!(matches!(
        s.check_sequence(Some(12)),
        Err(ServiceError::Conflict(_))
    ));
}

#[test]
fn limits_and_bad_reports_are_refused_without_change() {
    let input = scenario();
    let mut s = session_of(&input, 8);
    let reports = reports_of(&input);
    let small = Limits {
        max_tracks: 3,
        max_batch_reports: 10,
    };
    assert!(matches!(
        s.push(
            "s",
            TestBatch {
                reports: reports[..11].to_vec(),
                ..Default::default()
            },
            &small
        ),
        Err(ServiceError::TooLarge(_))
    ));
    assert!(matches!(
        s.push(
            "s",
            TestBatch {
                reports: reports[..10].to_vec(),
                ..Default::default()
            },
            &small
        ),
        Err(ServiceError::QuotaExceeded(_))
    ));
    let mut bad = reports[0].clone();
    bad.node = Some("zz".into());
    let mut values = bad.sample.covariance.values().to_vec();
    values[0] = -1.0;
    bad.sample.covariance = Rows::from_flat(values, 4, 4).unwrap();
    let Err(ServiceError::InvalidInput(v)) = s.push(
        "s",
        TestBatch {
            reports: vec![bad],
            ..Default::default()
        },
        &LIMITS,
    ) else {
        panic!("bad report accepted");
    };
    let fields: Vec<_> = v.iter().map(|f| f.field.as_str()).collect();
    assert_eq!(fields, ["reports[0].node", "reports[0].covariance"]);
    assert_eq!(s.batches, 0);
    assert_eq!(s.state.pending.len(), 0);
}

#[test]
fn corrupt_state_is_an_error_not_a_panic() {
    let input = scenario();
    let mut s = session_of(&input, 8);
    let reports = reports_of(&input);
    s.push(
        "s",
        TestBatch {
            reports: reports[..40].to_vec(),
            ..Default::default()
        },
        &LIMITS,
    )
    .unwrap();
    let bytes = s.encode();
    assert!(decode(&bytes).is_ok());
    for cut in (0..bytes.len()).step_by(97) {
        assert!(decode(&bytes[..cut]).is_err());
    }
    let mut wrong = bytes.clone();
    wrong[0] = 99;
    assert!(decode(&wrong).is_err());
}

/// A session written by the first release (format 1) — the scenario's
/// first half in sequenced batches of 16, history 8 — still reads, and
/// continues exactly as a session that never left this release.
#[test]
fn a_format_1_session_reads_and_continues_like_a_current_one() {
    let old = include_bytes!("../../../../../tests/fixtures/session_v1.bin");
    assert_eq!(old[0], 1);
    let input = scenario();
    let reports = reports_of(&input);
    let half = reports.len() / 2;
    let push = |s: &mut Session, i: usize, chunk: &[ReportInput]| {
        push_sequenced(s, i as u64 + 1, chunk);
    };
    let mut now = first_half_session();
    let mut read = decode(old).unwrap();
    assert_eq!(read.view("s", 0, 0).unwrap(), now.view("s", 0, 0).unwrap());
    assert!(read.last_update.is_none(), "format 1 kept no update");
    // Re-encoded in the current format: smaller (covariance triangles),
    // and equal to the current session's encoding but for the update
    // the current one kept.
    let current = now.encode();
    assert_eq!(current[0], ENVELOPE_FORMAT);
    assert!(
        current.len() < old.len(),
        "{} vs {}",
        current.len(),
        old.len()
    );
    for (j, chunk) in reports[half..].chunks(16).enumerate() {
        push(&mut read, half.div_ceil(16) + j, chunk);
        push(&mut now, half.div_ceil(16) + j, chunk);
    }
    assert_eq!(read.encode(), now.encode());
    assert_eq!(read.view("s", 0, 0).unwrap(), now.view("s", 0, 0).unwrap());
}

/// The scenario's first half in sequenced batches of 16, history 8 (the
/// fixtures' content).
fn first_half_session() -> Session {
    let input = scenario();
    let reports = reports_of(&input);
    let half = reports.len() / 2;
    let mut now = session_of(&input, 8);
    for (i, chunk) in reports[..half].chunks(16).enumerate() {
        push_sequenced(&mut now, i as u64 + 1, chunk);
    }
    now
}

#[test]
fn a_retried_last_batch_gets_its_update_again() {
    let input = scenario();
    let reports = reports_of(&input);
    let mut s = session_of(&input, 8);
    let mut updates = Vec::new();
    for (i, chunk) in reports[..64].chunks(16).enumerate() {
        let u = s
            .push(
                "s",
                TestBatch {
                    sequence: Some(i as u64 + 1),
                    reports: chunk.to_vec(),
                    flush: false,
                },
                &LIMITS,
            )
            .unwrap();
        updates.push(u);
        // Through the store's round trip.
        s = decode(&s.encode()).unwrap();
    }
    let last = updates.last().unwrap();
    assert!(!last.body.pairs.is_empty() && !last.body.system_tracks.is_empty());
    assert!(s.check_sequence(Some(4)).unwrap());
    let replay = s.duplicate_ack("s", 4, 9);
    assert!(replay.duplicate);
    assert_eq!(replay.version, 9);
    assert_eq!(replay.sequence, Some(4));
    assert_eq!(replay.body.instants, last.body.instants);
    assert_eq!(replay.body.changes, last.body.changes);
    assert_eq!(replay.body.pairs, last.body.pairs);
    assert_eq!(replay.body.system_tracks, last.body.system_tracks);
    assert_eq!(replay.body.retired, last.body.retired);
    assert_eq!(replay.body.pending_reports, last.body.pending_reports);
    assert_eq!(replay.warnings.len(), last.warnings.len() + 1);
    // An older batch: an empty acknowledgement.
    let older = s.duplicate_ack("s", 2, 9);
    assert!(older.duplicate && older.body.changes.is_empty() && older.body.pairs.is_empty());
    // After a batch without a sequence number there is nothing to replay.
    s.push(
        "s",
        TestBatch {
            reports: reports[64..70].to_vec(),
            ..Default::default()
        },
        &LIMITS,
    )
    .unwrap();
    let s = decode(&s.encode()).unwrap();
    assert!(s.duplicate_ack("s", 4, 10).body.pairs.is_empty());
}

/// A session written by the release before the envelope (format 2, by
/// `Session::encode` of that release: the scenario's first half in sequenced
/// batches of 16, history 8) reads as a correlation session with its kept
/// update, and continues bit for bit like a session that never left this
/// release.
#[test]
fn a_format_2_session_reads_and_continues_like_a_current_one() {
    let old = include_bytes!("../../../../../tests/fixtures/session_v2.bin");
    assert_eq!(old[0], 2);
    assert_eq!(
        crate::session::stored_kind(old).unwrap(),
        CorrelationSession::TAG
    );
    let input = scenario();
    let reports = reports_of(&input);
    let half = reports.len() / 2;
    let mut now = first_half_session();
    let mut read = decode(old).unwrap();
    assert_eq!(read.view("s", 0, 0).unwrap(), now.view("s", 0, 0).unwrap());
    assert_eq!(read.last_update, now.last_update);
    assert!(read.last_update.is_some(), "format 2 kept the last update");
    // The retry of the last batch replays the same update from both.
    let last = half.div_ceil(16) as u64;
    let replay = |s: &Session| match s.admit("s", Some(last), None, 7).unwrap() {
        Admission::Duplicate(u) => u,
        Admission::Apply => panic!("batch {last} is a duplicate"),
    };
    assert_eq!(replay(&read), replay(&now));
    // Re-encoded by this release: the envelope (format 3, correlation tag),
    // the same bytes from both.
    let current = now.encode();
    assert_eq!(current[..2], [ENVELOPE_FORMAT, CorrelationSession::TAG]);
    assert_eq!(read.encode(), current);
    for (j, chunk) in reports[half..].chunks(16).enumerate() {
        for s in [&mut read, &mut now] {
            push_sequenced(s, last + 1 + j as u64, chunk);
        }
    }
    assert_eq!(read.encode(), now.encode());
    assert_eq!(read.view("s", 0, 0).unwrap(), now.view("s", 0, 0).unwrap());
}
