#!/usr/bin/env python3
"""Ships under a biased coastal radar, with their real AIS: tracks per
vessel, MMSI right, and the radar bias the registration finds against AIS.

The AIS recording is Stone Soup's Solent demo data
(``docs/demos/SolentAIS_20160112_130211.csv`` in the stonesoup 1.9.1 sdist
on PyPI: 84 minutes, 91 vessels off Portsmouth and the Isle of Wight,
decoded position reports with millisecond receive times), fetched by
checks/setup_sea.sh. Each vessel's recorded track (positions linearly
interpolated, gaps over 60 s left unseen) is the truth.

Sensors (one run each, the same data):
  * a simulated coastal radar (2D, primary, 3-s scan, beam-timed plots,
    P_D 0.9, σ 15 m in range and 0.15° in azimuth, 25 km coverage, a few
    clutter plots a scan) that measures **120 m long in range and 0.4°
    clockwise in azimuth** (as seed 004's radars do);
  * the AIS reports, fed either as decoded reports (the service's
    ``cooperative`` list, source ``ais``) or as NMEA 0183 ``!AIVDM`` lines
    encoded by pyais (independent of the service's decoder) with tag blocks
    ``c:<Unix s>`` (the ``nmea`` block). The CSV has no accuracy flag: the
    reports say "worse than 10 m".

Runs (a plot_fusion session each, 10-s batches, defaults but the
initiator's speed band, 0-25 m/s for ships): radar only;
radar + AIS reports; radar + AIS NMEA. Scored at the end and every minute
over the vessels the radar covers: confirmed tracks per vessel (a track is
a vessel's when within 300 m of it), vessels with one track, with none,
with two (a radar duplicate of an AIS track), tracks near no vessel (false),
MMSI right (a track's MMSI is its vessel's), median position error, and
the registration's estimate against the simulated bias.

Usage (a server on --url; checks/.venv-sea from checks/setup_sea.sh):
    checks/.venv-sea/bin/python checks/sea_real_ais.py --minutes 20
"""
from __future__ import annotations

import argparse
import csv
import datetime as dt
import json
import math
import os
import sys
import urllib.request

import numpy as np

A_WGS84 = 6378137.0
F_WGS84 = 1 / 298.257223563
E2 = F_WGS84 * (2 - F_WGS84)
EPOCH = 1_452_600_000.0  # subtracted from Unix times (2016-01-12 12:00 UTC)


def ecef(lat: float, lon: float, h: float = 0.0) -> np.ndarray:
    la, lo = math.radians(lat), math.radians(lon)
    n = A_WGS84 / math.sqrt(1 - E2 * math.sin(la) ** 2)
    return np.array([(n + h) * math.cos(la) * math.cos(lo),
                     (n + h) * math.cos(la) * math.sin(lo),
                     (n * (1 - E2) + h) * math.sin(la)])


class Enu:
    """The local tangent plane at the origin (east, north, up)."""

    def __init__(self, lat: float, lon: float):
        la, lo = math.radians(lat), math.radians(lon)
        self.o = ecef(lat, lon)
        self.r = np.array([
            [-math.sin(lo), math.cos(lo), 0.0],
            [-math.sin(la) * math.cos(lo), -math.sin(la) * math.sin(lo), math.cos(la)],
            [math.cos(la) * math.cos(lo), math.cos(la) * math.sin(lo), math.sin(la)],
        ])

    def __call__(self, lat: float, lon: float) -> np.ndarray:
        return self.r @ (ecef(lat, lon) - self.o)


def load(path: str, minutes: float):
    rows = []
    with open(path) as f:
        for r in csv.DictReader(f):
            t = dt.datetime.fromisoformat(r["Time"]).replace(tzinfo=dt.timezone.utc).timestamp()
            lat, lon = float(r["Latitude_degrees"]), float(r["Longitude_degrees"])
            if not (50.0 < lat < 51.5 and -2.5 < lon < 0.5):
                continue  # a handful of rows lie outside the Solent (bad fixes)
            rows.append((t, int(r["MMSI"]), lat, lon, float(r["COG_degrees"]), float(r["SOG_knots"])))
    rows.sort()
    t0 = rows[0][0]
    return [r for r in rows if r[0] - t0 <= minutes * 60.0], t0


def tracks_of(rows, enu):
    by = {}
    for t, m, lat, lon, *_ in rows:
        by.setdefault(m, []).append((t, *enu(lat, lon)[:2]))
    return {m: np.array(v) for m, v in by.items()}


def truth_at(track: np.ndarray, t: float):
    """The vessel's interpolated position at t, None outside its record or
    across a gap of more than 60 s (600 s for a vessel that moved less than
    50 m across it: moored or at anchor, reporting every 3 minutes)."""
    ts = track[:, 0]
    if t < ts[0] or t > ts[-1]:
        return None
    i = int(np.searchsorted(ts, t))
    if i == 0:
        return track[0, 1:3]
    a, b = track[i - 1], track[i]
    gap = b[0] - a[0]
    if gap > 60.0 and (gap > 600.0 or np.hypot(*(b[1:3] - a[1:3])) > 50.0):
        return None
    w = 0.0 if b[0] == a[0] else (t - a[0]) / (b[0] - a[0])
    return a[1:3] + w * (b[1:3] - a[1:3])


def radar_plots(truths, t0, t1, args, rng):
    plots = []
    scan = t0
    period = 3.0
    while scan < t1:
        for m, tr in truths.items():
            p = truth_at(tr, scan)
            if p is None or np.hypot(*p) > args.coverage_m or rng.random() > 0.9:
                continue
            az = math.atan2(p[0], p[1]) % (2 * math.pi)
            t = scan + period * az / (2 * math.pi)
            p = truth_at(tr, t)
            if p is None:
                continue
            plots.append({"radar_id": "coast", "t": t - EPOCH,
                          "range_m": float(np.hypot(*p) + args.bias_range_m + 15.0 * rng.normal()),
                          "azimuth_deg": float(math.degrees(math.atan2(p[0], p[1]))
                                               + args.bias_azimuth_deg + 0.15 * rng.normal())})
        for _ in range(rng.poisson(args.clutter_per_scan)):
            az = rng.uniform(0, 360)
            plots.append({"radar_id": "coast", "t": scan + period * az / 360.0 - EPOCH,
                          "range_m": float(rng.uniform(500.0, args.coverage_m)),
                          "azimuth_deg": float(az)})
        scan += period
    plots.sort(key=lambda p: p["t"])
    return plots


def nmea_lines(rows):
    from pyais.encode import encode_dict
    out = []
    for t, m, lat, lon, cog, sog in rows:
        c = int(math.floor(t))
        msg = {"type": 1, "mmsi": m, "lat": lat, "lon": lon, "course": cog % 360.0,
               "speed": sog, "accuracy": 0, "second": c % 60, "heading": 511, "status": 0}
        for s in encode_dict(msg, talker_id="AI", radio_channel="A"):
            body = f"c:{c}"
            x = 0
            for ch in body:
                x ^= ord(ch)
            out.append((t, f"\\{body}*{x:02X}\\{s}"))
    return out


def post(url, path, body):
    req = urllib.request.Request(url + path, data=json.dumps(body).encode(),
                                 headers={"content-type": "application/json"})
    with urllib.request.urlopen(req, timeout=600) as r:
        return json.loads(r.read())


def get(url, path):
    with urllib.request.urlopen(url + path, timeout=600) as r:
        return json.loads(r.read())


def score(tracks, truths, t, args):
    """At the end of the data (t): per vessel the radar covers, the
    confirmed tracks within 300 m of it (each track matched to the nearest
    vessel of all those with a position, at the track's own time); tracks
    near no vessel (false); MMSI right (the vessel of the track's MMSI is
    within 300 m of it) or wrong; the matched tracks' errors."""
    def positions(at):
        out = {}
        for m, tr in truths.items():
            p = truth_at(tr, at)
            if p is not None:
                out[m] = p
        return out
    covered = {m for m, p in positions(t).items() if np.hypot(*p) <= args.coverage_m}
    # Under way: moved more than 60 m in the minute around t (2 kn).
    before, after = positions(t - 30.0), positions(t + 30.0)
    under_way = {m for m in covered if m in before and m in after
                 and np.hypot(*(after[m] - before[m])) > 60.0}
    per = {m: [] for m in covered}
    false = 0
    errors = []
    mmsi_right = mmsi_wrong = unscored = 0
    for tk in tracks:
        if tk["status"] != "confirmed":
            continue
        at = tk["t"] + EPOCH
        here = positions(at)
        p = np.array([tk["state"][0], tk["state"][2]])
        mmsi = tk.get("mmsi")
        if mmsi is not None and mmsi in truths and mmsi not in here:
            # Its vessel's recorded track has a gap here: not scored.
            unscored += 1
            continue
        best, d = None, 1e18
        for m, q in here.items():
            e = float(np.hypot(*(p - q)))
            if e < d:
                best, d = m, e
        if best is None or d > 300.0:
            false += 1
            continue
        if best in per:
            per[best].append(tk)
        errors.append(d)
        if mmsi is not None:
            q = here.get(mmsi)
            if q is not None and float(np.hypot(*(p - q))) <= 300.0:
                mmsi_right += 1
            else:
                mmsi_wrong += 1
    counts = [len(v) for v in per.values()]
    moving = [len(per[m]) for m in under_way]
    # Crowded: another vessel within 50 m (moored side by side, rafted).
    now = positions(t)
    crowded = {m for m in covered
               if any(k != m and np.hypot(*(now[k] - now[m])) < 50.0 for k in now)}
    # A radar duplicate: a vessel with a track of its MMSI and another
    # without any MMSI.
    duplicates = sum(1 for m, v in per.items()
                     if any(tk.get("mmsi") == m for tk in v)
                     and any(tk.get("mmsi") is None for tk in v))
    return {
        "crowded": len(crowded),
        "crowded_none": sum(1 for m in crowded if not per[m]),
        "under_way": len(under_way),
        "under_way_one_track": sum(1 for c in moving if c == 1),
        "under_way_none": sum(1 for c in moving if c == 0),
        "vessels": len(covered),
        "one_track": sum(1 for c in counts if c == 1),
        "none": sum(1 for c in counts if c == 0),
        "two_or_more": sum(1 for c in counts if c >= 2),
        "radar_duplicates": duplicates,
        "false_tracks": false,
        "unscored": unscored,
        "mmsi_right": mmsi_right,
        "mmsi_wrong": mmsi_wrong,
        "median_error_m": float(np.median(errors)) if errors else None,
        "p90_error_m": float(np.percentile(errors, 90)) if errors else None,
    }


def run(url, name, plots, ais_rows, lines, t0, t1, args, truths):
    body = {"kind": "plot_fusion",
            "origin": {"lat_deg": args.site[0], "lon_deg": args.site[1], "height_m": 0.0},
            "radars": [{"id": "coast", "kind": "2d",
                        "site": {"lat_deg": args.site[0], "lon_deg": args.site[1], "height_m": 0.0},
                        "sigma_range_m": 15.0, "sigma_azimuth_deg": 0.15, "scan_period_s": 3.0,
                        "p_detection": 0.9, "clutter_density": args.clutter_density}],
            # Ships: the initiator's speed band (default 0-600 m/s, for
            # aircraft) to 0-25 m/s (50 kn), or two moored ships' plots in
            # successive scans start a track between them.
            "tracker": {"initiation": {"v_max_mps": args.v_max_mps}}}
    sid = post(url, "/v1/sessions", body)["id"]
    every = []
    seq = 0
    t = t0
    next_score = t0 + 60.0
    pi = ai = li = 0
    while t < t1:
        end = t + 10.0
        batch = {"sequence": seq + 1, "plots": []}
        while pi < len(plots) and plots[pi]["t"] + EPOCH < end:
            batch["plots"].append(plots[pi])
            pi += 1
        if name == "radar + AIS reports":
            rep = []
            while ai < len(ais_rows) and ais_rows[ai][0] < end:
                tt, m, lat, lon, cog, sog = ais_rows[ai]
                rep.append({"source": "ais", "t": tt - EPOCH, "lat_deg": lat, "lon_deg": lon,
                            "sog_kn": min(sog, 102.2), "cog_deg": cog % 360.0,
                            "position_accurate": False, "mmsi": m})
                ai += 1
            batch["cooperative"] = rep
        if name == "radar + AIS NMEA":
            ls = []
            while li < len(lines) and lines[li][0] < end:
                ls.append(lines[li][1])
                li += 1
            batch["nmea"] = {"lines": ls, "time_offset_s": EPOCH}
        seq += 1
        post(url, f"/v1/sessions/{sid}/batches", batch)
        t = end
        if t >= next_score:
            state = get(url, f"/v1/sessions/{sid}")
            every.append(score(state["plot_fusion"]["tracks"], truths, min(t, t1), args))
            next_score += 60.0
    state = get(url, f"/v1/sessions/{sid}")
    pf = state["plot_fusion"]
    final = every[-1] if every else score(pf["tracks"], truths, t1 - 60.0, args)
    reg = pf.get("registration", [{}])[0]
    return {"final": final, "per_minute": every, "registration": reg,
            "warnings": state.get("warnings", [])[:5]}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--url", default="http://127.0.0.1:18080")
    ap.add_argument("--csv", default=os.path.join(os.path.dirname(os.path.abspath(__file__)),
                                                  ".cache", "SolentAIS_20160112_130211.csv"))
    ap.add_argument("--minutes", type=float, default=20.0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--site", type=float, nargs=2, default=(50.778, -1.089),
                    help="radar site lat lon (default: Southsea, at Portsmouth's harbour "
                         "entrance, where its VTS radar stands)")
    ap.add_argument("--coverage-m", type=float, default=25_000.0)
    ap.add_argument("--bias-range-m", type=float, default=120.0)
    ap.add_argument("--bias-azimuth-deg", type=float, default=0.4)
    ap.add_argument("--clutter-per-scan", type=float, default=3.0)
    ap.add_argument("--v-max-mps", type=float, default=25.0,
                    help="tracker.initiation.v_max_mps (ships: 25 m/s)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    area = math.pi * args.coverage_m ** 2
    args.clutter_density = args.clutter_per_scan / area
    rows, t0 = load(args.csv, args.minutes)
    enu = Enu(*args.site)
    truths = tracks_of(rows, enu)
    t1 = rows[-1][0]
    rng = np.random.default_rng(args.seed)
    plots = radar_plots(truths, t0, t1, args, rng)
    lines = nmea_lines(rows)
    out = {"vessels": len(truths), "ais_reports": len(rows), "nmea_lines": len(lines),
           "radar_plots": len(plots), "minutes": (t1 - t0) / 60.0,
           "bias": [args.bias_range_m, args.bias_azimuth_deg]}
    for name in ("radar only", "radar + AIS reports", "radar + AIS NMEA"):
        out[name] = run(args.url, name, plots, rows, lines, t0, t1, args, truths)
    if args.json:
        print(json.dumps(out, indent=1))
        return 0
    print(f"{out['vessels']} vessels, {out['ais_reports']} AIS reports ({out['nmea_lines']} NMEA lines), "
          f"{out['radar_plots']} radar plots over {out['minutes']:.1f} min; radar bias "
          f"{args.bias_range_m:.0f} m, {args.bias_azimuth_deg:.2f}°")
    print("per minute, averaged over the second half of the data:")
    hdr = ("run", "covered", "one track", "none", "2+", "radar dup.", "under way", "its one track",
           "its none",
           "false", "MMSI right", "MMSI wrong", "median m", "p90 m")
    print(" | ".join(hdr))
    for name in ("radar only", "radar + AIS reports", "radar + AIS NMEA"):
        per = out[name]["per_minute"]
        after = per[len(per) // 2:] if per else []
        n = max(1, len(after))

        def avg(k):
            return sum(x[k] or 0.0 for x in after) / n
        print(f"{name} | {avg('vessels'):.1f} | {avg('one_track'):.1f} | {avg('none'):.1f} | "
              f"{avg('two_or_more'):.1f} | {avg('radar_duplicates'):.1f} | {avg('under_way'):.1f} | "
              f"{avg('under_way_one_track'):.1f} | "
              f"{avg('under_way_none'):.1f} | {avg('false_tracks'):.1f} | {avg('mmsi_right'):.1f} | "
              f"{avg('mmsi_wrong'):.1f} | {avg('median_error_m'):.1f} | {avg('p90_error_m'):.1f}")
    for name in ("radar only", "radar + AIS reports", "radar + AIS NMEA"):
        per = out[name]["per_minute"]
        after = per[len(per) // 2:] or [{"crowded": 0, "crowded_none": 0}]
        print(f"{name}: vessels with another within 50 m "
              f"{sum(x['crowded'] for x in after) / len(after):.1f}, of them without a track "
              f"{sum(x['crowded_none'] for x in after) / len(after):.1f}")
    print("registration at the end (truth: "
          f"{args.bias_range_m:.0f} m, {args.bias_azimuth_deg:.3f}°):")
    for name in ("radar only", "radar + AIS reports", "radar + AIS NMEA"):
        r = out[name]["registration"]
        print(f"{name} | {r.get('range_m', 0):.1f} ± {r.get('sigma_range_m', 0):.1f} m | "
              f"{r.get('azimuth_deg', 0):.3f} ± {r.get('sigma_azimuth_deg', 0):.3f}° | "
              f"{r.get('pairs', 0):.0f} pairs | "
              f"{'converged' if r.get('converged') else 'not converged'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
