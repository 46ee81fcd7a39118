"""Writes the ASTERIX fixture of the decoder and tracker tests.

An independent encoder, libasterix (PyPI, pure Python, generated from the
asterix-specs definitions: CAT048 edition 1.32, CAT034 edition 1.29), builds
a two-radar scene as CAT034 service messages and CAT048 target reports, and
the same library parses the bytes back: the expected values come from its
decoding, never from the Rust code under test.

    bash checks/asterix_fixture.sh       # venv + libasterix, then this script

Scene: radar A (SAC/SIC 25/1, 2D, 4 s scan) and radar B (25/2, 3D with
I048/110 height and I048/120 Doppler, 5 s scan), 40 km apart, three aircraft
at about 3,000 m in straight flight, from 20 s before midnight to 70 s
after (the time of day rolls over). Every scan: a north marker, the target
reports, a sector crossing. Optional items vary record by record: I048/020
with one, two or three octets, I048/070, /090, /130 (compound), /220,
/250 (repetitive, 8 bytes each), /161, SP and RE (explicit length), and a
test target (TST = 1) and a report of an unknown SAC/SIC.

Outputs (checked in): tests/fixtures/asterix/scene.bin (the bytes) and
scene.json (per record: its byte offset, category and decoded values, in
the specification's units and in SI: 1 NM = 1852 m, 1 ft = 0.3048 m); and
scene_biased.bin, the same scene (same noise draws) with radar B's
measured range longer by BIAS_B's 300 m and its azimuth by 0.3 deg, for the
registration test of the UDP listener.
"""
import json
import math
import os
import random

from asterix.base import Bits, RawDatablock
import asterix.generated as gen

Cat034 = gen.Cat_034_1_29
Cat048 = gen.Cat_048_1_32

NM = 1852.0
FT = 0.3048
HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "..", "tests", "fixtures", "asterix")

RADARS = [
    # sac, sic, east, north, period, 3d + doppler, first scan (time of day)
    (25, 1, -20000.0, 0.0, 4.0, False, 86380.0),
    (25, 2, 20000.0, 0.0, 5.0, True, 86381.5),
]
# east, north (m) at tod 86380, velocity (m/s), height (m)
TARGETS = [
    (-15000.0, 30000.0, 120.0, -40.0, 3000.0),
    (10000.0, 45000.0, -90.0, -110.0, 3050.0),
    (0.0, 25000.0, 60.0, 150.0, 2950.0),
]
END_TOD = 86400.0 + 70.0
# Radar B's systematic error in scene_biased.bin: range (m), azimuth (deg).
BIAS_B = (300.0, 0.3)


def position(k, tod):
    e0, n0, ve, vn, h = TARGETS[k]
    dt = tod - 86380.0
    return e0 + ve * dt, n0 + vn * dt, h, ve, vn


def north_marker(sac, sic, tod):
    rec = Cat034.cv_record.create({
        "010": (("SAC", sac), ("SIC", sic)),
        "000": 1,
        "030": (tod % 86400.0, "s"),
        "041": (4.0 if sic == 1 else 5.0, "s"),
    })
    return rec


def sector_crossing(sac, sic, tod, sector_deg):
    return Cat034.cv_record.create({
        "010": (("SAC", sac), ("SIC", sic)),
        "000": 2,
        "030": (tod % 86400.0, "s"),
        "020": (sector_deg, "°"),
        # Compound I034/050 with its COM subfield, skipped by the decoder.
        "050": {"COM": 0},
    })


def target_report(rng, n, sac, sic, tod, rho_m, theta_deg, height_ft, doppler, k, fl):
    items = {
        "010": (("SAC", sac), ("SIC", sic)),
        "140": (tod % 86400.0, "s"),
        "040": (("RHO", (rho_m / NM, "NM")), ("THETA", (theta_deg % 360.0, "°"))),
    }
    # I048/020: one, two or three octets (FX), TST = 0.
    # Extended items are given as the raw bits of each octet's subfields
    # (7 bits, the FX bits are the library's): TYP SIM RDP SPI RAB, then
    # TST ERR XPP ME MI FOE/FRI(2), then ADSB(2) SCN(2) PAI(2) spare.
    ext = n % 3
    typ = 1 if sic == 2 else 2
    sim = 1 if n % 7 == 0 else 0
    first = typ << 4 | sim << 3
    items["020"] = [(first,), (first, 0), (first, 0, 0)][ext]
    if n % 2 == 0:
        items["070"] = (0, 0, 0, 0, ("MODE3A", "%04o" % (0o1200 + k)))
    if n % 3 != 1:
        items["090"] = (("V", 0), ("G", 0), ("FL", (fl, "FL")))
    if n % 4 == 1:
        items["130"] = {"SRL": 3, "SAM": rng.randint(-100, -20), "APD": 1}
    if n % 5 != 2:
        items["220"] = 0x3C0000 + 17 * k
    if n % 4 == 3:
        # Two repetitions of 8 bytes: the repetitive item's rule.
        items["250"] = [(("MBDATA", 0x11223344556677 + n), ("BDS1", 4), ("BDS2", 0)),
                        (("MBDATA", 0x01020304050607), ("BDS1", 5), ("BDS2", 0))]
    if n % 3 == 2:
        items["161"] = (0, ("TRN", 100 + k))
    if height_ft is not None:
        items["110"] = (0, ("3DH", (height_ft, "ft")))
    if doppler is not None:
        items["120"] = {"CAL": (("D", 0), 0, ("CAL", (doppler, "m/s")))}
    if n % 6 == 5:
        items["SP"] = bytes([0xAB, 0xCD, n % 256])
    if n % 8 == 3:
        items["RE"] = bytes([0x01, 0x02])
    return Cat048.cv_record.create(items)


def build(bias_b=(0.0, 0.0)):
    rng = random.Random(19)
    blocks = []  # (tod, bytes)
    n = 0
    for sac, sic, east, north, period, is3d, first in RADARS:
        tod = first
        while tod < END_TOD:
            blocks.append((tod - 0.01, Cat034.create([north_marker(sac, sic, tod - 0.01)])))
            records = []
            for k in range(len(TARGETS)):
                # Each target a little later in the scan, by its azimuth.
                e, nn, h, ve, vn = position(k, tod)
                de, dn = e - east, nn - north
                az = math.degrees(math.atan2(de, dn))
                t_k = tod + (az % 360.0) / 360.0 * period * 0.1
                e, nn, h, ve, vn = position(k, t_k)
                de, dn = e - east, nn - north
                rho = math.sqrt(de * de + dn * dn + h * h) + rng.gauss(0.0, 40.0)
                theta = math.degrees(math.atan2(de, dn)) + rng.gauss(0.0, 0.05)
                height_ft = h / FT + rng.gauss(0.0, 80.0) if is3d else None
                if sic == 2:
                    rho += bias_b[0]
                    theta += bias_b[1]
                dop = None
                if is3d:
                    r3 = math.sqrt(de * de + dn * dn + h * h)
                    dop = round((de * ve + dn * vn) / r3 + rng.gauss(0.0, 1.5))
                records.append(target_report(rng, n, sac, sic, t_k, rho, theta,
                                             height_ft, dop, k, h / FT / 100.0))
                n += 1
            if sic == 1 and abs(tod - 86392.0) < 1e-9:
                # A test target and a report of a radar no request declares.
                records.append(Cat048.cv_record.create({
                    "010": (("SAC", sac), ("SIC", sic)),
                    "140": (tod % 86400.0, "s"),
                    "020": (1 << 4, 1 << 6),
                    "040": (("RHO", (20.0, "NM")), ("THETA", (10.0, "°"))),
                }))
                records.append(Cat048.cv_record.create({
                    "010": (("SAC", 25), ("SIC", 9)),
                    "140": (tod % 86400.0, "s"),
                    "020": (2 << 4,),
                    "040": (("RHO", (30.0, "NM")), ("THETA", (200.0, "°"))),
                }))
            blocks.append((tod, Cat048.create(records)))
            blocks.append((tod + period / 2, Cat034.create(
                [sector_crossing(sac, sic, tod + period / 2, 180.0)])))
            tod += period
    blocks.sort(key=lambda b: b[0])
    return b"".join(db.unparse().to_bytes() for _, db in blocks)


def q(item, name, unit):
    return item.variation.get_item(name).variation.content.as_quantity(unit)


def u(item, name):
    return item.variation.get_item(name).variation.content.as_uint()


def decode(data):
    """The expected values, by libasterix's parser."""
    out = []
    offset = 0
    raw = RawDatablock.parse(Bits.from_bytes(data))
    assert not isinstance(raw, ValueError), raw
    for db in raw:
        cat = db.get_category()
        spec = {34: Cat034, 48: Cat048}[cat]
        records = spec.cv_uap.parse(db.get_raw_records())
        assert not isinstance(records, ValueError), records
        pos = offset + 3
        for rec in records:
            e = {"offset": pos, "category": cat}
            i010 = rec.get_item("010")
            e["sac"], e["sic"] = u(i010, "SAC"), u(i010, "SIC")
            tod_item = rec.get_item("030" if cat == 34 else "140")
            e["time_of_day_s"] = tod_item.variation.content.as_quantity("s")
            if cat == 34:
                e["message_type"] = rec.get_item("000").as_uint()
                i020 = rec.get_item("020")
                e["sector_deg"] = None if i020 is None else i020.variation.content.as_quantity("°")
                i041 = rec.get_item("041")
                e["rotation_period_s"] = (None if i041 is None
                                          else i041.variation.content.as_quantity("s"))
            else:
                i020 = rec.get_item("020")
                e["typ"] = u(i020, "TYP")
                e["sim"] = u(i020, "SIM")
                tst = i020.variation.get_item("TST")
                e["tst"] = None if tst is None else tst.variation.content.as_uint()
                i040 = rec.get_item("040")
                e["rho_nm"] = q(i040, "RHO", "NM")
                e["rho_m"] = e["rho_nm"] * NM
                e["theta_deg"] = q(i040, "THETA", "°")
                i070 = rec.get_item("070")
                e["mode_3a"] = (None if i070 is None else
                                i070.variation.get_item("MODE3A").variation.content.as_string())
                i090 = rec.get_item("090")
                e["flight_level"] = None if i090 is None else q(i090, "FL", "FL")
                i110 = rec.get_item("110")
                e["height_ft"] = None if i110 is None else q(i110, "3DH", "ft")
                e["height_m"] = None if e["height_ft"] is None else e["height_ft"] * FT
                i120 = rec.get_item("120")
                e["doppler_mps"] = None
                if i120 is not None:
                    cal = i120.variation.get_item("CAL")
                    e["doppler_mps"] = cal.variation.get_item("CAL").variation.content.as_quantity("m/s")
                i220 = rec.get_item("220")
                e["aircraft_address"] = None if i220 is None else i220.as_uint()
                i161 = rec.get_item("161")
                e["track_number"] = None if i161 is None else u(i161, "TRN")
            pos += len(rec.unparse().to_bytes())
            out.append(e)
        assert pos == offset + len(db.unparse().to_bytes())
        offset = pos
    assert offset == len(data)
    return out


def main():
    data = build()
    records = decode(data)
    os.makedirs(OUT, exist_ok=True)
    with open(os.path.join(OUT, "scene.bin"), "wb") as f:
        f.write(data)
    with open(os.path.join(OUT, "scene.json"), "w") as f:
        json.dump({
            "generator": "checks/asterix_fixture.py with libasterix "
                         "(Cat_048_1_32, Cat_034_1_29)",
            "radars": [{"sac": r[0], "sic": r[1], "position_m": [r[2], r[3]],
                        "scan_period_s": r[4], "three_d": r[5]} for r in RADARS],
            "records": records,
        }, f, indent=1)
        f.write("\n")
    biased = build(BIAS_B)
    assert len(decode(biased)) == len(records)
    with open(os.path.join(OUT, "scene_biased.bin"), "wb") as f:
        f.write(biased)
    print(f"{len(data)} bytes, {len(records)} records; biased scene {len(biased)} bytes")


if __name__ == "__main__":
    main()
