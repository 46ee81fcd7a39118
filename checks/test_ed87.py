#!/usr/bin/env python3
"""Tests of checks/ed87.py on synthetic cases whose figures are worked out
by hand (numpy and the standard library only).

    checks/.venv/bin/python checks/test_ed87.py      # or: python3 -m pytest checks/test_ed87.py

The scene: a target flying due east along the parallel of 48.85 N at
100 m/s and 3,000 m, reference samples every second from t = 0 to 80 s.
Track updates are placed with offsets (east, north, up) in the local
horizon of the reference point at their own time, so "30 m north and 10 m
behind" is exact up to the Earth's curvature over 30 m (micrometres).
"""
from __future__ import annotations

import contextlib
import io
import json
import math
import os
import sys
import tempfile

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import ed87  # noqa: E402

LAT0, LON0, H0 = 48.85, 2.45, 3000.0
SPEED = 100.0  # m/s due east
# Metres per degree of longitude on the parallel at the reference height.
M_PER_DEG_LON = ((ed87.A_WGS / math.sqrt(1 - ed87.E2_WGS * math.sin(math.radians(LAT0)) ** 2)
                  + H0) * math.cos(math.radians(LAT0)) * math.pi / 180.0)


def ref_point(t):
    """lat, lon, h of the eastbound target at time t."""
    return LAT0, LON0 + SPEED * t / M_PER_DEG_LON, H0


def reference(name="A", t1=80.0, lat0=LAT0, **kw) -> ed87.Reference:
    t = np.arange(0.0, t1 + 0.5, 1.0)
    lon = LON0 + SPEED * t / M_PER_DEG_LON
    return ed87.Reference(name, t, np.full(len(t), lat0), lon, np.full(len(t), H0), **kw)


def offset(t, east, north, up=0.0, lat=LAT0):
    """The point (east, north, up) m from the target at t, in its local horizon."""
    la, lo, h = ref_point(t)
    la = lat
    p = ed87.enu_to_geodetic(np.array([[east, north, up]]), (la, lo, h))
    return float(p[0][0]), float(p[1][0]), float(p[2][0])


def upd(t, track, east=0.0, north=0.0, up=0.0, lat=LAT0, **kw) -> dict:
    la, lo, h = offset(t, east, north, up, lat)
    return {"t": t, "track": track, "lat_deg": la, "lon_deg": lo, "height_m": h, **kw}


def every4(t0=2.0, t1=78.0):
    """2, 6, 10, ..., 78: one update in each 4-s period [4k, 4k + 4) of 0-80 s."""
    return [t0 + 4.0 * k for k in range(int((t1 - t0) / 4.0) + 1)]


def close(a, b, tol=1e-3):
    assert a is not None and abs(a - b) <= tol, f"{a} != {b} (tol {tol})"


# ---------------------------------------------------------------------------
def test_geodesy_round_trips():
    lat, lon, h = np.array([48.85, -33.9, 0.1]), np.array([2.45, 151.2, -179.9]), \
        np.array([3000.0, 10.0, 11000.0])
    la, lo, hh = ed87.ecef_to_geodetic(ed87.geodetic_to_ecef(lat, lon, h))
    assert np.allclose(la, lat, atol=1e-9) and np.allclose(lo, lon, atol=1e-9)
    assert np.allclose(hh, h, atol=1e-4)
    enu = ed87.geodetic_to_enu(lat[:1], lon[:1], h[:1], (48.0, 2.0, 100.0))
    la, lo, hh = ed87.enu_to_geodetic(enu, (48.0, 2.0, 100.0))
    assert abs(la[0] - 48.85) < 1e-9 and abs(lo[0] - 2.45) < 1e-9 and abs(hh[0] - 3000) < 1e-4


def test_along_across_offset_track():
    # A track 30 m north of the eastbound target and 10 m behind it (west),
    # 50 m above, its message sent 0.5 s after its time of applicability:
    #   along-track  = error . v/|v| = (-10, 30) . (1, 0) = -10 m
    #   across-track = left normal (0, 1) . (-10, 30)     = +30 m (left of an
    #                  eastbound course is north)
    #   horizontal   = sqrt(10^2 + 30^2) = 31.623 m, the same every update, so
    #                  mean = median = RMS = p95 = 31.623
    #   altitude     = +50 m; reported latency 0.5 s;
    #   implied latency = -along / speed = 10 / 100 = 0.1 s.
    recs = [upd(t, 1, east=-10.0, north=30.0, up=50.0, t_message=t + 0.5) for t in every4()]
    res = ed87.evaluate([reference()], ed87.make_updates(recs), ed87.Config(period_s=4.0))
    o = res["overall"]
    assert o["associated_updates"] == 20
    pos = o["position"]
    for k in ("mean", "median", "rms", "p95"):
        close(pos["horizontal_m"][k], math.sqrt(1000.0), 0.01)
    close(pos["along_m"]["mean"], -10.0, 0.01)
    close(pos["along_m"]["rms"], 10.0, 0.01)
    close(pos["across_m"]["mean"], 30.0, 0.01)
    close(pos["across_m"]["p95_abs"], 30.0, 0.01)
    close(pos["altitude_m"]["mean"], 50.0, 0.01)
    # All 20 are measured updates: the measured-only figures are the same.
    close(o["position_measured"]["across_m"]["mean"], 30.0, 0.01)
    assert o["position_measured"]["horizontal_m"]["n"] == 20
    close(o["latency"]["reported_s"]["median"], 0.5, 1e-9)
    close(o["latency"]["implied_s"]["mean"], 0.1, 1e-4)
    # One track, all 20 periods updated.
    close(o["probability_of_update"]["pu"], 1.0)
    assert o["continuity"]["tracks_per_target_mean"] == 1.0
    assert o["false"]["tracks"] == 0 and o["extra"]["tracks"] == 0


def test_westbound_signs():
    # The same offset (30 m north, 10 m west) of a *westbound* target: west
    # is ahead, so along = +10; north is to its right, so across = -30.
    t = np.arange(0.0, 81.0)
    lon = LON0 - SPEED * t / M_PER_DEG_LON
    ref = ed87.Reference("W", t, np.full(len(t), LAT0), lon, np.full(len(t), H0))
    recs = []
    for tk in every4():
        lo = LON0 - SPEED * tk / M_PER_DEG_LON
        p = ed87.enu_to_geodetic(np.array([[-10.0, 30.0, 0.0]]), (LAT0, lo, H0))
        recs.append({"t": tk, "track": 7, "lat_deg": p[0][0], "lon_deg": p[1][0],
                     "height_m": p[2][0]})
    o = ed87.evaluate([ref], ed87.make_updates(recs))["overall"]
    close(o["position"]["along_m"]["mean"], 10.0, 0.01)
    close(o["position"]["across_m"]["mean"], -30.0, 0.01)
    close(o["latency"]["implied_s"]["mean"], -0.1, 1e-4)


def test_probability_of_update_missing_periods():
    # Reference 0-80 s, 4-s periods [0,4), [4,8), ..., [76,80): 20 periods
    # (80 / 4), each with the reference throughout. The track updates once
    # per period (t = 2, 6, ..., 78) but misses the periods of t = 10, 30
    # and 50: 17 of 20 periods updated, PU = 17 / 20 = 85 %.
    # A coasted (extrapolated) output at t = 31 does not count as an update
    # (PU stays 85 %) but counts when every output counts: 18 / 20 = 90 %.
    ts = [t for t in every4() if t not in (10.0, 30.0, 50.0)]
    recs = [upd(t, 1) for t in ts] + [upd(31.0, 1, updated=False)]
    res = ed87.evaluate([reference()], ed87.make_updates(recs), ed87.Config(period_s=4.0))
    pu = res["overall"]["probability_of_update"]
    assert pu["periods"] == 20 and pu["updated_periods"] == 17
    close(pu["pu"], 0.85)
    close(pu["pu_any_output"], 0.90)
    tgt = res["targets"][0]
    close(tgt["pu"], 0.85)
    # Gaps are 8 s (6 -> 14, 26 -> 31 -> 34, 46 -> 54): under the break
    # threshold of 3 x 4 s = 12 s, so no track break.
    assert tgt["breaks"] == 0
    res = ed87.evaluate([reference()], ed87.make_updates(recs),
                        ed87.Config(period_s=4.0, pu_counts="any"))
    close(res["overall"]["probability_of_update"]["pu"], 0.90)


def test_track_break_and_coverage():
    # Updates at 2 ... 78 without 26, 30, 34, 38: a gap 22 -> 42 s = 20 s
    # > 12 s: one break, PU (20 - 4) / 20 = 80 %.
    ts = [t for t in every4() if t not in (26.0, 30.0, 34.0, 38.0)]
    recs = [upd(t, 1) for t in ts]
    res = ed87.evaluate([reference()], ed87.make_updates(recs), ed87.Config(period_s=4.0))
    tgt = res["targets"][0]
    assert tgt["breaks"] == 1 and tgt["break_spans"] == [(22.0, 42.0)]
    close(tgt["pu"], 0.80)
    # The same gap while the target is out of coverage (expected False at
    # the samples 23 to 41 s): no break, and a period is not counted when
    # any of its reference intervals touches an unexpected sample:
    # [20,24) (23 is out), [24,28), ..., [36,40), [40,44) (41 is out) = 6
    # periods left out, 20 - 6 = 14 counted; the updates 2 ... 18 and
    # 46 ... 78 hit all 14 (22 and 42 fall in periods not counted): 100 %.
    t = np.arange(0.0, 81.0)
    expected = ~((t >= 23) & (t <= 41))
    res = ed87.evaluate([reference(expected=expected)], ed87.make_updates(recs),
                        ed87.Config(period_s=4.0))
    tgt = res["targets"][0]
    assert tgt["breaks"] == 0
    assert tgt["periods"] == 14 and tgt["updated_periods"] == 14


def test_extra_track():
    # Track 1 follows the target all along (2 ... 78 s); track 2 starts on
    # the same target at 40.5 s and lasts to 76.5 s (10 updates, 4 s apart)
    # while track 1 goes on: track 1 was there first, so all 10 updates of
    # track 2 are extra: 1 extra track, 10 extra updates; 2 tracks on the
    # target; ID changes 0 (the main sequence is track 1's alone).
    # Over a declared hour: 1 extra track per hour.
    recs = [upd(t, 1, north=20.0) for t in every4()]
    recs += [upd(40.5 + 4.0 * k, 2, north=-20.0) for k in range(10)]
    res = ed87.evaluate([reference()], ed87.make_updates(recs),
                        ed87.Config(period_s=4.0, duration_s=3600.0))
    o, tgt = res["overall"], res["targets"][0]
    assert tgt["tracks"] == 2 and tgt["extra_tracks"] == 1 and tgt["extra_track_ids"] == ["2"]
    assert tgt["extra_updates"] == 10 and tgt["id_changes"] == 0
    assert o["extra"]["tracks"] == 1
    close(o["extra"]["tracks_per_hour"], 1.0)
    close(o["continuity"]["tracks_per_target_mean"], 2.0)
    assert o["false"]["tracks"] == 0


def test_handover_is_an_id_change_not_an_extra():
    # Track 1 from 2 to 38 s, track 2 from 42 to 78 s: no overlap, so no
    # extra track; the main sequence changes number once: 1 ID change; the
    # gap 38 -> 42 s is 4 s: no break; PU still 20 / 20.
    recs = [upd(t, 1) for t in every4(2.0, 38.0)] + [upd(t, 2) for t in every4(42.0, 78.0)]
    res = ed87.evaluate([reference()], ed87.make_updates(recs), ed87.Config(period_s=4.0))
    tgt = res["targets"][0]
    assert tgt["tracks"] == 2 and tgt["extra_tracks"] == 0 and tgt["id_changes"] == 1
    assert tgt["breaks"] == 0
    close(tgt["pu"], 1.0)


def test_false_track():
    # Track 9 is 50 km north of the target, beyond the 2 km bound: its 20
    # updates are associated with no target: 1 false track, 20 false
    # updates of 40 (50 %); over 1,800 s: 2 false tracks per hour and 40
    # false updates per hour. The target's own track 1 is not false.
    recs = [upd(t, 1) for t in every4()] + [upd(t, 9, north=50_000.0) for t in every4()]
    res = ed87.evaluate([reference()], ed87.make_updates(recs),
                        ed87.Config(period_s=4.0, duration_s=1800.0))
    f = res["overall"]["false"]
    assert f["tracks"] == 1 and f["track_ids"] == ["9"] and f["updates"] == 20
    close(f["update_share"], 0.5)
    close(f["tracks_per_hour"], 2.0)
    close(f["updates_per_hour"], 40.0)
    rows = {r["track"]: r for r in res["tracks"]}
    assert rows["9"]["false"] and not rows["1"]["false"]
    close(rows["9"]["associated_share"], 0.0)


def test_reference_gap_is_not_interpolated():
    # Reference samples every second but none between 30 and 61 s: a 31-s
    # gap, over max_ref_gap_s = 30, so not interpolated. The updates at
    # 34 ... 58 (7 of them) have no reference: unassociated (false); the
    # one at 30 s falls on a sample and is associated.
    t = np.concatenate([np.arange(0.0, 30.5), np.arange(61.0, 80.5)])
    lon = LON0 + SPEED * t / M_PER_DEG_LON
    ref = ed87.Reference("A", t, np.full(len(t), LAT0), lon, np.full(len(t), H0))
    recs = [upd(tk, 1) for tk in every4()]
    o = ed87.evaluate([ref], ed87.make_updates(recs), ed87.Config(period_s=4.0))["overall"]
    # every4: 2, 6, ..., 78; inside the hole (30, 61): 34, 38, ..., 58 -> 7.
    assert o["false"]["updates"] == 7
    # Periods: [0,4) ... [24,28) = 7 (the one [28,32) crosses the hole),
    # and [64,68), [68,72), [72,76), [76,80) = 4 ([60,64) starts before
    # sample 61): 11 counted, all updated.
    assert o["probability_of_update"]["periods"] == 11
    close(o["probability_of_update"]["pu"], 1.0)


def test_identity_correct_false_missing():
    # Target: address ABC123, callsign AFR123, Mode 3/A 1234 until t = 40
    # then 4321 (a new code from 40 s on). 20 updates (2 ... 78):
    #   address : 18 right, one wrong (ABC124 at 10 s), one missing (14 s):
    #             correct 18/20 = 90 %, false 5 %, missing 5 %;
    #   callsign: all 20 right;
    #   Mode 3/A: 10 updates before 40 s carry 1234 (right), 42 and 46 s
    #             still carry 1234 (false: the stale code), 50 ... 78 carry
    #             4321 (8, right): 18 right, 2 false = 90 %.
    t = np.arange(0.0, 81.0)
    codes = ["1234" if tk < 40 else "4321" for tk in t]
    ref = reference(address="abc123", callsign="AFR123 ", mode_3a=codes)
    recs = []
    for tk in every4():
        address = {10.0: "ABC124", 14.0: None}.get(tk, "ABC123")
        code = "1234" if tk < 48 else "4321"
        recs.append(upd(tk, 1, address=address, callsign="AFR123", mode_3a=code))
    o = ed87.evaluate([ref], ed87.make_updates(recs))["overall"]
    a, c, m = (o["identity"][k] for k in ("address", "callsign", "mode_3a"))
    assert (a["n"], a["correct"], a["false"], a["missing"]) == (20, 18, 1, 1)
    close(a["correct_share"], 0.90)
    close(a["false_share"], 0.05)
    close(a["missing_share"], 0.05)
    assert (c["correct"], c["false"], c["missing"]) == (20, 0, 0)
    assert (m["correct"], m["false"], m["missing"]) == (18, 2, 0)


def test_identity_in_association_and_address_on_a_target_without_one():
    # Targets A (address AAAAAA) and B (no address, squawking 7000) fly
    # side by side, B 1 km north of A. An update 700 m north of A (300 m
    # from B, so nearer B) carrying A's address goes to A: the address
    # decides among the targets within the 2 km bound (distance to A
    # 700 m). An update 100 m from B carrying address CCCCCC (nobody's)
    # goes to B by distance; B has no address, so that address is false.
    dlat = 1000.0 / 111_200.0  # ~1 km of latitude (exact value irrelevant)
    a = reference("A", address="AAAAAA")
    b = reference("B", lat0=LAT0 + dlat, mode_3a="7000")
    recs = [upd(20.0, 1, north=700.0, address="AAAAAA"),
            upd(20.0, 2, north=-100.0, lat=LAT0 + dlat, address="CCCCCC", mode_3a="7000")]
    res = ed87.evaluate([a, b], ed87.make_updates(recs))
    ta, tb = res["targets"]
    assert ta["updates"] == 1 and tb["updates"] == 1
    close(ta["horizontal_m"]["mean"], 700.0, 0.01)
    assert tb["identity"]["address"]["false"] == 1
    assert tb["identity"]["mode_3a"]["correct"] == 1
    # Without identity in the association, the first update goes to B.
    res = ed87.evaluate([a, b], ed87.make_updates(recs), ed87.Config(use_identity=False))
    assert res["targets"][0]["updates"] == 0 and res["targets"][1]["updates"] == 2


def test_our_json_history():
    # A plot-fusion answer: track 4 updated at 10.0 (listed at instant 10.2)
    # and listed again unchanged at instant 11.0 (the same (id, t): counted
    # once, its message time the first instant: latency 0.2 s); then at
    # 12.0, coasted (last_update_t 10.0): not a measured update. Track 5 has
    # no lat/lon: its position comes from state + state_layout + origin.
    la, lo, h = offset(10.0, 0.0, 0.0)
    origin = (LAT0, LON0, 0.0)
    e = ed87.geodetic_to_enu([la], [lo], [h], origin)[0]

    def track(i, t, last, **kw):
        d = {"id": i, "status": "confirmed", "t": t, "last_update_t": last,
             "state": [e[0], 0.0, e[1], 0.0, e[2], 0.0],
             "identity": {"mode_s_address": {"value": "4CA2D1", "plots": 3},
                          "mode_3a": {"value": "1000"},
                          "pressure_altitude": {"flight_level": 98.4}}}
        d.update(kw)
        return d

    resp = {"state_layout": ["x", "vx", "y", "vy", "z", "vz"],
            "history": [
                {"t": 10.2, "tracks": [track(4, 10.0, 10.0, lat_deg=la, lon_deg=lo, height_m=h),
                                       track(6, 10.0, 10.0, status="tentative")]},
                {"t": 11.0, "tracks": [track(4, 10.0, 10.0, lat_deg=la, lon_deg=lo, height_m=h),
                                       track(5, 11.0, 11.0)]},
                {"t": 12.0, "tracks": [track(4, 12.0, 10.0, lat_deg=la, lon_deg=lo,
                                             height_m=h)]}]}
    up, note = ed87.updates_from_response(resp, origin)
    assert len(up) == 3 and "history" in note
    assert up.track.tolist() == [4, 5, 4]
    assert up.updated.tolist() == [True, True, False]
    close(up.t_message[0] - up.t[0], 0.2, 1e-12)
    assert up.address.tolist() == ["4CA2D1"] * 3 and up.mode_3a[0] == "1000"
    close(up.flight_level[0], 98.4)
    # Track 5's position from its state: the same point as track 4's.
    close(up.lat_deg[1], la, 1e-9)
    close(up.lon_deg[1], lo, 1e-9)
    close(up.height_m[1], h, 1e-4)


def test_cli_csv_and_json():
    # The CLI on a reference CSV (names CALLSIGN/icao24 as
    # real_traffic_vs_stonesoup.py --truth-csv writes them) and track views
    # as JSON lines: the target's identity comes from its name.
    tmp = tempfile.mkdtemp()
    ref_csv = os.path.join(tmp, "ref.csv")
    with open(ref_csv, "w") as fh:
        fh.write("flight,t_s,lat_deg,lon_deg,height_m\n")
        for tk in range(0, 81):
            la, lo, h = ref_point(tk)
            fh.write(f"AFR12/39c4a1,{tk},{la:.9f},{lo:.9f},{h:.2f}\n")
    tracks = os.path.join(tmp, "tracks.jsonl")
    with open(tracks, "w") as fh:
        for tk in every4():
            r = upd(tk, 3, north=30.0)
            fh.write(json.dumps({"id": 3, "t": tk, "lat_deg": r["lat_deg"], "lon_deg": r["lon_deg"],
                                 "height_m": r["height_m"], "mode_s_address": "39C4A1",
                                 "callsign": "AFR12"}) + "\n")
    out = os.path.join(tmp, "res.json")
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        rc = ed87.main(["--reference", ref_csv, "--tracks", tracks, "--identity-from-name",
                        "--period-s", "4", "--json-out", out])
    assert rc == 0
    with open(out) as fh:
        res = json.load(fh)
    o = res["overall"]
    close(o["position"]["across_m"]["mean"], 30.0, 0.01)
    close(o["probability_of_update"]["pu"], 1.0)
    assert o["identity"]["address"]["correct"] == 20
    assert o["identity"]["callsign"]["correct"] == 20
    assert "no message time" in o["latency"]["note"]
    # The text report renders.
    txt = ed87.text_report(res)
    assert "probability of update" in txt and "AFR12/39c4a1" in txt
    assert "probability of update" in printed.getvalue()


def test_cat062_decoded():
    # One record as checks/cat062_oracle.py decode writes it.
    doc = {"blocks": [{"category": 62, "records": [{"items": {
        "070": {"value": 68.0390625}, "040": {"raw": 1},
        "105": {"LAT": {"value": 47.68794357776642}, "LON": {"value": 8.50115954875946}},
        "130": {"value": 10081.25}, "060": {"MODE3A": {"string": "1200"}},
        "380": {"ADR": {"raw": 3932160}}, "136": {"value": 98.5},
        "080": {"CNF": {"raw": 0}, "CST": {"raw": 1}}}}]}]}
    up = ed87.updates_from_cat062(doc)
    assert len(up) == 1 and up.track[0] == 1 and up.address[0] == "3C0000"
    assert up.mode_3a[0] == "1200" and not up.updated[0]
    close(up.height_m[0], 10081.25 * 0.3048, 1e-6)
    close(up.t[0], 68.0390625, 1e-12)


def main() -> int:
    tests = [(k, v) for k, v in sorted(globals().items()) if k.startswith("test_") and callable(v)]
    failed = 0
    for name, fn in tests:
        try:
            fn()
            print(f"ok    {name}")
        except Exception as exc:  # noqa: BLE001 — report every failure
            failed += 1
            import traceback

            traceback.print_exc()
            print(f"FAIL  {name}: {exc}")
    print(f"{len(tests) - failed} passed, {failed} failed")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
