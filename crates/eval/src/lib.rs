//! Seeded scenario generators and Monte Carlo evaluation of the papers'
//! experiments (issue 3).
//!
//! The pieces, from the bottom up:
//! - [`truth`]: target trajectories (constant velocity, coordinated turns at a
//!   g-load, speed changes, seed 000 eq. 26 process noise), random initial
//!   conditions and the crossing / splitting / parallel geometries.
//! - [`sensor`]: 2D/3D radars with optional Doppler, coverage, detection
//!   probability, Gaussian errors, systematic biases and Poisson clutter.
//! - [`ais`]: an AIS reporter in WGS84 and an NMEA 0183 `!AIVDM` type-1 encoder.
//! - [`asterix048`]: an ASTERIX CAT048 encoder (2D primary radar target
//!   reports), the bytes of `examples/asterix_load.rs`.
//! - [`tracker`]: the local Kalman filters of the distributed experiments
//!   (seed 000 eqs. 24–30), one per target per node.
//! - [`scenario000`]: the two-node scene of seed 000 §5.1 and the truth
//!   bookkeeping that maps local track ids to targets, with the
//!   [`scenario000::Correlator`] plug for track-to-track correlation methods.
//! - [`scenario001`]: the seed 001 tracker experiments' plots, frame-by-frame
//!   tracker runs and their scoring (RMSE, NEES, GOSPA, ID switches, false
//!   tracks, time to confirm).
//! - [`metrics`]: E_c/E_e/E_s, association rate, RMSE, NEES, OSPA, GOSPA.
//! - [`montecarlo`]: N runs from one seed, bit-for-bit reproducible for any
//!   thread count, with a progress bar on stderr.
//! - [`report`]: Markdown tables, CSV and hand-written SVG line plots.
//! - [`experiments`]: the registry behind `radar-fusion-eval`.
//!
//! Unlike `algo`, this crate uses randomness (`rand`, ChaCha) and writes
//! files; it calls `algo` for every piece of numerics the service also uses.

pub mod ais;
pub mod asterix048;
pub mod async_network;
pub mod benchmark;
pub mod experiments;
pub mod metrics;
pub mod montecarlo;
pub mod report;
pub mod scenario000;
pub mod scenario001;
pub mod sensor;
pub mod tracker;
pub mod truth;

use algo::AlgoError;

/// The random number generator of every simulation: ChaCha with 8 rounds,
/// portable and reproducible across platforms and versions of this crate.
pub type SimRng = rand_chacha::ChaCha8Rng;

/// Errors of the simulation layer.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// The numerical core rejected an input or hit a degenerate geometry.
    #[error(transparent)]
    Algo(#[from] AlgoError),
    /// Writing the outputs failed.
    #[error("i/o error: {0}")]
    Io(#[from] std::io::Error),
    /// A scenario or experiment parameter is out of range.
    #[error("invalid configuration: {0}")]
    InvalidConfig(String),
    /// `eval` was asked for an experiment that is not registered.
    #[error("unknown experiment `{0}` (see `radar-fusion-eval --list`)")]
    UnknownExperiment(String),
}

/// Standard gravity (m/s²), for g-loads.
pub const STANDARD_GRAVITY: f64 = 9.80665;
