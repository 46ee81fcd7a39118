//! A track whose numbers fail ([`StepReport::failed`], [`FailedStep`]):
//! the frame and the call go on, the other tracks update, the track is
//! named. The failures are put in deterministically by corrupting one
//! track's covariance between two calls (the tests see the tracker's
//! fields; [`Tracker::from_parts`] refuses such a track).

use super::tests::{Lcg, Target, fig5_config, scene};
use super::*;

/// Three targets well apart (tens of km), under the two radars of the
/// Fig. 5 scene (10-s and 8-s scans), 200 s.
fn targets() -> [Target; 3] {
    [
        Target {
            p0: [-25_000.0, 35_000.0, 0.0],
            v: [30.0, -50.0, 0.0],
        },
        Target {
            p0: [-5_000.0, 30_000.0, 0.0],
            v: [40.0, 10.0, 0.0],
        },
        Target {
            p0: [15_000.0, 40_000.0, 0.0],
            v: [-30.0, -20.0, 0.0],
        },
    ]
}

/// An IMM of two constant-velocity-like models that hardly switch (mean
/// sojourn 10⁹ s), so that one model's covariance stays its own.
fn imm(cfg: &mut TrackerConfig) {
    cfg.motion = Motion::Imm(Imm {
        models: vec![
            MotionModel::ConstantVelocity { sigma_a: [0.05; 3] },
            MotionModel::CoordinatedTurn {
                turn_rate: 0.01,
                sigma_a: [0.05; 3],
            },
        ],
        mean_sojourn: vec![1e9, 1e9],
        initial_probabilities: vec![0.5, 0.5],
    });
}

/// The scene fed up to t = 100 s, `corrupt` applied to the confirmed track
/// nearest the second target (its id returned), then the rest fed and
/// flushed: the report of the second part, the tracker, and the ids of the
/// other two targets' tracks before the corruption.
fn run(
    cfg: TrackerConfig,
    corrupt: impl FnOnce(&mut Track),
) -> (StepReport, Tracker, u64, Vec<u64>) {
    let plots = scene(&cfg.radars, &[0.0, 3.0], &targets(), 200.0, &mut Lcg(5));
    let (early, late): (Vec<Plot>, Vec<Plot>) = plots.iter().partition(|p| p.t < 100.0);
    let mut tracker = Tracker::new(cfg).unwrap();
    tracker.process(&early).unwrap();
    let confirmed = tracker.confirmed_tracks();
    assert_eq!(confirmed.len(), 3);
    let near = |t: &TrackOutput, k: usize| {
        let p = targets()[k].at(t.t);
        (t.state[0] - p[0]).hypot(t.state[2] - p[1]) < 1_000.0
    };
    let bad = confirmed.iter().find(|t| near(t, 1)).unwrap().id;
    let others: Vec<u64> = [0, 2]
        .map(|k| confirmed.iter().find(|t| near(t, k)).unwrap().id)
        .to_vec();
    let slot = tracker.tracks.iter().position(|t| t.id == bad).unwrap();
    corrupt(Arc::make_mut(&mut tracker.tracks[slot]));
    let mut report = tracker
        .process(&late)
        .expect("a track's failure is no error of the call");
    let flushed = tracker.flush().unwrap();
    report.failed.extend(flushed.failed);
    (report, tracker, bad, others)
}

/// The other targets' tracks went on: each updated at one of the last
/// scans, within 1 km of its target.
fn others_updated(tracker: &Tracker, others: &[u64]) {
    let tracks = tracker.confirmed_tracks();
    for (&id, k) in others.iter().zip([0, 2]) {
        let t = tracks.iter().find(|t| t.id == id).expect("kept");
        assert!(
            t.last_update >= 190.0,
            "track {id} last updated at {}",
            t.last_update
        );
        let p = targets()[k].at(t.t);
        assert!((t.state[0] - p[0]).hypot(t.state[2] - p[1]) < 1_000.0);
    }
}

/// `bad` failed at `step`, once, and is gone; its target has a new track.
fn dropped_at(report: &StepReport, tracker: &Tracker, bad: u64, step: FailedStep) {
    let mine: Vec<&TrackFailure> = report.failed.iter().filter(|f| f.id == bad).collect();
    assert_eq!(mine.len(), 1, "{:?}", report.failed);
    assert_eq!((mine[0].step, mine[0].confirmed), (step, true));
    assert!(mine[0].dropped());
    assert!(report.deleted.iter().all(|d| d.id != bad));
    let tracks = tracker.confirmed_tracks();
    assert!(tracks.iter().all(|t| t.id != bad));
    let p = targets()[1].at(tracker.last_time().unwrap());
    assert!(
        tracks
            .iter()
            .any(|t| (t.state[0] - p[0]).hypot(t.state[2] - p[1]) < 1_000.0),
        "the second target has no track again"
    );
}

/// A covariance made non-finite (constant velocity), or one IMM model's
/// state (its mixing then spreads it to every model): the prediction (of
/// its frame, or of its miss judged from the beam) fails, and the track
/// is dropped. Before, `process` returned the error: the whole call
/// failed, and every later call of a session with it.
#[test]
fn a_track_whose_prediction_fails_is_dropped_and_named() {
    let mut cfg = fig5_config(false);
    cfg.motion = Motion::ConstantVelocity;
    let (report, tracker, bad, others) = run(cfg, |t| t.p[(0, 0)] = f64::NAN);
    dropped_at(&report, &tracker, bad, FailedStep::Predict);
    assert!(matches!(
        report.failed[0].error,
        AlgoError::NonFinite { .. } | AlgoError::NotPositiveDefinite { .. }
    ));
    others_updated(&tracker, &others);

    let mut cfg = fig5_config(false);
    imm(&mut cfg);
    let (report, tracker, bad, others) = run(cfg, |t| t.modes[0].x[1] = f64::INFINITY);
    dropped_at(&report, &tracker, bad, FailedStep::Predict);
    others_updated(&tracker, &others);
}

/// An IMM track whose covariance (combined and per model) is finite but
/// not positive definite (a correlation of 10 between east and north):
/// the IMM prediction passes (it checks finiteness), the polar innovation
/// covariance H P H′ + R of its association is not positive definite. The
/// frame is associated again without it, and it is dropped.
#[test]
fn a_track_whose_innovation_covariance_is_not_positive_definite_is_dropped() {
    let mut cfg = fig5_config(false);
    imm(&mut cfg);
    let indefinite = |p: &mut nalgebra::DMatrix<f64>| {
        let c = 10.0 * (p[(0, 0)] * p[(2, 2)]).sqrt();
        p[(0, 2)] = c;
        p[(2, 0)] = c;
    };
    let (report, tracker, bad, others) = run(cfg, |t| {
        indefinite(&mut t.p);
        for m in &mut t.modes {
            indefinite(&mut m.p);
        }
    });
    dropped_at(&report, &tracker, bad, FailedStep::Associate);
    others_updated(&tracker, &others);
}

/// An IMM track one of whose models (probability 10⁻⁶) has an indefinite
/// covariance: the combined prediction the association uses is sound, the
/// model's own update (its innovation covariance by Cholesky) fails. The
/// track is dropped at that update.
#[test]
fn a_track_whose_update_fails_is_dropped_and_named() {
    let mut cfg = fig5_config(false);
    imm(&mut cfg);
    let (report, tracker, bad, others) = run(cfg, |t| {
        t.modes[0].probability = 1e-6;
        t.modes[1].probability = 1.0 - 1e-6;
        let p = &mut t.modes[0].p;
        let c = 10.0 * (p[(0, 0)] * p[(2, 2)]).sqrt();
        p[(0, 2)] = c;
        p[(2, 0)] = c;
    });
    dropped_at(&report, &tracker, bad, FailedStep::Update);
    assert!(matches!(
        report.failed[0].error,
        AlgoError::NotPositiveDefinite { .. }
    ));
    others_updated(&tracker, &others);
}

/// A tentative track made non-finite is dropped by the initiator, named;
/// the three targets are confirmed all the same (the dropped one's plots
/// start it again).
#[test]
fn a_tentative_track_whose_numbers_fail_is_dropped_and_named() {
    let cfg = fig5_config(false);
    let plots = scene(&cfg.radars, &[0.0, 3.0], &targets(), 200.0, &mut Lcg(5));
    let (early, late): (Vec<Plot>, Vec<Plot>) = plots.iter().partition(|p| p.t < 10.5);
    let mut tracker = Tracker::new(cfg).unwrap();
    tracker.process(&early).unwrap();
    assert!(tracker.confirmed_tracks().is_empty());
    let tentative = &mut tracker.initiator.tentatives[0];
    tentative.p[(0, 0)] = f64::NAN;
    let bad = tentative.id;
    let mut report = tracker.process(&late).unwrap();
    report.failed.extend(tracker.flush().unwrap().failed);
    let mine: Vec<&TrackFailure> = report.failed.iter().filter(|f| f.id == bad).collect();
    assert_eq!(mine.len(), 1, "{:?}", report.failed);
    assert_eq!(
        (mine[0].step, mine[0].confirmed),
        (FailedStep::Initiate, false)
    );
    assert!(tracker.track_ids().all(|id| id != bad));
    assert_eq!(tracker.confirmed_tracks().len(), 3);
}
