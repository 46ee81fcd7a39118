#!/usr/bin/env python3
"""Compare our multi-radar plot-fusion tracker with Stone Soup 1.9.1.

What it compares
    One deterministic simulated scene (numpy, ``--seed``): two 2D radars
    (range + azimuth, no elevation, no Doppler) at local ENU [-20 km, 0] and
    [+20 km, 0], radar A scanning every 4 s, radar B every 5 s with a 1.3 s
    phase offset, sigma_range 50 m, sigma_azimuth 0.2 deg, P_D 0.9, Poisson
    clutter uniform in range [1, 120] km x azimuth [0, 360) deg, and
    ``--targets`` nearly-constant-velocity targets (100-300 m/s, white-noise
    acceleration sigma 0.5 m/s^2), some of which start late / end early.

    The same plots go to
      * Stone Soup 1.9.1: MultiTargetMixtureTracker + JPDAwithEHM2 +
        PDAHypothesiser + ExtendedKalmanUpdater + KalmanPredictor
        (CV, q = sigma_a^2 = 1), CartesianToBearingRange per radar,
        MultiMeasurementInitiator (3 updates, GNN on Mahalanobis distance),
        UpdateTimeStepsDeleter (3 missed scans);
      * our service: POST {url}/v1/plot-fusion/track, serial mode, JPDA
        ("exact"), 3-of-4 logic initiation with a 600 m/s speed gate,
        deletion after 3 consecutive misses, sigma_a 1 m/s^2.

    At every scan instant of radar A both trackers' confirmed tracks are
    scored against the targets alive at that instant with GOSPA (p = 1,
    c = 1000 m, alpha = 2) on horizontal position. The script prints a
    markdown table of mean GOSPA and its localisation / missed / false parts,
    mean number of confirmed tracks vs true targets, and wall time.

How to run
    bash checks/setup.sh                       # once: checks/.venv
    checks/.venv/bin/python checks/plot_fusion_vs_stonesoup.py --stonesoup-only
    checks/.venv/bin/python checks/plot_fusion_vs_stonesoup.py \\
        --url http://127.0.0.1:8080 --targets 20 --json-out /tmp/fusion.json
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import dataclass, field
from datetime import datetime, timedelta

import numpy as np
from scipy.optimize import linear_sum_assignment

# --------------------------------------------------------------------------
# Scene constants (the brief's scene; only seed, targets, clutter and the
# late-start fraction are options).
# --------------------------------------------------------------------------
DURATION_S = 300.0
TRUTH_DT_S = 0.1  # truth grid; every scan instant is a multiple of it
RANGE_MIN_M = 1_000.0
RANGE_MAX_M = 120_000.0
SIGMA_RANGE_M = 50.0
SIGMA_AZIMUTH_DEG = 0.2
P_DETECTION = 0.9
TRUTH_SIGMA_A = 0.5  # m/s^2, truth white-noise acceleration
TRACKER_SIGMA_A = 1.0  # m/s^2, both trackers' process noise (q = 1)
GOSPA_C_M = 1000.0
GOSPA_P = 1
GOSPA_ALPHA = 2
FRESH_S = 10.0  # a track scores only if updated within this long
ORIGIN = {"lat_deg": 52.0, "lon_deg": 4.0, "height_m": 0.0}


@dataclass(frozen=True)
class Radar:
    id: str
    site: tuple[float, float]  # local ENU (m)
    period_s: float
    phase_s: float


RADARS = (
    Radar("A", (-20_000.0, 0.0), 4.0, 0.0),
    Radar("B", (20_000.0, 0.0), 5.0, 1.3),
)


def clutter_density(mean_false_per_scan: float) -> float:
    """Clutter per scan per unit of (azimuth rad x range m)."""
    return mean_false_per_scan / (2.0 * math.pi * (RANGE_MAX_M - RANGE_MIN_M))


# --------------------------------------------------------------------------
# Scene
# --------------------------------------------------------------------------
@dataclass
class Target:
    start_s: float
    end_s: float
    xy: np.ndarray  # (n_grid, 2) on the TRUTH_DT_S grid from 0 to DURATION_S

    def alive(self, t: float) -> bool:
        return self.start_s - 1e-9 <= t <= self.end_s + 1e-9

    def position(self, t: float) -> np.ndarray:
        return self.xy[int(round(t / TRUTH_DT_S))]


@dataclass
class Plot:
    radar: str
    t: float
    range_m: float
    azimuth_deg: float  # clockwise from north
    target: int | None  # None for clutter (kept for diagnostics only)


@dataclass
class Scene:
    targets: list[Target]
    scans: list[tuple[float, str, list[Plot]]]  # (t, radar id, plots), time order
    clutter_mean: float

    @property
    def plots(self) -> list[Plot]:
        return [p for _, _, plots in self.scans for p in plots]

    def scan_times(self, radar_id: str) -> list[float]:
        return [t for t, r, _ in self.scans if r == radar_id]


def cv_noise_cholesky(dt: float, q: float) -> np.ndarray:
    """Cholesky factor of the exact CV process noise of one axis."""
    qm = q * np.array([[dt**3 / 3.0, dt**2 / 2.0], [dt**2 / 2.0, dt]])
    return np.linalg.cholesky(qm)


def in_coverage(xy: np.ndarray) -> bool:
    """Every point within [RANGE_MIN_M, RANGE_MAX_M] of every radar."""
    for radar in RADARS:
        r = np.hypot(xy[:, 0] - radar.site[0], xy[:, 1] - radar.site[1])
        if r.min() < RANGE_MIN_M or r.max() > RANGE_MAX_M:
            return False
    return True


def make_targets(rng: np.random.Generator, n: int, late_fraction: float) -> list[Target]:
    """CV targets with white-noise acceleration, kept inside both coverages."""
    n_grid = int(round(DURATION_S / TRUTH_DT_S)) + 1
    f = np.array([[1.0, TRUTH_DT_S], [0.0, 1.0]])
    chol = cv_noise_cholesky(TRUTH_DT_S, TRUTH_SIGMA_A**2)
    n_late = int(round(late_fraction * n))
    targets = []
    for i in range(n):
        if i < n_late:
            start, end = rng.uniform(0.0, 60.0), rng.uniform(240.0, 300.0)
            start = round(start / TRUTH_DT_S) * TRUTH_DT_S
            end = round(end / TRUTH_DT_S) * TRUTH_DT_S
        else:
            start, end = 0.0, DURATION_S
        i0, i1 = int(round(start / TRUTH_DT_S)), int(round(end / TRUTH_DT_S))
        for _attempt in range(10_000):
            x0 = rng.uniform(-20_000.0, 20_000.0)
            y0 = rng.uniform(40_000.0, 80_000.0)
            speed = rng.uniform(100.0, 300.0)
            heading = rng.uniform(0.0, 2.0 * math.pi)  # clockwise from north
            axes = [np.array([x0, speed * math.sin(heading)]),
                    np.array([y0, speed * math.cos(heading)])]
            noise = rng.standard_normal((n_grid, 2, 2))
            xy = np.full((n_grid, 2), np.nan)
            for k in range(i0, i1 + 1):
                xy[k] = axes[0][0], axes[1][0]
                for a in range(2):
                    axes[a] = f @ axes[a] + chol @ noise[k, a]
            if in_coverage(xy[i0:i1 + 1]):
                break
        else:
            raise RuntimeError("could not place a target inside the coverage")
        targets.append(Target(start, end, xy))
    return targets


def measure(radar: Radar, xy: np.ndarray) -> tuple[float, float]:
    """True (range m, azimuth deg clockwise from north) of xy from radar."""
    dx, dy = xy[0] - radar.site[0], xy[1] - radar.site[1]
    return math.hypot(dx, dy), math.degrees(math.atan2(dx, dy)) % 360.0


def make_scene(seed: int, n_targets: int, clutter_mean: float,
               late_fraction: float) -> Scene:
    rng = np.random.default_rng(seed)
    targets = make_targets(rng, n_targets, late_fraction)
    instants = []
    for radar in RADARS:
        k = 0
        while radar.phase_s + k * radar.period_s <= DURATION_S + 1e-9:
            instants.append((round(radar.phase_s + k * radar.period_s, 6), radar))
            k += 1
    instants.sort(key=lambda tr: (tr[0], tr[1].id))
    scans = []
    for t, radar in instants:
        plots = []
        for j, target in enumerate(targets):
            if target.alive(t) and rng.uniform() < P_DETECTION:
                r, az = measure(radar, target.position(t))
                r += rng.normal(0.0, SIGMA_RANGE_M)
                az = (az + rng.normal(0.0, SIGMA_AZIMUTH_DEG)) % 360.0
                plots.append(Plot(radar.id, t, r, az, j))
        for _ in range(rng.poisson(clutter_mean)):
            plots.append(Plot(radar.id, t, rng.uniform(RANGE_MIN_M, RANGE_MAX_M),
                              rng.uniform(0.0, 360.0), None))
        plots = [plots[i] for i in rng.permutation(len(plots))]
        scans.append((t, radar.id, plots))
    return Scene(targets, scans, clutter_mean)


# --------------------------------------------------------------------------
# Scoring
# --------------------------------------------------------------------------
@dataclass
class Gospa:
    total: float
    localisation: float
    missed: float
    false: float


def gospa(truth: np.ndarray, tracks: np.ndarray, c: float = GOSPA_C_M,
          p: int = GOSPA_P, alpha: int = GOSPA_ALPHA) -> Gospa:
    """GOSPA with its decomposition (alpha = 2), truth and tracks (n, 2)."""
    assert alpha == 2, "decomposition below assumes alpha = 2"
    n, m = len(truth), len(tracks)
    if n == 0 or m == 0:
        missed = c**p / 2.0 * n
        false = c**p / 2.0 * m
        return Gospa((missed + false) ** (1.0 / p), 0.0, missed, false)
    d = np.linalg.norm(truth[:, None, :] - tracks[None, :, :], axis=2)
    cost = np.minimum(d, c) ** p
    rows, cols = linear_sum_assignment(cost)
    matched = d[rows, cols] < c
    loc = float(np.sum(cost[rows, cols][matched]))
    n_matched = int(np.sum(matched))
    missed = c**p / 2.0 * (n - n_matched)
    false = c**p / 2.0 * (m - n_matched)
    return Gospa((loc + missed + false) ** (1.0 / p), loc, missed, false)


@dataclass
class Snapshot:
    """Confirmed tracks' horizontal positions at one radar-A instant."""
    t: float
    positions: np.ndarray  # (n_tracks, 2)


@dataclass
class Result:
    name: str
    snapshots: list[Snapshot]
    wall_s: float
    compute_s: float | None = None
    extra: dict = field(default_factory=dict)


def score(scene: Scene, result: Result) -> dict:
    series = []
    for snap in result.snapshots:
        truth = np.array([tg.position(snap.t) for tg in scene.targets if tg.alive(snap.t)])
        truth = truth.reshape(-1, 2)
        g = gospa(truth, snap.positions.reshape(-1, 2))
        series.append({"t": snap.t, "gospa": g.total, "localisation": g.localisation,
                       "missed": g.missed, "false": g.false,
                       "n_tracks": len(snap.positions), "n_truth": len(truth)})

    def mean(key):
        return float(np.mean([s[key] for s in series]))

    out = {k: mean(k) for k in ("gospa", "localisation", "missed", "false",
                                "n_tracks", "n_truth")}
    out.update(wall_s=result.wall_s, compute_s=result.compute_s,
               instants=len(series), series=series, **result.extra)
    return out


# --------------------------------------------------------------------------
# Stone Soup 1.9.1
# --------------------------------------------------------------------------
EPOCH = datetime(2025, 1, 1)


def run_stonesoup(scene: Scene) -> Result:
    from stonesoup.base import Property
    from stonesoup.dataassociator.neighbour import GNNWith2DAssignment
    from stonesoup.dataassociator.probability import JPDAwithEHM2
    from stonesoup.deleter.time import UpdateTimeStepsDeleter
    from stonesoup.hypothesiser.distance import DistanceHypothesiser
    from stonesoup.hypothesiser.probability import PDAHypothesiser
    from stonesoup.initiator.simple import MultiMeasurementInitiator
    from stonesoup.measures import Mahalanobis
    from stonesoup.models.measurement.nonlinear import CartesianToBearingRange
    from stonesoup.models.transition.linear import (
        CombinedLinearGaussianTransitionModel, ConstantVelocity)
    from stonesoup.predictor.kalman import KalmanPredictor
    from stonesoup.reader.base import DetectionReader
    from stonesoup.tracker.simple import MultiTargetMixtureTracker
    from stonesoup.types.angle import Bearing
    from stonesoup.types.array import CovarianceMatrix, StateVector
    from stonesoup.types.detection import Clutter, Detection
    from stonesoup.types.state import GaussianState
    from stonesoup.types.update import Update
    from stonesoup.updater.kalman import ExtendedKalmanUpdater

    class ScanReader(DetectionReader):
        """Yields (time, set of detections) per radar scan, in time order."""
        scans: list = Property(doc="[(datetime, set of Detection)] in time order")

        @DetectionReader.generator_method
        def detections_gen(self):
            yield from self.scans

    q = TRACKER_SIGMA_A**2
    transition = CombinedLinearGaussianTransitionModel(
        [ConstantVelocity(q), ConstantVelocity(q)])
    models = {
        radar.id: CartesianToBearingRange(
            ndim_state=4, mapping=(0, 2),
            noise_covar=np.diag([math.radians(SIGMA_AZIMUTH_DEG) ** 2, SIGMA_RANGE_M**2]),
            translation_offset=StateVector([radar.site[0], radar.site[1]]))
        for radar in RADARS
    }

    def detection(plot: Plot, timestamp: datetime):
        # Stone Soup bearing: counter-clockwise from east; ours: clockwise
        # from north. Bearing() wraps into [-pi, pi).
        bearing = Bearing(math.pi / 2.0 - math.radians(plot.azimuth_deg))
        cls = Detection if plot.target is not None else Clutter  # same to the tracker
        return cls(StateVector([bearing, plot.range_m]), timestamp=timestamp,
                   measurement_model=models[plot.radar])

    scans = []
    for t, _radar, plots in scene.scans:
        ts = EPOCH + timedelta(seconds=t)
        scans.append((ts, {detection(p, ts) for p in plots}))

    predictor = KalmanPredictor(transition)
    updater = ExtendedKalmanUpdater(measurement_model=None)  # per-detection models

    hypothesiser = PDAHypothesiser(
        predictor=predictor, updater=updater,
        clutter_spatial_density=clutter_density(scene.clutter_mean),
        prob_detect=P_DETECTION, prob_gate=0.99)  # our track gate is 0.99 too
    associator = JPDAwithEHM2(hypothesiser=hypothesiser)
    deleter = UpdateTimeStepsDeleter(time_steps_since_update=3)

    # Initiation: a single plot gives position (converted from polar) and a
    # zero-mean velocity prior; sigma_v = 200 m/s per axis with a 3-sigma
    # Mahalanobis gate admits about 600 m/s per axis (ours: |v| <= 600).
    sigma_v0 = 200.0
    prior = GaussianState(StateVector([0.0, 0.0, 0.0, 0.0]),
                          CovarianceMatrix(np.diag([0.0, sigma_v0**2, 0.0, sigma_v0**2])))
    init_hypothesiser = DistanceHypothesiser(
        predictor, updater, measure=Mahalanobis(), missed_distance=3.0)
    initiator = MultiMeasurementInitiator(
        prior_state=prior,
        deleter=UpdateTimeStepsDeleter(time_steps_since_update=2),  # ~ ours: >1 miss in 4
        data_associator=GNNWith2DAssignment(init_hypothesiser),
        updater=updater,
        min_points=3)

    tracker = MultiTargetMixtureTracker(
        initiator=initiator, deleter=deleter, detector=ScanReader(scans),
        data_associator=associator, updater=updater)

    a_times = set(scene.scan_times("A"))
    snapshots = []
    all_tracks = set()
    loop_s = 0.0
    it = iter(tracker)
    for t, _radar, _plots in scene.scans:
        t0 = time.perf_counter()
        ts, tracks = next(it)
        loop_s += time.perf_counter() - t0
        all_tracks |= tracks
        if t not in a_times:
            continue
        positions = []
        for track in tracks:
            state = track.state  # every live track has a state at ts
            last_update = next((s.timestamp for s in reversed(track.states)
                                if isinstance(s, Update) and s.hypothesis), None)
            if state.timestamp > ts or last_update is None:
                continue
            if (ts - last_update).total_seconds() > FRESH_S:
                continue
            # State is at ts (prediction or update) for tracks the tracker keeps.
            dt = (ts - state.timestamp).total_seconds()
            sv = np.asarray(state.state_vector, dtype=float).ravel()
            positions.append([sv[0] + sv[1] * dt, sv[2] + sv[3] * dt])
        snapshots.append(Snapshot(t, np.array(positions, dtype=float).reshape(-1, 2)))
    return Result("Stone Soup 1.9.1", snapshots, loop_s,
                  extra={"tracks_total": len(all_tracks)})


# --------------------------------------------------------------------------
# Our service
# --------------------------------------------------------------------------
def build_request(scene: Scene) -> dict:
    return {
        "origin": ORIGIN,
        "radars": [
            {"id": r.id, "kind": "2d", "site": {"position_m": [r.site[0], r.site[1], 0.0]},
             "sigma_range_m": SIGMA_RANGE_M, "sigma_azimuth_deg": SIGMA_AZIMUTH_DEG,
             "scan_period_s": r.period_s, "p_detection": P_DETECTION,
             "clutter_density": clutter_density(scene.clutter_mean)}
            for r in RADARS
        ],
        "plots": [{"radar_id": p.radar, "t": p.t, "range_m": p.range_m,
                   "azimuth_deg": p.azimuth_deg} for p in scene.plots],
        "tracker": {"sigma_a_mps2": TRACKER_SIGMA_A, "association": "exact",
                    "initiation": {"m": 3, "n": 4, "v_max_mps": 600},
                    "deletion": {"max_consecutive_misses": 3}},
        "history": True,
    }


def run_ours(scene: Scene, url: str, timeout_s: float) -> Result:
    import requests

    body = build_request(scene)
    endpoint = url.rstrip("/") + "/v1/plot-fusion/track"
    t0 = time.perf_counter()
    resp = requests.post(endpoint, json=body, timeout=timeout_s)
    wall = time.perf_counter() - t0
    if resp.status_code != 200:
        raise RuntimeError(f"POST {endpoint}: HTTP {resp.status_code}: {resp.text[:2000]}")
    out = resp.json()

    layout = out.get("state_layout", ["x", "vx", "y", "vy"])
    ix, ivx, iy, ivy = (layout.index(k) for k in ("x", "vx", "y", "vy"))
    history = sorted(out.get("history") or [], key=lambda h: h["t"])
    if not history:
        raise RuntimeError("response has no history; was \"history\": true ignored?")
    hist_t = np.array([h["t"] for h in history])

    snapshots = []
    for t in scene.scan_times("A"):
        # Each history entry lists every confirmed track at that processing
        # instant, so the latest entry at or before t is the confirmed set
        # at t (ids absent from it were deleted); extrapolate to t if the
        # entry is earlier (a scan with no plots has no frame).
        k = int(np.searchsorted(hist_t, t + 1e-6, side="right")) - 1
        positions = []
        if k >= 0:
            entry = history[k]
            dt = t - entry["t"]
            for tr in entry["tracks"]:
                if tr.get("status", "confirmed") != "confirmed":
                    continue
                last = tr.get("last_update_t", entry["t"])
                if t - last > FRESH_S:
                    continue
                s = tr["state"]
                positions.append([s[ix] + s[ivx] * dt, s[iy] + s[ivy] * dt])
        snapshots.append(Snapshot(t, np.array(positions, dtype=float).reshape(-1, 2)))

    compute_us = (out.get("timing") or {}).get("compute_us", out.get("compute_us"))
    ids = {tr["id"] for h in history for tr in h["tracks"]}
    extra = {"mode": out.get("mode"), "counters": out.get("counters"),
             "warnings": out.get("warnings"), "tracks_total": len(ids),
             "request_bytes": len(json.dumps(body))}
    return Result("ours (plot-fusion)", snapshots, wall,
                  compute_s=None if compute_us is None else compute_us / 1e6, extra=extra)


# --------------------------------------------------------------------------
# Report
# --------------------------------------------------------------------------
def markdown_table(scene: Scene, figures: dict[str, dict]) -> str:
    lines = [
        "| tracker | mean GOSPA (m) | localisation | missed | false | "
        "confirmed tracks | true targets | tracks ever confirmed | wall time (s) | compute (s) |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for name, f in figures.items():
        compute = "-" if f.get("compute_s") is None else f"{f['compute_s']:.3f}"
        lines.append(
            f"| {name} | {f['gospa']:.1f} | {f['localisation']:.1f} | {f['missed']:.1f} | "
            f"{f['false']:.1f} | {f['n_tracks']:.2f} | {f['n_truth']:.2f} | "
            f"{f.get('tracks_total', '-')} | {f['wall_s']:.3f} | {compute} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--targets", type=int, default=10)
    ap.add_argument("--clutter", type=float, default=2.0,
                    help="mean false plots per scan per radar (default 2)")
    ap.add_argument("--late-fraction", type=float, default=0.3,
                    help="fraction of targets that start in [0,60] s and end in "
                         "[240,300] s (default 0.3; 0 = all live 0-300 s)")
    ap.add_argument("--url", default="http://127.0.0.1:8080")
    ap.add_argument("--timeout", type=float, default=600.0, help="HTTP timeout (s)")
    ap.add_argument("--stonesoup-only", action="store_true", help="skip our service")
    ap.add_argument("--json-out", metavar="FILE", help="write the figures as JSON")
    args = ap.parse_args(argv)

    scene = make_scene(args.seed, args.targets, args.clutter, args.late_fraction)
    n_clutter = sum(p.target is None for p in scene.plots)
    print(f"scene: seed {args.seed}, {len(scene.targets)} targets, {len(scene.scans)} scans, "
          f"{len(scene.plots)} plots ({n_clutter} clutter), "
          f"clutter density {clutter_density(args.clutter):.3e} /(rad m)")

    results = [run_stonesoup(scene)]
    if not args.stonesoup_only:
        try:
            results.append(run_ours(scene, args.url, args.timeout))
        except Exception as exc:  # noqa: BLE001 — report and fail clearly
            print(f"our service failed: {exc}", file=sys.stderr)
            return 2

    figures = {r.name: score(scene, r) for r in results}
    print()
    print(f"GOSPA p={GOSPA_P}, c={GOSPA_C_M:.0f} m, alpha={GOSPA_ALPHA}, mean over "
          f"{len(scene.scan_times('A'))} radar-A scan instants (confirmed tracks only)")
    print()
    print(markdown_table(scene, figures))
    for name, f in figures.items():
        if f.get("counters") is not None:
            print(f"\n{name}: mode {f.get('mode')}, counters {f['counters']}, "
                  f"warnings {f.get('warnings')}")

    if args.json_out:
        doc = {"scene": {"seed": args.seed, "targets": args.targets, "clutter": args.clutter,
                         "late_fraction": args.late_fraction, "scans": len(scene.scans),
                         "plots": len(scene.plots), "clutter_plots": n_clutter,
                         "clutter_density": clutter_density(args.clutter)},
               "gospa": {"p": GOSPA_P, "c_m": GOSPA_C_M, "alpha": GOSPA_ALPHA},
               "trackers": figures}
        with open(args.json_out, "w") as fh:
            json.dump(doc, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
