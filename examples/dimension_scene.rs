//! Dimension fusion (seed 003) on the benchmark scene of issue 15: compute
//! time, covariance consistency and association, in one run.
//!
//! ```text
//! cargo run --release --example dimension_scene -- \
//!     [--aircraft 36] [--duration 300] [--seeds 1,2,3] [--repeat 15] \
//!     [--dump FILE] [--dump-kinds FILE]
//! ```
//!
//! The scene is `sim::experiments::seed003_dimension::bench_scene`: two 3D
//! and two 2D radars tens of km apart, 10 s scans with different phases,
//! aircraft at 1–12 km (some turning), about 2,000 plots in about 90 local
//! tracks. For each seed and filter (α-β, Kalman) it runs the three methods
//! with the service's defaults and prints:
//! - compute: the median over `--repeat` runs of the wall time of
//!   `algo::dimension::fuse_methods` for all three methods (filters,
//!   association, fusion), and of `fuse_methods_with(…, Samples::Latest)`
//!   (each system track's latest sample only, as the service fuses an
//!   answer without history), checked against the history's last samples
//!   bit for bit;
//! - NEES: the mean 3D position NEES of the samples of pure system tracks
//!   (3 for a consistent estimator), over all samples and over the samples
//!   with a 3D member, and the share above χ²₃(0.99) = 11.34;
//! - association: multi-radar aircraft whose local tracks all form one pure
//!   system track;
//! - a digest of every pair's K-NN state and every group, to check that a
//!   change of the code leaves the association decisions as they were, and
//!   a digest of the bits of every number of the outcome (pair statistics,
//!   fused samples and covariances, altitude sources), to check that it
//!   leaves the estimates as they were; `--dump FILE` writes those numbers
//!   (one a line) for a comparison when the bits differ, and
//!   `--dump-kinds FILE` what each line of that dump is (`method:field`,
//!   for `checks/compare_dumps.py`).

use std::time::Instant;

use algo::{
    dimension::{self, Config, Filter, KnnParams, Method, Samples},
    gating::chi2_threshold,
};
use anyhow::{Context, bail};
use eval::{
    experiments::seed003_dimension::{BenchScene, bench_scene, position_nees},
    montecarlo::run_rng,
};
use service::dimension as svc;

const METHODS: [Method; 3] = [Method::Mapping, Method::Lifting, Method::Splitting];

fn config(filter: Filter) -> anyhow::Result<Config> {
    Ok(Config {
        filter,
        knn: KnnParams {
            n0: svc::DEFAULT_N0,
            k: svc::DEFAULT_K,
        },
        preset_altitude: svc::DEFAULT_PRESET_ALTITUDE_M,
        altitude_sigma: svc::DEFAULT_ALTITUDE_SIGMA_M,
        gate_sigmas: svc::DEFAULT_GATE_SIGMAS,
        chi2_2: chi2_threshold(2, svc::DEFAULT_SIGNIFICANCE)?,
        chi2_3: chi2_threshold(3, svc::DEFAULT_SIGNIFICANCE)?,
    })
}

/// FNV-1a of the association decisions.
fn digest(outs: &[dimension::Outcome]) -> u64 {
    let mut text = String::new();
    for o in outs {
        for p in &o.pairs {
            text.push_str(&format!("{}-{}:{:?};", p.a, p.b, p.state));
        }
        for s in &o.system_tracks {
            text.push_str(&format!("{:?}|", s.members));
        }
        text.push_str(&format!("c{}#", o.conflicts));
    }
    fnv(text.bytes())
}

fn fnv(bytes: impl Iterator<Item = u8>) -> u64 {
    bytes.fold(0xcbf2_9ce4_8422_2325u64, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    })
}

/// Every number of the outcomes in order: per pair its mean statistic, per
/// system-track sample t, x, p (column by column) and the altitude source
/// (0, 1, 2); with each, what it is (`method:stat`, `:t`, `:x3`, `:p24`
/// for row 2, column 4, `:alt`).
fn numbers(outs: &[dimension::Outcome]) -> (Vec<f64>, Vec<String>) {
    let (mut v, mut kinds) = (Vec::new(), Vec::new());
    for (o, m) in outs.iter().zip(METHODS) {
        let mut push = |x: f64, kind: String| {
            v.push(x);
            kinds.push(format!("{m:?}:{kind}"));
        };
        for p in &o.pairs {
            push(p.mean_statistic, "stat".into());
        }
        for s in o.system_tracks.iter().flat_map(|s| &s.samples) {
            push(s.t, "t".into());
            for (i, x) in s.x.iter().enumerate() {
                push(*x, format!("x{i}"));
            }
            for (k, x) in s.p.iter().enumerate() {
                push(*x, format!("p{}{}", k % 6, k / 6));
            }
            let alt = match s.altitude {
                dimension::AltitudeSource::Measured => 0.0,
                dimension::AltitudeSource::Lifted => 1.0,
                dimension::AltitudeSource::Assumed => 2.0,
            };
            push(alt, "alt".into());
        }
    }
    (v, kinds)
}

/// Whether `latest` (`Samples::Latest`) has the pairs, groups and conflicts
/// of `all` and, per system track, one sample whose every bit is the last
/// sample of the history.
fn same_latest(all: &[dimension::Outcome], latest: &[dimension::Outcome]) -> bool {
    let bits = |s: &dimension::Sample| {
        std::iter::once(s.t)
            .chain(s.x.iter().copied())
            .chain(s.p.iter().copied())
            .map(f64::to_bits)
            .collect::<Vec<_>>()
    };
    all.len() == latest.len()
        && all.iter().zip(latest).all(|(a, l)| {
            a.pairs == l.pairs
                && a.conflicts == l.conflicts
                && a.system_tracks.len() == l.system_tracks.len()
                && a.system_tracks
                    .iter()
                    .zip(&l.system_tracks)
                    .all(|(ta, tl)| {
                        ta.members == tl.members
                            && tl.samples.len() == 1
                            && ta.samples.last().map(bits) == Some(bits(&tl.samples[0]))
                            && ta.samples.last().map(|s| s.altitude) == Some(tl.samples[0].altitude)
                    })
        })
}

/// (multi-radar aircraft, those in exactly one pure system track holding all
/// of their local tracks).
fn association(scene: &BenchScene, out: &dimension::Outcome) -> (usize, usize) {
    let (mut multi, mut good) = (0, 0);
    for a in 0..scene.truth.len() {
        let mine: Vec<usize> = (0..scene.tracks.len())
            .filter(|&i| scene.owner[i] == a)
            .collect();
        let mut radars: Vec<usize> = mine.iter().map(|&i| scene.tracks[i].radar).collect();
        radars.sort_unstable();
        radars.dedup();
        if radars.len() < 2 {
            continue;
        }
        multi += 1;
        if out.system_tracks.iter().any(|s| s.members == mine) {
            good += 1;
        }
    }
    (multi, good)
}

fn main() -> anyhow::Result<()> {
    let mut aircraft = 36usize;
    let mut duration = 300.0;
    let mut seeds = vec![1u64, 2, 3];
    let mut repeat = 15usize;
    let mut dump: Option<String> = None;
    let mut dump_kinds: Option<String> = None;
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let value = it.next().context("a flag needs a value")?;
        match flag.as_str() {
            "--aircraft" => aircraft = value.parse()?,
            "--duration" => duration = value.parse()?,
            "--repeat" => repeat = value.parse::<usize>()?.max(1),
            "--seeds" => seeds = value.split(',').map(str::parse).collect::<Result<_, _>>()?,
            "--dump" => dump = Some(value),
            "--dump-kinds" => dump_kinds = Some(value),
            other => bail!("unknown flag {other}"),
        }
    }
    let chi2_99 = chi2_threshold(3, 0.01)?;
    let (mut dumped, mut kinds_dumped) = (String::new(), String::new());
    for seed in seeds {
        let mut rng = run_rng(seed, 0);
        let scene = bench_scene(aircraft, duration, &mut rng)?;
        let plots: usize = scene.tracks.iter().map(|t| t.plots.len()).sum();
        println!(
            "seed {seed}: {} aircraft, {} local tracks, {plots} plots",
            scene.truth.len(),
            scene.tracks.len()
        );
        for (fname, filter) in [
            (
                "alpha_beta",
                Filter::AlphaBeta {
                    window: svc::DEFAULT_WINDOW as usize,
                },
            ),
            (
                "kalman",
                Filter::Kalman {
                    sigma_a: svc::DEFAULT_SIGMA_A_MPS2,
                },
            ),
        ] {
            let cfg = config(filter)?;
            let timed = |samples| {
                timed(repeat, || {
                    dimension::fuse_methods_with(
                        &scene.centre,
                        &scene.radars,
                        &scene.tracks,
                        &METHODS,
                        &cfg,
                        samples,
                    )
                })
            };
            let (times, outs) = timed(Samples::All)?;
            // The same scene fusing only each system track's latest sample
            // (the service's answer without history).
            let (latest_times, latest) = timed(Samples::Latest)?;
            let (values, kinds) = numbers(&outs);
            println!(
                "  {fname:<10} compute (3 methods) median {:.2} ms (min {:.2}, max {:.2}), decisions {:016x}, estimates {:016x}",
                times[times.len() / 2],
                times[0],
                times[times.len() - 1],
                digest(&outs),
                fnv(values.iter().flat_map(|v| v.to_bits().to_le_bytes()))
            );
            println!(
                "  {:<10} latest samples only: median {:.2} ms (min {:.2}, max {:.2}), the history's last samples to the bit: {}",
                "",
                latest_times[latest_times.len() / 2],
                latest_times[0],
                latest_times[latest_times.len() - 1],
                if same_latest(&outs, &latest) {
                    "yes"
                } else {
                    "NO"
                }
            );
            let header = format!("# seed {seed} {fname} {}\n", values.len());
            if dump.is_some() {
                dumped.push_str(&header);
                for v in &values {
                    dumped.push_str(&format!("{v:e}\n"));
                }
            }
            if dump_kinds.is_some() {
                kinds_dumped.push_str(&header);
                for k in &kinds {
                    kinds_dumped.push_str(k);
                    kinds_dumped.push('\n');
                }
            }
            for (m, o) in METHODS.iter().zip(&outs) {
                let nees = position_nees(&scene, o);
                let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
                let all: Vec<f64> = nees.iter().map(|n| n.0).collect();
                let measured: Vec<f64> = nees.iter().filter(|n| n.1).map(|n| n.0).collect();
                let over =
                    all.iter().filter(|&&n| n > chi2_99).count() as f64 / all.len().max(1) as f64;
                let (multi, good) = association(&scene, o);
                println!(
                    "    {:<9} NEES mean {:>7.2} (3D-measured samples {:>7.2}, n = {}), > χ²₃(0.99): {:>5.1} %; \
                     aircraft in one pure track {good}/{multi}; system tracks {}",
                    format!("{m:?}"),
                    mean(&all),
                    mean(&measured),
                    all.len(),
                    100.0 * over,
                    o.system_tracks.len()
                );
            }
        }
    }
    for (path, text) in [(dump, dumped), (dump_kinds, kinds_dumped)] {
        if let Some(path) = path {
            std::fs::write(&path, text).with_context(|| format!("writing {path}"))?;
        }
    }
    Ok(())
}

/// `f` run `repeat` times (at least once): its wall times in ms, sorted,
/// and its last outcome.
fn timed<T, E>(repeat: usize, mut f: impl FnMut() -> Result<T, E>) -> Result<(Vec<f64>, T), E> {
    let mut times = Vec::new();
    let mut last = None;
    for _ in 0..repeat.max(1) {
        let start = Instant::now();
        last = Some(f()?);
        times.push(start.elapsed().as_secs_f64() * 1e3);
    }
    times.sort_by(f64::total_cmp);
    Ok((times, last.expect("at least one run")))
}
