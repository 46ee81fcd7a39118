//! Simulated AIS: ship positions reported in WGS84 at irregular intervals
//! (seed 004's second sensor), and an encoder for NMEA 0183 `!AIVDM` type-1
//! position reports (ITU-R M.1371 message 1, 168 bits, 6-bit ASCII armour),
//! since real users hold AIS as such sentences.

use rand::RngExt;
use rand_distr::StandardNormal;

use super::truth::Trajectory;
use super::{SimError, SimRng};
use algo::geo::LocalFrame;
use wire_formats::nmea::{self, BitWriter};

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

/// NMEA 0183 checksum (shared with the decoder in `wire_formats::nmea`).
pub fn nmea_checksum(body: &str) -> u8 {
    nmea::checksum(body)
}

pub use nmea::armour_char;

/// A simulated AIS–radar scene in the radar's local plane (x east, y north,
/// radar at the origin): ships moored along quays or sailing straight, radar
/// plots (the radar's tracks, one per ship) with a range and azimuth bias,
/// and AIS reports of the ships that carry AIS.
#[derive(Debug, Clone, PartialEq)]
pub struct AisSceneConfig {
    /// Ships moored in rows along quays, `berth_spacing` apart.
    pub moored: usize,
    /// Ships sailing straight at a uniform speed in `speed` on a uniform course.
    pub moving: usize,
    /// Fraction of the ships without AIS (the last ones of each kind).
    pub without_ais: f64,
    /// Centre-to-centre distance of neighbouring berths (m), uniform.
    pub berth_spacing: (f64, f64),
    /// Ships per quay row.
    pub berths_per_quay: usize,
    /// Centre of the quays (m east, m north of the radar).
    pub harbour_centre: [f64; 2],
    /// Start area of the sailing ships: `[east lo, east hi, north lo, north hi]` (m).
    pub sea: [f64; 4],
    /// Speed range of the sailing ships (m/s).
    pub speed: (f64, f64),
    /// Length of the scene (s).
    pub duration: f64,
    /// Radar scan period (s); one plot per ship per scan.
    pub radar_period: f64,
    pub sigma_range: f64,
    pub sigma_azimuth: f64,
    pub bias_range: f64,
    pub bias_azimuth: f64,
    /// Reporting intervals (s) of sailing and of moored ships.
    pub ais_interval_moving: (f64, f64),
    pub ais_interval_moored: (f64, f64),
    /// GNSS error of an AIS position per axis (m), independent per report.
    pub ais_sigma: f64,
    /// Standard deviation per axis of each ship's fixed antenna offset from
    /// the radar's reflection centre (m): an error shared by all reports of
    /// one ship.
    pub antenna_offset_sigma: f64,
}

impl AisSceneConfig {
    /// A busy harbour: `tracks` radar tracks, 60 % of them moored 10–70 m
    /// apart in rows of 12, the rest sailing at 2–10 m/s, a quarter without
    /// AIS; 20 minutes, radar every 2.5 s with σρ = 10 m and σθ = 0.1°, AIS
    /// every 2–10 s under way and every 3 min moored, GNSS σ 3 m, antenna
    /// offset σ 5 m.
    pub fn harbour(tracks: usize, bias_range: f64, bias_azimuth: f64) -> Self {
        let moored = tracks * 3 / 5;
        Self {
            moored,
            moving: tracks - moored,
            without_ais: 0.25,
            berth_spacing: (10.0, 70.0),
            berths_per_quay: 12,
            harbour_centre: [3000.0, 5000.0],
            sea: [-2000.0, 8000.0, 3000.0, 12_000.0],
            speed: (2.0, 10.0),
            duration: 1200.0,
            radar_period: 2.5,
            sigma_range: 10.0,
            sigma_azimuth: 0.1f64.to_radians(),
            bias_range,
            bias_azimuth,
            ais_interval_moving: (2.0, 10.0),
            ais_interval_moored: (180.0, 180.0),
            ais_sigma: 3.0,
            antenna_offset_sigma: 5.0,
        }
    }

    /// Seed 004 §3's open sea: `ships` ships in 20 × 20 km sailing at
    /// 30–80 m/s, all with AIS at the true position every 2–10 s, radar
    /// every 5 s for 30 scans with σρ = 50 m and σθ = 0.2°.
    pub fn open_sea(ships: usize, bias_range: f64, bias_azimuth: f64) -> Self {
        Self {
            moored: 0,
            moving: ships,
            without_ais: 0.0,
            sea: [0.0, 20_000.0, 0.0, 20_000.0],
            speed: (30.0, 80.0),
            duration: 145.0,
            radar_period: 5.0,
            sigma_range: 50.0,
            sigma_azimuth: 0.2f64.to_radians(),
            ais_sigma: 0.0,
            antenna_offset_sigma: 0.0,
            ..Self::harbour(0, bias_range, bias_azimuth)
        }
    }
}

/// A generated scene. Radar track i is ship i; AIS ship j is ship `owner[j]`.
#[derive(Debug, Clone, PartialEq)]
pub struct AisScene {
    pub radar: Vec<Vec<algo::bias::associate::RadarSample>>,
    pub ais: Vec<Vec<algo::bias::associate::AisPoint>>,
    pub owner: Vec<usize>,
    /// Velocity (m/s east, north) of every ship.
    pub velocity: Vec<[f64; 2]>,
}

impl AisSceneConfig {
    /// Draws a scene; times run from 0 to `duration`.
    pub fn generate(&self, rng: &mut SimRng) -> Result<AisScene, SimError> {
        use algo::bias::associate::{AisPoint, RadarSample, plane_to_polar};
        let ok = |x: f64| x.is_finite() && x > 0.0;
        if !(ok(self.duration) && ok(self.radar_period) && self.berths_per_quay > 0) {
            return Err(SimError::InvalidConfig(
                "duration, radar period and berths per quay must be > 0".into(),
            ));
        }
        let gauss = |rng: &mut SimRng, sd: f64| sd * rng.sample::<f64, _>(StandardNormal);
        let uniform = |rng: &mut SimRng, (lo, hi): (f64, f64)| {
            if lo < hi {
                rng.random_range(lo..hi)
            } else {
                lo
            }
        };
        // (start position, velocity, carries AIS, moored)
        let mut ships: Vec<([f64; 2], [f64; 2], bool, bool)> = Vec::new();
        let no_ais = |count: usize, k: usize| {
            k >= count - (count as f64 * self.without_ais).round() as usize
        };
        let mut along = 0.0;
        for k in 0..self.moored {
            let quay = k / self.berths_per_quay;
            if k % self.berths_per_quay == 0 {
                along = 0.0;
            } else {
                along += uniform(rng, self.berth_spacing);
            }
            let p = [
                self.harbour_centre[0] - 400.0 + along,
                self.harbour_centre[1] + 300.0 * quay as f64,
            ];
            ships.push((p, [0.0, 0.0], !no_ais(self.moored, k), true));
        }
        for k in 0..self.moving {
            let p = [
                uniform(rng, (self.sea[0], self.sea[1])),
                uniform(rng, (self.sea[2], self.sea[3])),
            ];
            let speed = uniform(rng, self.speed);
            let course: f64 = rng.random_range(0.0..std::f64::consts::TAU);
            let v = [speed * course.sin(), speed * course.cos()];
            ships.push((p, v, !no_ais(self.moving, k), false));
        }
        let mut scene = AisScene {
            radar: Vec::new(),
            ais: Vec::new(),
            owner: Vec::new(),
            velocity: ships.iter().map(|s| s.1).collect(),
        };
        let scans = (self.duration / self.radar_period).floor() as usize;
        for (s, &(p0, v, with_ais, moored)) in ships.iter().enumerate() {
            let at = |t: f64| [p0[0] + v[0] * t, p0[1] + v[1] * t];
            let mut track = Vec::with_capacity(scans + 1);
            for k in 0..=scans {
                let t = k as f64 * self.radar_period;
                let (r, a) = plane_to_polar(at(t));
                track.push(RadarSample {
                    t,
                    range: r + self.bias_range + gauss(rng, self.sigma_range),
                    azimuth: (a + self.bias_azimuth + gauss(rng, self.sigma_azimuth))
                        .rem_euclid(std::f64::consts::TAU),
                });
            }
            scene.radar.push(track);
            if with_ais {
                let interval = if moored {
                    self.ais_interval_moored
                } else {
                    self.ais_interval_moving
                };
                let offset = [
                    gauss(rng, self.antenna_offset_sigma),
                    gauss(rng, self.antenna_offset_sigma),
                ];
                let mut reports = Vec::new();
                let mut t = rng.random::<f64>() * uniform(rng, interval);
                while t <= self.duration {
                    let p = at(t);
                    reports.push(AisPoint::exact(
                        t,
                        [
                            p[0] + offset[0] + gauss(rng, self.ais_sigma),
                            p[1] + offset[1] + gauss(rng, self.ais_sigma),
                        ],
                    ));
                    t += uniform(rng, interval);
                }
                scene.ais.push(reports);
                scene.owner.push(s);
            }
        }
        Ok(scene)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::montecarlo::run_rng;
    use crate::truth::{TargetPlan, simulate};
    use algo::geo::Ellipsoid;

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

    /// Round trip through the service's decoder (`wire_formats::nmea`).
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
