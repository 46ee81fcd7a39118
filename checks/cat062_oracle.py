"""Independent check of the CAT062 encoder (crates/wire-formats/src/cat062.rs).

libasterix (PyPI, pure Python, generated from the asterix-specs definitions)
decodes the encoder's bytes with its CAT062 edition 1.20 definition
(Cat_062_1_20) and prints every decoded field as JSON; then the decoded
values are compared, field by field, with the encoder's inputs, with rules
written here from the specification (not from the Rust code): positions
within half an LSB, time within 1/256 s modulo the day, track numbers and
status bits exact, an item absent exactly when its input is out of the
item's range, ages and accuracies above their maximum decoded as the
maximum.

    bash checks/cat062_oracle.sh           # venv + libasterix, then:
    python checks/cat062_oracle.py decode tests/fixtures/cat062/sample.bin
    python checks/cat062_oracle.py compare tests/fixtures/cat062/sample_input.json \
        tests/fixtures/cat062/sample_decoded.json
    python checks/cat062_oracle.py service tests/fixtures/cat062/service_seed001.json \
        tests/fixtures/cat062/service_seed001_decoded.json

`service FIXTURE OUT` decodes a service answer's `cat062` (the fixture holds
the request and the answer, written by `cargo test --test api
regenerate_the_service_cat062_fixtures -- --ignored`), writes the decoding
to OUT and compares each record with the JSON track it stands for, from the
JSON alone (its own WGS-84 geometry for I062/220 and the APW/AGA/ARC
accuracies).

`decode FILE` writes the JSON to stdout: per data block its offset,
category and LEN, per record its offset, length, FSPEC (hex) and items;
each element as {"raw": unsigned bits} plus "value" and "unit" for a
quantity (in the specification's unit: s, °, m, m/s, ft, ft/min, NM),
"table" for a table entry, "string" for a string; an extended item has
"_octets", a compound item its subfields (only those present).
"""
import json
import math
import sys

from asterix.base import (Bits, RawDatablock, Element, Group, Extended,
                          Compound, Repetitive, Explicit, Item,
                          RuleVariationContextFree, RuleContentContextFree,
                          ContentQuantity, ContentTable, ContentString,
                          ContentInteger)
import asterix.generated as gen

SPEC = gen.Cat_062_1_20
FT = 0.3048
# I062/080 PSR/SSR/MDS/ADS: aged beyond this (s), as the service says
# (crates/service/src/plot_fusion/cat062.rs AGED_AFTER_S).
AGED_AFTER_S = 12.0
NM = 1852.0


# --- decode: every field, generically -------------------------------------

def element(v):
    out = {"raw": v.as_uint()}
    rule = v._get_rule()
    if isinstance(rule, RuleContentContextFree):
        content = rule._get_content()
    else:
        content = rule._get_content(None)
    if isinstance(content, ContentQuantity):
        out["value"] = content._as_quantity()
        out["unit"] = content.cv_unit
    elif isinstance(content, ContentTable):
        out["table"] = content.table_value()
    elif isinstance(content, ContentString):
        out["string"] = content.as_string()
    elif isinstance(content, ContentInteger):
        out["integer"] = content.as_integer()
    return out


def nonspare(nsp):
    rule = nsp.arg
    if isinstance(rule, RuleVariationContextFree):
        var = rule.arg
    else:
        var, _ = rule.__class__.cv_default_variation._parse(rule.bs)
    return variation(var)


def variation(v):
    if isinstance(v, Element):
        return element(v)
    if isinstance(v, Group):
        return {i.arg.cv_name: nonspare(i.arg) for i in v.arg if isinstance(i, Item)}
    if isinstance(v, Extended):
        out = {"_octets": len(v.arg)}
        for octet in v.arg:
            for i in octet:
                if isinstance(i, Item):
                    out[i.arg.cv_name] = nonspare(i.arg)
        return out
    if isinstance(v, Compound):
        return {name: nonspare(nsp) for name, nsp in v.arg.items()}
    if isinstance(v, Repetitive):
        return [variation(x) for x in v.arg]
    if isinstance(v, Explicit):
        return {"hex": v.get_bytes().hex()}
    raise TypeError(type(v))


def decode(data):
    raw = RawDatablock.parse(Bits.from_bytes(data))
    if isinstance(raw, ValueError):
        raise SystemExit(f"not ASTERIX data blocks: {raw}")
    blocks = []
    offset = 0
    for db in raw:
        cat = db.get_category()
        if cat != 62:
            raise SystemExit(f"block at {offset}: category {cat}, not 62")
        records = SPEC.cv_uap.parse(db.get_raw_records())
        if isinstance(records, ValueError):
            raise SystemExit(f"block at {offset}: {records}")
        pos = offset + 3
        recs = []
        for rec in records:
            b = rec.unparse().to_bytes()
            n = 0
            while True:
                n += 1
                if not b[n - 1] & 1:
                    break
            recs.append({
                "offset": pos,
                "len": len(b),
                "fspec": b[:n].hex(),
                "items": {name: nonspare(nsp) for name, nsp in rec.items_regular.items()},
            })
            pos += len(b)
        assert pos == offset + db.get_length(), "records do not fill the block"
        blocks.append({"offset": offset, "category": cat, "len": db.get_length(),
                       "records": recs})
        offset = pos
    assert offset == len(data)
    return {"generator": "checks/cat062_oracle.py decode, libasterix 0.36.3 Cat_062_1_20",
            "bytes": len(data), "blocks": blocks}


# --- compare: decoded values against the encoder's inputs -----------------

def rnd(x):
    """Round to nearest, ties away from zero (the encoder's documented rule;
    only used to tell whether a value is in an item's range)."""
    return math.copysign(math.floor(abs(x) + 0.5), x)


def in_range(v, lsb, lo, hi):
    return v is not None and math.isfinite(v) and lo <= rnd(v / lsb) <= hi


class Compare:
    def __init__(self):
        self.fields = 0
        self.mismatches = []

    def fail(self, track, what, msg):
        self.mismatches.append(f"track {track} ({what}): {msg}")

    def get(self, items, path):
        v = items
        for k in path:
            if not isinstance(v, dict) or k not in v:
                return None
            v = v[k]
        return v

    def value(self, track, items, path, want, tol, circular=None):
        """want None: the field must be absent."""
        self.fields += 1
        got = self.get(items, path)
        name = "/".join(path)
        if want is None:
            if got is not None:
                self.fail(track, name, f"decoded {got}, expected absent")
            return
        if got is None:
            self.fail(track, name, f"absent, expected {want}")
            return
        g = got["value"] if "value" in got else got["raw"]
        d = abs(g - want)
        if circular:
            d = d % circular
            d = min(d, circular - d)
        if d > tol * (1 + 1e-9):
            self.fail(track, name, f"decoded {g}, input {want} (|d| = {d} > {tol})")

    def raw(self, track, items, path, want):
        self.fields += 1
        got = self.get(items, path)
        got = None if got is None else got["raw"]
        if got != want:
            self.fail(track, "/".join(path), f"decoded {got}, expected {want}")


def capped(v, lsb, hi):
    """An age or accuracy: absent if negative/missing, else min(v, max)."""
    if v is None or not math.isfinite(v) or rnd(v / lsb) < 0:
        return None
    return min(v, hi * lsb)


def compare(inp, dec):
    c = Compare()
    cfg = inp["config"]
    records = [r for b in dec["blocks"] for r in b["records"]]
    for b in dec["blocks"]:
        if b["len"] > inp["max_block"] and len(b["records"]) > 1:
            c.fail("-", "block", f"block at {b['offset']} of {b['len']} bytes > max_block")
    tracks = inp["tracks"]
    if len(records) != len(tracks):
        c.fail("-", "records", f"{len(records)} records for {len(tracks)} tracks")
    wgs = 180.0 / 2 ** 25
    for i, (t, r) in enumerate(zip(tracks, records)):
        it = r["items"]
        c.raw(i, it, ["010", "SAC"], cfg["sac"])
        c.raw(i, it, ["010", "SIC"], cfg["sic"])
        c.raw(i, it, ["015"], cfg["service_id"])
        c.raw(i, it, ["040"], t["track_number"])
        c.value(i, it, ["070"], t["time_of_day"] % 86400.0, 1 / 256, circular=86400.0)
        # I062/105: LAT in [-90, 90], LON in [-180, 180).
        w = t["wgs84"]
        ok = w is not None and in_range(w[0], wgs, -2 ** 24, 2 ** 24) \
            and in_range(w[1], wgs, -2 ** 25, 2 ** 25 - 1)
        c.value(i, it, ["105", "LAT"], w[0] if ok else None, wgs / 2)
        c.value(i, it, ["105", "LON"], w[1] if ok else None, wgs / 2)
        x, y = t["xy"]
        ok = in_range(x, 0.5, -2 ** 23, 2 ** 23 - 1) and in_range(y, 0.5, -2 ** 23, 2 ** 23 - 1)
        c.value(i, it, ["100", "X"], x if ok else None, 0.25)
        c.value(i, it, ["100", "Y"], y if ok else None, 0.25)
        vx, vy = t["velocity"]
        ok = in_range(vx, 0.25, -32768, 32767) and in_range(vy, 0.25, -32768, 32767)
        c.value(i, it, ["185", "VX"], vx if ok else None, 0.125)
        c.value(i, it, ["185", "VY"], vy if ok else None, 0.125)
        # I062/130 geometric altitude, 6.25 ft, -1500..=150000 ft.
        h = t["height"]
        h_ft = None if h is None else h / FT
        h_ok = h_ft is not None and in_range(h_ft, 6.25, -1500 / 6.25, 150000 / 6.25)
        c.value(i, it, ["130"], h_ft if h_ok else None, 3.125)
        vr = t["vertical_rate"]
        vr_fpm = None if vr is None else vr / FT * 60.0
        ok = vr_fpm is not None and in_range(vr_fpm, 6.25, -32768, 32767)
        c.value(i, it, ["220"], vr_fpm if ok else None, 3.125)
        # I062/080.
        s = t["status"]
        c.raw(i, it, ["080", "MON"], int(s["monosensor"]))
        c.raw(i, it, ["080", "SPI"], int(s["spi"]))
        c.raw(i, it, ["080", "MRH"], int(h_ok))
        c.raw(i, it, ["080", "SRC"], s["altitude_source"] if h_ok else 0)
        c.raw(i, it, ["080", "CNF"], int(s["tentative"]))
        ext1 = s["simulated"] or s["last_message"] or s["first_message"] \
            or s["adsb_inconsistent"]
        ext3 = s["coasting"] or s["psr_aged"] or s["ssr_aged"] or s["mode_s_aged"] \
            or s["adsb_aged"]
        octets = 4 if ext3 else 2 if ext1 else 1
        c.fields += 1
        if it["080"]["_octets"] != octets:
            c.fail(i, "080", f"{it['080']['_octets']} octets, expected {octets}")
        for name, key, octet in [("SIM", "simulated", 2), ("TSE", "last_message", 2),
                                 ("TSB", "first_message", 2), ("AFF", "adsb_inconsistent", 2),
                                 ("CST", "coasting", 4), ("PSR", "psr_aged", 4),
                                 ("SSR", "ssr_aged", 4), ("MDS", "mode_s_aged", 4),
                                 ("ADS", "adsb_aged", 4)]:
            c.raw(i, it, ["080", name], int(s[key]) if octets >= octet else None)
        # Every other bit of I062/080 is 0.
        for name, v in it["080"].items():
            if name not in ("_octets", "MON", "SPI", "MRH", "SRC", "CNF", "SIM", "TSE",
                            "TSB", "AFF", "CST", "PSR", "SSR", "MDS", "ADS"):
                c.fields += 1
                if v["raw"] != 0:
                    c.fail(i, f"080/{name}", f"decoded {v['raw']}, expected 0")
        # I062/290: 1/4 s, 0..=255 LSB, maximum or above; ES (1090 ES
        # ADS-B) and MLT (multilateration) beside TRK, PSR, SSR, MDS.
        a = t["ages"]
        for sub, key in [("TRK", "track"), ("PSR", "psr"), ("SSR", "ssr"), ("MDS", "mode_s"),
                         ("ES", "adsb_es"), ("MLT", "mlat")]:
            c.value(i, it, ["290", sub], capped(a[key], 0.25, 255), 0.125)
        if "290" in it and set(it["290"]) - {"TRK", "PSR", "SSR", "MDS", "ES", "MLT"}:
            c.fail(i, "290", f"unexpected subfields {sorted(it['290'])}")
        # I062/500.
        acc = t["accuracy"] or {}
        pair = lambda k: acc.get(k) or (None, None)  # noqa: E731

        def both(k, lsb, hi, scale=1.0):
            p = pair(k)
            v = [None if q is None else q * scale for q in p]
            cv = [capped(q, lsb, hi) for q in v]
            return cv if None not in cv else [None, None]

        for sub, k, lsb, hi, scale in [("APC", "xy", 0.5, 65535, 1.0),
                                       ("APW", "wgs84", wgs, 65535, 1.0),
                                       ("ATV", "velocity", 0.25, 255, 1.0),
                                       ("AA", "acceleration", 0.25, 255, 1.0)]:
            names = ("LAT", "LON") if sub == "APW" else ("X", "Y")
            vals = both(k, lsb, hi, scale)
            for n, v in zip(names, vals):
                c.value(i, it, ["500", sub, n], v, lsb / 2)
        cov = acc.get("xy_covariance_m2")
        if cov is not None:
            comp = math.copysign(math.sqrt(abs(cov)), cov)
            cov = math.copysign(min(abs(comp), 32767 * 0.5), comp)
        c.value(i, it, ["500", "COV"], cov, 0.25)
        aga = acc.get("geometric_altitude")
        c.value(i, it, ["500", "AGA"], capped(None if aga is None else aga / FT, 6.25, 255), 3.125)
        arc = acc.get("vertical_rate")
        c.value(i, it, ["500", "ARC"],
                capped(None if arc is None else arc / FT * 60.0, 6.25, 255), 3.125)
        c.value(i, it, ["500", "ABA"], None, 0)
        # I062/340.
        m = t["last_measurement"] or {}
        sid = m.get("sensor")
        c.raw(i, it, ["340", "SID", "SAC"], None if sid is None else sid[0])
        c.raw(i, it, ["340", "SID", "SIC"], None if sid is None else sid[1])
        pol = m.get("polar")
        rho_nm = None if pol is None else pol[0] / NM
        ok = pol is not None and in_range(rho_nm, 1 / 256, 0, 65535) and math.isfinite(pol[1])
        c.value(i, it, ["340", "POS", "RHO"], rho_nm if ok else None, 1 / 512)
        c.value(i, it, ["340", "POS", "THETA"], pol[1] % 360.0 if ok else None,
                360 / 2 ** 17, circular=360.0)
        mh = m.get("height")
        mh_ft = None if mh is None else mh / FT
        ok = mh_ft is not None and in_range(mh_ft, 25, -32768, 32767)
        c.value(i, it, ["340", "HEIGHT"], mh_ft if ok else None, 12.5)
        # No item beyond those the encoder writes.
        extra = set(it) - {"010", "015", "070", "105", "100", "185", "040", "080", "290",
                           "130", "220", "500", "340"}
        c.fields += 1
        if extra:
            c.fail(i, "items", f"unexpected items {sorted(extra)}")
    return c


# --- service: a service answer's cat062 against the answer's JSON --------

A_WGS, F_WGS = 6378137.0, 1 / 298.257223563
E2 = F_WGS * (2 - F_WGS)


def geodetic_to_ecef(lat, lon, h):
    n = A_WGS / math.sqrt(1 - E2 * math.sin(lat) ** 2)
    return ((n + h) * math.cos(lat) * math.cos(lon), (n + h) * math.cos(lat) * math.sin(lon),
            (n * (1 - E2) + h) * math.sin(lat))


def ecef_to_geodetic(x, y, z):
    """Iterative (Heiskanen-Moritz); converges to < 1e-12 rad in a few steps."""
    lon = math.atan2(y, x)
    p = math.hypot(x, y)
    lat = math.atan2(z, p * (1 - E2))
    for _ in range(10):
        n = A_WGS / math.sqrt(1 - E2 * math.sin(lat) ** 2)
        h = p / math.cos(lat) - n
        lat = math.atan2(z, p * (1 - E2 * n / (n + h)))
    n = A_WGS / math.sqrt(1 - E2 * math.sin(lat) ** 2)
    return lat, lon, p / math.cos(lat) - n


class Frame:
    """ENU about a WGS-84 origin (degrees, metres)."""

    def __init__(self, lat_deg, lon_deg, h):
        self.lat, self.lon = math.radians(lat_deg), math.radians(lon_deg)
        self.o = geodetic_to_ecef(self.lat, self.lon, h)
        sl, cl = math.sin(self.lat), math.cos(self.lat)
        so, co = math.sin(self.lon), math.cos(self.lon)
        # Rows: east, north, up in ECEF.
        self.r = [(-so, co, 0.0), (-sl * co, -sl * so, cl), (cl * co, cl * so, sl)]

    def geodetic(self, enu):
        x = [self.o[k] + sum(self.r[i][k] * enu[i] for i in range(3)) for k in range(3)]
        lat, lon, h = ecef_to_geodetic(*x)
        return math.degrees(lat), math.degrees(lon), h

    def jacobian(self, enu):
        """d(lat deg, lon deg, h m)/d(e, n, u), central differences of 1 m."""
        j = [[0.0] * 3 for _ in range(3)]
        for k in range(3):
            a, b = list(enu), list(enu)
            a[k] += 1.0
            b[k] -= 1.0
            ga, gb = self.geodetic(a), self.geodetic(b)
            for i in range(3):
                j[i][k] = (ga[i] - gb[i]) / 2.0
        return j


def service_compare(fixture, dec):
    """Checks each record against the JSON track it stands for (the
    fixture's `answer.tracks`, in order), by the rules of
    docs/plot-fusion.md ("CAT062 out"), from the JSON only."""
    c = Compare()
    req, ans = fixture["request"], fixture["answer"]
    cfg = req["cat062"]
    day = cfg.get("day_start_t", 0.0)
    o = req.get("origin")
    frame = Frame(o["lat_deg"], o["lon_deg"], o.get("height_m", 0.0))
    sources = {r["id"]: (r.get("sac"), r.get("sic")) for r in req["radars"]}
    records = [r for b in dec["blocks"] for r in b["records"]]
    tracks = ans["tracks"]
    if len(records) != len(tracks):
        c.fail("-", "records", f"{len(records)} records for {len(tracks)} tracks")
    wgs = 180.0 / 2 ** 25
    for t, r in zip(tracks, records):
        i, it = t["id"], r["items"]
        s, p = t["state"], t["covariance"]
        three_d = len(s) == 6
        c.raw(i, it, ["010", "SAC"], cfg["sac"])
        c.raw(i, it, ["010", "SIC"], cfg["sic"])
        c.raw(i, it, ["015"], cfg.get("service_id"))
        c.raw(i, it, ["040"], t["id"] % 65536)
        c.value(i, it, ["070"], (t["t"] - day) % 86400.0, 1 / 256, circular=86400.0)
        c.value(i, it, ["105", "LAT"], t["lat_deg"], wgs / 2)
        c.value(i, it, ["105", "LON"], t["lon_deg"], wgs / 2)
        c.value(i, it, ["100", "X"], s[0], 0.25)
        c.value(i, it, ["100", "Y"], s[2], 0.25)
        c.value(i, it, ["185", "VX"], s[1], 0.125)
        c.value(i, it, ["185", "VY"], s[3], 0.125)
        enu = [s[0], s[2], s[4] if three_d else 0.0]
        j = frame.jacobian(enu)
        pos = [0, 2, 4] if three_d else [0, 2]
        vel = [1, 3, 5] if three_d else [1, 3]

        def spread(row, ix):
            return math.sqrt(max(0.0, sum(row[a] * p[u][v] * row[b]
                                          for a, u in enumerate(ix) for b, v in enumerate(ix))))

        ident = t.get("identity") or {}
        pa = ident.get("pressure_altitude")
        if three_d:
            c.value(i, it, ["130"], t["height_m"] / FT, 3.125)
        else:
            c.value(i, it, ["130"], None, 0)
        # I062/220: the pressure altitude's rate when the track has one,
        # else the geometric rate of a 3D track.
        if pa is not None:
            c.value(i, it, ["220"], pa["rate_of_climb_ftpm"], 3.125)
        elif three_d:
            rate = sum(j[2][k] * s[vel[k]] for k in range(3))
            c.value(i, it, ["220"], rate / FT * 60.0, 3.125)
        else:
            c.value(i, it, ["220"], None, 0)
        # Identity: I062/060, /245, /380 ADR and ID, /136.
        code = ident.get("mode_3a")
        if code is None:
            c.raw(i, it, ["060", "MODE3A"], None)
        else:
            c.raw(i, it, ["060", "MODE3A"], int(code["value"], 8))
            c.raw(i, it, ["060", "V"], 0)
            c.raw(i, it, ["060", "G"], 0)
            start = t.get("start_t")
            changed = ident.get("pending_mode_3a") is not None or (
                code["first_t"] > (start if start is not None else -math.inf)
                and t["t"] - code["first_t"] <= AGED_AFTER_S)
            c.raw(i, it, ["060", "CH"], int(changed))
        cs = ident.get("callsign")
        want = None if cs is None else cs["value"].ljust(8)
        for path in (["245", "CHR"], ["380", "ID"]):
            c.fields += 1
            got = c.get(it, path)
            got = None if got is None else got.get("string")
            if got != want:
                c.fail(i, "/".join(path), f"decoded {got!r}, expected {want!r}")
        c.raw(i, it, ["245", "STI"], None if cs is None else 0)
        adr = ident.get("mode_s_address")
        c.raw(i, it, ["380", "ADR"], None if adr is None else int(adr["value"], 16))
        c.value(i, it, ["136"], None if pa is None else pa["measured_flight_level"], 0.125)
        c.raw(i, it, ["080", "CNF"], int(t["status"] == "tentative"))
        c.raw(i, it, ["080", "MON"], int(len(req["radars"]) == 1))
        c.raw(i, it, ["080", "MRH"], int(three_d))
        c.raw(i, it, ["080", "SRC"], 2 if three_d else 0)
        def flag(name, on):
            """A bit of an I062/080 extension: as `on` where its octet is
            written, and the octet written where it is set."""
            present = c.get(it, ["080", name]) is not None
            c.raw(i, it, ["080", name], int(on) if present else (1 if on else None))

        flag("CST", t["consecutive_misses"] > 0)
        start = t.get("start_t")
        c.value(i, it, ["290", "TRK"], None if start is None else
                capped(t["t"] - start, 0.25, 255), 0.125)
        # Sources: the radars (by id) first, then the report sensors.
        radar_ids = {r["id"] for r in req["radars"]}
        radar_t, reports, seen = None, {}, set()
        for src in t.get("sources", []):
            name, last = src["sensor"], src["last_t"]
            if name in ("adsb", "mlat", "ais") and (name not in radar_ids or name in seen):
                reports[name] = last
            else:
                radar_t = last if radar_t is None else max(radar_t, last)
            seen.add(name)
        # Ages (I062/290 notes: t of I062/070 minus the last update of the
        # kind; never received, not sent). Radar plots date the identity's
        # primary, secondary and Mode S times. A track no radar's
        # secondary plot updated had primary plots only: with no identity
        # and no report, its last update; with reports, its latest radar.
        def since(last):
            return None if last is None else t["t"] - last

        if ident and ("last_secondary_t" in ident or not reports):
            psr = since(ident.get("last_primary_t"))
        elif not reports:
            psr = since(t["last_update_t"])
        else:
            psr = since(radar_t)
        ages = {"PSR": psr, "SSR": since(ident.get("last_secondary_t")),
                "MDS": since(ident.get("last_mode_s_t")), "ES": since(reports.get("adsb")),
                "MLT": since(reports.get("mlat"))}
        # I062/080 PSR, SSR, MDS, ADS: that kind's update older than the
        # threshold (MLT has no bit the service writes).
        flags = {"PSR": "PSR", "SSR": "SSR", "MDS": "MDS", "ES": "ADS"}
        for sub, a in ages.items():
            c.value(i, it, ["290", sub], capped(a, 0.25, 255), 0.125)
            if sub in flags:
                flag(flags[sub], a is not None and a > AGED_AFTER_S)
        if "290" in it and set(it["290"]) - {"TRK", "PSR", "SSR", "MDS", "ES", "MLT"}:
            c.fail(i, "290", f"unexpected subfields {sorted(it['290'])}")
        # AFF: ADS-B data inconsistent with other surveillance information,
        # while the track distrusts its self-reported positions and ADS-B
        # is among its sources.
        sr = t.get("self_reported") or {}
        flag("AFF", sr.get("trusted") is False and "adsb" in reports)
        # Every other bit of I062/080 is 0 (a batch answer has no first or
        # last message: TSB, TSE 0).
        for name, v in it["080"].items():
            if name not in ("_octets", "MON", "SPI", "MRH", "SRC", "CNF", "AFF", "CST", "PSR",
                            "SSR", "MDS", "ADS"):
                c.fields += 1
                if v["raw"] != 0:
                    c.fail(i, f"080/{name}", f"decoded {v['raw']}, expected 0")
        c.raw(i, it, ["080", "SPI"], int(bool(ident.get("spi"))))
        c.value(i, it, ["500", "APC", "X"], capped(math.sqrt(p[0][0]), 0.5, 65535), 0.25)
        c.value(i, it, ["500", "APC", "Y"], capped(math.sqrt(p[2][2]), 0.5, 65535), 0.25)
        comp = math.copysign(math.sqrt(abs(p[0][2])), p[0][2])
        c.value(i, it, ["500", "COV"], math.copysign(min(abs(comp), 16383.5), comp), 0.25)
        c.value(i, it, ["500", "APW", "LAT"], capped(spread(j[0], pos), wgs, 65535), wgs / 2)
        c.value(i, it, ["500", "APW", "LON"], capped(spread(j[1], pos), wgs, 65535), wgs / 2)
        c.value(i, it, ["500", "ATV", "X"], capped(math.sqrt(p[1][1]), 0.25, 255), 0.125)
        c.value(i, it, ["500", "ATV", "Y"], capped(math.sqrt(p[3][3]), 0.25, 255), 0.125)
        if three_d:
            c.value(i, it, ["500", "AGA"], capped(spread(j[2], pos) / FT, 6.25, 255), 3.125)
            c.value(i, it, ["500", "ARC"],
                    capped(spread(j[2], vel) / FT * 60.0, 6.25, 255), 3.125)
        lp = t.get("last_plot")
        sid = sources.get(lp["radar"]) if lp else None
        sid = sid if sid and sid[0] is not None else None
        c.raw(i, it, ["340", "SID", "SAC"], None if sid is None else sid[0])
        c.raw(i, it, ["340", "SID", "SIC"], None if sid is None else sid[1])
        c.value(i, it, ["340", "POS", "RHO"], None if lp is None else lp["range_m"] / NM,
                1 / 512)
        c.value(i, it, ["340", "POS", "THETA"], None if lp is None else lp["azimuth_deg"],
                360 / 2 ** 17, circular=360.0)
    return c


def main(argv):
    if len(argv) == 3 and argv[0] == "service":
        import base64
        with open(argv[1]) as f:
            fixture = json.load(f)
        dec = decode(base64.b64decode(fixture["answer"]["cat062"]))
        with open(argv[2], "w") as f:
            json.dump(dec, f, indent=1, ensure_ascii=False)
            f.write("\n")
        c = service_compare(fixture, dec)
        n = sum(len(b["records"]) for b in dec["blocks"])
        print(f"{argv[1]}: {len(dec['blocks'])} blocks, {n} records, {c.fields} fields "
              f"compared with the JSON answer, {len(c.mismatches)} mismatches")
        for m in c.mismatches:
            print("MISMATCH", m)
        return 1 if c.mismatches else 0
    if len(argv) == 2 and argv[0] == "decode":
        with open(argv[1], "rb") as f:
            json.dump(decode(f.read()), sys.stdout, indent=1, ensure_ascii=False)
        sys.stdout.write("\n")
    elif len(argv) == 3 and argv[0] == "compare":
        with open(argv[1]) as f:
            inp = json.load(f)
        with open(argv[2]) as f:
            dec = json.load(f)
        c = compare(inp, dec)
        n = sum(len(b["records"]) for b in dec["blocks"])
        print(f"{len(dec['blocks'])} blocks, {n} records, {c.fields} fields compared, "
              f"{len(c.mismatches)} mismatches")
        for m in c.mismatches:
            print("MISMATCH", m)
        return 1 if c.mismatches else 0
    else:
        print(__doc__)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
