#!/usr/bin/env python3
"""Surveillance evaluation of system tracks against reference trajectories,
in the terms of EUROCAE ED-87 and the OpenATS COMPASS evaluation.

ED-87 (the A-SMGCS MASPS) and the tools that apply it (OpenATS COMPASS,
EUROCONTROL's SASS-C) judge a surveillance data processing system by its
*output*: the track updates it sends, compared with a reference (ADS-B,
DGPS or a recorded truth) of every target in the area. The measures below
are written from those concepts in our own words; they are not a copy of
either tool's rules, and the choices left open (bounds, periods) are
parameters of ``Config``.

Inputs
    * reference: per target a time series ``t, lat, lon, altitude`` (WGS-84,
      altitude = height above the ellipsoid in m), optionally its Mode S
      address, callsign and Mode 3/A code (one value, or one per sample:
      a code may change), its pressure altitude (flight level) and a flag
      per sample saying whether the target is *expected* to be seen there
      (in coverage; default everywhere). The reference is interpolated
      linearly between samples, never across a gap over
      ``max_ref_gap_s``; its velocity is the samples' central difference,
      interpolated the same way.
    * system track updates: per update its time of applicability ``t``,
      track number, WGS-84 position (or a position in a local ENU frame
      and that frame's origin), optional height, whether it was a measured
      update or a coasted (extrapolated) one, the time the message was
      sent (``t_message``, when known) and the identity it carries
      (address, callsign, Mode 3/A, flight level). Loaders: our service's
      JSON (a plot-fusion answer with ``history``, or track views, one per
      line or in a list) and CAT062 as ``checks/cat062_oracle.py decode``
      writes it.

Association (``associate``)
    Each update on its own, at its time of applicability: the candidate
    targets are those whose reference exists at that time (inside its
    time span, not in a reference gap) and lies within ``max_distance_m``
    horizontally of the update (and within ``max_altitude_diff_m``
    vertically when set and both altitudes are known). When the update
    carries an identity that some candidates share, only those stay:
    first the Mode S address, then the callsign, then the Mode 3/A code.
    The nearest remaining candidate (horizontal distance) is the update's
    target; none: the update is unassociated (false). Several tracks can be
    associated with one target at one time (that is what "extra track"
    measures); one update never goes to two targets.

Measures (per target, and overall)
    * Probability of update (PU): time is cut into periods of
      ``period_s`` (on a grid from ``period_origin_s``). A period counts
      for a target when its reference exists and is expected over the
      whole period; it is updated when at least one track update
      associated with the target falls in it (a measured update, not a
      coasted one, unless ``pu_counts="any"``). PU = updated periods /
      counted periods. (ED-87's probability of update: the chance that the
      target's position is refreshed in an update interval.)
    * Track continuity: the number of distinct tracks associated with the
      target (1 when one track followed it all along); track breaks: gaps
      longer than ``break_s`` between consecutive updates associated with
      the target while its reference was expected throughout the gap;
      ID changes: changes of track number between consecutive updates of
      the target's main track sequence (extra tracks' updates left out), a
      swap or a restart. Per track, target changes: a track moving from
      one target to another.
    * Position error of every associated update, against the reference
      interpolated at the update's time of applicability, in the local
      horizontal plane at the reference point: horizontal distance;
      along-track = the error's component along the reference's ground
      velocity (positive: ahead of the target); across-track = the
      component along the normal to its left (positive: left of the
      target's course); altitude = update height - reference altitude;
      flight level (ft) = update FL - reference FL, when both exist. Each
      with mean, median, RMS and 95th percentile (of the absolute value
      for signed errors). Along and across need a reference ground speed of
      at least ``min_speed_mps``.
    * Latency: reported = t_message - t (the time the message left minus
      its time of applicability), where both are known (our plot-fusion
      history: the processing instant at which a state first appears minus
      the state's own ``t``, in the data's time scale, not wall time);
      otherwise left out with a note. Implied = -along-track error /
      reference ground speed (COMPASS's position latency: how late a track
      is along its course).
    * Extra tracks: an update is extra when another track was already
      following the same target at that time: that track's segment on the
      target (its associated updates, split at gaps over ``break_s``)
      started earlier and spans the update's time. Extra tracks: distinct
      (target, track) pairs with an extra update; also per hour.
    * False tracks: updates associated with no target (false updates), and
      tracks whose share of associated updates is under
      ``false_track_share``; counts and rates per hour of the evaluated
      time (``duration_s``, default the span of the updates).
    * Identity, of associated updates, per item (Mode S address, callsign,
      Mode 3/A): correct (equal to the target's at that time), false
      (different, or carried while the target has none), missing (the
      target has one, the update none); shares of the updates where the
      target or the update has the item.

Usage
    python3 checks/ed87.py --reference truth.csv --tracks answer.json [--json]
    (reference CSV columns: target|flight|name, t|t_s, lat_deg, lon_deg,
    height_m|alt_m, and optionally address, callsign, mode_3a,
    flight_level, expected; ``--identity-from-name`` reads
    "CALLSIGN/icao24" names as real_traffic_vs_stonesoup.py --truth-csv
    writes them). Module use: ``evaluate(references, updates, Config())``
    -> dict; ``text_report(result)``.
    Tests: checks/.venv/bin/python checks/test_ed87.py (numpy only).
"""
from __future__ import annotations

import argparse
import csv
import json
import math
import sys
from dataclasses import asdict, dataclass
from typing import Any, Iterable, Sequence

import numpy as np

# ---------------------------------------------------------------------------
# WGS-84 geometry (numpy only)
# ---------------------------------------------------------------------------
A_WGS = 6378137.0
F_WGS = 1.0 / 298.257223563
E2_WGS = F_WGS * (2.0 - F_WGS)
FT = 0.3048


def geodetic_to_ecef(lat_deg, lon_deg, h_m) -> np.ndarray:
    """(n,) lat, lon (deg), height (m) -> (n, 3) ECEF (m)."""
    la = np.radians(np.asarray(lat_deg, dtype=float))
    lo = np.radians(np.asarray(lon_deg, dtype=float))
    h = np.asarray(h_m, dtype=float)
    n = A_WGS / np.sqrt(1.0 - E2_WGS * np.sin(la) ** 2)
    return np.stack([(n + h) * np.cos(la) * np.cos(lo),
                     (n + h) * np.cos(la) * np.sin(lo),
                     (n * (1.0 - E2_WGS) + h) * np.sin(la)], axis=-1)


def ecef_to_geodetic(ecef: np.ndarray):
    """(n, 3) ECEF -> lat, lon (deg), height (m); fixed-point iteration
    (sub-millimetre after a few steps at aircraft heights)."""
    x, y, z = (np.asarray(ecef, dtype=float)[..., k] for k in range(3))
    p = np.hypot(x, y)
    lon = np.arctan2(y, x)
    lat = np.arctan2(z, p * (1.0 - E2_WGS))
    h = np.zeros_like(p)
    for _ in range(8):
        n = A_WGS / np.sqrt(1.0 - E2_WGS * np.sin(lat) ** 2)
        h = p / np.cos(lat) - n
        lat = np.arctan2(z, p * (1.0 - E2_WGS * n / (n + h)))
    n = A_WGS / np.sqrt(1.0 - E2_WGS * np.sin(lat) ** 2)
    h = p / np.cos(lat) - n
    return np.degrees(lat), np.degrees(lon), h


def enu_rotation(lat_deg, lon_deg) -> np.ndarray:
    """(n, 3, 3): rows east, north, up at each point (ECEF axes -> ENU)."""
    la = np.radians(np.asarray(lat_deg, dtype=float))
    lo = np.radians(np.asarray(lon_deg, dtype=float))
    sla, cla, slo, clo = np.sin(la), np.cos(la), np.sin(lo), np.cos(lo)
    zero = np.zeros_like(la)
    east = np.stack([-slo, clo, zero], axis=-1)
    north = np.stack([-sla * clo, -sla * slo, cla], axis=-1)
    up = np.stack([cla * clo, cla * slo, sla], axis=-1)
    return np.stack([east, north, up], axis=-2)


def enu_to_geodetic(enu: np.ndarray, origin: Sequence[float]):
    """(n, 3) positions in the topocentric ENU frame at origin (lat, lon,
    height) -> lat, lon, height."""
    lat0, lon0, h0 = origin
    x0 = geodetic_to_ecef(lat0, lon0, h0)
    r = enu_rotation(lat0, lon0)
    return ecef_to_geodetic(x0 + np.atleast_2d(enu) @ r)


def geodetic_to_enu(lat_deg, lon_deg, h_m, origin: Sequence[float]) -> np.ndarray:
    lat0, lon0, h0 = origin
    x0 = geodetic_to_ecef(lat0, lon0, h0)
    r = enu_rotation(lat0, lon0)
    return (geodetic_to_ecef(lat_deg, lon_deg, h_m) - x0) @ r.T


# ---------------------------------------------------------------------------
# Inputs
# ---------------------------------------------------------------------------
def norm_address(v) -> str | None:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return None
    if isinstance(v, (int, np.integer)):
        return f"{int(v):06X}"
    s = str(v).strip().upper()
    return s or None


def norm_callsign(v) -> str | None:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return None
    s = str(v).strip().upper()
    return s or None


def norm_mode_3a(v) -> str | None:
    """Four octal digits as text ("7000"); an int is read as its digits."""
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return None
    s = str(v).strip()
    if not s:
        return None
    return s.zfill(4)


NORM = {"address": norm_address, "callsign": norm_callsign, "mode_3a": norm_mode_3a}
IDENTITY_ITEMS = ("address", "callsign", "mode_3a")


@dataclass
class Reference:
    """One target's reference trajectory. Identity items: one value for the
    whole trajectory, or a sequence with one value per sample (None where
    unknown); a sample's value holds until the next sample."""
    name: str
    t: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    alt_m: np.ndarray | None = None
    address: Any = None
    callsign: Any = None
    mode_3a: Any = None
    flight_level: np.ndarray | None = None
    expected: np.ndarray | None = None

    def __post_init__(self):
        self.t = np.asarray(self.t, dtype=float)
        order = np.argsort(self.t, kind="stable")
        n = len(self.t)

        def per_sample(v, dtype=float):
            if v is None:
                return None
            a = np.asarray(v, dtype=dtype)
            return a[order] if a.ndim else np.full(n, a.item(), dtype=dtype)

        self.t = self.t[order]
        self.lat_deg = per_sample(self.lat_deg)
        self.lon_deg = np.degrees(np.unwrap(np.radians(per_sample(self.lon_deg))))
        self.alt_m = per_sample(self.alt_m)
        self.flight_level = per_sample(self.flight_level)
        self.expected = (np.ones(n, bool) if self.expected is None
                         else per_sample(self.expected, bool))
        for key in IDENTITY_ITEMS:
            v = getattr(self, key)
            if v is None or isinstance(v, (str, int, np.integer)):
                vals = [NORM[key](v)] * n
            else:
                vals = [NORM[key](x) for x in v]
                if len(vals) != n:
                    raise ValueError(f"reference {self.name}: {key} has {len(vals)} values "
                                     f"for {n} samples")
                vals = [vals[i] for i in order]
            setattr(self, key, np.array(vals, dtype=object))
        if n < 2:
            raise ValueError(f"reference {self.name}: at least two samples needed")


@dataclass
class Updates:
    """System track updates (one row each)."""
    t: np.ndarray  # time of applicability (s)
    track: np.ndarray  # track number / id (object)
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    height_m: np.ndarray  # nan: none (2D)
    updated: np.ndarray  # bool: a measured update (False: coasted)
    t_message: np.ndarray  # nan: unknown
    address: np.ndarray  # object, None: absent
    callsign: np.ndarray
    mode_3a: np.ndarray
    flight_level: np.ndarray  # nan: none

    def __len__(self) -> int:
        return len(self.t)


def make_updates(records: Iterable[dict], origin: Sequence[float] | None = None) -> Updates:
    """Updates from plain records: ``t``, ``track``, and ``lat_deg`` /
    ``lon_deg`` (+ ``height_m``) or ``position_m`` [e, n(, u)] about
    ``origin`` (lat, lon, height); optional ``updated`` (default True),
    ``t_message``, ``address``, ``callsign``, ``mode_3a``,
    ``flight_level``."""
    records = list(records)
    n = len(records)
    lat = np.full(n, np.nan)
    lon = np.full(n, np.nan)
    h = np.full(n, np.nan)
    enu_rows, enu_idx, enu_3d = [], [], []
    for i, r in enumerate(records):
        if r.get("lat_deg") is not None and r.get("lon_deg") is not None:
            lat[i], lon[i] = float(r["lat_deg"]), float(r["lon_deg"])
            if r.get("height_m") is not None:
                h[i] = float(r["height_m"])
        elif r.get("position_m") is not None:
            p = [float(x) for x in r["position_m"]]
            enu_3d.append(len(p) >= 3)
            enu_rows.append((p + [0.0])[:3])
            enu_idx.append(i)
        else:
            raise ValueError(f"update {i}: neither lat_deg/lon_deg nor position_m")
    if enu_rows:
        if origin is None:
            raise ValueError("updates in a local ENU frame need its origin (lat, lon, height)")
        la, lo, hh = enu_to_geodetic(np.array(enu_rows), origin)
        lat[enu_idx], lon[enu_idx] = la, lo
        hh = np.where(np.array(enu_3d), hh, np.nan)
        h[enu_idx] = hh

    def col(key):
        return np.array([np.nan if r.get(key) is None else float(r[key]) for r in records],
                        dtype=float).reshape(n)

    return Updates(
        t=np.array([float(r["t"]) for r in records], dtype=float).reshape(n),
        track=np.array([r["track"] for r in records] + [None], dtype=object)[:n],
        lat_deg=lat, lon_deg=lon, height_m=h,
        updated=np.array([bool(r.get("updated", True)) for r in records], dtype=bool).reshape(n),
        t_message=col("t_message"),
        address=np.array([norm_address(r.get("address")) for r in records] + [None],
                         dtype=object)[:n],
        callsign=np.array([norm_callsign(r.get("callsign")) for r in records] + [None],
                          dtype=object)[:n],
        mode_3a=np.array([norm_mode_3a(r.get("mode_3a")) for r in records] + [None],
                         dtype=object)[:n],
        flight_level=col("flight_level"))


def record_from_track(tr: dict, t_message: float | None = None,
                      state_layout: Sequence[str] | None = None) -> dict:
    """One record from one of our JSON track views (plot-fusion ``tracks``,
    ``history[].tracks``, a session's tracks): WGS-84 ``lat_deg``/``lon_deg``
    (+ ``height_m``) when present, else ``position_m`` or ``state`` with
    ``state_layout`` (x, y(, z)) in the fusion ENU frame; ``updated`` from
    ``last_update_t == t``; identity from ``identity`` (or flat
    ``mode_s_address``/``address``, ``callsign``, ``mode_3a``)."""
    rec = {"t": float(tr["t"]), "track": tr.get("id", tr.get("track"))}
    if tr.get("lat_deg") is not None and tr.get("lon_deg") is not None:
        rec.update(lat_deg=tr["lat_deg"], lon_deg=tr["lon_deg"], height_m=tr.get("height_m"))
    elif tr.get("position_m") is not None:
        rec["position_m"] = tr["position_m"]
    elif tr.get("state") is not None and state_layout:
        s = tr["state"]
        rec["position_m"] = [s[state_layout.index(k)] for k in ("x", "y", "z")
                             if k in state_layout]
    else:
        raise ValueError(f"track {rec['track']} at t {rec['t']}: no position")
    if tr.get("last_update_t") is not None:
        rec["updated"] = abs(float(tr["last_update_t"]) - rec["t"]) < 1e-9
    elif tr.get("consecutive_misses") is not None:
        rec["updated"] = int(tr["consecutive_misses"]) == 0
    elif tr.get("coasted") is not None:
        rec["updated"] = not tr["coasted"]
    tm = t_message if t_message is not None else tr.get("t_message")
    if tm is not None:
        rec["t_message"] = float(tm)
    ident = tr.get("identity") or {}

    def value(key):
        v = ident.get(key)
        return v.get("value") if isinstance(v, dict) else v

    rec["address"] = value("mode_s_address") or tr.get("mode_s_address") or tr.get("address")
    rec["callsign"] = value("callsign") or tr.get("callsign")
    rec["mode_3a"] = value("mode_3a") or tr.get("mode_3a")
    pa = ident.get("pressure_altitude")
    fl = pa.get("flight_level") if isinstance(pa, dict) else tr.get("flight_level")
    rec["flight_level"] = fl
    return rec


def updates_from_response(resp: dict, origin: Sequence[float] | None = None,
                          confirmed_only: bool = True) -> tuple[Updates, str]:
    """Our ``POST /v1/plot-fusion/track`` answer -> updates, and a note.
    With ``history``: every confirmed track state after every processing
    instant, each distinct (id, t) once, its ``t_message`` the instant
    (history entry ``t``) at which it first appears. Without: the final
    ``tracks`` and ``deleted`` (no latency)."""
    layout = resp.get("state_layout")
    recs, seen = [], set()
    if resp.get("history"):
        for entry in resp["history"]:
            for tr in entry["tracks"]:
                if confirmed_only and tr.get("status", "confirmed") != "confirmed":
                    continue
                key = (tr["id"], tr["t"])
                if key in seen:
                    continue
                seen.add(key)
                recs.append(record_from_track(tr, entry["t"], layout))
        note = ("history: distinct (id, t) states; t_message = the history instant at which a "
                "state first appears (in the batch call every state is at its processing "
                "instant, so this latency is 0 by construction)")
    else:
        for tr in list(resp.get("tracks") or []) + list(resp.get("deleted") or []):
            if confirmed_only and tr.get("status") == "tentative":
                continue
            recs.append(record_from_track(tr, None, layout))
        note = "final tracks only (no history): no reported latency"
    return make_updates(recs, origin), note


def updates_from_cat062(doc: dict, day_start_t: float = 0.0,
                        confirmed_only: bool = True) -> Updates:
    """CAT062 decoded by ``checks/cat062_oracle.py decode`` (libasterix):
    I062/070 time of track information (+ ``day_start_t``), I062/040 track
    number, I062/105 lat/lon, I062/130 geometric altitude (ft), I062/380
    ADR (address) and ID / I062/245 callsign, I062/060 Mode 3/A, I062/136
    measured flight level, I062/080 CST (coasted) and CNF (tentative).
    CAT062 carries no sending time: no reported latency."""
    recs = []
    for block in doc.get("blocks", []):
        if block.get("category") != 62:
            continue
        for r in block.get("records", []):
            it = r.get("items", {})
            if "070" not in it or "105" not in it or "040" not in it:
                continue
            st = it.get("080", {})
            if confirmed_only and (st.get("CNF") or {}).get("raw") == 1:
                continue

            def string(item, *subs):
                for s in subs:
                    v = (it.get(item) or {}).get(s)
                    if isinstance(v, dict) and v.get("string"):
                        return v["string"]
                return None

            adr = (it.get("380") or {}).get("ADR")
            rec = {"t": day_start_t + it["070"]["value"], "track": it["040"]["raw"],
                   "lat_deg": it["105"]["LAT"]["value"], "lon_deg": it["105"]["LON"]["value"],
                   "height_m": (it["130"]["value"] * FT) if "130" in it else None,
                   "updated": (st.get("CST") or {}).get("raw", 0) == 0,
                   "address": None if adr is None else f"{adr['raw']:06X}",
                   "callsign": string("380", "ID") or string("245", "CHR", "CALLSIGN"),
                   "mode_3a": string("060", "MODE3A"),
                   "flight_level": (it["136"]["value"]) if "136" in it else None}
            recs.append(rec)
    return make_updates(recs)


# ---------------------------------------------------------------------------
# Configuration
# ---------------------------------------------------------------------------
@dataclass
class Config:
    max_distance_m: float = 2000.0
    max_altitude_diff_m: float | None = None
    max_ref_gap_s: float = 30.0
    period_s: float = 5.0
    period_origin_s: float = 0.0
    pu_counts: str = "updated"  # or "any"
    break_s: float | None = None  # default 3 x period_s
    min_speed_mps: float = 10.0
    false_track_share: float = 0.5
    duration_s: float | None = None
    use_identity: bool = True

    @property
    def break_gap_s(self) -> float:
        return self.break_s if self.break_s is not None else 3.0 * self.period_s


# ---------------------------------------------------------------------------
# Reference at given times
# ---------------------------------------------------------------------------
@dataclass
class RefAt:
    valid: np.ndarray
    expected: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    alt: np.ndarray
    vel_en: np.ndarray  # (n, 2) ground velocity east, north (m/s)
    fl: np.ndarray
    ident: dict


class RefTrack:
    """A reference prepared for interpolation."""

    def __init__(self, ref: Reference, max_gap_s: float):
        self.ref = ref
        t = ref.t
        self.t = t
        dt = np.diff(t)
        self.ok_interval = (dt > 0) & (dt <= max_gap_s)
        alt = ref.alt_m if ref.alt_m is not None else np.zeros(len(t))
        self.has_alt = ref.alt_m is not None
        self.alt = alt
        ecef = geodetic_to_ecef(ref.lat_deg, ref.lon_deg, alt)
        with np.errstate(invalid="ignore", divide="ignore"):
            vi = np.diff(ecef, axis=0) / dt[:, None]
        vi[~self.ok_interval] = np.nan
        # Sample velocities: the mean of the adjacent valid intervals'.
        left = np.vstack([np.full((1, 3), np.nan), vi])
        right = np.vstack([vi, np.full((1, 3), np.nan)])
        vs = np.where(np.isnan(left), right, np.where(np.isnan(right), left, 0.5 * (left + right)))
        r = enu_rotation(ref.lat_deg, ref.lon_deg)
        self.vel_en = np.einsum("nij,nj->ni", r, np.nan_to_num(vs))[:, :2]
        bad = ~self.ok_interval | ~(ref.expected[:-1] & ref.expected[1:])
        self.bad_cum = np.concatenate([[0], np.cumsum(bad)])

    def at(self, times: np.ndarray) -> RefAt:
        t = self.t
        times = np.asarray(times, dtype=float)
        k = np.clip(np.searchsorted(t, times, side="right") - 1, 0, len(t) - 2)
        inside = (times >= t[0]) & (times <= t[-1])
        # Between two samples of a good interval, or on a sample itself.
        valid = inside & (self.ok_interval[k] | (times == t[k]) | (times == t[k + 1]))
        dt = t[k + 1] - t[k]
        w = np.where(dt > 0, (times - t[k]) / np.where(dt > 0, dt, 1.0), 0.0)
        w = np.clip(w, 0.0, 1.0)

        def lin(a):
            return (1.0 - w) * a[k] + w * a[k + 1]

        ref = self.ref
        expected = valid & ref.expected[k] & ref.expected[k + 1]
        # Identity: the value of the last sample at or before the time.
        j = np.clip(np.searchsorted(t, times, side="right") - 1, 0, len(t) - 1)
        ident = {key: getattr(ref, key)[j] for key in IDENTITY_ITEMS}
        fl = lin(ref.flight_level) if ref.flight_level is not None else np.full(len(times), np.nan)
        return RefAt(valid, expected, lin(ref.lat_deg), lin(ref.lon_deg), lin(self.alt),
                     (1.0 - w)[:, None] * self.vel_en[k] + w[:, None] * self.vel_en[k + 1],
                     fl, ident)

    def good_span(self, s: np.ndarray, e: np.ndarray) -> np.ndarray:
        """Whether the reference exists and is expected over all of [s, e]."""
        t = self.t
        inside = (s >= t[0]) & (e <= t[-1])
        ks = np.clip(np.searchsorted(t, s, side="right") - 1, 0, len(t) - 2)
        ke = np.clip(np.searchsorted(t, e, side="left") - 1, 0, len(t) - 2)
        ke = np.maximum(ke, ks)
        return inside & (self.bad_cum[ke + 1] - self.bad_cum[ks] == 0)


# ---------------------------------------------------------------------------
# Association
# ---------------------------------------------------------------------------
@dataclass
class Association:
    target: np.ndarray  # (n,) index of the associated reference, -1: none
    e_en: np.ndarray  # (n, 2) horizontal error east, north (m), nan when none
    d_alt: np.ndarray  # (n,) altitude error (m)
    vel_en: np.ndarray  # (n, 2) reference ground velocity
    d_fl_ft: np.ndarray
    ref_ident: dict  # item -> (n,) the associated target's value


def associate(refs: list[RefTrack], up: Updates, cfg: Config) -> Association:
    n, m = len(up), len(refs)
    dist = np.full((n, m), np.inf)
    e_all = np.full((n, m, 2), np.nan)
    dalt = np.full((n, m), np.nan)
    vel = np.full((n, m, 2), np.nan)
    dfl = np.full((n, m), np.nan)
    ident = {key: np.full((n, m), None, dtype=object) for key in IDENTITY_ITEMS}
    for j, rt in enumerate(refs):
        ra = rt.at(up.t)
        v = ra.valid
        if not v.any():
            continue
        # The update's point at the reference's altitude, in the local
        # horizontal frame at the reference point.
        x_ref = geodetic_to_ecef(ra.lat[v], ra.lon[v], ra.alt[v])
        x_up = geodetic_to_ecef(up.lat_deg[v], up.lon_deg[v], ra.alt[v])
        r = enu_rotation(ra.lat[v], ra.lon[v])
        e = np.einsum("nij,nj->ni", r, x_up - x_ref)[:, :2]
        e_all[v, j] = e
        dist[v, j] = np.hypot(e[:, 0], e[:, 1])
        if rt.has_alt:
            dalt[v, j] = up.height_m[v] - ra.alt[v]
        vel[v, j] = ra.vel_en[v]
        dfl[v, j] = (up.flight_level[v] - ra.fl[v]) * 100.0
        for key in IDENTITY_ITEMS:
            ident[key][v, j] = ra.ident[key][v]
    cand = dist <= cfg.max_distance_m
    if cfg.max_altitude_diff_m is not None:
        cand &= ~(np.abs(dalt) > cfg.max_altitude_diff_m)  # unknown altitude passes
    if cfg.use_identity:
        for key in IDENTITY_ITEMS:
            mine = getattr(up, key)
            has = np.array([x is not None for x in mine], dtype=bool)
            if not has.any():
                continue
            match = (ident[key] == mine[:, None]) & has[:, None]
            narrowed = cand & match
            rows = narrowed.any(axis=1)
            cand[rows] = narrowed[rows]
    score = np.where(cand, dist, np.inf)
    target = np.full(n, -1)
    if m:
        best = np.argmin(score, axis=1)
        ok = np.isfinite(score[np.arange(n), best])
        target[ok] = best[ok]
    rows = np.flatnonzero(target >= 0)
    cols = target[rows]
    e_en = np.full((n, 2), np.nan)
    e_en[rows] = e_all[rows, cols]
    v_en = np.full((n, 2), np.nan)
    v_en[rows] = vel[rows, cols]
    d_alt = np.full(n, np.nan)
    d_alt[rows] = dalt[rows, cols]
    d_fl = np.full(n, np.nan)
    d_fl[rows] = dfl[rows, cols]
    ref_ident = {}
    for key in IDENTITY_ITEMS:
        col = np.full(n, None, dtype=object)
        col[rows] = ident[key][rows, cols]
        ref_ident[key] = col
    return Association(target, e_en, d_alt, v_en, d_fl, ref_ident)


# ---------------------------------------------------------------------------
# Statistics
# ---------------------------------------------------------------------------
def stats(x, signed: bool = False) -> dict:
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    if len(x) == 0:
        return {"n": 0}
    out = {"n": int(len(x)), "mean": float(np.mean(x)), "median": float(np.median(x)),
           "rms": float(np.sqrt(np.mean(x * x)))}
    if signed:
        out["std"] = float(np.std(x))
        out["p95_abs"] = float(np.percentile(np.abs(x), 95))
    else:
        out["p95"] = float(np.percentile(x, 95))
        out["max"] = float(np.max(x))
    return out


def identity_counts(mine: np.ndarray, theirs: np.ndarray) -> dict:
    """Correct / false / missing of one identity item over updates."""
    c = f = miss = 0
    for a, b in zip(mine, theirs):
        if b is not None:
            if a is None:
                miss += 1
            elif a == b:
                c += 1
            else:
                f += 1
        elif a is not None:
            f += 1  # the update claims an identity the target has not
    n = c + f + miss
    return {"n": n, "correct": c, "false": f, "missing": miss,
            "correct_share": c / n if n else None, "false_share": f / n if n else None,
            "missing_share": miss / n if n else None}


def segments(times: np.ndarray, gap: float) -> list[tuple[float, float]]:
    """[start, end] runs of sorted times, split at gaps over ``gap``."""
    if len(times) == 0:
        return []
    cut = np.flatnonzero(np.diff(times) > gap)
    starts = np.concatenate([[0], cut + 1])
    ends = np.concatenate([cut, [len(times) - 1]])
    return [(float(times[a]), float(times[b])) for a, b in zip(starts, ends)]


# ---------------------------------------------------------------------------
# Evaluation
# ---------------------------------------------------------------------------
def evaluate(references: list[Reference], up: Updates, cfg: Config | None = None) -> dict:
    cfg = cfg or Config()
    refs = [RefTrack(r, cfg.max_ref_gap_s) for r in references]
    asc = associate(refs, up, cfg)
    n = len(up)
    tgt = asc.target
    assoc = tgt >= 0
    speed = np.hypot(asc.vel_en[:, 0], asc.vel_en[:, 1])
    fast = assoc & (speed >= cfg.min_speed_mps)
    with np.errstate(invalid="ignore", divide="ignore"):
        along = np.where(fast, np.einsum("ij,ij->i", asc.e_en, asc.vel_en) / speed, np.nan)
        across = np.where(fast, (asc.vel_en[:, 0] * asc.e_en[:, 1]
                                 - asc.vel_en[:, 1] * asc.e_en[:, 0]) / speed, np.nan)
        implied_latency = np.where(fast, -along / speed, np.nan)
    horiz = np.where(assoc, np.hypot(asc.e_en[:, 0], asc.e_en[:, 1]), np.nan)
    reported_latency = up.t_message - up.t
    has_latency = np.isfinite(reported_latency)

    gap = cfg.break_gap_s
    extra = np.zeros(n, bool)
    per_target = []
    tot_periods = tot_updated = tot_updated_any = 0
    for j, rt in enumerate(refs):
        idx = np.flatnonzero(tgt == j)
        idx = idx[np.lexsort((up.track[idx].astype(str), up.t[idx]))]
        tj = up.t[idx]
        tracks = list(dict.fromkeys(up.track[idx].tolist()))
        # Extra updates: another track's earlier-started segment spans them.
        segs = {}
        for tr in tracks:
            mine = idx[up.track[idx] == tr]
            segs[tr] = segments(up.t[mine], gap)
        order = {tr: k for k, tr in enumerate(sorted(tracks, key=str))}
        for tr in tracks:
            mine = idx[up.track[idx] == tr]
            for s0, s1 in segs[tr]:
                in_seg = mine[(up.t[mine] >= s0) & (up.t[mine] <= s1)]
                for other in tracks:
                    if other == tr:
                        continue
                    for o0, o1 in segs[other]:
                        if o0 < s0 or (o0 == s0 and order[other] < order[tr]):
                            lo, hi = max(s0, o0), min(s1, o1)
                            if lo <= hi:
                                extra[in_seg[(up.t[in_seg] >= lo) & (up.t[in_seg] <= hi)]] = True
        extra_tracks = sorted({str(x) for x in up.track[idx[extra[idx]]]})
        # ID changes along the main (non-extra) sequence.
        main = idx[~extra[idx]]
        seq = up.track[main]
        id_changes = int(sum(a != b for a, b in zip(seq[:-1], seq[1:])))
        # Breaks: gaps over break_s with the reference expected throughout.
        breaks = []
        if len(tj) > 1:
            g = np.flatnonzero(np.diff(tj) > gap)
            if len(g):
                ok = rt.good_span(tj[g], tj[g + 1])
                breaks = [(float(tj[a]), float(tj[a + 1])) for a, o in zip(g, ok) if o]
        # Probability of update.
        p, o = cfg.period_s, cfg.period_origin_s
        k0 = math.ceil((rt.t[0] - o) / p)
        k1 = math.floor((rt.t[-1] - o) / p) - 1
        ks = np.arange(k0, k1 + 1) if k1 >= k0 else np.empty(0, int)
        good = rt.good_span(o + ks * p, o + (ks + 1) * p) if len(ks) else np.empty(0, bool)
        counted = set(ks[good].tolist())

        def periods_hit(mask):
            hit = np.floor((up.t[idx[mask]] - o) / p).astype(int)
            return len(counted & set(hit.tolist()))

        n_upd = periods_hit(up.updated[idx])
        n_any = periods_hit(np.ones(len(idx), bool))
        n_per = len(counted)
        tot_periods += n_per
        tot_updated += n_upd
        tot_updated_any += n_any
        n_pu = n_any if cfg.pu_counts == "any" else n_upd
        ident = {key: identity_counts(getattr(up, key)[idx], asc.ref_ident[key][idx])
                 for key in IDENTITY_ITEMS}
        per_target.append({
            "target": rt.ref.name, "updates": int(len(idx)),
            "measured_updates": int(up.updated[idx].sum()),
            "periods": n_per, "updated_periods": n_pu,
            "pu": n_pu / n_per if n_per else None,
            "pu_any_output": n_any / n_per if n_per else None,
            "tracks": len(tracks), "track_ids": [str(x) for x in tracks],
            "breaks": len(breaks), "break_spans": breaks, "id_changes": id_changes,
            "extra_tracks": len(extra_tracks), "extra_track_ids": extra_tracks,
            "extra_updates": int(extra[idx].sum()),
            "horizontal_m": stats(horiz[idx]),
            "along_m": stats(along[idx], True), "across_m": stats(across[idx], True),
            "altitude_m": stats(asc.d_alt[idx], True),
            "flight_level_ft": stats(asc.d_fl_ft[idx], True),
            "latency_reported_s": stats(reported_latency[idx], True),
            "latency_implied_s": stats(implied_latency[idx], True),
            "identity": ident,
        })

    # Tracks: false ones, target changes.
    track_rows = []
    false_tracks = []
    target_changes = 0
    for tr in dict.fromkeys(up.track.tolist()):
        mine = np.flatnonzero(up.track == tr)
        mine = mine[np.argsort(up.t[mine], kind="stable")]
        share = float(np.mean(assoc[mine]))
        seq = tgt[mine][assoc[mine]]
        changes = int(np.sum(seq[1:] != seq[:-1])) if len(seq) > 1 else 0
        target_changes += changes
        targets = sorted({references[k].name for k in set(seq.tolist())})
        is_false = share < cfg.false_track_share
        if is_false:
            false_tracks.append(str(tr))
        track_rows.append({"track": str(tr), "updates": int(len(mine)),
                           "associated_share": share, "targets": targets,
                           "target_changes": changes, "false": is_false})

    if cfg.duration_s is not None:
        duration = cfg.duration_s
    elif n:
        duration = float(up.t.max() - up.t.min())
    else:
        duration = 0.0
    hours = duration / 3600.0

    def per_hour(x):
        return x / hours if hours > 0 else None

    followed = [r for r in per_target if r["updates"]]
    ident_all = {key: identity_counts(getattr(up, key)[assoc], asc.ref_ident[key][assoc])
                 for key in IDENTITY_ITEMS}
    n_extra_tracks = sum(r["extra_tracks"] for r in per_target)
    n_false_updates = int((~assoc).sum())
    lat_note = (None if has_latency.any() else
                "no message time with the updates: reported latency left out")
    overall = {
        "updates": n, "measured_updates": int(up.updated.sum()),
        "associated_updates": int(assoc.sum()), "tracks": len(track_rows),
        "targets": len(refs), "targets_followed": len(followed),
        "duration_s": duration,
        "probability_of_update": {
            "periods": tot_periods,
            "updated_periods": tot_updated_any if cfg.pu_counts == "any" else tot_updated,
            "pu": ((tot_updated_any if cfg.pu_counts == "any" else tot_updated) / tot_periods
                   if tot_periods else None),
            "pu_any_output": tot_updated_any / tot_periods if tot_periods else None},
        "continuity": {
            "tracks_per_target_mean": (float(np.mean([r["tracks"] for r in followed]))
                                       if followed else None),
            "targets_with_one_track": sum(r["tracks"] == 1 for r in followed),
            "breaks": sum(r["breaks"] for r in per_target),
            "id_changes": sum(r["id_changes"] for r in per_target),
            "track_target_changes": target_changes},
        "position": {"horizontal_m": stats(horiz), "along_m": stats(along, True),
                     "across_m": stats(across, True), "altitude_m": stats(asc.d_alt, True),
                     "flight_level_ft": stats(asc.d_fl_ft, True)},
        # The same over the measured updates alone (coasted outputs left out).
        "position_measured": {"horizontal_m": stats(horiz[up.updated]),
                              "along_m": stats(along[up.updated], True),
                              "across_m": stats(across[up.updated], True),
                              "altitude_m": stats(asc.d_alt[up.updated], True)},
        "latency": {"reported_s": stats(reported_latency[assoc], True),
                    "implied_s": stats(implied_latency, True), "note": lat_note},
        "extra": {"tracks": n_extra_tracks, "updates": int(extra.sum()),
                  "tracks_per_hour": per_hour(n_extra_tracks)},
        "false": {"tracks": len(false_tracks), "track_ids": false_tracks,
                  "updates": n_false_updates,
                  "update_share": n_false_updates / n if n else None,
                  "tracks_per_hour": per_hour(len(false_tracks)),
                  "updates_per_hour": per_hour(n_false_updates)},
        "identity": ident_all,
    }
    return {"config": {**asdict(cfg), "break_s": gap}, "overall": overall,
            "targets": per_target, "tracks": track_rows}


# ---------------------------------------------------------------------------
# Report
# ---------------------------------------------------------------------------
def _f(x, fmt="{:.1f}", none="–"):
    return none if x is None or (isinstance(x, float) and not math.isfinite(x)) else fmt.format(x)


def _pct(x):
    return _f(None if x is None else 100.0 * x, "{:.1f} %")


def _err(s: dict, signed: bool) -> str:
    if not s.get("n"):
        return "–"
    p95 = s["p95_abs"] if signed else s["p95"]
    return (f"{s['mean']:+.1f} / {s['median']:+.1f} / {s['rms']:.1f} / {p95:.1f}" if signed else
            f"{s['mean']:.1f} / {s['median']:.1f} / {s['rms']:.1f} / {p95:.1f}")


def _ident(d: dict) -> str:
    if not d["n"]:
        return "–"
    return (f"{100 * d['correct_share']:.1f} / {100 * d['false_share']:.1f} / "
            f"{100 * d['missing_share']:.1f} % of {d['n']}")


def text_report(res: dict, title: str | None = None, per_target: bool = True) -> str:
    c, o = res["config"], res["overall"]
    pu = o["probability_of_update"]
    cont = o["continuity"]
    pos = o["position"]
    lat = o["latency"]
    vert = ("" if c["max_altitude_diff_m"] is None
            else f", vertical <= {c['max_altitude_diff_m']:g} m")
    out = []
    if title:
        out.append(title)
    out.append(
        f"{o['targets']} targets ({o['targets_followed']} followed), {o['tracks']} tracks, "
        f"{o['updates']} track updates ({o['measured_updates']} measured) over "
        f"{o['duration_s'] / 3600.0:.3f} h; association: horizontal <= {c['max_distance_m']:g} m"
        f"{vert}"
        f"{', identity first' if c['use_identity'] else ''}; PU period {c['period_s']:g} s "
        f"({'any output' if c['pu_counts'] == 'any' else 'measured updates'}); "
        f"break > {c['break_s']:g} s")
    rows = [
        ("probability of update",
         f"{_pct(pu['pu'])} ({pu['updated_periods']} of {pu['periods']} periods; "
         f"any output {_pct(pu['pu_any_output'])})"),
        ("tracks per target", f"{_f(cont['tracks_per_target_mean'], '{:.2f}')} "
                              f"({cont['targets_with_one_track']} of {o['targets_followed']} "
                              f"by one track)"),
        ("track breaks / ID changes", f"{cont['breaks']} / {cont['id_changes']} "
                                      f"(tracks changing target: {cont['track_target_changes']})"),
        ("horizontal error (m) mean/med/RMS/p95", _err(pos["horizontal_m"], False)),
        ("along-track (m) mean/med/RMS/p95|.|", _err(pos["along_m"], True)),
        ("across-track (m) mean/med/RMS/p95|.|", _err(pos["across_m"], True)),
        ("altitude (m) mean/med/RMS/p95|.|", _err(pos["altitude_m"], True)),
        ("measured only: horiz. (m) mean/med/RMS/p95",
         _err(o["position_measured"]["horizontal_m"], False)),
        ("measured only: along, across (m) mean / RMS",
         f"{_f(o['position_measured']['along_m'].get('mean'), '{:+.1f}')} / "
         f"{_f(o['position_measured']['along_m'].get('rms'))}, "
         f"{_f(o['position_measured']['across_m'].get('mean'), '{:+.1f}')} / "
         f"{_f(o['position_measured']['across_m'].get('rms'))}"),
        ("flight level (ft) mean/med/RMS/p95|.|", _err(pos["flight_level_ft"], True)),
        ("latency reported (s) mean/med/RMS/p95|.|",
         _err(lat["reported_s"], True) if lat["reported_s"].get("n") else f"– ({lat['note']})"),
        ("latency implied -along/v (s)", _err(lat["implied_s"], True)),
        ("extra tracks", f"{o['extra']['tracks']} ({o['extra']['updates']} updates), "
                         f"{_f(o['extra']['tracks_per_hour'], '{:.1f}')} /h"),
        ("false tracks", f"{o['false']['tracks']} "
                         f"({_f(o['false']['tracks_per_hour'], '{:.1f}')} /h); "
                         f"false updates {o['false']['updates']} "
                         f"({_pct(o['false']['update_share'])}, "
                         f"{_f(o['false']['updates_per_hour'], '{:.0f}')} /h)"),
        ("identity address ok/false/missing", _ident(o["identity"]["address"])),
        ("identity callsign ok/false/missing", _ident(o["identity"]["callsign"])),
        ("identity Mode 3/A ok/false/missing", _ident(o["identity"]["mode_3a"])),
    ]
    w = max(len(r[0]) for r in rows)
    out += [f"  {a:<{w}}  {b}" for a, b in rows]
    if per_target:
        out.append("")
        out.append("| target | upd | PU | tracks | breaks | ID chg | extra | "
                   "horiz. RMS / p95 (m) | along mean / RMS (m) | across mean / RMS (m) | "
                   "alt. RMS (m) | addr. ok/false/miss % | 3/A ok/false/miss % |")
        out.append("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")

        def short(d):
            if not d["n"]:
                return "–"
            return (f"{100 * d['correct_share']:.0f}/{100 * d['false_share']:.0f}/"
                    f"{100 * d['missing_share']:.0f}")

        for r in res["targets"]:
            h, a, x, z = r["horizontal_m"], r["along_m"], r["across_m"], r["altitude_m"]
            out.append(
                f"| {r['target']} | {r['updates']} | {_pct(r['pu'])} | {r['tracks']} | "
                f"{r['breaks']} | {r['id_changes']} | {r['extra_tracks']} | "
                f"{_f(h.get('rms'))} / {_f(h.get('p95'))} | "
                f"{_f(a.get('mean'), '{:+.1f}')} / {_f(a.get('rms'))} | "
                f"{_f(x.get('mean'), '{:+.1f}')} / {_f(x.get('rms'))} | {_f(z.get('rms'))} | "
                f"{short(r['identity']['address'])} | {short(r['identity']['mode_3a'])} |")
    return "\n".join(out)


def summary_row(name: str, res: dict) -> str:
    """One line of a comparison table (``summary_header``)."""
    o = res["overall"]
    pos = o["position"]

    def g(s, k):
        return _f(s.get(k))

    return (f"| {name} | {_pct(o['probability_of_update']['pu'])} | "
            f"{_f(o['continuity']['tracks_per_target_mean'], '{:.2f}')} | "
            f"{o['continuity']['breaks']} / {o['continuity']['id_changes']} | "
            f"{g(pos['horizontal_m'], 'rms')} / {g(pos['horizontal_m'], 'p95')} | "
            f"{_f(pos['along_m'].get('mean'), '{:+.1f}')} / {g(pos['along_m'], 'rms')} | "
            f"{_f(pos['across_m'].get('mean'), '{:+.1f}')} / {g(pos['across_m'], 'rms')} | "
            f"{g(pos['altitude_m'], 'rms')} | "
            f"{_f(o['latency']['reported_s'].get('median'), '{:.2f}')} / "
            f"{_f(o['latency']['implied_s'].get('mean'), '{:+.2f}')} | "
            f"{o['extra']['tracks']} | {o['false']['tracks']} / {o['false']['updates']} | "
            f"{_pct(o['identity']['address']['correct_share'])} / "
            f"{_pct(o['identity']['mode_3a']['correct_share'])} |")


def summary_header() -> str:
    return ("| system | PU | tracks / target | breaks / ID chg | horiz. RMS / p95 (m) | "
            "along mean / RMS (m) | across mean / RMS (m) | alt. RMS (m) | "
            "latency rep. median / implied mean (s) | extra tracks | false tracks / updates | "
            "address / 3/A correct |\n"
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")


# ---------------------------------------------------------------------------
# Files
# ---------------------------------------------------------------------------
def _pick(row: dict, *names):
    for k in names:
        if k in row and row[k] not in (None, ""):
            return row[k]
    return None


def references_from_rows(rows: Iterable[dict], identity_from_name: bool = False) -> list[Reference]:
    """Rows with target|flight|name, t|t_s, lat_deg|lat, lon_deg|lon,
    height_m|alt_m|altitude_m, and optionally address|mode_s_address|icao24,
    callsign, mode_3a|squawk, flight_level, expected."""
    by: dict[str, list[dict]] = {}
    for r in rows:
        by.setdefault(str(_pick(r, "target", "flight", "name")), []).append(r)
    refs = []
    for name, rs in by.items():
        def num(*keys):
            vals = [_pick(r, *keys) for r in rs]
            if all(v is None for v in vals):
                return None
            return np.array([np.nan if v is None else float(v) for v in vals])

        def ident(*keys):
            vals = [_pick(r, *keys) for r in rs]
            return None if all(v is None for v in vals) else vals

        address, callsign = ident("address", "mode_s_address", "icao24"), ident("callsign")
        if identity_from_name and "/" in name:
            cs, tail = name.split("/", 1)
            if address is None and len(tail) == 6 and all(ch in "0123456789abcdefABCDEF"
                                                          for ch in tail):
                address = tail
            if callsign is None and cs and cs != "?":
                callsign = cs
        exp = [_pick(r, "expected") for r in rs]
        expected = (None if all(v is None for v in exp) else
                    [str(v).strip().lower() in ("1", "true", "yes") if isinstance(v, str)
                     else bool(v) for v in exp])
        refs.append(Reference(name, num("t", "t_s"), num("lat_deg", "lat"), num("lon_deg", "lon"),
                              num("height_m", "alt_m", "altitude_m"), address, callsign,
                              ident("mode_3a", "squawk"), num("flight_level"), expected))
    return refs


def load_references(path: str, identity_from_name: bool = False) -> list[Reference]:
    with open(path) as fh:
        if path.endswith(".csv"):
            return references_from_rows(csv.DictReader(fh), identity_from_name)
        text = fh.read()
    try:
        doc = json.loads(text)
    except json.JSONDecodeError:
        doc = [json.loads(line) for line in text.splitlines() if line.strip()]
    if isinstance(doc, dict):  # {name: {t: [...], lat_deg: [...], ...}}
        return [Reference(name, d["t"], d["lat_deg"], d["lon_deg"],
                          d.get("alt_m", d.get("height_m")),
                          d.get("address"), d.get("callsign"), d.get("mode_3a"),
                          d.get("flight_level"), d.get("expected"))
                for name, d in doc.items()]
    return references_from_rows(doc, identity_from_name)


def load_updates(path: str, origin: Sequence[float] | None = None) -> tuple[Updates, str]:
    with open(path) as fh:
        text = fh.read()
    try:
        doc = json.loads(text)
    except json.JSONDecodeError:
        doc = [json.loads(line) for line in text.splitlines() if line.strip()]
    if isinstance(doc, dict) and "blocks" in doc:
        return updates_from_cat062(doc), "CAT062 (decoded): no reported latency"
    if isinstance(doc, dict) and ("history" in doc or "tracks" in doc):
        return updates_from_response(doc, origin)
    if isinstance(doc, list):
        return (make_updates([record_from_track(tr, None, tr.get("state_layout"))
                              for tr in doc], origin), "track views")
    raise ValueError(f"{path}: not a plot-fusion answer, track views or decoded CAT062")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--reference", required=True, help="CSV, JSON or JSON lines")
    ap.add_argument("--tracks", required=True,
                    help="our plot-fusion answer (JSON), track views (JSON list or lines) "
                         "or decoded CAT062 (cat062_oracle.py decode)")
    ap.add_argument("--origin", help="LAT,LON,HEIGHT of the ENU frame of tracks without lat/lon")
    ap.add_argument("--identity-from-name", action="store_true",
                    help="reference names CALLSIGN/icao24 give callsign and address")
    d = Config()
    ap.add_argument("--max-distance-m", type=float, default=d.max_distance_m)
    ap.add_argument("--max-altitude-diff-m", type=float, default=None)
    ap.add_argument("--max-ref-gap-s", type=float, default=d.max_ref_gap_s)
    ap.add_argument("--period-s", type=float, default=d.period_s)
    ap.add_argument("--period-origin-s", type=float, default=d.period_origin_s)
    ap.add_argument("--pu-counts", choices=("updated", "any"), default=d.pu_counts)
    ap.add_argument("--break-s", type=float, default=None, help="default 3 x --period-s")
    ap.add_argument("--min-speed-mps", type=float, default=d.min_speed_mps)
    ap.add_argument("--false-track-share", type=float, default=d.false_track_share)
    ap.add_argument("--duration-s", type=float, default=None)
    ap.add_argument("--no-identity-association", action="store_true")
    ap.add_argument("--json", action="store_true", help="print the JSON instead of the table")
    ap.add_argument("--json-out", metavar="FILE")
    args = ap.parse_args(argv)
    origin = [float(x) for x in args.origin.split(",")] if args.origin else None
    if origin is not None and len(origin) == 2:
        origin.append(0.0)
    cfg = Config(max_distance_m=args.max_distance_m, max_altitude_diff_m=args.max_altitude_diff_m,
                 max_ref_gap_s=args.max_ref_gap_s, period_s=args.period_s,
                 period_origin_s=args.period_origin_s, pu_counts=args.pu_counts,
                 break_s=args.break_s, min_speed_mps=args.min_speed_mps,
                 false_track_share=args.false_track_share, duration_s=args.duration_s,
                 use_identity=not args.no_identity_association)
    refs = load_references(args.reference, args.identity_from_name)
    updates, note = load_updates(args.tracks, origin)
    res = evaluate(refs, updates, cfg)
    res["input_note"] = note
    if args.json_out:
        with open(args.json_out, "w") as fh:
            json.dump(res, fh, indent=1)
    if args.json:
        json.dump(res, sys.stdout, indent=1)
        print()
    else:
        print(text_report(res, f"ED-87 / COMPASS-style evaluation of {args.tracks} ({note})"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
