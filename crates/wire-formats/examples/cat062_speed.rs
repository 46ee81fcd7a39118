//! Speed of the CAT062 encoder: 1,000 system tracks with every item the
//! encoder writes (WGS-84 and Cartesian positions, velocity, status with
//! extensions, ages, geometric altitude, rate of climb, accuracies,
//! measured information), encoded 1,000 times into 1,024-byte blocks.
//!
//!     cargo run -p wire-formats --release --example cat062_speed [tracks] [repetitions]

use std::hint::black_box;
use std::time::Instant;
use wire_formats::cat062::{
    Accuracy, AltitudeSource, Cat062Config, DEFAULT_MAX_BLOCK, LastMeasurement, SystemTrack,
    TrackStatusFlags, UpdateAges, encode_records,
};

fn tracks(n: usize) -> Vec<SystemTrack> {
    (0..n)
        .map(|i| {
            let k = i as f64;
            SystemTrack {
                track_number: (i % 65_536) as u16,
                time_of_day: 43_200.0 + k * 0.003,
                wgs84: Some((50.0 + k * 1e-3, 4.0 - k * 1e-3)),
                xy: (-150_000.0 + k * 301.7, 120_000.0 - k * 211.3),
                velocity: (-200.0 + k * 0.41, 180.0 - k * 0.37),
                status: TrackStatusFlags {
                    altitude_source: AltitudeSource::Radar3d,
                    tentative: i % 10 == 0,
                    coasting: i % 7 == 0,
                    last_message: i % 97 == 0,
                    ..TrackStatusFlags::default()
                },
                ages: UpdateAges {
                    track: Some(k % 300.0),
                    psr: Some(1.5),
                    ssr: Some(0.5),
                    mode_s: None,
                    adsb_es: Some(0.5),
                    mlat: None,
                },
                accuracy: Some(Accuracy {
                    xy: Some((40.0, 55.0)),
                    xy_covariance_m2: Some(-120.0),
                    velocity: Some((2.0, 2.5)),
                    geometric_altitude: Some(30.0),
                    ..Accuracy::default()
                }),
                height: Some(3_000.0 + k),
                vertical_rate: Some(-3.0),
                last_measurement: Some(LastMeasurement {
                    sensor: Some((25, (i % 4) as u8)),
                    polar: Some((40_000.0 + k * 50.0, (k * 7.3) % 360.0)),
                    height: None,
                }),
                callsign: Default::default(),
                address: Default::default(),
                measured_flight_level: Default::default(),
                mode_3a: Default::default(),
            }
        })
        .collect()
}

fn main() {
    let mut args = std::env::args().skip(1);
    let n: usize = args.next().and_then(|a| a.parse().ok()).unwrap_or(1_000);
    let reps: usize = args.next().and_then(|a| a.parse().ok()).unwrap_or(1_000);
    let cfg = Cat062Config {
        sac: 25,
        sic: 100,
        service_id: Some(1),
    };
    let tracks = tracks(n);
    let first = encode_records(&cfg, &tracks, DEFAULT_MAX_BLOCK);
    let bytes: usize = first.blocks.iter().map(Vec::len).sum();
    let start = Instant::now();
    let mut total = 0usize;
    for _ in 0..reps {
        let e = encode_records(black_box(&cfg), black_box(&tracks), DEFAULT_MAX_BLOCK);
        total += e.blocks.len();
        black_box(e);
    }
    let s = start.elapsed().as_secs_f64();
    let records = (n * reps) as f64;
    println!(
        "{n} tracks x {reps}: {} blocks, {bytes} bytes ({:.1} bytes/record) a pass; \
         {:.3} s, {:.2} M records/s, {:.0} MB/s, {:.0} ns/record",
        total / reps.max(1),
        bytes as f64 / n.max(1) as f64,
        s,
        records / s / 1e6,
        (bytes * reps) as f64 / s / 1e6,
        s / records * 1e9
    );
}
