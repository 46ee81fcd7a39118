#!/usr/bin/env python3
"""Our plot-fusion tracker against Stone Soup 1.9.1 on real aircraft trajectories.

What it compares
    Real ADS-B trajectories from a sample collection shipped inside the
    ``traffic`` package (default ``quickstart``: three hours of arrivals,
    departures and overflights around Paris, 1-s OpenSky state vectors;
    ``switzerland`` has only en-route flights above FL300 at 10-s
    sampling). ``--flights`` aircraft airborne in a common ``--minutes``
    window are seen by two or three simulated 3D radars tens of km apart
    (different scan periods and phases, P_D 0.9, Poisson clutter, optional
    Doppler). The geometry is pyproj's alone (WGS84 -> ECEF -> each radar's
    topocentric ENU -> range/azimuth/elevation; the truth for scoring in the
    topocentric ENU frame at the ``origin`` sent to the service), never the
    service's code.

    The same plots go to
      * our service, ``POST {url}/v1/plot-fusion/track`` with its defaults:
        only the radars (site, sigmas, P_D, clutter density, scan period:
        facts of the scene, not tracker options), the plots, the origin and
        ``"history": true``; ``--tracker-json '{...}'`` (repeatable) adds a
        row with those ``tracker`` options;
      * Stone Soup 1.9.1: ExtendedKalmanUpdater with one
        CartesianToElevationBearingRange(Rate) model per radar (its site
        offset and the rotation from the fusion ENU to the radar's own ENU),
        KalmanPredictor with CombinedLinearGaussianTransitionModel of three
        ConstantVelocity(q), a JPDA tracker (MultiTargetMixtureTracker +
        JPDAwithEHM2 + PDAHypothesiser) and a GNN tracker
        (MultiTargetTracker + GNNWith2DAssignment + DistanceHypothesiser,
        Mahalanobis, 99 % gate), MultiMeasurementInitiator (3 updates) and
        UpdateTimeDeleter, for every q of ``--q-grid``.

Scene
    * Truth: per flight, the ADS-B fixes off the ground with finite
      position and altitude, stale repeats and outliers removed, split at
      gaps over 30 s (the longest piece in the window kept), converted to
      ECEF and fitted with a smoothing spline per axis (scipy's
      make_smoothing_spline, GCV); tabulated at 1 s (``--truth-csv``), and
      evaluated at exact times for the plots and the scoring. Altitude:
      the barometric altitude (ft) is taken as the geometric height above
      the WGS84 ellipsoid (x 0.3048), the same for plots, truth and both
      trackers; the real geometric height differs by tens to hundreds of
      metres (ISA deviation, geoid), which changes the scene, not the
      comparison.
    * Radars: rotating clockwise, north crossing at phase + k * period; a
      target's plot is timed when the beam crosses its azimuth, so the
      plots of one scan have different times. Coverage: range 1 km to
      ``--max-range-km``, elevation -0.5 to 60 deg (straight lines, no
      refraction, no terrain). sigma_range 50 m, sigma_azimuth 0.1 deg,
      sigma_elevation 0.2 deg, sigma_radial_velocity 1 m/s (``--doppler``;
      positive receding, from the spline's velocity). Clutter: Poisson
      ``--clutter`` per scan, uniform in range x azimuth x elevation over
      the coverage (radial velocity uniform in +-400 m/s).

Feeding Stone Soup
    Its trackers take one step (time, detections) and treat every
    detection of a step as taken at that time (MultiTargetMixtureTracker
    mixes the missed-detection prediction at the step time with updates at
    the detections' times), so each distinct plot time is one step (plots
    are timed by the beam, so almost every step holds one plot). Deletion
    and the initiator's holding tracks are therefore by time, not steps.

Scoring (``score``)
    Every state of every confirmed track at its own time: our service's
    ``history`` (the confirmed tracks after every frame, each with its
    ``t``) and every Stone Soup step's tracks (their last state, at the
    step time). At each of a tracker's instants its estimates are assigned
    to the truths in coverage (alive, seen by at least one radar) by
    optimal assignment of 3D distance with a ``--cutoff-m`` cutoff
    (default 2 km). Figures: median and p90 horizontal (in the truth's
    local horizon) and 3D position error of the assigned states (and 3D of
    the states just updated), false confirmed tracks (assigned in under
    half of their states), missed aircraft (truths in coverage held by a
    confirmed track at under half of the instants), ID swaps (changes of
    the track id held by a truth), mean GOSPA (3D, p = 1, c = 1000 m,
    alpha = 2) over the instants, position NEES (3D, the reported
    covariance) mean and fraction inside the two-sided 95 % chi^2(3) band,
    and wall time.

A biased radar (``--bias B:300:0.3[:EL]``)
    Radar B's target plots measure the range longer by 300 m and the
    azimuth (and elevation) larger by 0.3 deg, after the noise: a radar's
    systematic error. Every tracker then gets the biased plots; our
    service with its defaults (registration on with two radars or more)
    and, as the floor, the same plots without the bias ("unbiased plots").
    Stone Soup has no registration: its rows show what a tracker does
    without one. ``--settle-s S`` adds every figure scored over the
    instants from S s on only (after the estimates converge); our rows
    print the registration the service reports.

How to run
    bash checks/setup_traffic.sh               # once: checks/.venv
    /work/scratch/radar-fusion-debug --http-addr 127.0.0.1:18080 \\
        --grpc-addr 127.0.0.1:15051 --request-timeout-s 900 &
    checks/.venv/bin/python checks/real_traffic_vs_stonesoup.py \\
        --url http://127.0.0.1:18080 [--doppler] [--flights 10 --minutes 6] \\
        [--tracker-json '{"sigma_a_mps2": 1}'] [--json-out FILE]
    (--request-timeout-s: a big history from a debug build can take longer
    than the default 30 s.) Stone Soup costs 2-3 ms per track x plot pair:
    the default scene takes about 2 min per grid point; --jobs 2, --q-grid,
    --associators or --ours-only shorten a run.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from dataclasses import dataclass, field, replace
from datetime import datetime, timedelta

import numpy as np
from scipy.optimize import least_squares, linear_sum_assignment
from scipy.stats import chi2

# --------------------------------------------------------------------------
# Scene constants
# --------------------------------------------------------------------------
FT_TO_M = 0.3048
SIGMA_RANGE_M = 50.0
SIGMA_AZIMUTH_DEG = 0.1
SIGMA_ELEVATION_DEG = 0.2
SIGMA_RADIAL_VELOCITY_MPS = 1.0
# Per radar (index in the scene): what its declared sigmas are multiplied
# by, for our service and Stone Soup alike (--declared-factors); the plots
# keep the true sigmas above.
DECLARED_FACTORS: list[float] = []


def declared_factor(index: int) -> float:
    return DECLARED_FACTORS[index] if index < len(DECLARED_FACTORS) else 1.0


P_DETECTION = 0.9
# Per radar: the detection probability it declares (--declared-p-detection;
# the plots keep P_DETECTION). Stone Soup's JPDA takes one P_D for all
# radars: it is given their mean.
DECLARED_P_DETECTION: list[float] = []


def declared_p_detection(index: int) -> float:
    return DECLARED_P_DETECTION[index] if index < len(DECLARED_P_DETECTION) else P_DETECTION
RANGE_MIN_M = 1_000.0
ELEVATION_MIN_DEG = -0.5
ELEVATION_MAX_DEG = 60.0
CLUTTER_RR_MAX_MPS = 400.0
MAX_GAP_S = 30.0  # ADS-B gaps bridged by the spline; longer ones split a flight
MIN_SEGMENT_S = 120.0
GOSPA_C_M = 1000.0
GOSPA_P = 1
GOSPA_ALPHA = 2
EPOCH = datetime(2025, 1, 1)


@dataclass(frozen=True)
class Site:
    lat_deg: float
    lon_deg: float
    height_m: float


@dataclass(frozen=True)
class RadarDef:
    id: str
    site: Site
    period_s: float
    phase_s: float


# The collections' sites: an origin near the middle of the traffic and three
# radars tens of km apart around it (the first --radars are used).
SCENES = {
    "quickstart": {  # Paris: CDG, Orly, Le Bourget, Beauvais traffic
        "origin": Site(48.85, 2.45, 100.0),
        "radars": (
            RadarDef("A", Site(49.02, 2.58, 150.0), 4.0, 0.0),
            RadarDef("B", Site(48.70, 2.33, 140.0), 5.0, 1.7),
            RadarDef("C", Site(48.86, 1.95, 180.0), 6.0, 3.1),
        ),
    },
    "switzerland": {  # en-route over the Swiss plateau
        "origin": Site(47.0, 7.8, 500.0),
        "radars": (
            RadarDef("A", Site(47.48, 8.40, 860.0), 4.0, 0.0),
            RadarDef("B", Site(46.95, 7.45, 900.0), 5.0, 1.7),
            RadarDef("C", Site(46.75, 8.15, 1100.0), 6.0, 3.1),
        ),
    },
}


# --------------------------------------------------------------------------
# Geometry (pyproj only)
# --------------------------------------------------------------------------
class Frame:
    """The topocentric ENU frame at a WGS84 point (pyproj's +proj=topocentric)."""

    def __init__(self, site: Site):
        from pyproj import Transformer

        self.site = site
        self._geod_to_ecef = Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True)
        self._topo = Transformer.from_pipeline(
            f"+proj=topocentric +ellps=WGS84 +lat_0={site.lat_deg!r} "
            f"+lon_0={site.lon_deg!r} +h_0={site.height_m!r}")
        self.ecef0 = np.array(self._geod_to_ecef.transform(
            site.lon_deg, site.lat_deg, site.height_m))
        # The topocentric map is affine (ENU = R (X - X0)): R column by column.
        d = 1000.0
        self.rotation = np.empty((3, 3))  # ECEF axes -> this frame's ENU axes
        for j in range(3):
            p = self.ecef0.copy()
            p[j] += d
            self.rotation[:, j] = np.array(self._topo.transform(*p)) / d

    def enu(self, ecef: np.ndarray) -> np.ndarray:
        """ECEF (n, 3) -> ENU (n, 3) in this frame."""
        ecef = np.atleast_2d(ecef)
        e, n, u = self._topo.transform(ecef[:, 0], ecef[:, 1], ecef[:, 2])
        return np.column_stack([e, n, u])

    def enu_velocity(self, vel_ecef: np.ndarray) -> np.ndarray:
        return np.atleast_2d(vel_ecef) @ self.rotation.T


_GEOD = None


def geodetic_to_ecef(lat, lon, h) -> np.ndarray:
    global _GEOD
    from pyproj import Transformer

    if _GEOD is None:
        _GEOD = (Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True),
                 Transformer.from_crs("EPSG:4978", "EPSG:4979", always_xy=True))
    x, y, z = _GEOD[0].transform(np.asarray(lon), np.asarray(lat), np.asarray(h))
    return np.column_stack([x, y, z])


def ecef_to_geodetic(ecef: np.ndarray):
    geodetic_to_ecef(0.0, 0.0, 0.0)  # make the transformers
    lon, lat, h = _GEOD[1].transform(ecef[:, 0], ecef[:, 1], ecef[:, 2])
    return np.asarray(lat), np.asarray(lon), np.asarray(h)


def polar(enu: np.ndarray):
    """(range m, azimuth deg clockwise from north in [0, 360), elevation deg)."""
    e, n, u = enu[:, 0], enu[:, 1], enu[:, 2]
    rho = np.sqrt(e * e + n * n + u * u)
    az = np.degrees(np.arctan2(e, n)) % 360.0
    el = np.degrees(np.arcsin(u / rho))
    return rho, az, el


# --------------------------------------------------------------------------
# Truth from the traffic sample
# --------------------------------------------------------------------------
@dataclass
class Truth:
    name: str
    t0: float  # scene seconds (0 = window start)
    t1: float
    splines: list  # 3 BSplines of ECEF (m) over scene seconds, about the mean
    mean: np.ndarray
    n_fixes: int

    def alive(self, t: np.ndarray) -> np.ndarray:
        return (t >= self.t0) & (t <= self.t1)

    def ecef(self, t) -> np.ndarray:
        t = np.atleast_1d(np.asarray(t, dtype=float))
        return np.column_stack([s(t) for s in self.splines]) + self.mean

    def ecef_velocity(self, t) -> np.ndarray:
        t = np.atleast_1d(np.asarray(t, dtype=float))
        return np.column_stack([s.derivative()(t) for s in self.splines])

    def ecef_acceleration(self, t) -> np.ndarray:
        t = np.atleast_1d(np.asarray(t, dtype=float))
        return np.column_stack([s.derivative(2)(t) for s in self.splines])


def clean_fixes(d, t_window0: float):
    """(t scene s, lat, lon, h m) of one flight's usable ADS-B fixes."""
    import pandas as pd

    d = d.copy()
    if "onground" in d.columns:
        d = d[~d["onground"].fillna(False).astype(bool)]
    d = d.dropna(subset=["latitude", "longitude", "altitude"])
    if len(d) < 10:
        return None
    t = (pd.to_datetime(d["timestamp"]).astype("int64").to_numpy() / 1e9) - t_window0
    lat = d["latitude"].to_numpy(float)
    lon = d["longitude"].to_numpy(float)
    h = d["altitude"].to_numpy(float) * FT_TO_M
    order = np.argsort(t, kind="stable")
    t, lat, lon, h = t[order], lat[order], lon[order], h[order]
    # OpenSky repeats the last position until a new one comes: keep the first.
    fresh = np.ones(len(t), bool)
    fresh[1:] = (np.diff(lat) != 0) | (np.diff(lon) != 0)
    fresh[1:] &= np.diff(t) > 0
    t, lat, lon, h = t[fresh], lat[fresh], lon[fresh], h[fresh]
    if len(t) < 10:
        return None
    # Outliers: far from a running median (altitude spikes, position jumps).
    def med(x, w=15):
        return pd.Series(x).rolling(w, center=True, min_periods=1).median().to_numpy()

    ecef = geodetic_to_ecef(lat, lon, h)
    ok = np.abs(h - med(h)) < 150.0
    for k in range(3):
        ok &= np.abs(ecef[:, k] - med(ecef[:, k])) < 1500.0
    return t[ok], lat[ok], lon[ok], h[ok]


def fit_truth(name: str, t: np.ndarray, lat, lon, h) -> Truth | None:
    from scipy.interpolate import make_smoothing_spline

    ecef = geodetic_to_ecef(lat, lon, h)
    mean = ecef.mean(axis=0)
    splines = [make_smoothing_spline(t, ecef[:, k] - mean[k]) for k in range(3)]
    truth = Truth(name, float(t[0]), float(t[-1]), splines, mean, len(t))
    # A fit that still has the jumps of bad data is no aircraft: drop it.
    grid = np.arange(math.ceil(truth.t0), math.floor(truth.t1) + 1.0)
    acc = np.linalg.norm(truth.ecef_acceleration(grid), axis=1)
    speed = np.linalg.norm(truth.ecef_velocity(grid), axis=1)
    if acc.max() > 25.0 or speed.max() > 350.0:
        return None
    return truth


def load_truths(collection: str, n_flights: int, minutes: float,
                start: str | None) -> tuple[list[Truth], float, dict]:
    """The window (Unix s of its start) and the flights airborne in it."""
    import importlib

    import pandas as pd

    samples = importlib.import_module("traffic.data.samples")
    traffic = getattr(samples, collection)
    duration = minutes * 60.0
    flights = []
    for f in traffic:
        d = f.data
        ts = pd.to_datetime(d["timestamp"]).astype("int64").to_numpy() / 1e9
        flights.append((f, float(ts.min()), float(ts.max())))
    if start:
        w0 = pd.Timestamp(start).timestamp()
        if pd.Timestamp(start).tzinfo is None:
            w0 = pd.Timestamp(start, tz="UTC").timestamp()
    else:
        # The window (on a 1-min grid) with the most flights spanning half of it.
        lo = min(a for _, a, _ in flights)
        hi = max(b for _, _, b in flights) - duration
        best = (-1, lo)
        for w in np.arange(math.ceil(lo / 60) * 60, hi + 1, 60.0):
            ov = sum(max(0.0, min(b, w + duration) - max(a, w)) >= duration / 2
                     for _, a, b in flights)
            if ov > best[0]:
                best = (ov, w)
        w0 = best[1]
    candidates = []
    for f, a, b in flights:
        if min(b, w0 + duration) - max(a, w0) < MIN_SEGMENT_S:
            continue
        fixes = clean_fixes(f.data, w0)
        if fixes is None:
            continue
        t, lat, lon, h = fixes
        # Pieces between gaps over MAX_GAP_S; the one most inside the window.
        cuts = np.flatnonzero(np.diff(t) > MAX_GAP_S) + 1
        best_piece, best_len = None, 0.0
        for piece in np.split(np.arange(len(t)), cuts):
            tp = t[piece]
            inside = min(tp[-1], duration) - max(tp[0], 0.0)
            if inside > best_len:
                best_piece, best_len = piece, inside
        if best_piece is None or best_len < MIN_SEGMENT_S:
            continue
        # Fit over the window and a margin (the spline's ends are looser).
        piece = best_piece[(t[best_piece] >= -120.0) & (t[best_piece] <= duration + 120.0)]
        if len(piece) < 20:
            continue
        name = f"{f.callsign or '?'}/{f.icao24}"
        candidates.append((best_len, name, t[piece], lat[piece], lon[piece], h[piece]))
    candidates.sort(key=lambda c: (-c[0], c[1]))
    truths, rejected = [], []
    for inside, name, t, lat, lon, h in candidates:
        if len(truths) == n_flights:
            break
        truth = fit_truth(name, t, lat, lon, h)
        if truth is None:
            rejected.append(name)
            continue
        truth.t0, truth.t1 = max(truth.t0, 0.0), min(truth.t1, duration)
        truths.append(truth)
    info = {"collection": collection,
            "window_start_utc": pd.Timestamp(w0, unit="s", tz="UTC").isoformat(),
            "window_s": duration, "candidates": len(candidates),
            "rejected_bad_fit": rejected}
    return truths, w0, info


# --------------------------------------------------------------------------
# Radars and plots
# --------------------------------------------------------------------------
@dataclass
class Radar:
    id: str
    site: Site
    period_s: float
    phase_s: float
    frame: Frame
    site_fusion_enu: np.ndarray  # the site in the fusion (origin) ENU frame
    fusion_to_radar: np.ndarray  # rotation: fusion ENU axes -> radar ENU axes


@dataclass
class Plot:
    radar: str
    t: float
    range_m: float
    azimuth_deg: float
    elevation_deg: float
    radial_velocity_mps: float | None
    truth: int | None  # None: clutter (diagnostics only)


@dataclass
class Scene:
    truths: list[Truth]
    radars: list[Radar]
    origin: Site
    origin_frame: Frame
    plots: list[Plot]  # time order
    duration_s: float
    doppler: bool
    clutter_mean: float
    max_range_m: float
    info: dict = field(default_factory=dict)

    def clutter_density(self) -> float:
        """False plots per scan per m . rad^2 (range x azimuth x elevation)."""
        span = math.radians(ELEVATION_MAX_DEG - ELEVATION_MIN_DEG)
        return self.clutter_mean / ((self.max_range_m - RANGE_MIN_M) * 2.0 * math.pi * span)

    def covered(self, truth: Truth, t: np.ndarray) -> np.ndarray:
        """Alive and seen by at least one radar at each t."""
        t = np.asarray(t, dtype=float)
        out = truth.alive(t)
        if not out.any():
            return out
        ecef = truth.ecef(t[out])
        seen = np.zeros(len(ecef), bool)
        for radar in self.radars:
            seen |= in_coverage(radar, ecef, self.max_range_m)
        out = out.copy()
        out[out] = seen
        return out


def in_coverage(radar: Radar, ecef: np.ndarray, max_range_m: float) -> np.ndarray:
    rho, _, el = polar(radar.frame.enu(ecef))
    return ((rho >= RANGE_MIN_M) & (rho <= max_range_m)
            & (el >= ELEVATION_MIN_DEG) & (el <= ELEVATION_MAX_DEG))


def make_radars(defs, origin_frame: Frame) -> list[Radar]:
    radars = []
    for d in defs:
        frame = Frame(d.site)
        site_ecef = frame.ecef0[None, :]
        radars.append(Radar(d.id, d.site, d.period_s, d.phase_s, frame,
                            origin_frame.enu(site_ecef)[0],
                            frame.rotation @ origin_frame.rotation.T))
    return radars


def beam_times(radar: Radar, truth: Truth, t_lo: float, t_hi: float) -> np.ndarray:
    """Times in [t_lo, t_hi] at which the beam crosses the truth's azimuth."""
    grid = np.arange(math.ceil(t_lo), math.floor(t_hi) + 1.0)
    if len(grid) < 2:
        return np.empty(0)
    _, az, _ = polar(radar.frame.enu(truth.ecef(grid)))
    az_u = np.degrees(np.unwrap(np.radians(az)))
    g = (grid - radar.phase_s) / radar.period_s - az_u / 360.0
    if not np.all(np.diff(g) > 0):  # the target outruns the beam: never here
        keep = np.concatenate([[True], np.diff(g) > 0])
        grid, az_u, g = grid[keep], az_u[keep], g[keep]
    ks = np.arange(math.ceil(g[0]), math.floor(g[-1]) + 1)
    if len(ks) == 0:
        return np.empty(0)
    t = np.interp(ks, g, grid)
    for _ in range(3):  # Newton on g(t) = k with dg/dt ~ 1 / period
        ref = np.interp(t, grid, az_u)
        _, az_t, _ = polar(radar.frame.enu(truth.ecef(t)))
        az_t = ref + ((az_t - ref + 180.0) % 360.0 - 180.0)
        gt = (t - radar.phase_s) / radar.period_s - az_t / 360.0
        t = t - (gt - ks) * radar.period_s
    return t[(t >= t_lo) & (t <= t_hi)]


def parse_bias(text: str) -> tuple[str, float, float, float]:
    """``ID:RANGE_M:AZIMUTH_DEG[:ELEVATION_DEG]``."""
    parts = text.split(":")
    if len(parts) not in (3, 4):
        raise argparse.ArgumentTypeError(f"--bias {text!r}: ID:RANGE_M:AZIMUTH_DEG[:ELEVATION_DEG]")
    try:
        values = [float(x) for x in parts[1:]] + [0.0] * (4 - len(parts))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"--bias {text!r}: {exc}") from exc
    return parts[0], values[0], values[1], values[2]


def biased(scene: Scene, bias: tuple[str, float, float, float]) -> Scene:
    """The scene with one radar's target plots biased (clutter is uniform
    over the coverage either way, so it is left as drawn)."""
    radar, dr, da, de = bias
    if radar not in {r.id for r in scene.radars}:
        raise SystemExit(f"--bias: no radar {radar!r} in this scene "
                         f"({', '.join(r.id for r in scene.radars)})")
    plots = [replace(p, range_m=p.range_m + dr, azimuth_deg=(p.azimuth_deg + da) % 360.0,
                     elevation_deg=p.elevation_deg + de)
             if p.radar == radar and p.truth is not None else p for p in scene.plots]
    info = {**scene.info, "bias": {"radar": radar, "range_m": dr, "azimuth_deg": da,
                                   "elevation_deg": de}}
    return replace(scene, plots=plots, info=info)


def settled(res: Result, t0: float) -> Result:
    """The tracker's output from t0 on."""
    keep = res.t >= t0
    return replace(res, name=f"{res.name} from {t0:g} s", times=res.times[res.times >= t0],
                   t=res.t[keep], ids=res.ids[keep], pos=res.pos[keep], cov=res.cov[keep],
                   updated=res.updated[keep])


def make_scene(args) -> Scene:
    spec = SCENES[args.collection]
    origin = spec["origin"]
    origin_frame = Frame(origin)
    radars = make_radars(spec["radars"][:args.radars], origin_frame)
    truths, w0, info = load_truths(args.collection, args.flights, args.minutes, args.start)
    duration = args.minutes * 60.0
    max_range = args.max_range_km * 1000.0
    rng = np.random.default_rng(args.seed)
    plots: list[Plot] = []
    for radar in radars:
        for j, truth in enumerate(truths):
            t = beam_times(radar, truth, truth.t0, min(truth.t1, duration - 1e-6))
            if len(t) == 0:
                continue
            t = np.round(t, 6)
            ecef = truth.ecef(t)
            seen = in_coverage(radar, ecef, max_range) & (rng.uniform(size=len(t)) < P_DETECTION)
            enu = radar.frame.enu(ecef)
            rho, az, el = polar(enu)
            rr = None
            if args.doppler:
                los = ecef - radar.frame.ecef0
                rr = np.einsum("ij,ij->i", los, truth.ecef_velocity(t)) / np.linalg.norm(los, axis=1)
            n = len(t)
            rho = rho + rng.normal(0.0, SIGMA_RANGE_M, n)
            az = (az + rng.normal(0.0, SIGMA_AZIMUTH_DEG, n)) % 360.0
            el = el + rng.normal(0.0, SIGMA_ELEVATION_DEG, n)
            if rr is not None:
                rr = rr + rng.normal(0.0, SIGMA_RADIAL_VELOCITY_MPS, n)
            for i in np.flatnonzero(seen):
                plots.append(Plot(radar.id, float(t[i]), float(rho[i]), float(az[i]),
                                  float(el[i]), None if rr is None else float(rr[i]), j))
        # Clutter, scan by scan (a scan covers [phase + k T, phase + (k+1) T)).
        k0 = math.floor((0.0 - radar.phase_s) / radar.period_s)
        k1 = math.ceil((duration - radar.phase_s) / radar.period_s)
        for k in range(k0, k1 + 1):
            tk = radar.phase_s + k * radar.period_s
            for _ in range(rng.poisson(args.clutter)):
                az = rng.uniform(0.0, 360.0)
                t = round(tk + radar.period_s * az / 360.0, 6)
                rho = rng.uniform(RANGE_MIN_M, max_range)
                el = rng.uniform(ELEVATION_MIN_DEG, ELEVATION_MAX_DEG)
                rr = rng.uniform(-CLUTTER_RR_MAX_MPS, CLUTTER_RR_MAX_MPS) if args.doppler else None
                if 0.0 <= t < duration:
                    plots.append(Plot(radar.id, t, rho, az, el, rr, None))
    plots.sort(key=lambda p: (p.t, p.radar))
    info["window_start_unix_s"] = w0
    return Scene(truths, radars, origin, origin_frame, plots, duration, args.doppler,
                 args.clutter, max_range, info)


def describe_truths(scene: Scene) -> dict:
    """Speed, turn, climb figures of the truths on their 1-s grid."""
    acc_h, vs, speeds, heights, horiz_turn = [], [], [], [], []
    for truth in scene.truths:
        grid = np.arange(math.ceil(truth.t0), math.floor(truth.t1) + 1.0)
        if len(grid) == 0:
            continue
        enu_v = scene.origin_frame.enu_velocity(truth.ecef_velocity(grid))
        enu_a = scene.origin_frame.enu_velocity(truth.ecef_acceleration(grid))
        speeds.append(np.linalg.norm(enu_v[:, :2], axis=1))
        vs.append(np.abs(enu_v[:, 2]))
        acc_h.append(np.linalg.norm(enu_a[:, :2], axis=1))
        _, _, h = ecef_to_geodetic(truth.ecef(grid))
        heights.append(h)
    cat = np.concatenate
    return {
        "flights": len(scene.truths),
        "speed_mps_p10_p50_p90": np.percentile(cat(speeds), [10, 50, 90]).round(1).tolist(),
        "height_m_min_p50_max": [float(np.min(cat(heights)).round(0)),
                                 float(np.median(cat(heights)).round(0)),
                                 float(np.max(cat(heights)).round(0))],
        "vertical_speed_mps_p90_max": np.percentile(cat(vs), [90, 100]).round(1).tolist(),
        "horizontal_acc_mps2_p50_p90_p99_max":
            np.percentile(cat(acc_h), [50, 90, 99, 100]).round(2).tolist(),
        "time_turning_over_1mps2": float(np.mean(cat(acc_h) > 1.0).round(3)),
    }


def write_truth_csv(scene: Scene, path: str) -> None:
    """The truth on its 1-s grid: WGS84 and fusion ENU."""
    with open(path, "w") as fh:
        fh.write("flight,t_s,lat_deg,lon_deg,height_m,e_m,n_m,u_m\n")
        for truth in scene.truths:
            grid = np.arange(math.ceil(truth.t0), math.floor(truth.t1) + 1.0)
            ecef = truth.ecef(grid)
            lat, lon, h = ecef_to_geodetic(ecef)
            enu = scene.origin_frame.enu(ecef)
            for i, t in enumerate(grid):
                fh.write(f"{truth.name},{t:.0f},{lat[i]:.7f},{lon[i]:.7f},{h[i]:.1f},"
                         f"{enu[i, 0]:.1f},{enu[i, 1]:.1f},{enu[i, 2]:.1f}\n")


# --------------------------------------------------------------------------
# Tracker output, as scored
# --------------------------------------------------------------------------
@dataclass
class Result:
    name: str
    times: np.ndarray  # the tracker's processing instants (s)
    t: np.ndarray  # (n,) each confirmed state's own time
    ids: np.ndarray  # (n,) its track id
    pos: np.ndarray  # (n, 3) fusion ENU position
    cov: np.ndarray  # (n, 3, 3) its position covariance
    updated: np.ndarray  # (n,) bool: the state is an update at that time
    wall_s: float
    compute_s: float | None = None
    extra: dict = field(default_factory=dict)
    # Our service only: (track id, t) -> (Mode S address, flight level).
    identity: dict = field(default_factory=dict)
    # Our service only: the JSON answer (checks/ed87.py scores its history).
    response: dict | None = None


def result_from_rows(name, times, rows, wall_s, compute_s=None, extra=None) -> Result:
    n = len(rows)
    t = np.array([r[0] for r in rows], dtype=float).reshape(n)
    ids = np.array([r[1] for r in rows], dtype=object).reshape(n)
    pos = np.array([r[2] for r in rows], dtype=float).reshape(n, 3)
    cov = np.array([r[3] for r in rows], dtype=float).reshape(n, 3, 3)
    upd = np.array([r[4] for r in rows], dtype=bool).reshape(n)
    return Result(name, np.unique(np.asarray(times, dtype=float)), t, ids, pos, cov, upd,
                  wall_s, compute_s, extra or {})


# --------------------------------------------------------------------------
# Stone Soup 1.9.1
# --------------------------------------------------------------------------
def stonesoup_rotation_offset(m: np.ndarray) -> np.ndarray:
    """Stone Soup's rotation_offset whose rotation_matrix is m."""
    from stonesoup.functions import build_rotation_matrix

    def resid(a):
        return (build_rotation_matrix(np.array([[a[0]], [a[1]], [a[2]]])) - m).ravel()

    sol = least_squares(resid, np.zeros(3), xtol=1e-15, ftol=1e-15, gtol=1e-15)
    if np.max(np.abs(resid(sol.x))) > 1e-9:
        raise RuntimeError("no Stone Soup rotation_offset matches the radar's rotation")
    return sol.x


def stonesoup_models(scene: Scene) -> dict:
    from stonesoup.models.measurement.nonlinear import (
        CartesianToElevationBearingRange, CartesianToElevationBearingRangeRate)
    from stonesoup.types.array import StateVector

    models = {}
    for k, radar in enumerate(scene.radars):
        angles = stonesoup_rotation_offset(radar.fusion_to_radar)
        common = dict(ndim_state=6, mapping=(0, 2, 4),
                      translation_offset=StateVector(radar.site_fusion_enu.tolist()),
                      rotation_offset=StateVector(angles.tolist()))
        f2 = declared_factor(k) ** 2
        sig = [f2 * math.radians(SIGMA_ELEVATION_DEG) ** 2,
               f2 * math.radians(SIGMA_AZIMUTH_DEG) ** 2, f2 * SIGMA_RANGE_M ** 2]
        if scene.doppler:
            models[radar.id] = CartesianToElevationBearingRangeRate(
                velocity_mapping=(1, 3, 5),
                noise_covar=np.diag(sig + [f2 * SIGMA_RADIAL_VELOCITY_MPS ** 2]), **common)
        else:
            models[radar.id] = CartesianToElevationBearingRange(noise_covar=np.diag(sig), **common)
    return models


def check_stonesoup_geometry(scene: Scene, models: dict) -> dict:
    """Stone Soup's noise-free measurement of truth states vs pyproj's."""
    from stonesoup.types.state import State

    worst = {"range_m": 0.0, "azimuth_deg": 0.0, "elevation_deg": 0.0, "radial_velocity_mps": 0.0}
    for truth in scene.truths[:5]:
        t = np.linspace(truth.t0, truth.t1, 7)
        ecef, vel = truth.ecef(t), truth.ecef_velocity(t)
        enu_f = scene.origin_frame.enu(ecef)
        vel_f = scene.origin_frame.enu_velocity(vel)
        for radar in scene.radars:
            rho, az, el = polar(radar.frame.enu(ecef))
            los = ecef - radar.frame.ecef0
            rr = np.einsum("ij,ij->i", los, vel) / np.linalg.norm(los, axis=1)
            for i in range(len(t)):
                sv = np.array([enu_f[i, 0], vel_f[i, 0], enu_f[i, 1], vel_f[i, 1],
                               enu_f[i, 2], vel_f[i, 2]])
                z = np.asarray(models[radar.id].function(State(sv.reshape(6, 1))),
                               dtype=float).ravel()
                az_ss = (90.0 - math.degrees(z[1])) % 360.0
                worst["elevation_deg"] = max(worst["elevation_deg"],
                                             abs(math.degrees(z[0]) - el[i]))
                worst["azimuth_deg"] = max(worst["azimuth_deg"],
                                           abs((az_ss - az[i] + 180.0) % 360.0 - 180.0))
                worst["range_m"] = max(worst["range_m"], abs(z[2] - rho[i]))
                if scene.doppler:
                    worst["radial_velocity_mps"] = max(worst["radial_velocity_mps"],
                                                       abs(z[3] - rr[i]))
    return worst


def run_stonesoup(scene: Scene, q: float, associator: str, models: dict,
                  delete_after_s: float, hold_delete_after_s: float) -> Result:
    from stonesoup.base import Property
    from stonesoup.dataassociator.neighbour import GNNWith2DAssignment
    from stonesoup.dataassociator.probability import JPDAwithEHM2
    from stonesoup.deleter.time import UpdateTimeDeleter
    from stonesoup.hypothesiser.distance import DistanceHypothesiser
    from stonesoup.hypothesiser.probability import PDAHypothesiser
    from stonesoup.initiator.simple import MultiMeasurementInitiator
    from stonesoup.measures import Mahalanobis
    from stonesoup.models.transition.linear import (
        CombinedLinearGaussianTransitionModel, ConstantVelocity)
    from stonesoup.predictor.kalman import KalmanPredictor
    from stonesoup.reader.base import DetectionReader
    from stonesoup.tracker.simple import MultiTargetMixtureTracker, MultiTargetTracker
    from stonesoup.types.angle import Bearing, Elevation
    from stonesoup.types.array import CovarianceMatrix, StateVector
    from stonesoup.types.detection import Clutter, Detection
    from stonesoup.types.state import GaussianState
    from stonesoup.types.update import Update
    from stonesoup.updater.kalman import ExtendedKalmanUpdater

    class StepReader(DetectionReader):
        """Yields (time, set of detections) per distinct plot time."""
        steps: list = Property(doc="[(datetime, set of Detection)] in time order")

        @DetectionReader.generator_method
        def detections_gen(self):
            yield from self.steps

    steps, by_t = [], {}
    for p in scene.plots:
        by_t.setdefault(p.t, []).append(p)
    for t in sorted(by_t):
        ts = EPOCH + timedelta(seconds=t)
        dets = set()
        for p in by_t[t]:
            z = [Elevation(math.radians(p.elevation_deg)),
                 Bearing(math.pi / 2.0 - math.radians(p.azimuth_deg)), p.range_m]
            if scene.doppler:
                z.append(p.radial_velocity_mps)
            cls = Detection if p.truth is not None else Clutter  # same to the tracker
            dets.add(cls(StateVector(z), timestamp=ts, measurement_model=models[p.radar]))
        steps.append((ts, dets))

    transition = CombinedLinearGaussianTransitionModel(
        [ConstantVelocity(q), ConstantVelocity(q), ConstantVelocity(q)])
    predictor = KalmanPredictor(transition)
    updater = ExtendedKalmanUpdater(measurement_model=None)  # per-detection models
    ndim_meas = 4 if scene.doppler else 3
    # Initiation: a plot's position (inverted through its model) and a zero
    # velocity prior of 200 m/s per horizontal axis, 30 m/s vertical; a
    # Mahalanobis gate of 3 then admits about 600 m/s (ours: 0-600 m/s).
    prior = GaussianState(StateVector([0.0] * 6), CovarianceMatrix(
        np.diag([0.0, 200.0 ** 2, 0.0, 200.0 ** 2, 0.0, 30.0 ** 2])))
    initiator = MultiMeasurementInitiator(
        prior_state=prior,
        deleter=UpdateTimeDeleter(timedelta(seconds=hold_delete_after_s)),
        data_associator=GNNWith2DAssignment(DistanceHypothesiser(
            predictor, updater, measure=Mahalanobis(), missed_distance=3.0)),
        updater=updater, min_points=3)
    deleter = UpdateTimeDeleter(timedelta(seconds=delete_after_s))
    clutter_density = scene.clutter_density()
    if scene.doppler:
        clutter_density /= 2.0 * CLUTTER_RR_MAX_MPS
    if associator == "jpda":
        hypothesiser = PDAHypothesiser(
            predictor=predictor, updater=updater, clutter_spatial_density=clutter_density,
            prob_detect=float(np.mean([declared_p_detection(k)
                                       for k in range(len(scene.radars))])),
            prob_gate=0.99)
        tracker = MultiTargetMixtureTracker(
            initiator=initiator, deleter=deleter, detector=StepReader(steps),
            data_associator=JPDAwithEHM2(hypothesiser=hypothesiser), updater=updater)
    else:
        hypothesiser = DistanceHypothesiser(
            predictor, updater, measure=Mahalanobis(),
            missed_distance=math.sqrt(chi2.ppf(0.99, ndim_meas)))
        tracker = MultiTargetTracker(
            initiator=initiator, deleter=deleter, detector=StepReader(steps),
            data_associator=GNNWith2DAssignment(hypothesiser), updater=updater)

    rows, times, all_ids = [], [], set()
    pos_idx = [0, 2, 4]
    t0 = time.perf_counter()
    for ts, tracks in tracker:
        t_step = (ts - EPOCH).total_seconds()
        times.append(t_step)
        for track in tracks:
            st = track.state
            sv = np.asarray(st.state_vector, dtype=float).ravel()
            cv = np.asarray(st.covar, dtype=float)
            rows.append(((st.timestamp - EPOCH).total_seconds(), track.id, sv[pos_idx],
                         cv[np.ix_(pos_idx, pos_idx)], isinstance(st, Update)))
            all_ids.add(track.id)
    wall = time.perf_counter() - t0
    name = f"Stone Soup {'JPDA-EHM2' if associator == 'jpda' else 'GNN'} q={q:g}"
    return result_from_rows(name, times, rows, wall,
                            extra={"q": q, "associator": associator,
                                   "tracks_total": len(all_ids), "steps": len(steps)})


# --------------------------------------------------------------------------
# Our service
# --------------------------------------------------------------------------
def build_request(scene: Scene, tracker: dict | None) -> dict:
    radars = []
    for k, r in enumerate(scene.radars):
        f = declared_factor(k)
        radar = {"id": r.id, "kind": "3d",
                 "site": {"lat_deg": r.site.lat_deg, "lon_deg": r.site.lon_deg,
                          "height_m": r.site.height_m},
                 "sigma_range_m": f * SIGMA_RANGE_M, "sigma_azimuth_deg": f * SIGMA_AZIMUTH_DEG,
                 "sigma_elevation_deg": f * SIGMA_ELEVATION_DEG, "scan_period_s": r.period_s,
                 "p_detection": declared_p_detection(k),
                 "clutter_density": scene.clutter_density()}
        if scene.doppler:
            radar["sigma_radial_velocity_mps"] = f * SIGMA_RADIAL_VELOCITY_MPS
        radars.append(radar)
    plots = []
    for p in scene.plots:
        plot = {"radar_id": p.radar, "t": p.t, "range_m": p.range_m,
                "azimuth_deg": p.azimuth_deg, "elevation_deg": p.elevation_deg}
        if p.radial_velocity_mps is not None:
            plot["radial_velocity_mps"] = p.radial_velocity_mps
        plots.append(plot)
    body = {"origin": {"lat_deg": scene.origin.lat_deg, "lon_deg": scene.origin.lon_deg,
                       "height_m": scene.origin.height_m},
            "radars": radars, "plots": plots, "history": True}
    if tracker:
        body["tracker"] = tracker
    return body


def run_ours(scene: Scene, url: str, tracker: dict | None, name: str, timeout_s: float,
             api_key: str | None, body: dict | None = None) -> Result:
    """``body``: the request to send instead of ``build_request(scene, tracker)``
    (checks/ssr_real_traffic.py adds SSR fields). ``Result.identity``
    maps (track id, t) to the track's (Mode S address, flight level)."""
    import requests

    if body is None:
        body = build_request(scene, tracker)
    endpoint = url.rstrip("/") + "/v1/plot-fusion/track"
    headers = {"authorization": f"Bearer {api_key}"} if api_key else {}
    t0 = time.perf_counter()
    resp = requests.post(endpoint, json=body, timeout=timeout_s, headers=headers)
    if resp.status_code != 200:
        raise RuntimeError(f"POST {endpoint}: HTTP {resp.status_code}: {resp.text[:2000]}")
    out = resp.json()
    wall = time.perf_counter() - t0
    warnings = out.get("warnings") or []
    if any("history cut" in w for w in warnings):
        raise RuntimeError(f"the service cut the history: {warnings}")
    layout = out["state_layout"]
    ip = [layout.index(k) for k in ("x", "y", "z")]
    rows, times, ids = [], [], set()
    seen = set()
    identity = {}
    for entry in out.get("history") or []:
        times.append(entry["t"])
        for tr in entry["tracks"]:
            if tr.get("status", "confirmed") != "confirmed":
                continue
            key = (tr["id"], tr["t"])
            if key in seen:  # the same state listed again after a later frame
                continue
            seen.add(key)
            s = np.asarray(tr["state"], dtype=float)
            c = np.asarray(tr["covariance"], dtype=float)
            rows.append((tr["t"], tr["id"], s[ip], c[np.ix_(ip, ip)],
                         abs(tr["last_update_t"] - tr["t"]) < 1e-9))
            ids.add(tr["id"])
            i = tr.get("identity") or {}
            pa = i.get("pressure_altitude")
            identity[key] = ((i.get("mode_s_address") or {}).get("value"),
                             None if pa is None else pa["flight_level"])
    if not times:
        raise RuntimeError("the response has no history: was \"history\": true ignored?")
    compute_us = (out.get("timing") or {}).get("compute_us")
    extra = {"mode": out.get("mode"), "counters": out.get("counters"), "warnings": warnings,
             "registration": out.get("registration"), "accuracy": out.get("accuracy"),
             "pressure_offset": out.get("pressure_offset"),
             "tracks_total": len(ids), "tracker": tracker or {},
             "request_bytes": len(resp.request.body or b""),
             "response_bytes": len(resp.content)}
    res = result_from_rows(name, times, rows, wall,
                           None if compute_us is None else compute_us / 1e6, extra)
    res.identity = identity
    res.response = out
    return res


# --------------------------------------------------------------------------
# Scoring
# --------------------------------------------------------------------------
def gospa(d: np.ndarray, c: float = GOSPA_C_M, p: int = GOSPA_P) -> float:
    """GOSPA (alpha = 2) from a truths x tracks distance matrix."""
    n, m = d.shape
    if n == 0 or m == 0:
        return (c ** p / 2.0 * (n + m)) ** (1.0 / p)
    cost = np.minimum(d, c) ** p
    rows, cols = linear_sum_assignment(cost)
    matched = d[rows, cols] < c
    loc = float(np.sum(cost[rows, cols][matched]))
    k = int(np.sum(matched))
    return (loc + c ** p / 2.0 * (n - k) + c ** p / 2.0 * (m - k)) ** (1.0 / p)


# A truth climbing or descending faster than this (m/s) is "climbing" in
# the split of the 3D error by segment.
CLIMB_MPS = 2.0


def score(scene: Scene, res: Result, cutoff_m: float) -> dict:
    times = np.unique(np.concatenate([res.times, res.t]))
    # The truths at every instant: fusion ENU position, local up, coverage.
    truth_pos, truth_up, truth_vz, covered = [], [], [], []
    for truth in scene.truths:
        cov = scene.covered(truth, times)
        pos = np.full((len(times), 3), np.nan)
        up = np.full((len(times), 3), np.nan)
        vz = np.full(len(times), np.nan)
        if cov.any():
            ecef = truth.ecef(times[cov])
            pos[cov] = scene.origin_frame.enu(ecef)
            lat, lon, _ = ecef_to_geodetic(ecef)
            la, lo = np.radians(lat), np.radians(lon)
            normal = np.column_stack([np.cos(la) * np.cos(lo), np.cos(la) * np.sin(lo),
                                      np.sin(la)])
            up[cov] = scene.origin_frame.enu_velocity(normal)
            vz[cov] = np.sum(truth.ecef_velocity(times[cov]) * normal, axis=1)
        truth_pos.append(pos)
        truth_up.append(up)
        truth_vz.append(vz)
        covered.append(cov)
    truth_pos = np.stack(truth_pos, axis=1) if scene.truths else np.empty((len(times), 0, 3))
    truth_up = np.stack(truth_up, axis=1) if scene.truths else np.empty((len(times), 0, 3))
    covered = np.stack(covered, axis=1) if scene.truths else np.empty((len(times), 0), bool)
    truth_vz = np.stack(truth_vz, axis=1) if scene.truths else np.empty((len(times), 0))

    index = np.searchsorted(times, res.t)
    order = np.argsort(index, kind="stable")
    bounds = np.searchsorted(index[order], np.arange(len(times) + 1))
    assigned_truth = np.full(len(res.t), -1)
    err_h, err_3d, err_v, climbing, nees, upd = [], [], [], [], [], []
    gospas = []
    held = np.zeros(len(scene.truths), int)
    for k in range(len(times)):
        states = order[bounds[k]:bounds[k + 1]]
        tj = np.flatnonzero(covered[k])
        if len(tj) and len(states):
            d = np.linalg.norm(truth_pos[k, tj][:, None, :] - res.pos[states][None, :, :], axis=2)
        else:
            d = np.zeros((len(tj), len(states)))
        gospas.append(gospa(d))
        if d.size == 0:
            continue
        rows, cols = linear_sum_assignment(np.where(d < cutoff_m, d, 10.0 * cutoff_m))
        for r, c in zip(rows, cols):
            if d[r, c] >= cutoff_m:
                continue
            j, s = tj[r], states[c]
            assigned_truth[s] = j
            held[j] += 1
            e = res.pos[s] - truth_pos[k, j]
            u = truth_up[k, j]
            err_3d.append(float(np.linalg.norm(e)))
            err_h.append(float(np.linalg.norm(e - (e @ u) * u)))
            err_v.append(abs(float(e @ u)))
            climbing.append(abs(float(truth_vz[k, j])) > CLIMB_MPS)
            upd.append(bool(res.updated[s]))
            try:
                nees.append(float(e @ np.linalg.solve(res.cov[s], e)))
            except np.linalg.LinAlgError:
                nees.append(float("inf"))
    err_h, err_3d, err_v, climbing, nees, upd = map(
        np.asarray, (err_h, err_3d, err_v, climbing, nees, upd))

    # Tracks: false when assigned in under half of their states.
    track_ids = list(dict.fromkeys(res.ids.tolist()))
    false_tracks = []
    for tid in track_ids:
        mine = res.ids == tid
        if np.mean(assigned_truth[mine] >= 0) < 0.5:
            false_tracks.append(str(tid))
    # Truths: missed when held at under half of their covered instants; swaps.
    missed, swaps, held_frac = [], 0, []
    for j, truth in enumerate(scene.truths):
        n_cov = int(covered[:, j].sum())
        if n_cov == 0:
            continue
        frac = held[j] / n_cov
        held_frac.append(frac)
        if frac < 0.5:
            missed.append(truth.name)
        mine = np.flatnonzero(assigned_truth == j)
        seq = res.ids[mine[np.argsort(res.t[mine], kind="stable")]]
        swaps += int(sum(a != b for a, b in zip(seq[:-1], seq[1:])))
    lo, hi = chi2.ppf(0.025, 3), chi2.ppf(0.975, 3)

    def pct(x, q):
        return float(np.percentile(x, q)) if len(x) else float("nan")

    return {
        "name": res.name,
        "median_h_m": pct(err_h, 50), "p90_h_m": pct(err_h, 90),
        "median_3d_m": pct(err_3d, 50), "p90_3d_m": pct(err_3d, 90),
        "median_3d_updated_m": pct(err_3d[upd], 50) if len(upd) else float("nan"),
        "median_v_m": pct(err_v, 50),
        "median_3d_level_m": pct(err_3d[~climbing], 50) if len(climbing) else float("nan"),
        "median_3d_climbing_m": pct(err_3d[climbing], 50) if len(climbing) else float("nan"),
        "climbing_fraction": float(np.mean(climbing)) if len(climbing) else float("nan"),
        "assigned_states": int(len(err_3d)), "states": int(len(res.t)),
        "instants": int(len(times)),
        "confirmed_tracks": len(track_ids), "false_tracks": len(false_tracks),
        "false_track_ids": false_tracks,
        "truths_in_coverage": len(held_frac), "missed": len(missed), "missed_names": missed,
        "mean_held_fraction": float(np.mean(held_frac)) if held_frac else float("nan"),
        "id_swaps": swaps,
        "mean_gospa_m": float(np.mean(gospas)) if gospas else float("nan"),
        "nees_mean": float(np.mean(nees)) if len(nees) else float("nan"),
        "nees_in_band": float(np.mean((nees >= lo) & (nees <= hi))) if len(nees) else float("nan"),
        "wall_s": res.wall_s, "compute_s": res.compute_s, **res.extra,
    }


# --------------------------------------------------------------------------
# Report
# --------------------------------------------------------------------------
def table(rows: list[tuple[str, dict]]) -> str:
    out = ["| tracker | median / p90 horiz. (m) | median / p90 3D (m) | median 3D updated (m) | "
           "confirmed tracks | false tracks | missed aircraft | ID swaps | mean GOSPA (m) | "
           "NEES mean (3) | NEES in 95 % band | wall (s) |",
           "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for label, f in rows:
        wall = f"{f['wall_s']:.2f}"
        if f.get("compute_s") is not None:
            wall += f" (compute {f['compute_s']:.2f})"
        out.append(
            f"| {label} | {f['median_h_m']:.1f} / {f['p90_h_m']:.1f} | "
            f"{f['median_3d_m']:.1f} / {f['p90_3d_m']:.1f} | {f['median_3d_updated_m']:.1f} | "
            f"{f['confirmed_tracks']} | {f['false_tracks']} | "
            f"{f['missed']} of {f['truths_in_coverage']} | {f['id_swaps']} | "
            f"{f['mean_gospa_m']:.1f} | {f['nees_mean']:.2f} | {100 * f['nees_in_band']:.0f} % | "
            f"{wall} |")
    return "\n".join(out)


def best(figures: list[dict], associator: str) -> dict | None:
    mine = [f for f in figures if f.get("associator") == associator
            and not math.isnan(f["median_3d_m"])]
    return min(mine, key=lambda f: f["median_3d_m"]) if mine else None


_WORK: dict = {}  # what the Stone Soup runs share (inherited by forked workers)


def _stonesoup_job(job: tuple[float, str]) -> Result:
    q, assoc = job
    w = _WORK
    return run_stonesoup(w["scene"], q, assoc, w["models"], w["delete_after"], w["hold"])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--url", default="http://127.0.0.1:18080")
    ap.add_argument("--api-key", default=os.environ.get("FUSION_API_KEY"),
                    help="Bearer key, when the server has --api-keys (default $FUSION_API_KEY)")
    ap.add_argument("--collection", choices=sorted(SCENES), default="quickstart")
    ap.add_argument("--flights", type=int, default=10)
    ap.add_argument("--minutes", type=float, default=6.0)
    ap.add_argument("--start", help="window start (UTC, e.g. 2021-10-07T14:05); "
                                    "default: the window with the most flights")
    ap.add_argument("--radars", type=int, choices=(2, 3), default=3)
    ap.add_argument("--doppler", action="store_true", help="plots carry radial velocity")
    ap.add_argument("--clutter", type=float, default=2.0, help="false plots per scan (mean)")
    ap.add_argument("--max-range-km", type=float, default=200.0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--tracker-json", action="append", default=[], metavar="JSON",
                    help="extra row: our service with these `tracker` options (repeatable)")
    ap.add_argument("--q-grid", default="0.1,0.5,1,2,5,10,25",
                    help="Stone Soup CV process noise q (m^2/s^3), comma-separated")
    ap.add_argument("--associators", default="jpda,gnn", help="Stone Soup: jpda, gnn or both")
    ap.add_argument("--delete-after-s", type=float, default=None,
                    help="Stone Soup: delete a track this long without update "
                         "(default 2 x the longest scan period)")
    ap.add_argument("--jobs", type=int, default=1,
                    help="Stone Soup runs in parallel processes (each run is timed alone "
                         "only with 1)")
    ap.add_argument("--cutoff-m", type=float, default=2000.0)
    ap.add_argument("--timeout", type=float, default=900.0, help="HTTP timeout (s)")
    ap.add_argument("--stonesoup-only", action="store_true")
    ap.add_argument("--ours-only", action="store_true")
    ap.add_argument("--bias", type=parse_bias, metavar="ID:RANGE_M:AZ_DEG[:EL_DEG]",
                    help="one radar's systematic error on its target plots (e.g. B:300:0.3)")
    ap.add_argument("--settle-s", type=float, default=None,
                    help="also score every tracker from this time on (s)")
    ap.add_argument("--declared-factors", metavar="F1,F2,...",
                    help="per radar, what its declared sigmas are multiplied by (ours and "
                         "Stone Soup alike; the plots keep the true sigmas), e.g. 0.3,3,1")
    ap.add_argument("--declared-p-detection", metavar="P1,P2,...",
                    help="per radar, the detection probability it declares (the plots keep "
                         f"{P_DETECTION}; Stone Soup is given their mean), e.g. 0.99,0.7,0.9")
    ap.add_argument("--json-out", metavar="FILE")
    ap.add_argument("--truth-csv", metavar="FILE", help="write the 1-s truth table")
    args = ap.parse_args(argv)
    if args.declared_factors:
        DECLARED_FACTORS[:] = [float(x) for x in args.declared_factors.split(",")]
    if args.declared_p_detection:
        DECLARED_P_DETECTION[:] = [float(x) for x in args.declared_p_detection.split(",")]
    trackers = [json.loads(s) for s in args.tracker_json]
    for s, t in zip(args.tracker_json, trackers):
        if not isinstance(t, dict):
            ap.error(f"--tracker-json {s!r} is not a JSON object")

    t0 = time.perf_counter()
    scene = make_scene(args)
    unbiased = None
    if args.bias:
        unbiased, scene = scene, biased(scene, args.bias)
    truth_stats = describe_truths(scene)
    n_clutter = sum(p.truth is None for p in scene.plots)
    print(f"scene: {scene.info['collection']} from {scene.info['window_start_utc']}, "
          f"{len(scene.truths)} flights over {args.minutes:g} min, {len(scene.radars)} 3D radars "
          f"({', '.join(f'{r.id} {r.period_s:g} s' for r in scene.radars)}), "
          f"{'with' if args.doppler else 'no'} Doppler, {len(scene.plots)} plots "
          f"({n_clutter} clutter), seed {args.seed}; built in {time.perf_counter() - t0:.1f} s")
    print(f"truth: {json.dumps(truth_stats)}")
    if args.truth_csv:
        write_truth_csv(scene, args.truth_csv)

    results: list[Result] = []
    geometry = None
    if not args.stonesoup_only:
        runs = [(None, "ours (defaults)", scene)] + [
            (t, f"ours {json.dumps(t)}", scene) for t in trackers]
        if unbiased is not None:
            runs.append((None, "ours (defaults, unbiased plots)", unbiased))
        for tracker, name, plots in runs:
            try:
                res = run_ours(plots, args.url, tracker, name, args.timeout, args.api_key)
            except Exception as exc:  # noqa: BLE001 — report and fail clearly
                print(f"our service failed ({name}): {exc}", file=sys.stderr)
                return 2
            print(f"{name}: {res.wall_s:.1f} s, mode {res.extra.get('mode')}, "
                  f"counters {res.extra.get('counters')}", flush=True)
            for w in res.extra.get("warnings") or []:
                print(f"  warning: {w}")
            for b in res.extra.get("registration") or []:
                el = ("" if b.get("elevation_deg") is None else
                      f", elevation {b['elevation_deg']:+.3f} ± {b['sigma_elevation_deg']:.3f} deg")
                print(f"  registration {b['radar']}: range {b['range_m']:+.1f} ± "
                      f"{b['sigma_range_m']:.1f} m, azimuth {b['azimuth_deg']:+.4f} ± "
                      f"{b['sigma_azimuth_deg']:.4f} deg{el}, {b['pairs']:.0f} pairs, "
                      f"{'converged' if b['converged'] else 'not converged'}"
                      f"{', reference' if b['reference'] else ''}")
            for a in res.extra.get("accuracy") or []:
                parts = []
                for key in ("range_m", "azimuth_deg", "elevation_deg", "radial_velocity_mps",
                            "p_detection"):
                    c = a.get(key)
                    if c is None:
                        continue
                    est = ("–" if c.get("estimated") is None else
                           f"{c['estimated']:.4g} ± {c['sigma']:.2g}")
                    parts.append(f"{key} declared {c['declared']:.4g}, learnt {est}"
                                 f"{' (applied)' if c['converged'] and not a['pinned'] else ''}")
                print(f"  accuracy {a['radar']}: " + "; ".join(parts))
            results.append(res)
    grid = [float(q) for q in args.q_grid.split(",") if q.strip()]
    if not args.ours_only:
        models = stonesoup_models(scene)
        geometry = check_stonesoup_geometry(scene, models)
        print(f"Stone Soup models vs pyproj, worst noise-free difference: {geometry}")
        longest = max(r.period_s for r in scene.radars)
        delete_after = args.delete_after_s or 2.0 * longest
        jobs = [(q, a.strip()) for a in args.associators.split(",") if a.strip() for q in grid]
        _WORK.update(scene=scene, models=models, delete_after=delete_after,
                     hold=longest + 1.0)
        if args.jobs > 1:
            import multiprocessing
            from concurrent.futures import ProcessPoolExecutor

            with ProcessPoolExecutor(args.jobs, mp_context=multiprocessing.get_context("fork")) as ex:
                for res in ex.map(_stonesoup_job, jobs):
                    print(f"{res.name}: {res.wall_s:.1f} s", flush=True)
                    results.append(res)
        else:
            for job in jobs:
                res = _stonesoup_job(job)
                print(f"{res.name}: {res.wall_s:.1f} s", flush=True)
                results.append(res)

    figures = [score(scene, r, args.cutoff_m) for r in results]
    if args.settle_s is not None:
        figures += [score(scene, settled(r, args.settle_s), args.cutoff_m) for r in results]
    rows = [(f["name"], f) for f in figures if f["name"].startswith("ours")]
    ss = [f for f in figures if not f["name"].startswith("ours") and " from " not in f["name"]]
    ss_settled = [f for f in figures if not f["name"].startswith("ours") and " from " in f["name"]]
    for assoc in ("jpda", "gnn"):
        b = best(ss, assoc)
        if b:
            rows.append((f"**Stone Soup best {b['name'][len('Stone Soup '):]}**", b))
    rows += [(f["name"], f) for f in ss]
    rows += [(f["name"], f) for f in ss_settled]
    print()
    print(f"Every confirmed state at its own time, assigned to the truths in coverage "
          f"(cutoff {args.cutoff_m:.0f} m); GOSPA 3D p={GOSPA_P} c={GOSPA_C_M:.0f} m "
          f"alpha={GOSPA_ALPHA}; NEES of 3D position, band [{chi2.ppf(0.025, 3):.2f}, "
          f"{chi2.ppf(0.975, 3):.2f}]")
    print()
    print(table(rows))
    for f in figures:
        if f["false_track_ids"] or f["missed_names"]:
            print(f"{f['name']}: false tracks {f['false_track_ids'][:10]}, "
                  f"missed {f['missed_names']}")
    if args.json_out:
        doc = {"scene": {**scene.info, "flights": [t.name for t in scene.truths],
                         "truth": truth_stats, "plots": len(scene.plots),
                         "clutter_plots": n_clutter, "doppler": args.doppler,
                         "seed": args.seed, "minutes": args.minutes,
                         "radars": [{"id": r.id, "site": vars(r.site), "period_s": r.period_s,
                                     "phase_s": r.phase_s} for r in scene.radars],
                         "origin": vars(scene.origin),
                         "clutter_density_per_m_rad2": scene.clutter_density()},
               "stonesoup_geometry_check": geometry, "q_grid": grid,
               "cutoff_m": args.cutoff_m, "trackers": figures}
        with open(args.json_out, "w") as fh:
            json.dump(doc, fh, indent=1, default=str)
    return 0


if __name__ == "__main__":
    sys.exit(main())
