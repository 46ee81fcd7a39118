//! Simulated AIS: ship positions reported in WGS84 at irregular intervals
//! (seed 004's second sensor), and an encoder for NMEA 0183 `!AIVDM` type-1
//! position reports (ITU-R M.1371 message 1, 168 bits, 6-bit ASCII armour),
//! since real users hold AIS as such sentences.

use rand::RngExt;
use rand_distr::StandardNormal;

use super::truth::Trajectory;
use super::{SimError, SimRng};
use crate::algo::bias::nmea::{self, BitWriter};
use crate::algo::geo::LocalFrame;

/// Metres per second in one knot.
pub const MPS_PER_KNOT: f64 = 1852.0 / 3600.0;

/// One AIS position report as received (before encoding).
#[derive(Debug, Clone, PartialEq)]
pub struct AisReport {
    /// Time of the report (s, same epoch as the scenario).
    pub t: f64,
    /// Maritime Mobile Service Identity.
    pub mmsi: u32,
    /// WGS84 latitude (degrees).
    pub lat_deg: f64,
    /// WGS84 longitude (degrees).
    pub lon_deg: f64,
    /// Speed over ground (knots).
    pub sog_knots: f64,
    /// Course over ground (degrees clockwise from north, [0, 360)).
    pub cog_deg: f64,
    /// Truth label: the scenario's target index.
    pub target: usize,
}

/// Generates AIS reports for ships.
#[derive(Debug, Clone, PartialEq)]
pub struct AisReporter {
    /// The local frame the scenario lives in.
    pub frame: LocalFrame,
    /// Reporting interval range `[lo, hi]` (s), drawn uniformly per report.
    pub interval: (f64, f64),
    /// Standard deviation of the reported position per axis (m), e.g. GNSS error.
    pub sigma_position: f64,
}

impl AisReporter {
    /// Reports of the ship following `traj` between `t0` and `t1`: the first
    /// at `t0` plus a uniform fraction of an interval, then one every
    /// uniform(`interval`) seconds.
    pub fn reports(
        &self,
        traj: &Trajectory,
        target: usize,
        mmsi: u32,
        t0: f64,
        t1: f64,
        rng: &mut SimRng,
    ) -> Result<Vec<AisReport>, SimError> {
        let (lo, hi) = self.interval;
        if !(lo.is_finite() && hi.is_finite() && 0.0 < lo && lo <= hi) {
            return Err(SimError::InvalidConfig(
                "AIS interval must satisfy 0 < lo <= hi".into(),
            ));
        }
        let draw = |rng: &mut SimRng| {
            if lo == hi {
                lo
            } else {
                rng.random_range(lo..hi)
            }
        };
        let mut out = Vec::new();
        let mut t = t0 + rng.random::<f64>() * draw(rng);
        while t <= t1 {
            if let Some(s) = traj.state_at(t) {
                let ne: f64 = rng.sample(StandardNormal);
                let nn: f64 = rng.sample(StandardNormal);
                let enu = [
                    s[0] + self.sigma_position * ne,
                    s[2] + self.sigma_position * nn,
                    0.0,
                ];
                let (lat, lon, _) = self.frame.enu_to_geodetic(enu)?;
                out.push(AisReport {
                    t,
                    mmsi,
                    lat_deg: lat.to_degrees(),
                    lon_deg: lon.to_degrees(),
                    sog_knots: s[1].hypot(s[3]) / MPS_PER_KNOT,
                    cog_deg: s[1].atan2(s[3]).to_degrees().rem_euclid(360.0),
                    target,
                });
            }
            t += draw(rng);
        }
        Ok(out)
    }
}

/// The fields of an AIS message 1 (position report, class A), in the units
/// of the message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PositionReport {
    /// MMSI (30 bits).
    pub mmsi: u32,
    /// Navigational status (0 under way using engine … 15 not defined).
    pub nav_status: u8,
    /// Rate of turn, raw signed value (−128 = not available).
    pub rot: i8,
    /// Speed over ground in 0.1 knot (1023 = not available).
    pub sog_tenths: u16,
    /// Position accuracy flag (1 = better than 10 m).
    pub accuracy: bool,
    /// Longitude in 1/10000 minute (181° = not available).
    pub lon: i32,
    /// Latitude in 1/10000 minute (91° = not available).
    pub lat: i32,
    /// Course over ground in 0.1° (3600 = not available).
    pub cog_tenths: u16,
    /// True heading in degrees (511 = not available).
    pub heading: u16,
    /// UTC second of the report (60 = not available).
    pub second: u8,
    /// Manoeuvre indicator (0 = not available).
    pub manoeuvre: u8,
    /// RAIM flag.
    pub raim: bool,
    /// Radio status (19 bits, SOTDMA/ITDMA communication state).
    pub radio: u32,
}

impl PositionReport {
    /// The message for a simulated report: under way using engine, rate of
    /// turn and heading not available, UTC second from `t`.
    pub fn from_report(r: &AisReport) -> Self {
        Self {
            mmsi: r.mmsi,
            nav_status: 0,
            rot: -128,
            sog_tenths: ((r.sog_knots * 10.0).round() as u16).min(1022),
            accuracy: false,
            lon: (r.lon_deg * 600_000.0).round() as i32,
            lat: (r.lat_deg * 600_000.0).round() as i32,
            cog_tenths: ((r.cog_deg * 10.0).round() as u16) % 3600,
            heading: 511,
            second: (r.t.floor() as i64).rem_euclid(60) as u8,
            manoeuvre: 0,
            raim: false,
            radio: 0,
        }
    }

    /// The 168-bit payload armoured into 28 six-bit characters.
    pub fn payload(&self) -> String {
        let mut w = BitWriter::default();
        w.put(1, 6); // message type
        w.put(0, 2); // repeat indicator
        w.put(u64::from(self.mmsi), 30);
        w.put(u64::from(self.nav_status), 4);
        w.put(self.rot as u8 as u64, 8);
        w.put(u64::from(self.sog_tenths), 10);
        w.put(u64::from(self.accuracy), 1);
        w.put_signed(i64::from(self.lon), 28);
        w.put_signed(i64::from(self.lat), 27);
        w.put(u64::from(self.cog_tenths), 12);
        w.put(u64::from(self.heading), 9);
        w.put(u64::from(self.second), 6);
        w.put(u64::from(self.manoeuvre), 2);
        w.put(0, 3); // spare
        w.put(u64::from(self.raim), 1);
        w.put(u64::from(self.radio), 19);
        debug_assert_eq!(w.len(), 168);
        w.armoured().0
    }

    /// A single-fragment `!AIVDM` sentence on `channel` ('A' or 'B').
    pub fn sentence(&self, channel: char) -> String {
        let body = format!("AIVDM,1,1,,{channel},{},0", self.payload());
        format!("!{body}*{:02X}", nmea_checksum(&body))
    }
}

/// NMEA 0183 checksum (shared with the decoder in `algo::bias::nmea`).
pub fn nmea_checksum(body: &str) -> u8 {
    nmea::checksum(body)
}

pub use nmea::armour_char;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algo::geo::Ellipsoid;
    use crate::sim::montecarlo::run_rng;
    use crate::sim::truth::{TargetPlan, simulate};

    /// The published example of the gpsd "AIVDM/AIVDO protocol decoding"
    /// document and many AIS decoders' test suites; its decoding there is
    /// MMSI 477553000, status 5 (moored), ROT 0, SOG 0, accuracy 0,
    /// lon −122.345833°, lat 47.582833°, COG 51.0°, heading 181, second 15.
    const PUBLISHED: &str = "!AIVDM,1,1,,B,177KQJ5000G?tO`K>RA1wUbN0TKH,0*5C";

    /// Test-only de-armouring and bit reading, written independently of the
    /// encoder: character c → c − 48, minus 8 more if above 40.
    fn bits_of(payload: &str) -> Vec<u8> {
        payload
            .bytes()
            .flat_map(|c| {
                let mut v = c - 48;
                if v > 40 {
                    v -= 8;
                }
                (0..6).rev().map(move |i| (v >> i) & 1)
            })
            .collect()
    }

    fn field(bits: &[u8], start: usize, len: usize) -> u64 {
        bits[start..start + len]
            .iter()
            .fold(0, |acc, &b| (acc << 1) | u64::from(b))
    }

    fn signed(bits: &[u8], start: usize, len: usize) -> i64 {
        let v = field(bits, start, len) as i64;
        if v >> (len - 1) == 1 {
            v - (1 << len)
        } else {
            v
        }
    }

    #[test]
    fn published_sentence_decodes_to_its_published_fields() {
        let payload = PUBLISHED.split(',').nth(5).unwrap();
        let b = bits_of(payload);
        assert_eq!(b.len(), 168);
        assert_eq!(field(&b, 0, 6), 1);
        assert_eq!(field(&b, 8, 30), 477_553_000);
        assert_eq!(field(&b, 38, 4), 5);
        assert_eq!(signed(&b, 42, 8), 0);
        assert_eq!(field(&b, 50, 10), 0);
        let lon = signed(&b, 61, 28) as f64 / 600_000.0;
        let lat = signed(&b, 89, 27) as f64 / 600_000.0;
        assert!((lon + 122.345833).abs() < 1e-6, "{lon}");
        assert!((lat - 47.582833).abs() < 1e-6, "{lat}");
        assert_eq!(field(&b, 116, 12), 510);
        assert_eq!(field(&b, 128, 9), 181);
        assert_eq!(field(&b, 137, 6), 15);
        // Checksum: XOR of the characters between '!' and '*' is 0x5C.
        let body = &PUBLISHED[1..PUBLISHED.find('*').unwrap()];
        assert_eq!(nmea_checksum(body), 0x5C);
    }

    #[test]
    fn encoder_reproduces_the_published_sentence() {
        let b = bits_of(PUBLISHED.split(',').nth(5).unwrap());
        let msg = PositionReport {
            mmsi: 477_553_000,
            nav_status: 5,
            rot: 0,
            sog_tenths: 0,
            accuracy: false,
            lon: signed(&b, 61, 28) as i32,
            lat: signed(&b, 89, 27) as i32,
            cog_tenths: 510,
            heading: 181,
            second: 15,
            manoeuvre: field(&b, 143, 2) as u8,
            raim: field(&b, 148, 1) == 1,
            radio: field(&b, 149, 19) as u32,
        };
        assert_eq!(msg.sentence('B'), PUBLISHED);
    }

    /// Round trip through the service's decoder (`algo::bias::nmea`).
    #[test]
    fn encoded_sentences_decode_with_the_service_decoder() {
        let r = AisReport {
            t: 12.0,
            mmsi: 412_000_007,
            lat_deg: -33.856_789,
            lon_deg: 151.215_432,
            sog_knots: 14.2,
            cog_deg: 271.3,
            target: 0,
        };
        let d = nmea::decode(&[PositionReport::from_report(&r).sentence('A')]);
        assert!(d.errors.is_empty());
        let p = &d.positions[0];
        assert_eq!((p.message_type, p.mmsi), (1, 412_000_007));
        // 1/10000 minute resolution: half a unit is 1/1 200 000 degree.
        assert!((p.lat_deg - r.lat_deg).abs() <= 0.5 / 600_000.0 + 1e-12);
        assert!((p.lon_deg - r.lon_deg).abs() <= 0.5 / 600_000.0 + 1e-12);
        assert_eq!((p.sog_knots, p.cog_deg), (Some(14.2), Some(271.3)));
    }

    #[test]
    fn negative_fields_and_not_available_values_round_trip() {
        let r = AisReport {
            t: 125.7,
            mmsi: 235_000_001,
            lat_deg: -33.9,
            lon_deg: 151.2,
            sog_knots: 12.34,
            cog_deg: 359.99,
            target: 0,
        };
        let m = PositionReport::from_report(&r);
        let b = bits_of(&m.payload());
        assert_eq!(field(&b, 8, 30), 235_000_001);
        // ROT not available is −128 (0x80).
        assert_eq!(signed(&b, 42, 8), -128);
        assert_eq!(field(&b, 50, 10), 123);
        assert_eq!(signed(&b, 89, 27), (-33.9f64 * 600_000.0).round() as i64);
        assert_eq!(signed(&b, 61, 28), 90_720_000);
        // 359.99° rounds to 3600 tenths, which wraps to 0.
        assert_eq!(field(&b, 116, 12), 0);
        assert_eq!(field(&b, 128, 9), 511);
        assert_eq!(field(&b, 137, 6), 5); // 125 s → second 5
    }

    #[test]
    fn reports_come_at_irregular_intervals_in_wgs84() {
        let frame = LocalFrame::new(
            Ellipsoid::WGS84,
            30f64.to_radians(),
            122f64.to_radians(),
            0.0,
        )
        .unwrap();
        let plan = TargetPlan::constant_velocity(0.0, [0.0, 0.0, 0.0, 10.0, 0.0, 0.0]);
        let mut rng = run_rng(1, 0);
        let traj = simulate(&plan, 1.0, 1000.0, &mut rng).unwrap();
        let rep = AisReporter {
            frame,
            interval: (2.0, 10.0),
            sigma_position: 0.0,
        };
        let out = rep.reports(&traj, 0, 1, 0.0, 1000.0, &mut rng).unwrap();
        // Mean interval 6 s over 1000 s: about 167 reports.
        assert!((120..220).contains(&out.len()), "{}", out.len());
        for w in out.windows(2) {
            let dt = w[1].t - w[0].t;
            assert!((2.0..10.0).contains(&dt));
        }
        let last = out.last().unwrap();
        // 10 m/s north = 19.438 kn, course 0°; latitude grows ~ 1/111 km.
        assert!((last.sog_knots - 10.0 / MPS_PER_KNOT).abs() < 1e-9);
        assert!(last.cog_deg.abs() < 1e-9);
        let north = 10.0 * last.t;
        assert!((last.lat_deg - 30.0 - north / 110_850.0).abs() < 1e-3);
        assert!((last.lon_deg - 122.0).abs() < 1e-9);
    }
}
