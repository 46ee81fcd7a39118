//! Fuzzing of the decoders of untrusted bytes on stable Rust (issue 53):
//! ASTERIX CAT048/CAT034/CAT021/CAT020 (`wire_formats::asterix::decode`), NMEA
//! AIVDM/AIVDO (`wire_formats::nmea::decode`), stored sessions of both kinds
//! (`Envelope::decode`), stored tracker state (`decode_tracker`), session
//! events (`events::decode`) and the X.509 fields the server reads from a
//! client certificate (`tls::x509`). No nightly toolchain and no
//! instrumentation: each target mutates the inputs of its corpus
//! (`fuzz/corpus/<target>/`, plus the fixtures and seeds named below) with
//! a seeded generator (bit flips, interesting bytes, inserted, deleted,
//! repeated and spliced ranges, truncation), and every input must decode
//! or be refused without a panic. A panicking input is written to
//! `target/fuzz-crashes/<target>-<n>.bin` and the run fails.
//!
//! `cargo run --release --example fuzz -- [--seconds S] [--seed N] [TARGET…]`
//! (`checks/fuzz.sh` runs every target for `FUZZ_SECONDS`, 60 s by default).

use std::{
    panic::{AssertUnwindSafe, catch_unwind},
    path::Path,
    time::{Duration, Instant},
};

use service::session::{
    Envelope, correlation::CorrelationSession, events, plot_fusion::PlotFusionSession,
};

const TARGETS: [&str; 6] = ["asterix", "nmea", "session", "tracker", "event", "x509"];

fn main() -> anyhow::Result<()> {
    let mut seconds = 10.0f64;
    let mut seed = 53u64;
    let mut chosen = Vec::new();
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--seconds" => seconds = args.next().unwrap_or_default().parse()?,
            "--seed" => seed = args.next().unwrap_or_default().parse()?,
            t if TARGETS.contains(&t) => chosen.push(t.to_string()),
            other => anyhow::bail!("unknown argument {other} (targets: {TARGETS:?})"),
        }
    }
    if chosen.is_empty() {
        chosen = TARGETS.iter().map(|t| t.to_string()).collect();
    }
    // Panics are caught and reported here, one line each.
    std::panic::set_hook(Box::new(|_| {}));
    let mut failed = false;
    for target in &chosen {
        let corpus = corpus(target)?;
        let (runs, crashes) = fuzz(target, &corpus, Duration::from_secs_f64(seconds), seed)?;
        println!(
            "{target:8} {} seed input(s), {runs} runs in {seconds} s ({:.0}/s), {crashes} crash(es)",
            corpus.len(),
            runs as f64 / seconds
        );
        failed |= crashes > 0;
    }
    if failed {
        anyhow::bail!("a decoder panicked: inputs in target/fuzz-crashes/");
    }
    Ok(())
}

/// The seed inputs of `target`: the files of its corpus directory, and
/// fixtures and generated values named here.
fn corpus(target: &str) -> anyhow::Result<Vec<Vec<u8>>> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut seeds = Vec::new();
    let dir = root.join("fuzz/corpus").join(target);
    if dir.is_dir() {
        let mut paths: Vec<_> = std::fs::read_dir(&dir)?
            .map(|e| e.map(|e| e.path()))
            .collect::<Result<_, _>>()?;
        paths.sort();
        for p in paths {
            seeds.push(std::fs::read(p)?);
        }
    }
    match target {
        "session" => {
            // Correlation sessions of both earlier formats (68 and 60 kB).
            for f in ["session_v1.bin", "session_v2.bin"] {
                seeds.push(std::fs::read(root.join("tests/fixtures").join(f))?);
            }
        }
        "asterix" => {
            // CAT021, CAT020 and a datagram of all four categories.
            for f in ["adsb.bin", "mlat.bin", "mixed.bin"] {
                seeds.push(std::fs::read(root.join("tests/fixtures/cat021").join(f))?);
            }
        }
        "event" => seeds.push(events::encode_deleted("acme", "0123456789abcdef")),
        "x509" => {
            let mut params = rcgen::CertificateParams::new(vec![
                "client.example".to_string(),
                "127.0.0.1".to_string(),
            ])?;
            params
                .distinguished_name
                .push(rcgen::DnType::CommonName, "acme-ingest");
            params.subject_alt_names.push(rcgen::SanType::URI(
                "spiffe://radar.example/ingest/acme".try_into()?,
            ));
            let key = rcgen::KeyPair::generate()?;
            seeds.push(params.self_signed(&key)?.der().to_vec());
        }
        _ => {}
    }
    anyhow::ensure!(!seeds.is_empty(), "no seed input for {target}");
    Ok(seeds)
}

/// Feeds `input` to the decoder of `target`; its result is dropped (only a
/// panic is a finding).
fn run(target: &str, input: &[u8]) {
    match target {
        "asterix" => drop(wire_formats::asterix::decode(input)),
        "nmea" => {
            let text = String::from_utf8_lossy(input);
            let lines: Vec<String> = text.lines().map(str::to_string).collect();
            drop(wire_formats::nmea::decode(&lines));
        }
        "session" => {
            drop(Envelope::<CorrelationSession>::decode(input));
            drop(Envelope::<PlotFusionSession>::decode(input));
        }
        "tracker" => drop(formats::state::tracker::decode_tracker(input)),
        "event" => drop(events::decode(input)),
        "x509" => {
            drop(radar_fusion::tls::x509::names(input));
            std::hint::black_box(radar_fusion::tls::x509::not_after_unix(input));
        }
        _ => unreachable!("targets are checked"),
    }
}

/// Mutates the corpus for `time`; returns the runs and the crashes.
fn fuzz(target: &str, corpus: &[Vec<u8>], time: Duration, seed: u64) -> anyhow::Result<(u64, u64)> {
    let mut rng = Rng(seed ^ fnv(target.as_bytes()) | 1);
    let crashes_dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/fuzz-crashes");
    let start = Instant::now();
    let (mut runs, mut crashes) = (0u64, 0u64);
    // Every seed as it is first.
    let mut inputs: Vec<Vec<u8>> = corpus.to_vec();
    while start.elapsed() < time || runs < corpus.len() as u64 {
        let input = if (runs as usize) < inputs.len() {
            inputs[runs as usize].clone()
        } else {
            let base = &corpus[rng.below(corpus.len())];
            let other = &corpus[rng.below(corpus.len())];
            mutate(base, other, &mut rng)
        };
        runs += 1;
        if catch_unwind(AssertUnwindSafe(|| run(target, &input))).is_err() {
            crashes += 1;
            std::fs::create_dir_all(&crashes_dir)?;
            let path = crashes_dir.join(format!("{target}-{crashes}.bin"));
            std::fs::write(&path, &input)?;
            println!(
                "{target}: PANIC on {} bytes, saved to {}",
                input.len(),
                path.display()
            );
            if crashes >= 10 {
                break;
            }
        }
        if runs as usize == inputs.len() {
            inputs.clear();
        }
    }
    Ok((runs, crashes))
}

/// One to eight stacked mutations of `base` (`other`: a second corpus
/// input for splices).
fn mutate(base: &[u8], other: &[u8], rng: &mut Rng) -> Vec<u8> {
    const INTERESTING: [u8; 8] = [0x00, 0x01, 0x7f, 0x80, 0xff, b',', b'*', b'\n'];
    let mut v = base.to_vec();
    for _ in 0..1 + rng.below(8) {
        let len = v.len();
        match rng.below(8) {
            0 if len > 0 => {
                let i = rng.below(len);
                v[i] ^= 1 << rng.below(8);
            }
            1 if len > 0 => {
                let i = rng.below(len);
                v[i] = INTERESTING[rng.below(INTERESTING.len())];
            }
            2 if len > 0 => {
                let i = rng.below(len);
                v[i] = rng.next() as u8;
            }
            3 => {
                let i = rng.below(len + 1);
                let n = 1 + rng.below(16);
                let bytes: Vec<u8> = (0..n).map(|_| rng.next() as u8).collect();
                v.splice(i..i, bytes);
            }
            4 if len > 0 => {
                let i = rng.below(len);
                let n = 1 + rng.below((len - i).min(64));
                v.drain(i..i + n);
            }
            5 if len > 0 => {
                // Repeat a range (lengths and counts that run over).
                let i = rng.below(len);
                let n = 1 + rng.below((len - i).min(32));
                let chunk = v[i..i + n].to_vec();
                v.splice(i..i, chunk);
            }
            6 if !other.is_empty() => {
                // Splice: a prefix of this input, a suffix of another.
                let cut = rng.below(len + 1);
                let from = rng.below(other.len());
                v.truncate(cut);
                v.extend_from_slice(&other[from..]);
            }
            7 if len > 0 => v.truncate(rng.below(len)),
            _ => {}
        }
    }
    v
}

/// xorshift64*: a seeded generator, enough for mutations.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

fn fnv(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    })
}
