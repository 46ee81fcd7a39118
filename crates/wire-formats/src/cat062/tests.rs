//! Expected bytes are computed by hand from the CAT062 1.20 definition
//! (`specs/cat062/cat-1.20.ast`), the arithmetic in the comments; the
//! decoded fixture (`tests/fixtures/cat062/sample_decoded.json`) is
//! libasterix's reading of our bytes.

use super::*;
use proptest::prelude::*;

mod oracle;

fn cfg() -> Cat062Config {
    Cat062Config {
        sac: 25,
        sic: 7,
        service_id: None,
    }
}

/// A 2D track at the origin, time 0, track number 1, nothing optional.
fn base() -> SystemTrack {
    SystemTrack {
        track_number: 1,
        ..SystemTrack::default()
    }
}

/// The one record of `t` (checks the block header around it).
fn record(t: &SystemTrack) -> Vec<u8> {
    let e = encode_records(&cfg(), std::slice::from_ref(t), DEFAULT_MAX_BLOCK);
    assert_eq!(e.blocks.len(), 1, "{e:?}");
    let b = &e.blocks[0];
    assert_eq!(b[0], 62);
    assert_eq!(usize::from(u16::from_be_bytes([b[1], b[2]])), b.len());
    b[3..].to_vec()
}

/// Item sizes of the subfields of a compound item, in order.
fn compound_sizes(frn: u32) -> &'static [usize] {
    match frn {
        // TRK PSR SSR MDS ADS(2) ES VDL | UAT LOP MLT
        14 => &[1, 1, 1, 1, 2, 1, 1, 1, 1, 1],
        // APC COV APW AGA ABA ATV AA | ARC
        27 => &[4, 2, 4, 1, 1, 2, 2, 1],
        // SID POS HEIGHT MDC MDA TYP
        28 => &[2, 4, 2, 2, 2, 1],
        _ => panic!("FRN {frn} is not compound"),
    }
}

/// Splits a record into (FRN, item bytes) by the 1.20 UAP, for the items
/// the encoder writes (a test decoder: panics on anything else). Returns
/// the items and the number of bytes read.
fn split(rec: &[u8]) -> (Vec<(u32, Vec<u8>)>, usize) {
    let mut pos = 0;
    let mut frns = Vec::new();
    loop {
        let b = rec[pos];
        for bit in 0..7 {
            if b & (0x80 >> bit) != 0 {
                frns.push(pos as u32 * 7 + bit + 1);
            }
        }
        pos += 1;
        if b & 1 == 0 {
            break;
        }
    }
    let mut items = Vec::new();
    for frn in frns {
        let start = pos;
        match frn {
            1 => pos += 2,
            3 => pos += 1,
            4 => pos += 3,
            5 => pos += 8,
            6 => pos += 6,
            7 => pos += 4,
            12 => pos += 2,
            13 => {
                while rec[pos] & 1 == 1 {
                    pos += 1;
                }
                pos += 1;
            }
            14 | 27 | 28 => {
                let sizes = compound_sizes(frn);
                let mut flags = Vec::new();
                loop {
                    let b = rec[pos];
                    for bit in 0..7 {
                        flags.push(b & (0x80 >> bit) != 0);
                    }
                    pos += 1;
                    if b & 1 == 0 {
                        break;
                    }
                }
                for (i, f) in flags.iter().enumerate() {
                    if *f {
                        pos += sizes[i];
                    }
                }
            }
            18 | 20 => pos += 2,
            other => panic!("FRN {other} is never written"),
        }
        items.push((frn, rec[start..pos].to_vec()));
    }
    (items, pos)
}

/// The bytes of item `frn` in `rec`, if present.
fn item(rec: &[u8], frn: u32) -> Option<Vec<u8>> {
    let (items, end) = split(rec);
    assert_eq!(end, rec.len(), "record has trailing bytes");
    items.into_iter().find(|(f, _)| *f == frn).map(|(_, b)| b)
}

fn encode_one(t: &SystemTrack) -> Encoded {
    encode_records(&cfg(), std::slice::from_ref(t), DEFAULT_MAX_BLOCK)
}

#[test]
fn the_minimal_record_byte_by_byte() {
    // FSPEC octet 1: FRN 1 (I062/010) 0x80, FRN 4 (/070) 0x10, FRN 6
    // (/100) 0x04, FRN 7 (/185) 0x02, FX 0x01 = 0x97. Octet 2 (FRN 8..14
    // at bits 8..2): FRN 12 (/040) bit 4 = 0x08, FRN 13 (/080) bit 3 =
    // 0x04 = 0x0C, FX clear.
    // I062/010 SAC 25 = 0x19, SIC 7; /070 0 s; /100 x = y = 0; /185 0, 0;
    // /040 track 1; /080 one octet, all 0 (confirmed multisensor track,
    // MRH 0 and SRC 0: no I062/130).
    let expected = [
        0x97, 0x0C, 0x19, 0x07, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0x00, 0x01, 0x00,
    ];
    assert_eq!(record(&base()), expected);
    // The whole block: CAT 62 = 0x3E, LEN 3 + 20 = 23 = 0x0017.
    let e = encode_one(&base());
    assert_eq!(&e.blocks[0][..3], &[0x3E, 0x00, 0x17]);
    assert!(e.skipped.is_empty() && e.saturated.is_empty());
}

#[test]
fn a_record_with_every_item_byte_by_byte() {
    let t = SystemTrack {
        track_number: 0x1234,
        // 12,345.678 s × 128 = 1,580,246.784 → 1,580,247 = 0x181CD7.
        time_of_day: 12_345.678,
        // 45.5° / (180/2²⁵ °) = 8,481,814.76 → 8,481,815 = 0x00816C17;
        // -73.25° → -13,654,789.69 → -13,654,790 = 2³² - 13,654,790 =
        // 0xFF2FA4FA.
        wgs84: Some((45.5, -73.25)),
        // x -1,234.3 m / 0.5 = -2,468.6 → -2,469 = 2²⁴ - 2,469 = 0xFFF65B;
        // y 1,234.25 / 0.5 = 2,468.5 → 2,469 (tie away from zero) = 0x0009A5.
        xy: (-1_234.3, 1_234.25),
        // vx -0.3 / 0.25 = -1.2 → -1 = 0xFFFF; vy 8,191.75 / 0.25 = 32,767
        // = 0x7FFF (the largest).
        velocity: (-0.3, 8_191.75),
        status: TrackStatusFlags {
            altitude_source: AltitudeSource::Radar3d,
            last_message: true,
            ..TrackStatusFlags::default()
        },
        ages: UpdateAges {
            // 12.3 / 0.25 = 49.2 → 49 = 0x31.
            track: Some(12.3),
            ..UpdateAges::default()
        },
        // 3,000 m / (6.25 × 0.3048 m) = 1,574.80 → 1,575 = 0x0627.
        height: Some(3_000.0),
        // 5 m/s / (6.25 × 0.3048 / 60 m/s) = 157.48 → 157 = 0x009D.
        vertical_rate: Some(5.0),
        accuracy: Some(Accuracy {
            // ATV only: 0.6 / 0.25 = 2.4 → 2; 1.0 / 0.25 = 4.
            velocity: Some((0.6, 1.0)),
            ..Accuracy::default()
        }),
        last_measurement: Some(LastMeasurement {
            sensor: Some((25, 1)),
            ..LastMeasurement::default()
        }),
        address: Default::default(),
        measured_flight_level: Default::default(),
        callsign: Default::default(),
        mode_3a: Default::default(),
    };
    let c = Cat062Config {
        sac: 25,
        sic: 7,
        service_id: Some(9),
    };
    let e = encode_records(&c, &[t], DEFAULT_MAX_BLOCK);
    assert!(e.skipped.is_empty(), "{:?}", e.skipped);
    let expected: Vec<u8> = [
        // FSPEC. Octet 1: FRN 1 0x80 | FRN 3 (/015) 0x20 | FRN 4 (/070)
        // 0x10 | FRN 5 (/105) 0x08 | FRN 6 (/100) 0x04 | FRN 7 (/185)
        // 0x02 | FX = 0xBF. Octet 2 (FRN 8..14): FRN 12 (/040) bit 4 0x08
        // | FRN 13 (/080) bit 3 0x04 | FRN 14 (/290) bit 2 0x02 | FX =
        // 0x0F. Octet 3 (FRN 15..21):
        // FRN 18 (/130) is the 4th, bit 5 = 0x10; FRN 20 (/220) the 6th,
        // bit 3 = 0x04; FX = 0x15. Octet 4 (FRN 22..28): FRN 27 (/500)
        // the 6th, 0x04; FRN 28 (/340) the 7th, 0x02 = 0x06.
        &[0xBF, 0x0F, 0x15, 0x06][..],
        &[0x19, 0x07],                                     // I062/010
        &[0x09],                                           // I062/015
        &[0x18, 0x1C, 0xD7],                               // I062/070
        &[0x00, 0x81, 0x6C, 0x17, 0xFF, 0x2F, 0xA4, 0xFA], // I062/105
        &[0xFF, 0xF6, 0x5B, 0x00, 0x09, 0xA5],             // I062/100
        &[0xFF, 0xFF, 0x7F, 0xFF],                         // I062/185
        &[0x12, 0x34],                                     // I062/040
        // I062/080: MRH 1 (0x20, I062/130 written) | SRC 2 (3D radar) << 2
        // = 0x08 → 0x28, FX → 0x29; first extension TSE = bit 7 = 0x40.
        &[0x29, 0x40],
        // I062/290: primary TRK = bit 8 = 0x80, then TRK 0x31.
        &[0x80, 0x31],
        &[0x06, 0x27], // I062/130
        &[0x00, 0x9D], // I062/220
        // I062/500: primary ATV = 6th subfield, bit 3 = 0x04; X 2, Y 4.
        &[0x04, 0x02, 0x04],
        // I062/340: primary SID = bit 8 = 0x80; SAC 25, SIC 1.
        &[0x80, 0x19, 0x01],
    ]
    .concat();
    let block = &e.blocks[0];
    assert_eq!(&block[3..], &expected[..]);
    // 4 + 2 + 1 + 3 + 8 + 6 + 4 + 2 + 2 + 2 + 2 + 2 + 3 + 3 = 44 bytes:
    // LEN 3 + 44 = 47 = 0x002F.
    assert_eq!(expected.len(), 44);
    assert_eq!(&block[..3], &[0x3E, 0x00, 0x2F]);
}

#[test]
fn cartesian_position_boundaries() {
    let at = |x: f64, y: f64| SystemTrack {
        xy: (x, y),
        wgs84: Some((0.0, 0.0)),
        ..base()
    };
    // Largest: 4,194,303.5 m / 0.5 = 8,388,607 = 2²³ - 1 = 0x7FFFFF;
    // smallest -4,194,304 m = -2²³ = 0x800000.
    assert_eq!(
        item(&record(&at(4_194_303.5, -4_194_304.0)), 6).unwrap(),
        [0x7F, 0xFF, 0xFF, 0x80, 0x00, 0x00]
    );
    // -0.25 m / 0.5 = -0.5 → -1 (ties away from zero) = 0xFFFFFF; 0.74 m
    // → 1.48 → 1.
    assert_eq!(
        item(&record(&at(-0.25, 0.74)), 6).unwrap(),
        [0xFF, 0xFF, 0xFF, 0x00, 0x00, 0x01]
    );
    // One LSB beyond: 4,194,304 m → 8,388,608 > 2²³ - 1; the item is left
    // out (the record keeps I062/105), never wrapped to 0x800000.
    for (x, y) in [(4_194_304.0, 0.0), (0.0, -4_194_304.5), (f64::NAN, 0.0)] {
        let e = encode_one(&at(x, y));
        let rec = &e.blocks[0][3..];
        assert_eq!(item(rec, 6), None);
        assert!(item(rec, 5).is_some());
        assert_eq!(e.skipped.len(), 1, "{:?}", e.skipped);
        let s = &e.skipped[0];
        assert_eq!(s.item, if x == 0.0 { "I062/100 Y" } else { "I062/100 X" });
        assert_eq!((s.min, s.max), (-4_194_304.0, 4_194_303.5));
        assert!(!s.record_dropped);
    }
    // 4,194,303.75 m → 8,388,607.5 → 8,388,608 (ties away): out.
    assert_eq!(encode_one(&at(4_194_303.75, 0.0)).skipped.len(), 1);
}

#[test]
fn a_record_without_any_position_is_not_written() {
    let t = SystemTrack {
        xy: (1e7, 0.0),
        ..base()
    };
    let e = encode_one(&t);
    assert!(e.blocks.is_empty());
    assert_eq!(e.skipped.len(), 1);
    assert!(e.skipped[0].record_dropped);
    assert_eq!(e.skipped[0].value, 1e7);
    assert!(e.skipped[0].reason.contains("record not written"));
}

#[test]
fn time_of_track_information_and_the_24_hour_wrap() {
    let tod = |t: f64| {
        item(
            &record(&SystemTrack {
                time_of_day: t,
                ..base()
            }),
            4,
        )
        .unwrap()
    };
    // 86,399 s + 127/128 s = 11,059,199 LSB = 0xA8BFFF, the last of the day.
    assert_eq!(tod(86_399.0 + 127.0 / 128.0), [0xA8, 0xBF, 0xFF]);
    // 86,400.5 s is 0.5 s after midnight: 64 LSB = 0x000040.
    assert_eq!(tod(86_400.5), [0x00, 0x00, 0x40]);
    // 86,399.999 s × 128 = 11,059,199.87 → 11,059,200 = midnight → 0.
    assert_eq!(tod(86_399.999), [0x00, 0x00, 0x00]);
    // -1 s is 86,399 s of the day before: 11,059,072 = 0xA8BF80.
    assert_eq!(tod(-1.0), [0xA8, 0xBF, 0x80]);
    // 1/256 s = 0.5 LSB → 1 (ties away from zero).
    assert_eq!(tod(1.0 / 256.0), [0x00, 0x00, 0x01]);
    // A time that is not a number: no record.
    for t in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        let e = encode_one(&SystemTrack {
            time_of_day: t,
            ..base()
        });
        assert!(e.blocks.is_empty());
        assert_eq!(e.skipped.len(), 1);
        assert_eq!(e.skipped[0].item, "I062/070");
        assert!(e.skipped[0].record_dropped);
    }
}

#[test]
fn time_of_day_of_a_unix_time() {
    // 1,700,000,000 s = 19,675 days × 86,400 s + 80,000 s.
    assert_eq!(time_of_day(1_700_000_000.0), 80_000.0);
    assert_eq!(time_of_day(1_700_000_000.25), 80_000.25);
    assert_eq!(time_of_day(-1.0), 86_399.0);
    assert!(time_of_day(f64::NAN).is_nan());
}

#[test]
fn wgs84_position_boundaries() {
    let at = |lat: f64, lon: f64| SystemTrack {
        wgs84: Some((lat, lon)),
        ..base()
    };
    // -33.8675° / (180/2²⁵) = -6,313,359.59 → -6,313,360 = 0xFF9FAA70;
    // 151.207° → 28,187,027.77 → 28,187,028 = 0x01AE1994.
    assert_eq!(
        item(&record(&at(-33.8675, 151.207)), 5).unwrap(),
        [0xFF, 0x9F, 0xAA, 0x70, 0x01, 0xAE, 0x19, 0x94]
    );
    // 90° = 2²⁴ LSB = 0x01000000 (the range includes +90°); -180° = -2²⁵
    // = 0xFE000000; the largest longitude 180° - 180/2²⁵ ° = 2²⁵ - 1 =
    // 0x01FFFFFF.
    assert_eq!(
        item(&record(&at(90.0, -180.0)), 5).unwrap(),
        [0x01, 0x00, 0x00, 0x00, 0xFE, 0x00, 0x00, 0x00]
    );
    let lsb = 180.0 / 33_554_432.0;
    assert_eq!(
        item(&record(&at(-90.0, 180.0 - lsb)), 5).unwrap(),
        [0xFF, 0x00, 0x00, 0x00, 0x01, 0xFF, 0xFF, 0xFF]
    );
    // Beyond: latitude 90° + 1 LSB, longitude 180° (the range is < 180°).
    for (lat, lon, name) in [
        (90.0 + lsb, 0.0, "I062/105 LAT"),
        (0.0, 180.0, "I062/105 LON"),
        (0.0, f64::INFINITY, "I062/105 LON"),
    ] {
        let e = encode_one(&at(lat, lon));
        assert_eq!(item(&e.blocks[0][3..], 5), None);
        assert_eq!(e.skipped.len(), 1);
        assert_eq!(e.skipped[0].item, name);
    }
}

#[test]
fn velocity_boundaries() {
    let v = |vx: f64, vy: f64| SystemTrack {
        velocity: (vx, vy),
        ..base()
    };
    // -8,192 m/s / 0.25 = -32,768 = 0x8000; 8,191.75 → 32,767 = 0x7FFF.
    assert_eq!(
        item(&record(&v(-8_192.0, 8_191.75)), 7).unwrap(),
        [0x80, 0x00, 0x7F, 0xFF]
    );
    // -250.1 / 0.25 = -1,000.4 → -1,000 = 0xFC18; 0.125 → 0.5 → 1.
    assert_eq!(
        item(&record(&v(-250.1, 0.125)), 7).unwrap(),
        [0xFC, 0x18, 0x00, 0x01]
    );
    // 8,192 m/s → 32,768: out; the item goes, the record stays.
    let e = encode_one(&v(8_192.0, 0.0));
    assert_eq!(item(&e.blocks[0][3..], 7), None);
    assert_eq!(e.skipped[0].item, "I062/185 VX");
    assert_eq!((e.skipped[0].min, e.skipped[0].max), (-8_192.0, 8_191.75));
}

#[test]
fn track_status_octets_and_fx_chaining() {
    let status = |s: TrackStatusFlags, height: Option<f64>| {
        item(
            &record(&SystemTrack {
                status: s,
                height,
                ..base()
            }),
            13,
        )
        .unwrap()
    };
    let f = TrackStatusFlags::default();
    // Confirmed multisensor track: one octet, 0.
    assert_eq!(status(f, None), [0x00]);
    // CNF (tentative) is bit 2: 0x02.
    let tentative = TrackStatusFlags {
        tentative: true,
        ..f
    };
    assert_eq!(status(tentative, None), [0x02]);
    // MON bit 8, SPI bit 7: 0xC0.
    let mono = TrackStatusFlags {
        monosensor: true,
        spi: true,
        ..f
    };
    assert_eq!(status(mono, None), [0xC0]);
    // SRC without I062/130 is written 0, and MRH 0.
    let gnss = TrackStatusFlags {
        altitude_source: AltitudeSource::Gnss,
        ..f
    };
    assert_eq!(status(gnss, None), [0x00]);
    // With I062/130: MRH 0x20 | SRC 1 << 2 = 0x04 → 0x24. SRC 7 → 0x3C.
    assert_eq!(status(gnss, Some(100.0)), [0x24]);
    let mlat = TrackStatusFlags {
        altitude_source: AltitudeSource::Multilateration,
        ..f
    };
    assert_eq!(status(mlat, Some(100.0)), [0x3C]);
    // TSE (last message) is bit 7 of the first extension: FX set in the
    // first octet, then 0x40. TSB bit 6 = 0x20, SIM bit 8 = 0x80.
    let end = TrackStatusFlags {
        last_message: true,
        ..f
    };
    assert_eq!(status(end, None), [0x01, 0x40]);
    let first_sim = TrackStatusFlags {
        first_message: true,
        simulated: true,
        tentative: true,
        ..f
    };
    assert_eq!(status(first_sim, None), [0x03, 0xA0]);
    // CST (coasting) is bit 8 of the third extension: octets 1 and 2 and
    // 3 carry FX only, then 0x80.
    let coast = TrackStatusFlags {
        coasting: true,
        ..f
    };
    assert_eq!(status(coast, None), [0x01, 0x01, 0x01, 0x80]);
    // CST | PSR bit 7 0x40 | SSR bit 6 0x20 | MDS bit 5 0x10 = 0xF0, with
    // TSE 0x40 | FX in the first extension.
    let all = TrackStatusFlags {
        coasting: true,
        psr_aged: true,
        ssr_aged: true,
        mode_s_aged: true,
        last_message: true,
        ..f
    };
    assert_eq!(status(all, None), [0x01, 0x41, 0x01, 0xF0]);
    // AFF (ADS-B data inconsistent with other surveillance information)
    // is bit 4 of the first extension: 0x08, with FX in the first octet.
    let inconsistent = TrackStatusFlags {
        adsb_inconsistent: true,
        ..f
    };
    assert_eq!(status(inconsistent, None), [0x01, 0x08]);
    // ADS (ADS-B update aged) is bit 4 of the third extension: 0x08 after
    // three octets carrying FX only.
    let adsb_aged = TrackStatusFlags {
        adsb_aged: true,
        ..f
    };
    assert_eq!(status(adsb_aged, None), [0x01, 0x01, 0x01, 0x08]);
    // Both, with TSB 0x20: first extension 0x20 | 0x08 | FX = 0x29; third
    // MDS 0x10 | ADS 0x08 = 0x18.
    let both = TrackStatusFlags {
        adsb_inconsistent: true,
        adsb_aged: true,
        mode_s_aged: true,
        first_message: true,
        ..f
    };
    assert_eq!(status(both, None), [0x01, 0x29, 0x01, 0x18]);
}

#[test]
fn update_ages_compound_and_saturation() {
    let ages = |a: UpdateAges| encode_one(&SystemTrack { ages: a, ..base() });
    let e = ages(UpdateAges {
        // TRK 12.3 / 0.25 = 49.2 → 49 = 0x31; PSR 0.125 / 0.25 = 0.5 → 1
        // (ties away); MDS 100 s > 63.75 s: written 255 = 0xFF (maximum
        // value or above).
        track: Some(12.3),
        psr: Some(0.125),
        ssr: None,
        mode_s: Some(100.0),
        ..UpdateAges::default()
    });
    // Primary: TRK 0x80 | PSR 0x40 | MDS (4th) 0x10 = 0xD0, no FX.
    assert_eq!(
        item(&e.blocks[0][3..], 14).unwrap(),
        [0xD0, 0x31, 0x01, 0xFF]
    );
    assert!(e.skipped.is_empty());
    assert_eq!(e.saturated.len(), 1);
    assert_eq!(e.saturated[0].item, "I062/290 MDS");
    assert_eq!(e.saturated[0].max, 63.75);
    // 63.75 s exactly is 255 and not a saturation; SSR alone is 0x20.
    let e = ages(UpdateAges {
        ssr: Some(63.75),
        ..UpdateAges::default()
    });
    assert_eq!(item(&e.blocks[0][3..], 14).unwrap(), [0x20, 0xFF]);
    assert!(e.saturated.is_empty());
    // A negative age is left out; with nothing left, no item.
    let e = ages(UpdateAges {
        psr: Some(-1.0),
        ..UpdateAges::default()
    });
    assert_eq!(item(&e.blocks[0][3..], 14), None);
    assert_eq!(e.skipped[0].item, "I062/290 PSR");
    // No age at all: no item, FSPEC octet 2 without FRN 14 (0x0C).
    assert_eq!(record(&base())[1], 0x0C);
}

#[test]
fn adsb_es_and_mlat_ages_are_subfields_6_and_10() {
    // I062/290 in 1.20: TRK PSR SSR MDS ADS(2 octets) ES VDL | UAT LOP
    // MLT. ES is the 6th subfield, bit 3 of the primary's first octet
    // (0x04); MLT the 10th, bit 6 of its second octet (0x20).
    let ages = |a: UpdateAges| encode_one(&SystemTrack { ages: a, ..base() });
    // ES alone: one primary octet 0x04; 2.6 s / 0.25 = 10.4 → 10 = 0x0A.
    let e = ages(UpdateAges {
        adsb_es: Some(2.6),
        ..UpdateAges::default()
    });
    assert_eq!(item(&e.blocks[0][3..], 14).unwrap(), [0x04, 0x0A]);
    // MLT alone: the primary's first octet is FX only (0x01), the second
    // 0x20; 0.875 s / 0.25 = 3.5 → 4 (ties away from zero).
    let e = ages(UpdateAges {
        mlat: Some(0.875),
        ..UpdateAges::default()
    });
    assert_eq!(item(&e.blocks[0][3..], 14).unwrap(), [0x01, 0x20, 0x04]);
    // TRK, MDS, ES and MLT: primary 0x80 | 0x10 | 0x04 | FX = 0x95, then
    // 0x20; values in subfield order: TRK 40 s → 160 = 0xA0, MDS 4.25 s →
    // 17 = 0x11, ES 0 s → 0, MLT 70 s > 63.75 s → 255 = 0xFF (maximum
    // value or above, a saturation).
    let e = ages(UpdateAges {
        track: Some(40.0),
        mode_s: Some(4.25),
        adsb_es: Some(0.0),
        mlat: Some(70.0),
        ..UpdateAges::default()
    });
    assert_eq!(
        item(&e.blocks[0][3..], 14).unwrap(),
        [0x95, 0x20, 0xA0, 0x11, 0x00, 0xFF]
    );
    assert_eq!(e.saturated.len(), 1);
    assert_eq!(e.saturated[0].item, "I062/290 MLT");
    assert_eq!(e.saturated[0].max, 63.75);
    // A negative or NaN age is left out (never received is not sent).
    let e = ages(UpdateAges {
        adsb_es: Some(-0.5),
        mlat: Some(f64::NAN),
        ..UpdateAges::default()
    });
    assert_eq!(item(&e.blocks[0][3..], 14), None);
    let left_out: Vec<&str> = e.skipped.iter().map(|s| s.item).collect();
    assert_eq!(left_out, ["I062/290 ES", "I062/290 MLT"]);
}

#[test]
fn accuracy_compound_with_an_extended_primary_subfield() {
    let acc = Accuracy {
        // APC 12.3 / 0.5 = 24.6 → 25 = 0x0019; 7 / 0.5 = 14 = 0x000E.
        xy: Some((12.3, 7.0)),
        // COV: Cov = -100 m² → -√100 = -10 m / 0.5 = -20 = 0xFFEC.
        xy_covariance_m2: Some(-100.0),
        // APW 1e-5° / (180/2²⁵) = 1.86 → 2; 2e-5° → 3.73 → 4.
        wgs84: Some((1e-5, 2e-5)),
        // AGA 30 m / (6.25 × 0.3048) = 15.75 → 16 = 0x10.
        geometric_altitude: Some(30.0),
        // ATV 0.6 / 0.25 = 2.4 → 2; 70 / 0.25 = 280 > 255: 0xFF.
        velocity: Some((0.6, 70.0)),
        // AA 0.1 / 0.25 = 0.4 → 0; 0.125 → 0.5 → 1.
        acceleration: Some((0.1, 0.125)),
        // ARC 1 m/s / (6.25 × 0.3048 / 60) = 31.50 → 31 = 0x1F.
        vertical_rate: Some(1.0),
    };
    let e = encode_one(&SystemTrack {
        accuracy: Some(acc),
        ..base()
    });
    // Primary: APC 0x80 | COV 0x40 | APW 0x20 | AGA 0x10 | (ABA 0x08 no)
    // | ATV 0x04 | AA 0x02 | FX 0x01 = 0xF7; second octet ARC bit 8 = 0x80.
    assert_eq!(
        item(&e.blocks[0][3..], 27).unwrap(),
        [
            0xF7, 0x80, 0x00, 0x19, 0x00, 0x0E, 0xFF, 0xEC, 0x00, 0x02, 0x00, 0x04, 0x10, 0x02,
            0xFF, 0x00, 0x01, 0x1F
        ]
    );
    assert_eq!(e.saturated.len(), 1);
    assert_eq!(e.saturated[0].item, "I062/500 ATV Y");
    // ATV alone: one octet of primary, 0x04. Positive covariance 2.25 m²
    // → 1.5 m → 3; zero → 0.
    let only = |a: Accuracy| {
        item(
            &record(&SystemTrack {
                accuracy: Some(a),
                ..base()
            }),
            27,
        )
    };
    assert_eq!(
        only(Accuracy {
            velocity: Some((0.25, 0.5)),
            ..Accuracy::default()
        })
        .unwrap(),
        [0x04, 0x01, 0x02]
    );
    assert_eq!(
        only(Accuracy {
            xy_covariance_m2: Some(2.25),
            ..Accuracy::default()
        })
        .unwrap(),
        [0x40, 0x00, 0x03]
    );
    // ARC alone: the first octet carries FX only.
    assert_eq!(
        only(Accuracy {
            vertical_rate: Some(0.0),
            ..Accuracy::default()
        })
        .unwrap(),
        [0x01, 0x80, 0x00]
    );
    // Nothing left: no item. A huge covariance saturates at ±32,767:
    // -1e12 m² → -10⁶ m → -32,767 = 0x8001.
    assert_eq!(
        only(Accuracy {
            xy: Some((-1.0, 1.0)),
            ..Accuracy::default()
        }),
        None
    );
    assert_eq!(
        only(Accuracy {
            xy_covariance_m2: Some(-1e12),
            ..Accuracy::default()
        })
        .unwrap(),
        [0x40, 0x80, 0x01]
    );
}

#[test]
fn measured_information_compound() {
    let m = |m: LastMeasurement| {
        encode_one(&SystemTrack {
            last_measurement: Some(m),
            ..base()
        })
    };
    let e = m(LastMeasurement {
        sensor: Some((25, 1)),
        // RHO 50,000 m / (1,852 / 256 m) = 6,911.45 → 6,911 = 0x1AFF;
        // THETA -90° → 270° / (360/2¹⁶ °) = 49,152 = 0xC000.
        polar: Some((50_000.0, -90.0)),
        // HEIGHT 3,000 m / (25 × 0.3048 m) = 393.70 → 394 = 0x018A.
        height: Some(3_000.0),
    });
    // Primary: SID 0x80 | POS 0x40 | HEIGHT 0x20 = 0xE0.
    assert_eq!(
        item(&e.blocks[0][3..], 28).unwrap(),
        [0xE0, 0x19, 0x01, 0x1A, 0xFF, 0xC0, 0x00, 0x01, 0x8A]
    );
    // THETA 359.999° → 65,535.82 → 65,536 = 360° = 0°; RHO 0.
    let e = m(LastMeasurement {
        polar: Some((0.0, 359.999)),
        ..LastMeasurement::default()
    });
    assert_eq!(
        item(&e.blocks[0][3..], 28).unwrap(),
        [0x40, 0x00, 0x00, 0x00, 0x00]
    );
    // RHO 256 NM = 65,536 LSB: beyond the 16 bits; POS is left out, SID
    // stays.
    let e = m(LastMeasurement {
        sensor: Some((1, 2)),
        polar: Some((256.0 * 1852.0, 10.0)),
        height: None,
    });
    assert_eq!(item(&e.blocks[0][3..], 28).unwrap(), [0x80, 0x01, 0x02]);
    assert_eq!(e.skipped[0].item, "I062/340 POS RHO");
    // Nothing: no item.
    let e = m(LastMeasurement::default());
    assert_eq!(item(&e.blocks[0][3..], 28), None);
}

#[test]
fn geometric_altitude_boundaries() {
    let h = |h: f64| {
        encode_one(&SystemTrack {
            height: Some(h),
            ..base()
        })
    };
    // -1,500 ft = -457.2 m / 1.905 m = -240 = 0xFF10, the lowest.
    assert_eq!(item(&h(-457.2).blocks[0][3..], 18).unwrap(), [0xFF, 0x10]);
    // 150,000 ft = 45,720 m = 24,000 LSB = 0x5DC0, the highest.
    assert_eq!(item(&h(45_720.0).blocks[0][3..], 18).unwrap(), [0x5D, 0xC0]);
    // -458.2 m → -240.52 → -241 and 45,721 m → 24,000.52 → 24,001 are
    // outside the specification's -1,500..=150,000 ft, though 16 bits hold
    // them: left out, and MRH/SRC then 0.
    for v in [-458.2, 45_721.0, f64::NAN] {
        let e = h(v);
        let rec = &e.blocks[0][3..];
        assert_eq!(item(rec, 18), None);
        assert_eq!(item(rec, 13).unwrap(), [0x00]);
        assert_eq!(e.skipped[0].item, "I062/130");
    }
}

#[test]
fn rate_of_climb_descent() {
    let r = |v: f64| {
        encode_one(&SystemTrack {
            vertical_rate: Some(v),
            ..base()
        })
    };
    // -10 m/s / (6.25 × 0.3048 / 60 m/s) = -314.96 → -315 = 0xFEC5.
    assert_eq!(item(&r(-10.0).blocks[0][3..], 20).unwrap(), [0xFE, 0xC5]);
    // The largest: 32,767 × 0.03175 m/s = 1,040.35 m/s → 0x7FFF; 1,041
    // m/s → 32,787 is out.
    assert_eq!(
        item(&r(32_767.0 * 0.031_75).blocks[0][3..], 20).unwrap(),
        [0x7F, 0xFF]
    );
    let e = r(1_041.0);
    assert_eq!(item(&e.blocks[0][3..], 20), None);
    assert_eq!(e.skipped[0].item, "I062/220");
}

#[test]
fn blocks_split_at_record_boundaries() {
    // The minimal record is 20 bytes: 3 + 20 + 20 = 43 ≤ 50 < 63.
    let tracks: Vec<SystemTrack> = (0..5)
        .map(|i| SystemTrack {
            track_number: i,
            ..base()
        })
        .collect();
    let lens = |max: usize| {
        encode_records(&cfg(), &tracks, max)
            .blocks
            .iter()
            .map(|b| {
                assert_eq!(b[0], 62);
                let len = usize::from(u16::from_be_bytes([b[1], b[2]]));
                assert_eq!(len, b.len());
                len
            })
            .collect::<Vec<_>>()
    };
    assert_eq!(lens(50), [43, 43, 23]);
    assert_eq!(lens(43), [43, 43, 23]);
    assert_eq!(lens(42), [23, 23, 23, 23, 23]);
    // Below one record: each record alone, over the limit.
    assert_eq!(lens(0), [23, 23, 23, 23, 23]);
    assert_eq!(lens(DEFAULT_MAX_BLOCK), [103]);
    // Records in order: track numbers 0..5 in the last two bytes of /040.
    let e = encode_records(&cfg(), &tracks, 50);
    let numbers: Vec<u16> = e
        .blocks
        .iter()
        .flat_map(|b| {
            b[3..]
                .chunks(20)
                .map(|r| u16::from_be_bytes([r[17], r[18]]))
                .collect::<Vec<_>>()
        })
        .collect();
    assert_eq!(numbers, [0, 1, 2, 3, 4]);
    // No track, or only dropped ones: no block.
    assert!(encode_records(&cfg(), &[], 1024).blocks.is_empty());
    let bad = SystemTrack {
        time_of_day: f64::NAN,
        ..base()
    };
    let e = encode_records(&cfg(), &[bad, bad], 1024);
    assert!(e.blocks.is_empty());
    assert_eq!(e.skipped.len(), 2);
    assert_eq!(e.skipped[1].track_index, 1);
    // A limit above LEN's range is taken as 65,535: 3,300 records of 20
    // bytes are 66,000 bytes, so two blocks.
    let many = vec![base(); 3_300];
    let e = encode_records(&cfg(), &many, usize::MAX);
    assert_eq!(e.blocks.len(), 2);
    assert_eq!(e.blocks[0].len(), 3 + 3_276 * 20);
}

#[test]
fn skip_reasons_say_what_and_why() {
    let e = encode_one(&SystemTrack {
        velocity: (9_000.0, 0.0),
        ..base()
    });
    let s = &e.skipped[0];
    assert_eq!(s.track_index, 0);
    assert_eq!(s.value, 9_000.0);
    assert_eq!(s.unit, "m/s");
    assert!(s.reason.contains("I062/185 VX"), "{}", s.reason);
    assert!(s.reason.contains("9000"), "{}", s.reason);
    assert!(s.reason.contains("-8192..=8191.75"), "{}", s.reason);
}

fn any_f64() -> impl Strategy<Value = f64> {
    prop_oneof![
        any::<f64>(),
        Just(f64::NAN),
        Just(f64::INFINITY),
        Just(f64::NEG_INFINITY),
        -1e7..1e7f64,
        -100.0..100.0f64,
    ]
}

fn opt<T: std::fmt::Debug + Clone>(
    s: impl Strategy<Value = T>,
) -> impl Strategy<Value = Option<T>> {
    prop_oneof![Just(None), s.prop_map(Some)]
}

fn any_track() -> impl Strategy<Value = SystemTrack> {
    let pair = || (any_f64(), any_f64());
    (
        (any::<u16>(), any_f64(), opt(pair()), pair(), pair()),
        (any::<[bool; 12]>(), 0u8..8),
        (
            opt(any_f64()),
            opt(any_f64()),
            opt(any_f64()),
            opt(any_f64()),
            opt(any_f64()),
            opt(any_f64()),
        ),
        (
            opt(pair()),
            opt(any_f64()),
            opt(pair()),
            opt(any_f64()),
            opt(pair()),
            opt(pair()),
            opt(any_f64()),
        ),
        (opt(any_f64()), opt(any_f64())),
        opt((opt(any::<(u8, u8)>()), opt(pair()), opt(any_f64()))),
    )
        .prop_map(|(a, (b, src), c, d, (height, vertical_rate), m)| {
            let sources = [
                AltitudeSource::NoSource,
                AltitudeSource::Gnss,
                AltitudeSource::Radar3d,
                AltitudeSource::Triangulation,
                AltitudeSource::HeightFromCoverage,
                AltitudeSource::SpeedLookUpTable,
                AltitudeSource::DefaultHeight,
                AltitudeSource::Multilateration,
            ];
            SystemTrack {
                track_number: a.0,
                time_of_day: a.1,
                wgs84: a.2,
                xy: a.3,
                velocity: a.4,
                status: TrackStatusFlags {
                    monosensor: b[0],
                    spi: b[1],
                    altitude_source: sources[usize::from(src)],
                    tentative: b[2],
                    simulated: b[3],
                    last_message: b[4],
                    first_message: b[5],
                    coasting: b[6],
                    psr_aged: b[7],
                    ssr_aged: b[8],
                    mode_s_aged: b[9],
                    adsb_inconsistent: b[10],
                    adsb_aged: b[11],
                },
                ages: UpdateAges {
                    track: c.0,
                    psr: c.1,
                    ssr: c.2,
                    mode_s: c.3,
                    adsb_es: c.4,
                    mlat: c.5,
                },
                accuracy: Some(Accuracy {
                    xy: d.0,
                    xy_covariance_m2: d.1,
                    wgs84: d.2,
                    geometric_altitude: d.3,
                    velocity: d.4,
                    acceleration: d.5,
                    vertical_rate: d.6,
                }),
                height,
                vertical_rate,
                last_measurement: m.map(|(sensor, polar, height)| LastMeasurement {
                    sensor,
                    polar,
                    height,
                }),
                address: Default::default(),
                measured_flight_level: Default::default(),
                callsign: Default::default(),
                mode_3a: Default::default(),
            }
        })
}

proptest! {
    #[test]
    fn never_panics_and_blocks_are_well_formed(
        tracks in proptest::collection::vec(any_track(), 0..12),
        max_block in 0usize..300,
        service in opt(any::<u8>()),
    ) {
        let c = Cat062Config { sac: 1, sic: 2, service_id: service };
        let e = encode_records(&c, &tracks, max_block);
        let mut records = 0;
        for b in &e.blocks {
            prop_assert_eq!(b[0], 62);
            prop_assert_eq!(usize::from(u16::from_be_bytes([b[1], b[2]])), b.len());
            let mut pos = 3;
            let mut in_block = 0;
            while pos < b.len() {
                let (_, n) = split(&b[pos..]);
                pos += n;
                in_block += 1;
            }
            prop_assert_eq!(pos, b.len());
            prop_assert!(in_block >= 1);
            prop_assert!(b.len() <= max_block || in_block == 1);
            records += in_block;
        }
        let dropped: std::collections::BTreeSet<usize> = e
            .skipped
            .iter()
            .filter(|s| s.record_dropped)
            .map(|s| s.track_index)
            .collect();
        prop_assert_eq!(records + dropped.len(), tracks.len());
        for s in e.skipped.iter().chain(&e.saturated) {
            prop_assert!(s.track_index < tracks.len());
            prop_assert!(!s.reason.is_empty());
        }
    }
}
