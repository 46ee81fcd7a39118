//! `radar-fusion-eval`: the papers' seeded Monte Carlo experiments. Lists
//! them, or runs one and writes DIR/EXPERIMENT.md, .csv and .svg plots.
//! (Until the workspace split this was `radar-fusion eval`; the server no
//! longer links the simulator.)

use std::path::PathBuf;

use clap::{Args, Parser};
use eval::experiments::{EvalOptions, listing, run_and_write};
use eval::montecarlo::Progress;

/// Run a seeded Monte Carlo experiment of the papers and write
/// DIR/EXPERIMENT.md, .csv and .svg plots (`--list` lists them).
#[derive(Debug, Parser)]
#[command(name = "radar-fusion-eval", version, about)]
struct Cli {
    #[command(flatten)]
    args: EvalArgs,
}

/// Arguments of `radar-fusion-eval`.
#[derive(Debug, Clone, Args)]
struct EvalArgs {
    /// The experiment to run (see `--list`).
    #[arg(required_unless_present = "list")]
    experiment: Option<String>,
    /// List the experiments with a one-line description and exit.
    #[arg(long)]
    list: bool,
    /// Number of Monte Carlo runs.
    #[arg(long, default_value_t = 50)]
    runs: usize,
    /// Master seed; run i draws from ChaCha stream i of this seed.
    #[arg(long, default_value_t = 18)]
    seed: u64,
    /// Output directory (created if needed).
    #[arg(long, default_value = "eval-out")]
    out: PathBuf,
    /// Worker threads (0 = all cores); results do not depend on it.
    #[arg(long, default_value_t = 0)]
    threads: usize,
    /// Override the experiment's number of targets.
    #[arg(long)]
    targets: Option<usize>,
    /// Override the experiment's number of scans.
    #[arg(long)]
    scans: Option<usize>,
    /// Override the σ in metres of the seed 000 initial-position region (denser scenes).
    #[arg(long)]
    region_sigma_m: Option<u32>,
    /// Always draw the progress bar on stderr (by default only on a terminal).
    #[arg(long)]
    progress: bool,
}

fn main() -> anyhow::Result<()> {
    let args = Cli::parse().args;
    let Some(name) = args.experiment.filter(|_| !args.list) else {
        return print_ignoring_closed_pipe(&listing());
    };
    let mut opts = EvalOptions::new(args.runs, args.seed);
    opts.runner.threads = args.threads;
    opts.runner.progress = if args.progress {
        Progress::Always
    } else {
        Progress::Auto
    };
    opts.targets = args.targets;
    opts.scans = args.scans;
    opts.region_sigma_m = args.region_sigma_m;
    let started = std::time::Instant::now();
    let written = run_and_write(&name, &opts, &args.out)?;
    for p in written {
        println!("{}", p.display());
    }
    eprintln!(
        "{name}: {} runs in {:.2} s",
        args.runs,
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

/// Writes `text` to standard output; a reader that stops early (`| head`)
/// ends the output quietly instead of a broken-pipe panic.
fn print_ignoring_closed_pipe(text: &str) -> anyhow::Result<()> {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        other => Ok(other?),
    }
}
