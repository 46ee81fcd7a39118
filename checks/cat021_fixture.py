"""Writes the CAT021/CAT020 fixtures of the cooperative-report decoders.

An independent encoder, libasterix (PyPI, pure Python, generated from the
asterix-specs definitions: CAT021 edition 2.7, CAT020 edition 1.11, and
CAT048 1.32 / CAT034 1.29 for the mixed datagram), builds ADS-B and
multilateration target reports that exercise every item the Rust decoder
reads and, around them, items it only skips (I021/110 compound with a
repetitive subfield, /220 and /295 compound, /250 repetitive, /271
extended, RE and SP explicit; I020/170 and /030 extended, /400 and /250
repetitive, RE and SP). The same library parses the bytes back: the
expected values come from its decoding, converted to SI here (1 ft =
0.3048 m, 1 NM = 1852 m, 1 kt = 1852/3600 m/s), never from the Rust code
under test. Derived values are computed here independently: the full
high-precision reception time (I021/073 whole seconds moved by FSI, plus
the I021/074 fraction, wrapped at midnight), the east/north velocity of
I021/160 (gs·sin θ, gs·cos θ) and the σ of NACp (DO-260B's EPU table /
sqrt(-2 ln 0.05)).

    bash checks/cat021_fixture.sh       # venv + libasterix, then this script

Outputs (checked in), in tests/fixtures/cat021/: adsb.bin (CAT021 blocks),
mlat.bin (CAT020 blocks), mixed.bin (one datagram of CAT048, CAT034,
CAT021 and CAT020 blocks), and expected.json (per file, per record: byte
offset, category and decoded values).
"""
import json
import math
import os

from asterix.base import Bits, RawDatablock
import asterix.generated as gen

Cat021 = gen.Cat_021_2_7
Cat020 = gen.Cat_020_1_11
Cat048 = gen.Cat_048_1_32
Cat034 = gen.Cat_034_1_29

FT = 0.3048
NM = 1852.0
KT = NM / 3600.0
HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "..", "tests", "fixtures", "cat021")

# DO-260B / ED-102A: NACp -> EPU (95 % horizontal bound, m).
NACP_EPU_M = {11: 3.0, 10: 10.0, 9: 30.0, 8: 0.05 * NM, 7: 0.1 * NM, 6: 0.3 * NM,
              5: 0.5 * NM, 4: 1.0 * NM, 3: 2.0 * NM, 2: 4.0 * NM, 1: 10.0 * NM}
K95 = math.sqrt(-2.0 * math.log(0.05))


def bits(*fields):
    """An octet of an extended item from (value, width) pairs, MSB first,
    7 bits in all (the FX bit is the library's)."""
    v, n = 0, 0
    for value, width in fields:
        v = v << width | value
        n += width
    assert n == 7, n
    return v


# ---------------------------------------------------------------- CAT021


def adsb_full():
    """Every item of the 2.7 UAP."""
    return {
        "010": (("SAC", 30), ("SIC", 7)),
        # ATP 0, ARC 1 (100 ft), RC 1, RAB 0 | DCR 1, GBS 0, SIM 0, TST 0,
        # SAA 1, CL 1 | spare, LLC 1, IPC 0, NOGO 1, CPR 0, LDPJ 1, RCF 0.
        "040": (bits((0, 3), (1, 2), (1, 1), (0, 1)),
                bits((1, 1), (0, 1), (0, 1), (0, 1), (1, 1), (1, 2)),
                bits((0, 1), (1, 1), (0, 1), (1, 1), (0, 1), (1, 1), (0, 1))),
        "161": (0, ("TRNUM", 0xABC)),
        "015": 3,
        "071": (43210.0078125, "s"),
        "130": (("LAT", (47.123456, "°")), ("LON", (8.654321, "°"))),
        "131": (("LAT", (47.1234567891, "°")), ("LON", (8.6543219876, "°"))),
        "072": (43210.25, "s"),
        "150": (("IM", 0), ("AS", ([0], (0.0702, "NM/s")))),
        "151": (("RE", 0), ("TAS", (452.0, "kt"))),
        "080": 0x4B1A2C,
        "073": (43210.5, "s"),
        "074": (("FSI", 0), ("TOMRP", (0.4321, "s"))),
        "075": (43210.75, "s"),
        "076": (("FSI", 1), ("TOMRP", (0.0625, "s"))),
        "140": (35125.0, "ft"),
        # NACv 2, NIC 8 | NIC baro 1, SIL 3, NACp 9 | spare, SILS 1, SDA 2,
        # GVA 2 | PIC 10, SRC 1, spare.
        "090": (bits((2, 3), (8, 4)),
                bits((1, 1), (3, 2), (9, 4)),
                bits((0, 2), (1, 1), (2, 2), (2, 2)),
                bits((10, 4), (1, 1), (0, 2))),
        "210": (0, ("VNS", 0), ("VN", 2), ("LTT", 2)),
        "070": (0, ("MODE3A", "7421")),
        "230": (-12.5, "°"),
        "145": (350.25, "FL"),
        "152": (123.0, "°"),
        "200": (("ICF", 0), ("LNAV", 1), ("ME", 0), ("PS", 3), ("SS", 2)),
        "155": (("RE", 0), ("BVR", (-1200.0, "ft/min"))),
        "157": (("RE", 0), ("GVR", (1587.5, "ft/min"))),
        "160": (("RE", 0), ("GS", (0.125, "NM/s")), ("TA", (237.5, "°"))),
        "165": (0, ("TAR", (1.5, "°/s"))),
        "077": (43211.0, "s"),
        "170": "SWR123  ",
        "020": 3,
        "220": {"WS": 45, "WD": 270, "TMP": (-52.25, "°C"), "TRB": 2},
        "146": (("SAS", 1), ("S", 2), ("ALT", (35000.0, "ft"))),
        "148": (("MV", 0), ("AH", 1), ("AM", 0), ("ALT", (35000.0, "ft"))),
        # TIS one octet; TID two points of 15 bytes each.
        "110": {"TIS": (bits((0, 1), (0, 1), (0, 5)),),
                "TID": [0x0102030405060708090A0B0C0D0E0F,
                        0x1112131415161718191A1B1C1D1E1F]},
        "016": (2.5, "s"),
        "008": (("RA", 0), ("TC", 1), ("TS", 1), ("ARV", 0), ("CDTIA", 1),
                ("NOTTCAS", 0), ("SA", 0)),
        "271": (bits((0, 2), (1, 1), (0, 1), (0, 1), (1, 1), (0, 1)),
                bits((5, 4), (0, 3))),
        "132": (-70.0, "dBm"),
        "250": [0x2010203040506070, 0x4011223344556677, 0x6099AABBCCDDEEFF],
        "260": (("TYP", 28), ("STYP", 2), ("ARA", 0x1234), ("RAC", 5), ("RAT", 0),
                ("MTE", 1), ("TTI", 1), ("TID", 0x2ABCDEF)),
        "400": 4,
        "295": {"AOS": 12, "TRD": 1, "QI": 3, "GH": 2, "FL": 1, "GV": 4, "TI2": 9,
                "SCC": 30},
        "RE": bytes([0x80, 0x11, 0x22, 0x33]),
        "SP": bytes([0xAB, 0xCD]),
    }


def adsb_records():
    recs = [adsb_full()]
    # Southern and western, negative heights and rates, Mach, RE bits,
    # FSI 2 across midnight, one-octet descriptor and quality.
    recs.append({
        "010": (("SAC", 30), ("SIC", 7)),
        "040": (bits((3, 3), (0, 2), (0, 1), (0, 1)),),
        "071": (0.25, "s"),
        "130": (("LAT", (-33.9425, "°")), ("LON", (-118.4081, "°"))),
        "150": (("IM", 1), ("AS", ([1], (0.785, "Mach")))),
        "151": (("RE", 1), ("TAS", (32767.0, "kt"))),
        "080": 0xA1B2C3,
        "073": (0.5, "s"),
        "074": (("FSI", 2), ("TOMRP", (0.9, "s"))),
        "140": (-1250.0, "ft"),
        "090": (bits((4, 3), (11, 4)),),
        "145": (-10.0, "FL"),
        "155": (("RE", 1), ("BVR", (-3200.0, "ft/min"))),
        "157": (("RE", 0), ("GVR", (-750.0, "ft/min"))),
        "160": (("RE", 1), ("GS", (1.9999, "NM/s")), ("TA", (359.99, "°"))),
        "170": "A1      ",
        "RE": bytes([0x01]),
    })
    # "Greater than" geometric height, simulated test target on the
    # ground, no 071 (reception time stands in), NACp 11.
    recs.append({
        "010": (("SAC", 30), ("SIC", 8)),
        "040": (bits((2, 3), (2, 2), (0, 1), (1, 1)),
                bits((0, 1), (1, 1), (1, 1), (1, 1), (0, 1), (2, 2))),
        "161": (0, ("TRNUM", 7)),
        "131": (("LAT", (-0.0000001, "°")), ("LON", (179.9999999, "°"))),
        "080": 0x000001,
        "073": (86399.9921875, "s"),
        "074": (("FSI", 1), ("TOMRP", (0.125, "s"))),
        "140": 0x7FFF,
        "090": (bits((1, 3), (7, 4)), bits((0, 1), (1, 2), (11, 4))),
        "070": (0, ("MODE3A", "7700")),
        "200": (("ICF", 1), ("LNAV", 0), ("ME", 1), ("PS", 1), ("SS", 1)),
        "160": (("RE", 0), ("GS", (0.0, "NM/s")), ("TA", (0.0, "°"))),
        "170": "        ",
        "020": 20,
    })
    # Minimal: position only; then time only; then no quality but 072.
    recs.append({
        "010": (("SAC", 31), ("SIC", 1)),
        "130": (("LAT", (89.9999, "°")), ("LON", (-180.0, "°"))),
    })
    recs.append({
        "010": (("SAC", 31), ("SIC", 1)),
        "071": (86399.9921875, "s"),
        "072": (0.0, "s"),
        "076": (("FSI", 3), ("TOMRP", (0.5, "s"))),
        "075": (12.0, "s"),
        "SP": bytes([0x00]),
    })
    recs.append({
        "010": (("SAC", 31), ("SIC", 2)),
        "040": (bits((0, 3), (0, 2), (0, 1), (0, 1)),),
        "071": (600.0, "s"),
        "131": (("LAT", (51.4700, "°")), ("LON", (-0.4543, "°"))),
        "090": (bits((3, 3), (9, 4)), bits((1, 1), (2, 2), (8, 4)),
                bits((0, 2), (0, 1), (1, 2), (1, 2))),
        "160": (("RE", 0), ("GS", (0.06, "NM/s")), ("TA", (45.0, "°"))),
        "250": [0x0102030405060708],
        "295": {"AOS": 1},
        "110": {"TIS": (bits((1, 1), (1, 1), (0, 5)),)},
    })
    return [Cat021.cv_record.create(r) for r in recs]


# ---------------------------------------------------------------- CAT020


def mlat_records():
    recs = []
    recs.append({
        "010": (("SAC", 40), ("SIC", 2)),
        # SSR 0, MS 1, HF 0, VDL4 0, UAT 0, DME 0, OT 1 | RAB 0, SPI 1,
        # CHN 1, GBS 0, CRT 1, SIM 0, TST 0 | CF 1, spare.
        "020": (bits((0, 1), (1, 1), (0, 1), (0, 1), (0, 1), (0, 1), (1, 1)),
                bits((0, 1), (1, 1), (1, 1), (0, 1), (1, 1), (0, 1), (0, 1)),
                bits((1, 2), (0, 5))),
        "140": (50000.5078125, "s"),
        "041": (("LAT", (47.4582, "°")), ("LON", (8.5555, "°"))),
        "042": (("X", (-1234.5, "m")), ("Y", (5678.0, "m"))),
        "161": (0, ("TRN", 0x123)),
        "170": (bits((1, 1), (0, 1), (0, 1), (2, 2), (0, 1), (0, 1)), bits((0, 1), (0, 6))),
        "070": (("V", 0), ("G", 1), ("L", 0), 0, ("MODE3A", "1234")),
        "202": (("VX", (-120.25, "m/s")), ("VY", (65.5, "m/s"))),
        "090": (("V", 0), ("G", 0), ("FL", (123.75, "FL"))),
        "100": 0x80000FFF,
        "220": 0x3C6DD2,
        "245": (("STI", 0), 0, ("CHR", "DLH4AB  ")),
        "110": (2000.0, "ft"),
        "105": (2150.0, "ft"),
        "210": (("AX", (1.25, "m/s²")), ("AY", (-0.5, "m/s²"))),
        "300": 5,
        "310": (("TRB", 0), ("MSG", 2)),
        "500": {"DOP": (("X", (1.5, "")), ("Y", (2.25, "")), ("XY", (0.75, ""))),
                "SDP": (("X", (7.25, "m")), ("Y", (12.5, "m")), ("XY", (0.5, ""))),
                "SDH": (15.5, "m")},
        "400": [0x81, 0x02],
        "250": [(("BDSDATA", 0x11223344556677), ("BDS1", 4), ("BDS2", 0)),
                (("BDSDATA", 0x0102030405060A), ("BDS1", 6), ("BDS2", 0))],
        "230": (("COM", 1), ("STAT", 0), ("CASEVN", 0), ("MSSC", 1), ("ARC", 1),
                ("AIC", 1), ("B1A", 1), ("B1B", 5)),
        "260": 0x112233445566AA,
        "030": [1, 17],
        "055": (("V", 0), ("G", 0), ("L", 0), ("MODE1", 5)),
        "050": (("V", 0), ("G", 0), ("L", 0), 0, ("MODE2", "0123")),
        "RE": bytes([0x40, 0x80, 0x00, 0x10, 0x00, 0x20, 0x00, 0x00]),
        "SP": bytes([0x99, 0x98, 0x97]),
    })
    # Negative Cartesian position, velocity and height; SDP only; one
    # octet descriptor; southern/western WGS-84.
    recs.append({
        "010": (("SAC", 40), ("SIC", 2)),
        "020": (bits((1, 1), (0, 1), (0, 1), (0, 1), (0, 1), (0, 1), (0, 1)),),
        "140": (0.0, "s"),
        "041": (("LAT", (-12.3456789, "°")), ("LON", (-77.1111111, "°"))),
        "042": (("X", (-4194300.0, "m")), ("Y", (-0.5, "m"))),
        "202": (("VX", (-0.25, "m/s")), ("VY", (-8192.0, "m/s"))),
        "105": (-412.5, "ft"),
        "090": (("V", 1), ("G", 0), ("FL", (-12.25, "FL"))),
        "500": {"SDP": (("X", (0.25, "m")), ("Y", (16383.75, "m")), ("XY", (0.0, "")))},
    })
    # SIM/TST target, DOP and SDH only, a callsign with STI 1.
    recs.append({
        "010": (("SAC", 40), ("SIC", 3)),
        "020": (bits((0, 1), (1, 1), (0, 1), (0, 1), (0, 1), (0, 1), (0, 1)),
                bits((1, 1), (0, 1), (0, 1), (1, 1), (0, 1), (1, 1), (1, 1))),
        "140": (86399.9921875, "s"),
        "041": (("LAT", (0.0, "°")), ("LON", (0.0, "°"))),
        "220": 0xFFFFFF,
        "245": (("STI", 1), 0, ("CHR", "TEST01  ")),
        "500": {"DOP": (("X", (0.25, "")), ("Y", (0.5, "")), ("XY", (0.25, ""))),
                "SDH": (0.5, "m")},
        "030": [3],
    })
    # Minimal.
    recs.append({
        "010": (("SAC", 41), ("SIC", 0)),
        "140": (3600.0, "s"),
        "042": (("X", (10.0, "m")), ("Y", (20.0, "m"))),
    })
    return [Cat020.cv_record.create(r) for r in recs]


# ---------------------------------------------------------- the decoding


def opt(item, f):
    return None if item is None else f(item)


def sub(item, name):
    return item.variation.get_item(name)


def q(item, name, unit):
    return sub(item, name).variation.content.as_quantity(unit)


def u(item, name):
    return sub(item, name).variation.content.as_uint()


def ext(item, name):
    """A subitem of an extended item, or None when its octet is absent."""
    x = item.variation.get_item(name)
    return None if x is None else x.variation.content.as_uint()


def whole(item, unit):
    return item.variation.content.as_quantity(unit)


def precise(coarse_s, fsi, fraction_s):
    if coarse_s is None or fsi is None or fsi == 3:
        return None
    return (math.floor(coarse_s) + {0: 0, 1: 1, 2: -1}[fsi] + fraction_s) % 86400.0


def expected_021(rec):
    e = {}
    i010 = rec.get_item("010")
    e["sac"], e["sic"] = u(i010, "SAC"), u(i010, "SIC")
    i040 = rec.get_item("040")
    for key in ["ATP", "ARC", "RC", "RAB", "DCR", "GBS", "SIM", "TST", "SAA", "CL",
                "LLC", "IPC", "NOGO", "CPR", "LDPJ", "RCF"]:
        e["d_" + key.lower()] = None if i040 is None else ext(i040, key)
    e["descriptor"] = i040 is not None
    e["track_number"] = opt(rec.get_item("161"), lambda i: u(i, "TRNUM"))
    e["toa_position_s"] = opt(rec.get_item("071"), lambda i: whole(i, "s"))
    e["toa_velocity_s"] = opt(rec.get_item("072"), lambda i: whole(i, "s"))
    e["tomr_position_s"] = opt(rec.get_item("073"), lambda i: whole(i, "s"))
    e["tomr_velocity_s"] = opt(rec.get_item("075"), lambda i: whole(i, "s"))
    e["tort_s"] = opt(rec.get_item("077"), lambda i: whole(i, "s"))
    for item, key, coarse in [("074", "tomr_position", "tomr_position_s"),
                              ("076", "tomr_velocity", "tomr_velocity_s")]:
        i = rec.get_item(item)
        e[key + "_fsi"] = opt(i, lambda i: u(i, "FSI"))
        e[key + "_fraction_s"] = opt(i, lambda i: q(i, "TOMRP", "s"))
        e[key + "_precise_s"] = precise(e[coarse], e[key + "_fsi"], e[key + "_fraction_s"])
    i130 = rec.get_item("130")
    e["lat_deg"] = opt(i130, lambda i: q(i, "LAT", "°"))
    e["lon_deg"] = opt(i130, lambda i: q(i, "LON", "°"))
    i131 = rec.get_item("131")
    e["lat_hr_deg"] = opt(i131, lambda i: q(i, "LAT", "°"))
    e["lon_hr_deg"] = opt(i131, lambda i: q(i, "LON", "°"))
    i150 = rec.get_item("150")
    e["ias_mps"] = e["mach"] = None
    if i150 is not None:
        im = u(i150, "IM")
        speed = sub(i150, "AS").variation.rule.content([im])
        if im == 0:
            e["ias_mps"] = speed.as_quantity("NM/s") * NM
        else:
            e["mach"] = speed.as_quantity("Mach")
    i151 = rec.get_item("151")
    e["tas_mps"] = opt(i151, lambda i: q(i, "TAS", "kt") * KT)
    e["tas_re"] = opt(i151, lambda i: u(i, "RE"))
    e["address"] = opt(rec.get_item("080"), lambda i: i.as_uint())
    i140 = rec.get_item("140")
    e["geometric_height_ft"] = opt(i140, lambda i: whole(i, "ft"))
    e["geometric_height_m"] = opt(e["geometric_height_ft"], lambda h: h * FT)
    e["geometric_height_greater_than"] = opt(i140, lambda i: i.as_uint() == 0x7FFF)
    i090 = rec.get_item("090")
    for key in ["NUCRNACV", "NUCPNIC", "NICBARO", "SIL", "NACP", "SILS", "SDA", "GVA", "PIC"]:
        e["q_" + key.lower()] = None if i090 is None else ext(i090, key)
    i210 = rec.get_item("210")
    e["mops_vns"] = opt(i210, lambda i: u(i, "VNS"))
    e["mops_vn"] = opt(i210, lambda i: u(i, "VN"))
    e["mops_ltt"] = opt(i210, lambda i: u(i, "LTT"))
    e["mode_3a"] = opt(rec.get_item("070"),
                       lambda i: sub(i, "MODE3A").variation.content.as_string())
    e["flight_level"] = opt(rec.get_item("145"), lambda i: whole(i, "FL"))
    i200 = rec.get_item("200")
    for key in ["ICF", "LNAV", "ME", "PS", "SS"]:
        e["s_" + key.lower()] = opt(i200, lambda i: u(i, key))
    for item, key, name in [("155", "bvr", "BVR"), ("157", "gvr", "GVR")]:
        i = rec.get_item(item)
        e[key + "_fpm"] = opt(i, lambda i: q(i, name, "ft/min"))
        e[key + "_mps"] = opt(e[key + "_fpm"], lambda v: v * FT / 60.0)
        e[key + "_re"] = opt(i, lambda i: u(i, "RE"))
    i160 = rec.get_item("160")
    e["gs_mps"] = opt(i160, lambda i: q(i, "GS", "NM/s") * NM)
    e["track_deg"] = opt(i160, lambda i: q(i, "TA", "°"))
    e["gv_re"] = opt(i160, lambda i: u(i, "RE"))
    e["velocity_en_mps"] = None
    if i160 is not None and e["gv_re"] == 0:
        t = math.radians(e["track_deg"])
        e["velocity_en_mps"] = [e["gs_mps"] * math.sin(t), e["gs_mps"] * math.cos(t)]
    i170 = rec.get_item("170")
    e["callsign"] = opt(i170, lambda i: i.variation.content.as_string().rstrip() or None)
    e["emitter_category"] = opt(rec.get_item("020"), lambda i: i.as_uint())
    # The tracker's view.
    nacp = e["q_nacp"]
    e["position_sigma_m"] = (None if nacp not in NACP_EPU_M
                             else NACP_EPU_M[nacp] / K95)
    e["time_of_applicability_s"] = next(
        (t for t in [e["toa_position_s"], e["tomr_position_precise_s"],
                     e["tomr_position_s"]] if t is not None), None)
    e["simulated_or_test"] = e["d_sim"] == 1 or e["d_tst"] == 1
    return e


def expected_020(rec):
    e = {}
    i010 = rec.get_item("010")
    e["sac"], e["sic"] = u(i010, "SAC"), u(i010, "SIC")
    i020 = rec.get_item("020")
    for key in ["SSR", "MS", "HF", "VDL4", "UAT", "DME", "OT", "RAB", "SPI", "CHN", "GBS",
                "CRT", "SIM", "TST", "CF"]:
        e["d_" + key.lower()] = None if i020 is None else ext(i020, key)
    e["descriptor"] = i020 is not None
    e["time_of_day_s"] = opt(rec.get_item("140"), lambda i: whole(i, "s"))
    i041 = rec.get_item("041")
    e["lat_deg"] = opt(i041, lambda i: q(i, "LAT", "°"))
    e["lon_deg"] = opt(i041, lambda i: q(i, "LON", "°"))
    i042 = rec.get_item("042")
    e["x_m"] = opt(i042, lambda i: q(i, "X", "m"))
    e["y_m"] = opt(i042, lambda i: q(i, "Y", "m"))
    e["track_number"] = opt(rec.get_item("161"), lambda i: u(i, "TRN"))
    i070 = rec.get_item("070")
    e["mode_3a"] = opt(i070, lambda i: sub(i, "MODE3A").variation.content.as_string())
    for key in ["V", "G", "L"]:
        e["mode_3a_" + key.lower()] = opt(i070, lambda i: u(i, key))
    i202 = rec.get_item("202")
    e["vx_mps"] = opt(i202, lambda i: q(i, "VX", "m/s"))
    e["vy_mps"] = opt(i202, lambda i: q(i, "VY", "m/s"))
    i090 = rec.get_item("090")
    e["flight_level"] = opt(i090, lambda i: q(i, "FL", "FL"))
    e["flight_level_v"] = opt(i090, lambda i: u(i, "V"))
    e["flight_level_g"] = opt(i090, lambda i: u(i, "G"))
    e["address"] = opt(rec.get_item("220"), lambda i: i.as_uint())
    i245 = rec.get_item("245")
    e["callsign"] = opt(i245, lambda i: sub(i, "CHR").variation.content.as_string().rstrip()
                        or None)
    e["callsign_sti"] = opt(i245, lambda i: u(i, "STI"))
    e["geometric_height_m"] = opt(rec.get_item("105"), lambda i: whole(i, "ft") * FT)
    i500 = rec.get_item("500")
    dop = sdp = sdh = None
    if i500 is not None:
        dop = i500.variation.get_item("DOP")
        sdp = i500.variation.get_item("SDP")
        sdh = i500.variation.get_item("SDH")
    e["accuracy"] = i500 is not None
    e["dop"] = opt(dop, lambda i: [q(i, "X", ""), q(i, "Y", ""),
                                  sub(i, "XY").variation.content.as_uint()])
    e["sdp"] = opt(sdp, lambda i: [q(i, "X", "m"), q(i, "Y", "m"),
                                  sub(i, "XY").variation.content.as_uint()])
    e["sdh_m"] = opt(sdh, lambda i: i.variation.content.as_quantity("m"))
    e["position_sigma_m"] = opt(e["sdp"], lambda s: s[:2])
    e["simulated_or_test"] = e["d_sim"] == 1 or e["d_tst"] == 1
    return e


def expected_048(rec):
    i010 = rec.get_item("010")
    return {"sac": u(i010, "SAC"), "sic": u(i010, "SIC"),
            "time_of_day_s": rec.get_item("140").variation.content.as_quantity("s")}


def expected_034(rec):
    i010 = rec.get_item("010")
    return {"sac": u(i010, "SAC"), "sic": u(i010, "SIC"),
            "message_type": rec.get_item("000").as_uint()}


SPECS = {21: (Cat021, expected_021), 20: (Cat020, expected_020),
         48: (Cat048, expected_048), 34: (Cat034, expected_034)}


def decode(data):
    """The expected values, by libasterix's parser."""
    out = []
    offset = 0
    raw = RawDatablock.parse(Bits.from_bytes(data))
    assert not isinstance(raw, ValueError), raw
    for db in raw:
        cat = db.get_category()
        spec, expected = SPECS[cat]
        records = spec.cv_uap.parse(db.get_raw_records())
        assert not isinstance(records, ValueError), records
        pos = offset + 3
        for rec in records:
            e = {"offset": pos, "category": cat}
            e.update(expected(rec))
            pos += len(rec.unparse().to_bytes())
            out.append(e)
        assert pos == offset + len(db.unparse().to_bytes())
        offset = pos
    assert offset == len(data)
    return out


def blocks(spec, records, per_block):
    return [spec.create(records[i:i + per_block]) for i in range(0, len(records), per_block)]


def to_bytes(dbs):
    return b"".join(db.unparse().to_bytes() for db in dbs)


def mixed():
    plot = Cat048.cv_record.create({
        "010": (("SAC", 25), ("SIC", 1)),
        "140": (43200.0, "s"),
        "020": (2 << 4,),
        "040": (("RHO", (20.0, "NM")), ("THETA", (45.0, "°"))),
    })
    marker = Cat034.cv_record.create({
        "010": (("SAC", 25), ("SIC", 1)),
        "000": 1,
        "030": (43199.5, "s"),
    })
    adsb = adsb_records()
    mlat = mlat_records()
    return to_bytes([
        Cat034.create([marker]),
        Cat021.create(adsb[:2]),
        Cat048.create([plot]),
        Cat020.create(mlat[:1]),
        Cat021.create(adsb[5:]),
        Cat020.create(mlat[3:]),
    ])


def main():
    files = {
        "adsb.bin": to_bytes(blocks(Cat021, adsb_records(), 3)),
        "mlat.bin": to_bytes(blocks(Cat020, mlat_records(), 2)),
        "mixed.bin": mixed(),
    }
    os.makedirs(OUT, exist_ok=True)
    expected = {
        "generator": "checks/cat021_fixture.py with libasterix 0.36.3 "
                     "(Cat_021_2_7, Cat_020_1_11, Cat_048_1_32, Cat_034_1_29)",
        "files": {},
    }
    for name, data in files.items():
        with open(os.path.join(OUT, name), "wb") as f:
            f.write(data)
        expected["files"][name] = decode(data)
        print(f"{name}: {len(data)} bytes, {len(expected['files'][name])} records")
    with open(os.path.join(OUT, "expected.json"), "w") as f:
        json.dump(expected, f, indent=1)
        f.write("\n")


if __name__ == "__main__":
    main()
