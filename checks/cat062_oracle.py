"""Independent check of the CAT062 encoder (crates/formats/src/cat062.rs).

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
        ext1 = s["simulated"] or s["last_message"] or s["first_message"]
        ext3 = s["coasting"] or s["psr_aged"] or s["ssr_aged"] or s["mode_s_aged"]
        octets = 4 if ext3 else 2 if ext1 else 1
        c.fields += 1
        if it["080"]["_octets"] != octets:
            c.fail(i, "080", f"{it['080']['_octets']} octets, expected {octets}")
        for name, key, octet in [("SIM", "simulated", 2), ("TSE", "last_message", 2),
                                 ("TSB", "first_message", 2), ("CST", "coasting", 4),
                                 ("PSR", "psr_aged", 4), ("SSR", "ssr_aged", 4),
                                 ("MDS", "mode_s_aged", 4)]:
            c.raw(i, it, ["080", name], int(s[key]) if octets >= octet else None)
        # Every other bit of I062/080 is 0.
        for name, v in it["080"].items():
            if name not in ("_octets", "MON", "SPI", "MRH", "SRC", "CNF", "SIM", "TSE",
                            "TSB", "CST", "PSR", "SSR", "MDS"):
                c.fields += 1
                if v["raw"] != 0:
                    c.fail(i, f"080/{name}", f"decoded {v['raw']}, expected 0")
        # I062/290: 1/4 s, 0..=255 LSB, maximum or above.
        a = t["ages"]
        for sub, key in [("TRK", "track"), ("PSR", "psr"), ("SSR", "ssr"), ("MDS", "mode_s")]:
            c.value(i, it, ["290", sub], capped(a[key], 0.25, 255), 0.125)
        if "290" in it and set(it["290"]) - {"TRK", "PSR", "SSR", "MDS"}:
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


def main(argv):
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
