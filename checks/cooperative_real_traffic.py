#!/usr/bin/env python3
"""ADS-B beside Mode S radars on real flights: one track per aircraft,
continuity through ADS-B outages, a spoofed aircraft flagged.

The scene is checks/ssr_real_traffic.py's (real flights of the ``traffic``
package's collections under simulated beam-timed 3D radars, A and B Mode S,
C primary, clutter; two VFR aircraft side by side squawking 7000 without
Mode S and without ADS-B), with each real flight's ADS-B as cooperative
reports (the service's ``cooperative`` list):

  * every second, the recorded trajectory's WGS-84 position and geometric
    height with GNSS-like noise (σ 5 m per axis, half of what NACp 9's
    bound allows: NACp 9 says EPU < 30 m, σ ≤ 12.3 m), its ground velocity
    (noise σ 0.5 m/s, NACv 2), its address, callsign and barometric
    flight level (25 ft);
  * faults: flight 1's ADS-B is **spoofed** 3 km north from 40 % of the
    window on (its stated quality unchanged); flight 2's ADS-B claims NACp
    9 but its positions are **300 m off at random** (σ 300 m per axis);
    flights 3 and 4 have **ADS-B outages** of 90 s in the middle of the
    window, where the radars still see them.

Runs: our tracker with the radars only (SSR and Mode S), and with the
radars and ADS-B. Scored as the parent scripts score (horizontal error,
tracks, false tracks, swaps) and by checks/ed87.py (probability of update,
tracks per aircraft, breaks, along/across-track error, identity); then the
spoof: when the track of the spoofed address distrusts its ADS-B, its
distance from the aircraft after, and the most tracks any address held at
one instant (one aircraft, one track).

Usage (a server on --url; checks/.venv from checks/setup_traffic.sh):
    checks/.venv/bin/python checks/cooperative_real_traffic.py --flights 8 --minutes 5
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
import ssr_real_traffic as ssr  # noqa: E402

FT = 0.3048
GNSS_SIGMA_M = 5.0
VELOCITY_SIGMA_MPS = 0.5
SPOOF_M = 3000.0
BAD_NACP_SIGMA_M = 300.0
OUTAGE_S = 90.0


def enu_axes(lat_deg: float, lon_deg: float) -> np.ndarray:
    """Rows east, north, up of the local frame at a point, in ECEF."""
    la, lo = math.radians(lat_deg), math.radians(lon_deg)
    return np.array([
        [-math.sin(lo), math.cos(lo), 0.0],
        [-math.sin(la) * math.cos(lo), -math.sin(la) * math.sin(lo), math.cos(la)],
        [math.cos(la) * math.cos(lo), math.cos(la) * math.sin(lo), math.sin(la)],
    ])


def adsb_reports(scene, args) -> tuple[list, dict]:
    """The real flights' ADS-B reports (module documentation) and what was
    done to which flight."""
    rng = np.random.default_rng(args.seed + 2000)
    real = [j for j, t in enumerate(scene.truths) if not t.name.endswith("/7000")]
    faults = {"spoofed": real[1], "bad_nacp": real[2], "outage": real[3:5]}
    t_spoof = scene.duration_s * 0.4
    reports = []
    for j in real:
        truth = scene.truths[j]
        ident = ssr.true_identity(scene, j, truth.t0)
        t = math.ceil(truth.t0 * 2.0) / 2.0 + 0.25
        mid = 0.5 * (truth.t0 + truth.t1)
        while t <= truth.t1:
            if j in faults["outage"] and abs(t - mid) < OUTAGE_S / 2:
                t += 1.0
                continue
            ecef = truth.ecef(np.array([t]))[0]
            vel = truth.ecef_velocity(np.array([t]))[0]
            lat, lon, h = (float(v[0]) for v in rt.ecef_to_geodetic(ecef[None, :]))
            axes = enu_axes(lat, lon)
            sigma = BAD_NACP_SIGMA_M if j == faults["bad_nacp"] else GNSS_SIGMA_M
            offset = axes.T @ np.array([rng.normal(0, sigma), rng.normal(0, sigma),
                                        rng.normal(0, GNSS_SIGMA_M)])
            if j == faults["spoofed"] and t >= t_spoof:
                offset = offset + axes[1] * SPOOF_M
            lat, lon, h = (float(v[0]) for v in rt.ecef_to_geodetic((ecef + offset)[None, :]))
            v_enu = axes @ vel
            h_ft = ssr.pressure_altitude_ft(truth, t, args)
            r = {"source": "adsb", "t": t, "lat_deg": lat, "lon_deg": lon,
                 "geometric_height_m": h,
                 "velocity_east_mps": float(v_enu[0] + rng.normal(0, VELOCITY_SIGMA_MPS)),
                 "velocity_north_mps": float(v_enu[1] + rng.normal(0, VELOCITY_SIGMA_MPS)),
                 "nacp": 9, "nacv": 2,
                 "flight_level": round(h_ft / 25.0) * 25.0 / 100.0}
            for k in ("mode_s_address", "callsign"):
                if k in ident:
                    r[k] = ident[k]
            reports.append(r)
            t += 1.0
    info = {
        "spoofed": scene.truths[faults["spoofed"]].name,
        "spoof_from_t": t_spoof,
        "bad_nacp": scene.truths[faults["bad_nacp"]].name,
        "outages": [scene.truths[j].name for j in faults["outage"]],
        "reports": len(reports),
    }
    return reports, info


def spoof_figures(scene, res, info: dict) -> dict:
    """From the answer's history: when the spoofed address's track first
    distrusts its ADS-B, its horizontal distance from the aircraft after,
    and the most confirmed tracks one address held at one instant."""
    address = info["spoofed"].split("/")[1].upper()
    j = next(k for k, t in enumerate(scene.truths) if t.name == info["spoofed"])
    truth = scene.truths[j]
    flagged_t = None
    after = []
    most = 0
    for entry in res.response.get("history") or []:
        per_address: dict = {}
        for tr in entry["tracks"]:
            if tr.get("status", "confirmed") != "confirmed":
                continue
            a = ((tr.get("identity") or {}).get("mode_s_address") or {}).get("value")
            if a is not None:
                per_address[a] = per_address.get(a, 0) + 1
            if a != address:
                continue
            check = tr.get("self_reported") or {}
            if check.get("trusted") is False:
                if flagged_t is None:
                    flagged_t = entry["t"]
                p = scene.origin_frame.enu(truth.ecef(np.array([tr["t"]])))[0]
                after.append(math.hypot(tr["state"][0] - p[0], tr["state"][2] - p[1]))
        most = max([most, *per_address.values()])
    return {
        "address": address,
        "spoof_from_t": info["spoof_from_t"],
        "flagged_t": flagged_t,
        "time_to_flag_s": None if flagged_t is None else flagged_t - info["spoof_from_t"],
        "distance_after_flag_median_m": float(np.median(after)) if after else None,
        "distance_after_flag_p90_m": float(np.percentile(after, 90)) if after else None,
        "most_tracks_of_one_address": most,
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--url", default="http://127.0.0.1:18080")
    ap.add_argument("--collection", default="quickstart", choices=sorted(rt.SCENES))
    ap.add_argument("--flights", type=int, default=8)
    ap.add_argument("--minutes", type=float, default=5.0)
    ap.add_argument("--radars", type=int, default=3, choices=(2, 3))
    ap.add_argument("--clutter", type=float, default=2.0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--max-range-km", type=float, default=200.0)
    ap.add_argument("--cutoff-m", type=float, default=2000.0)
    ap.add_argument("--timeout", type=float, default=900.0)
    ap.add_argument("--pressure-offset-m", type=float, default=0.0)
    ap.add_argument("--pressure-slope", type=float, default=0.0)
    ap.add_argument("--ed87-period-s", type=float, default=5.0)
    ap.add_argument("--json-out")
    args = ap.parse_args()

    scene = ssr.scene_with_pair(args)
    body = ssr.add_ssr(scene, rt.build_request(scene, None), args)
    reports, info = adsb_reports(scene, args)
    print(f"scene: {scene.info['collection']} from {scene.info['window_start_utc']}, "
          f"{scene.info['real_flights']} real flights + 2 VFR (7000, no ADS-B), "
          f"{len(scene.radars)} radars, {len(scene.plots)} plots, {info['reports']} ADS-B "
          f"reports; spoofed {info['spoofed']} from t = {info['spoof_from_t']:.0f} s, "
          f"bad NACp {info['bad_nacp']}, outages {', '.join(info['outages'])}")
    radar_only = rt.run_ours(scene, args.url, None, "ours, radars (SSR and Mode S)",
                             args.timeout, None, body=body)
    fused_body = json.loads(json.dumps(body))
    fused_body["cooperative"] = reports
    fused = rt.run_ours(scene, args.url, None, "ours, radars and ADS-B", args.timeout,
                        None, body=fused_body)
    runs = [fused, radar_only]
    figures = [rt.score(scene, r, args.cutoff_m) for r in runs]
    print()
    print("| tracker | median / p90 horiz. (m) | median / p90 3D (m) | confirmed tracks | "
          "false tracks | missed aircraft | ID swaps |")
    print("|---|---|---|---|---|---|---|")
    for f in figures:
        print(f"| {f['name']} | {f['median_h_m']:.1f} / {f['p90_h_m']:.1f} | "
              f"{f['median_3d_m']:.1f} / {f['p90_3d_m']:.1f} | {f['confirmed_tracks']} | "
              f"{f['false_tracks']} | {f['missed']} | {f['id_swaps']} |")
    spoof = spoof_figures(scene, fused, info)
    print()
    print(f"spoof: {json.dumps(spoof)}")
    for w in fused.extra.get("warnings") or []:
        print(f"  warning: {w}")
    ed87_figures = ssr.ed87_report(scene, runs, args)
    if args.json_out:
        with open(args.json_out, "w") as fh:
            json.dump({"scene": {k: v for k, v in scene.info.items() if k != "squawks"},
                       "faults": info, "trackers": figures, "spoof": spoof,
                       "ed87": ed87_figures}, fh, indent=1, default=str)
    return 0


if __name__ == "__main__":
    sys.exit(main())
