#!/usr/bin/env python3
"""SSR and Mode S on real flights: identity and pressure altitude in our tracker.

The scene is checks/real_traffic_vs_stonesoup.py's (real ADS-B flights of
the ``traffic`` package's collections under simulated beam-timed 3D
radars, pyproj geometry, clutter), with what secondary radars add:

  * radars A and B are Mode S radars: each of their plots carries the
    flight's recorded ICAO address, callsign and squawk (the ``squawk``
    column at the plot's time) and its Mode C flight level, the recorded
    barometric altitude quantised to 25 ft; radar C (with three radars) is
    primary only (no SSR field);
  * 2 % of the Mode S radars' replies have a garbled code (a random bit of
    the 12 flipped): half flagged (G = 1), half not;
  * every third flight changes its code at the middle of the window (a
    sector handover: a new discrete code from then on);
  * two more aircraft fly side by side, 1.5 km apart, a copy of the first
    flight shifted east and west, both squawking 7000 without Mode S (SSR
    Mode A/C only) at the same flight level: identity cannot tell them
    apart, position must.

The same plots go to our service with their SSR fields and without them
(position only, as today's Stone Soup and MATLAB trackers use them), and,
unless ``--ours-only``, to Stone Soup's JPDA tracker (position only) over
``--q-grid``. Scored as the parent script scores (horizontal and 3D
errors, ID swaps: a truth's state sequence changing track), plus for our
tracker with SSR: the states whose track carries the right Mode S address
(of the truth it is assigned to), the wrong one, none; the flight level
error against the recorded barometric altitude (states with a pressure
altitude): share within 50 ft, median, 95th percentile.

``--ed87`` adds checks/ed87.py's surveillance-evaluation measures (ED-87 /
OpenATS COMPASS: probability of update, tracks per target, breaks, ID
changes, along- and across-track error, latency, extra and false tracks,
identity correct / false / missing) of every run (our three, and Stone
Soup's unless --ours-only) against the recorded flights: one summary row
per run, then ours with SSR per flight.

Usage (a server on --url; checks/.venv from checks/setup_traffic.sh):
    checks/.venv/bin/python checks/ssr_real_traffic.py --flights 10 --minutes 6
    checks/.venv/bin/python checks/ssr_real_traffic.py --flights 6 --minutes 4 \
        --ours-only --ed87 [--ed87-period-s 5]
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import real_traffic_vs_stonesoup as rt  # noqa: E402

GARBLE_RATE = 0.02
SIDE_BY_SIDE_M = 1500.0
FT = 0.3048


def side_by_side(truths: list) -> list:
    """Two copies of the first flight, 1.5 km east and west of it."""
    import copy

    base = truths[0]
    t = np.linspace(base.t0, base.t1, 5)
    ecef = base.ecef(t).mean(axis=0)
    lat, lon, _ = rt.ecef_to_geodetic(ecef[None, :])
    la, lo = math.radians(float(lat[0])), math.radians(float(lon[0]))
    east = np.array([-math.sin(lo), math.cos(lo), 0.0])
    out = []
    for sign, tag in ((1.0, "E"), (-1.0, "W")):
        twin = copy.copy(base)
        twin.name = f"VFR{tag}/7000"
        twin.mean = base.mean + sign * SIDE_BY_SIDE_M * east
        out.append(twin)
    _ = la
    return out


def squawk_table(collection: str, truths: list, w0: float) -> dict:
    """Per flight name: (scene times, codes) of its recorded squawks."""
    import importlib

    import pandas as pd

    samples = importlib.import_module("traffic.data.samples")
    wanted = {t.name for t in truths}
    out = {}
    for f in getattr(samples, collection):
        name = f"{f.callsign or '?'}/{f.icao24}"
        if name not in wanted or "squawk" not in f.data.columns:
            continue
        d = f.data.dropna(subset=["squawk"])
        if len(d) == 0:
            continue
        ts = pd.to_datetime(d["timestamp"]).astype("int64").to_numpy() / 1e9 - w0
        codes = [str(s).zfill(4) for s in d["squawk"]]
        ok = [all(c in "01234567" for c in code) and len(code) == 4 for code in codes]
        if any(ok):
            order = np.argsort(ts)
            out[name] = (ts[order][np.array(ok)[order]],
                         [codes[i] for i in order if ok[i]])
    return out


def pressure_altitude_ft(truth, t: float, args) -> float:
    """The pressure altitude (ft) a transponder reports at time t: the
    truth's geometric height H with the atmosphere of --pressure-offset-m A
    and --pressure-slope B taken out, h_p = (H - A) / (1 + B) (the tracker
    models H = h_p + a + b h_p; A = B = 0 by default: the recorded
    barometric altitude is the truth's height)."""
    h = float(rt.ecef_to_geodetic(truth.ecef(np.array([t])))[2][0])
    return (h - args.pressure_offset_m) / (1.0 + args.pressure_slope) / FT


def true_identity(scene, j: int, t: float) -> dict:
    """What truth j's transponder replies at time t, ungarbled: its Mode S
    address and callsign (none for the 7000 pair) and its Mode 3/A code:
    the recorded squawk at t (a made-up discrete code when the flight has
    none recorded), changed at the middle of the window for every third
    real flight."""
    truth = scene.truths[j]
    callsign, icao = truth.name.split("/")
    if icao == "7000":
        return {"mode_3a": "7000"}
    out = {"mode_s_address": icao.upper()}
    cs = callsign.strip().upper()
    if cs and cs != "?" and len(cs) <= 8 and all(c.isalnum() for c in cs):
        out["callsign"] = cs
    code = None
    squawks = scene.info["squawks"]
    if truth.name in squawks:
        ts, codes = squawks[truth.name]
        k = int(np.searchsorted(ts, t, side="right")) - 1
        code = codes[max(k, 0)]
    if code is None:
        code = f"{(j * 97 + 0o1000) % 0o7777:04o}"
    if j % 3 == 0 and j < scene.info["real_flights"] and t >= scene.duration_s / 2.0:
        code = f"{(int(code, 8) + 0o123) % 0o7777:04o}"
    out["mode_3a"] = code
    return out


def add_ssr(scene, body: dict, args) -> dict:
    """The request's plots with the Mode S radars' SSR fields."""
    rng = np.random.default_rng(args.seed + 1000)
    mode_s = {r.id for r in scene.radars[:2]}
    for plot, p in zip(body["plots"], scene.plots):
        if p.truth is None or p.radar not in mode_s:
            continue
        truth = scene.truths[p.truth]
        h_ft = pressure_altitude_ft(truth, p.t, args)
        fields = {"flight_level": round(h_ft / 25.0) * 25.0 / 100.0, "detection": "combined"}
        fields.update(true_identity(scene, p.truth, p.t))
        if "mode_3a" in fields and rng.uniform() < GARBLE_RATE:
            bad = int(fields["mode_3a"], 8) ^ (1 << int(rng.integers(12)))
            fields["mode_3a"] = f"{bad:04o}"
            if rng.uniform() < 0.5:
                fields["mode_3a_garbled"] = True
        plot.update(fields)
    return body


def ed87_references(scene, args) -> list:
    """The truths as checks/ed87.py references: WGS-84 position and height
    on a 1-s grid (and the ends of each flight), expected where at least
    one radar covers the flight, with the identity its transponder replies
    (``true_identity``, ungarbled) and its pressure altitude."""
    import ed87

    refs = []
    for j, truth in enumerate(scene.truths):
        grid = np.unique(np.concatenate([[truth.t0], np.arange(math.ceil(truth.t0),
                                                                math.floor(truth.t1) + 1.0),
                                         [truth.t1]]))
        lat, lon, h = rt.ecef_to_geodetic(truth.ecef(grid))
        ident = [true_identity(scene, j, float(t)) for t in grid]
        fl = (h - args.pressure_offset_m) / (1.0 + args.pressure_slope) / FT / 100.0
        refs.append(ed87.Reference(
            truth.name, grid, lat, lon, h,
            address=[i.get("mode_s_address") for i in ident],
            callsign=[i.get("callsign") for i in ident],
            mode_3a=[i.get("mode_3a") for i in ident],
            flight_level=fl, expected=scene.covered(truth, grid)))
    return refs


def ed87_report(scene, runs: list, args) -> dict:
    """checks/ed87.py's measures of every run against the recorded flights
    (ours from the answer's history; Stone Soup's from its tracks' states,
    without identity): one summary row per run, then the first run's (ours
    with SSR) full table."""
    import ed87

    refs = ed87_references(scene, args)
    cfg = ed87.Config(max_distance_m=args.cutoff_m, period_s=args.ed87_period_s,
                      duration_s=scene.duration_s)
    print()
    print(f"ED-87 / COMPASS-style measures (checks/ed87.py) against the {len(refs)} flights "
          f"(1-s reference, expected where a radar covers them); association within "
          f"{cfg.max_distance_m:g} m horizontally, identity first; PU per {cfg.period_s:g} s; "
          f"track states of the history (each (id, t) once); reported latency = history "
          f"instant - t (0 by construction in the batch call: every state is at its processing "
          f"instant), implied latency = -along-track error / ground speed")
    print()
    print(ed87.summary_header())
    out = {}
    origin = (scene.origin.lat_deg, scene.origin.lon_deg, scene.origin.height_m)
    for res in runs:
        if res.response is not None:
            updates, _ = ed87.updates_from_response(res.response)
        else:  # Stone Soup: its tracks' states in the fusion ENU frame, each (id, t) once
            seen, recs = set(), []
            for k in range(len(res.t)):
                key = (res.ids[k], float(res.t[k]))
                if key not in seen:
                    seen.add(key)
                    recs.append({"t": float(res.t[k]), "track": str(res.ids[k]),
                                 "position_m": res.pos[k].tolist(),
                                 "updated": bool(res.updated[k])})
            updates = ed87.make_updates(recs, origin)
        out[res.name] = ed87.evaluate(refs, updates, cfg)
        print(ed87.summary_row(res.name, out[res.name]))
    print()
    print(ed87.text_report(out[runs[0].name], title=f"{runs[0].name}:"))
    return out


def identity_figures(scene, res, ident: dict, cutoff: float, args) -> dict:
    """Per confirmed state assigned to a truth (Hungarian per instant, as
    the parent's score): right / wrong / no address, flight level error."""
    from scipy.optimize import linear_sum_assignment

    right = wrong = none = no_address_truth = 0
    fl_err, fl_updated = [], []
    last_track: dict = {}
    swaps = {"mode_s": 0, "pair_7000": 0}
    for tk in np.unique(res.t):
        states = np.flatnonzero(res.t == tk)
        live = [j for j, tr in enumerate(scene.truths) if scene.covered(tr, np.array([tk]))[0]]
        if not live:
            continue
        pos = np.array([scene.origin_frame.enu(scene.truths[j].ecef(np.array([tk])))[0]
                        for j in live])
        d = np.linalg.norm(pos[:, None, :] - res.pos[states][None, :, :], axis=2)
        r, c = linear_sum_assignment(np.where(d < cutoff, d, 10 * cutoff))
        for a, b in zip(r, c):
            if d[a, b] >= cutoff:
                continue
            truth = scene.truths[live[a]]
            s = states[b]
            # A swap: the truth's states move from one track to another
            # (a restart counts too).
            kind = "pair_7000" if truth.name.endswith("/7000") else "mode_s"
            tid = int(res.ids[s])
            if last_track.get(live[a], tid) != tid:
                swaps[kind] += 1
                address = ident.get((tid, float(res.t[s])), (None, None))[0]
                print(f"  t {tk:.1f} s: {truth.name} moves from track {last_track[live[a]]} "
                      f"to track {tid} (its address {address})")
            last_track[live[a]] = tid
            address, fl = ident.get((int(res.ids[s]), float(res.t[s])), (None, None))
            icao = truth.name.split("/")[1].upper()
            if icao == "7000":
                no_address_truth += 1
                wrong += address is not None
            elif address is None:
                none += 1
            elif address == icao:
                right += 1
            else:
                wrong += 1
            if fl is not None:
                h_ft = pressure_altitude_ft(truth, float(tk), args)
                fl_err.append(abs(fl * 100.0 - h_ft))
                fl_updated.append(bool(res.updated[s]))
    fl_err = np.asarray(fl_err)
    upd = np.asarray(fl_updated, bool)
    n = right + wrong + none
    return {
        "states_with_address_truth": n,
        "right_address": right, "wrong_address": wrong, "no_address": none,
        "right_share": right / n if n else float("nan"),
        "track_changes_mode_s_truths": swaps["mode_s"],
        "track_changes_7000_pair": swaps["pair_7000"],
        "states_of_7000_pair": no_address_truth,
        "fl_states": int(len(fl_err)),
        "fl_within_50ft": float(np.mean(fl_err <= 50.0)) if len(fl_err) else float("nan"),
        "fl_median_ft": float(np.median(fl_err)) if len(fl_err) else float("nan"),
        "fl_p95_ft": float(np.percentile(fl_err, 95)) if len(fl_err) else float("nan"),
        "fl_updated_states": int(upd.sum()),
        "fl_updated_within_50ft": float(np.mean(fl_err[upd] <= 50.0)) if upd.any() else float("nan"),
        "fl_updated_p95_ft": float(np.percentile(fl_err[upd], 95)) if upd.any() else float("nan"),
    }


def scene_with_pair(args):
    """The parent's scene (``rt.make_scene``) of ``args``' collection,
    flights, minutes, radars, range, seed and clutter, with the recorded
    squawks in its info and the two side-by-side 7000 aircraft added."""
    load = rt.load_truths

    def with_pair(collection, n, minutes, start):
        truths, w0, info = load(collection, n, minutes, start)
        info["real_flights"] = len(truths)
        info["squawks"] = squawk_table(collection, truths, w0)
        return truths + side_by_side(truths), w0, info

    rt.load_truths = with_pair
    try:
        ns = argparse.Namespace(collection=args.collection, radars=args.radars,
                                flights=args.flights, minutes=args.minutes, start=None,
                                max_range_km=args.max_range_km, seed=args.seed,
                                doppler=False, clutter=args.clutter)
        return rt.make_scene(ns)
    finally:
        rt.load_truths = load


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--url", default="http://127.0.0.1:18080")
    ap.add_argument("--collection", default="quickstart", choices=sorted(rt.SCENES))
    ap.add_argument("--flights", type=int, default=10)
    ap.add_argument("--minutes", type=float, default=6.0)
    ap.add_argument("--radars", type=int, default=3, choices=(2, 3))
    ap.add_argument("--clutter", type=float, default=2.0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--max-range-km", type=float, default=200.0)
    ap.add_argument("--cutoff-m", type=float, default=2000.0)
    ap.add_argument("--q-grid", default="1,5")
    ap.add_argument("--ours-only", action="store_true")
    ap.add_argument("--timeout", type=float, default=900.0)
    ap.add_argument("--pressure-offset-m", type=float, default=0.0,
                    help="geometric minus pressure altitude at h_p = 0 (m)")
    ap.add_argument("--pressure-slope", type=float, default=0.0,
                    help="geometric height per pressure altitude beyond 1 (ISA+dT: dT/288)")
    ap.add_argument("--ed87", action="store_true",
                    help="also print checks/ed87.py's measures of our runs (ED-87 / COMPASS)")
    ap.add_argument("--ed87-period-s", type=float, default=5.0,
                    help="the probability of update's period (s)")
    ap.add_argument("--json-out")
    args = ap.parse_args()

    scene = scene_with_pair(args)
    print(f"scene: {scene.info['collection']} from {scene.info['window_start_utc']}, "
          f"{scene.info['real_flights']} real flights + 2 side by side (7000), "
          f"{len(scene.radars)} radars (Mode S: "
          f"{', '.join(r.id for r in scene.radars[:2])}; primary: "
          f"{', '.join(r.id for r in scene.radars[2:]) or 'none'}), {len(scene.plots)} plots, "
          f"recorded squawks for {len(scene.info['squawks'])} flights")
    body = rt.build_request(scene, None)
    plain = json.loads(json.dumps(body))
    ssr = add_ssr(scene, body, args)
    results = []
    ours_ssr = rt.run_ours(scene, args.url, None, "ours, SSR and Mode S (defaults)",
                           args.timeout, None, body=ssr)
    no_height = json.loads(json.dumps(ssr))
    no_height.setdefault("tracker", {})["mode_c_height"] = {"enabled": False}
    ours_no_height = rt.run_ours(scene, args.url, None,
                                 "ours, SSR and Mode S, Mode C not in the height",
                                 args.timeout, None, body=no_height)
    ours_plain = rt.run_ours(scene, args.url, None, "ours, position only (defaults)",
                             args.timeout, None, body=plain)
    ident = ours_ssr.identity
    results += [ours_ssr, ours_no_height, ours_plain]
    if not args.ours_only:
        models = rt.stonesoup_models(scene)
        longest = max(r.period_s for r in scene.radars)
        rt._WORK.update(scene=scene, models=models, delete_after=2.0 * longest,
                        hold=longest + 1.0)
        for q in [float(x) for x in args.q_grid.split(",")]:
            res = rt._stonesoup_job((q, "jpda"))
            print(f"{res.name}: {res.wall_s:.1f} s", flush=True)
            results.append(res)
    figures = [rt.score(scene, r, args.cutoff_m) for r in results]
    idf = identity_figures(scene, ours_ssr, ident, args.cutoff_m, args)
    print()
    print("| tracker | median / p90 horiz. (m) | median / p90 3D (m) | median vertical (m) | "
          "NEES mean / in 95 % band | confirmed tracks | false tracks | missed aircraft | "
          "ID swaps | mean GOSPA (m) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for f in figures:
        print(f"| {f['name']} | {f['median_h_m']:.1f} / {f['p90_h_m']:.1f} | "
              f"{f['median_3d_m']:.1f} / {f['p90_3d_m']:.1f} | {f['median_v_m']:.1f} | "
              f"{f['nees_mean']:.1f} / {100 * f['nees_in_band']:.0f} % | "
              f"{f['confirmed_tracks']} | "
              f"{f['false_tracks']} | {f['missed']} | {f['id_swaps']} | "
              f"{f['mean_gospa_m']:.1f} |")
    print()
    print(f"identity (ours, SSR): {json.dumps(idf)}")
    po = ours_ssr.extra.get("pressure_offset")
    if po:
        print(f"pressure offset learnt: {json.dumps(po)} (simulated: offset "
              f"{args.pressure_offset_m} m, slope {args.pressure_slope})")
    for w in ours_ssr.extra.get("warnings") or []:
        print(f"  warning: {w}")
    ed87_figures = ed87_report(scene, results, args) if args.ed87 else None
    if args.json_out:
        with open(args.json_out, "w") as fh:
            json.dump({"scene": {k: v for k, v in scene.info.items() if k != "squawks"},
                       "trackers": figures, "identity": idf, "ed87": ed87_figures},
                      fh, indent=1, default=str)
    return 0


if __name__ == "__main__":
    sys.exit(main())
