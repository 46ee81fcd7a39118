//! The experiment registry behind `radar-fusion-eval`.
//!
//! An experiment is a name, a one-line summary and a function from
//! [`EvalOptions`] to a [`Report`]. Adding one is: write the function (use
//! [`crate::montecarlo::run_batch`] for the runs and the service's
//! `algo` code for the method under test) and add one [`Experiment`] line to
//! [`REGISTRY`].

pub mod correlation;
pub mod late_plots;
pub mod registration;
pub mod seed000_async_network;
pub mod seed000_correlation;
pub mod seed000_local_tracking;
pub mod seed000_miss_probability;
pub mod seed001_initiation;
pub mod seed001_montecarlo;
pub mod seed001_plot_association;
pub mod seed001_serial_jpda;
pub mod seed002_jpda;
pub mod seed003_dimension;
pub mod seed004_ais_bias;
pub mod tracker_manoeuvres;

use std::path::{Path, PathBuf};

use super::SimError;
use super::montecarlo::RunnerOptions;
use super::report::Report;

/// Options shared by every experiment.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EvalOptions {
    /// Runs, seed, threads, progress bar.
    pub runner: RunnerOptions,
    /// Overrides the experiment's number of targets (smaller scenes for tests).
    pub targets: Option<usize>,
    /// Overrides the experiment's number of scans.
    pub scans: Option<usize>,
    /// Overrides the σ (metres) of the seed 000 initial-position region:
    /// smaller is denser.
    pub region_sigma_m: Option<u32>,
}

impl EvalOptions {
    /// `runs` runs from `seed` with the experiment's own scene size.
    pub fn new(runs: usize, seed: u64) -> Self {
        Self {
            runner: RunnerOptions::new(runs, seed),
            targets: None,
            scans: None,
            region_sigma_m: None,
        }
    }

    /// The seed 000 scene with `targets` targets (unless overridden) and the
    /// scan count and region overrides applied.
    pub fn seed000_scene(&self, targets: usize) -> super::scenario000::Seed000Scene {
        let mut scene = super::scenario000::Seed000Scene::paper(self.targets.unwrap_or(targets));
        if let Some(s) = self.scans {
            scene.scans = s;
        }
        if let Some(r) = self.region_sigma_m {
            scene.region_sigma = f64::from(r);
        }
        scene
    }
}

/// A registered experiment.
#[derive(Clone, Copy)]
pub struct Experiment {
    /// Name on the command line and of the output files.
    pub name: &'static str,
    /// One line for `eval --list`.
    pub summary: &'static str,
    /// Runs the experiment.
    pub run: fn(&EvalOptions) -> Result<Report, SimError>,
}

/// Every experiment `eval` knows, in listing order.
pub const REGISTRY: &[Experiment] = &[
    Experiment {
        name: "seed000-correlation",
        summary: "seed 000 §5: E_c/E_e/E_s of the weighted, modified and double-threshold methods and the baselines, 60 and 120 targets",
        run: seed000_correlation::run,
    },
    Experiment {
        name: "seed000-async-network",
        summary: "correlation of unsynchronised radar networks (4/4 s offset 2, 4/5 s, 10/12 s offset 3, three radars) with the endpoint's defaults: correct, wrong, missed",
        run: seed000_async_network::run,
    },
    Experiment {
        name: "seed000-local-tracking",
        summary: "seed 000 §5.1 local Kalman filters of both nodes: position RMSE and NEES consistency",
        run: seed000_local_tracking::run,
    },
    Experiment {
        name: "seed000-miss-probability",
        summary: "seed 000 eq. 23 checked by Monte Carlo: chi-square exceedances and L/R miss rates of same-target pairs",
        run: seed000_miss_probability::run,
    },
    Experiment {
        name: "seed001-plot-association",
        summary: "seed 001 Fig. 3: GNN plot-to-plot association and ML fusion of two radars' plots, three crossing targets",
        run: seed001_plot_association::run,
    },
    Experiment {
        name: "seed001-serial-jpda",
        summary: "seed 001 Fig. 5: serial plot fusion with JPDA vs each radar alone, position RMSE over time",
        run: seed001_serial_jpda::run,
    },
    Experiment {
        name: "seed001-initiation",
        summary: "seed 001 Fig. 6: logic track initiation with the per-axis velocity gate, clean and with clutter at P_D = 0.9",
        run: seed001_initiation::run,
    },
    Experiment {
        name: "seed001-montecarlo",
        summary: "seed 001 beyond the patent: 2-4 unsynchronised Doppler radars, turning targets, clutter; parallel vs serial vs best single radar",
        run: seed001_montecarlo::run,
    },
    Experiment {
        name: "seed004-ais-bias",
        summary: "seed 004 §3: AIS–radar bias estimation and association, tables 2 and 4, paper CA-CFAR seeding vs bias search",
        run: seed004_ais_bias::run,
    },
    Experiment {
        name: "seed002-jpda",
        summary: "seed 002 table 1: correct association rate and time per scan of NN, GNN, AMSJPDA and exact JPDA, 10/60/100 targets in clutter",
        run: seed002_jpda::run,
    },
    Experiment {
        name: "seed003-dimension",
        summary: "seed 003 table 1: association probability, fusion error and time of mapping, dimension lifting and splitting, two 3D and two 2D radars",
        run: seed003_dimension::run,
    },
    Experiment {
        name: "late-plots",
        summary: "a stream of late and reordered plots (seed-001 scene, 3 radars, per-radar delays and 3 % hiccups): the session before and after the lag window against the batch call; dropped plots, exactness, RMSE, GOSPA, latency",
        run: late_plots::run,
    },
    Experiment {
        name: "late-plots-fifo",
        summary: "late-plots with links that keep each radar's order (radar k's plots a fixed delay late, 3 % held 6–10 s): reprocessing against retrodiction",
        run: late_plots::run_fifo,
    },
    Experiment {
        name: "registration",
        summary: "radar registration in the tracker: the seed-001 scene with every radar biased (±500 m, ±0.5°), unbiased vs unregistered vs registered; RMSE, NEES, false and duplicate tracks, bias errors against their σ",
        run: registration::run,
    },
    Experiment {
        name: "tracker-manoeuvres",
        summary: "plot-fusion tracker per kind of segment (level, turning, speed change, climb) on 3D Doppler radars: default IMM vs CV, with and without range rate, serial vs parallel; RMSE and 3-dof NEES",
        run: tracker_manoeuvres::run,
    },
    Experiment {
        name: "accuracy",
        summary: "each radar's σ learnt online: the tracker-manoeuvres scene with every radar's σ declared ×0.3/×1/×3 at random per radar, learnt vs estimator off vs declared right; RMSE and NEES per segment, false tracks, breaks, the learnt σ against the truth and their time to converge",
        run: tracker_manoeuvres::run_accuracy,
    },
];

/// The experiment called `name`.
pub fn find(name: &str) -> Result<&'static Experiment, SimError> {
    REGISTRY
        .iter()
        .find(|e| e.name == name)
        .ok_or_else(|| SimError::UnknownExperiment(name.to_string()))
}

/// `name: summary` lines for `eval --list`.
pub fn listing() -> String {
    let width = REGISTRY.iter().map(|e| e.name.len()).max().unwrap_or(0);
    REGISTRY
        .iter()
        .map(|e| format!("{:width$}  {}\n", e.name, e.summary))
        .collect()
}

/// Runs experiment `name` and writes its files into `out`; returns the
/// paths written.
pub fn run_and_write(name: &str, opts: &EvalOptions, out: &Path) -> Result<Vec<PathBuf>, SimError> {
    if opts.runner.runs == 0 {
        return Err(SimError::InvalidConfig("--runs must be at least 1".into()));
    }
    let exp = find(name)?;
    let report = (exp.run)(opts)?;
    report.write(out, exp.name)
}

/// Formats a rate or other figure with 4 decimals.
pub(crate) fn f4(v: f64) -> String {
    format!("{v:.4}")
}

/// Mean and standard error of the mean of per-run values.
pub(crate) fn mean_se(xs: &[f64]) -> (f64, f64) {
    let n = xs.len() as f64;
    if xs.is_empty() {
        return (0.0, 0.0);
    }
    let m = xs.iter().sum::<f64>() / n;
    if xs.len() < 2 {
        return (m, 0.0);
    }
    let v = xs.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0);
    (m, (v / n).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn registry_names_are_unique_and_findable() {
        for e in REGISTRY {
            assert_eq!(find(e.name).unwrap().name, e.name);
            assert_eq!(REGISTRY.iter().filter(|o| o.name == e.name).count(), 1);
            assert!(listing().contains(e.name));
        }
        assert!(matches!(find("nope"), Err(SimError::UnknownExperiment(_))));
    }

    #[test]
    fn mean_and_standard_error_by_hand() {
        // 1, 2, 3: mean 2, sample variance 1, SE = √(1/3).
        let (m, se) = mean_se(&[1.0, 2.0, 3.0]);
        assert_eq!(m, 2.0);
        assert!((se - (1.0f64 / 3.0).sqrt()).abs() < 1e-15);
    }
}
