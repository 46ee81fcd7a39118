//! Decoding speed of the ASTERIX decoder (`wire_formats::asterix`) on the
//! libasterix fixture, and of the whole input path (decoding, SAC/SIC
//! mapping, time roll-over and plot validation) into a tracker's plots.
//!
//! `cargo run --release --example asterix_decode -- [--passes N]`

use std::time::Instant;

use service::plot_fusion::{self as svc, asterix as input, network};
use wire_formats::asterix;

const SCENE: &[u8] = include_bytes!("../tests/fixtures/asterix/scene.bin");

fn main() -> anyhow::Result<()> {
    let mut passes = 20_000usize;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--passes" => passes = args.next().unwrap_or_default().parse()?,
            other => anyhow::bail!("unknown argument {other}"),
        }
    }
    let once = asterix::decode(SCENE);
    let records = once.target_reports.len() + once.service_messages.len();
    let start = Instant::now();
    let mut sink = 0usize;
    for _ in 0..passes {
        let d = asterix::decode(std::hint::black_box(SCENE));
        sink += d.target_reports.len() + d.service_messages.len();
    }
    let s = start.elapsed().as_secs_f64();
    let n = (records * passes) as f64;
    println!(
        "decode: {records} records ({} bytes) × {passes}: {:.0} records/s, {:.3} µs/record, \
         {:.0} MB/s [{sink}]",
        SCENE.len(),
        n / s,
        s / n * 1e6,
        (SCENE.len() * passes) as f64 / s / 1e6
    );

    let radar = |id: &str, kind: &str, x: f64, period: f64, sic: u32| svc::RadarInput {
        id: Some(id.into()),
        kind: Some(kind.into()),
        site: Some(svc::SiteInput {
            geodetic: None,
            position_m: Some(vec![x, 0.0]),
        }),
        sigma_range_m: Some(60.0),
        sigma_azimuth_deg: Some(0.08),
        sigma_elevation_deg: (kind == "3d").then_some(0.2),
        sigma_radial_velocity_mps: (kind == "3d").then_some(2.0),
        scan_period_s: Some(period),
        sac: Some(25),
        sic: Some(sic),
        ..Default::default()
    };
    let spec = svc::SpecInput {
        radars: vec![
            radar("a", "2d", -20_000.0, 4.0, 1),
            radar("b", "3d", 20_000.0, 5.0, 2),
        ],
        ..Default::default()
    };
    let (net, config, _) = network::validate(&spec).map_err(|e| anyhow::anyhow!("{e}"))?;
    let clock = input::Clock::DayStart(0.0);
    let start = Instant::now();
    let mut plots = 0usize;
    for _ in 0..passes {
        plots += input::plots(&net, &config, std::hint::black_box(SCENE), clock, None)
            .plots
            .len();
    }
    let s = start.elapsed().as_secs_f64();
    println!(
        "to plots: {:.0} records/s, {:.3} µs/record ({} plots a pass)",
        n / s,
        s / n * 1e6,
        plots / passes
    );
    Ok(())
}
