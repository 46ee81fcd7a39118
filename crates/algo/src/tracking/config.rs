//! The tracker's inputs: radar descriptions, plots and options (seed 001,
//! the multi-radar plot-fusion patent, steps 1–8), with their validation.
//!
//! Option names follow MATLAB's `trackerJPDA` and `trackHistoryLogic` where
//! they exist (confirmation M-of-N, deletion M-of-N, time tolerance for
//! simultaneous detections). Units are SI, angles in radians, azimuth
//! clockwise from north, positions in the fusion centre's ENU frame.

use crate::error::{self, AlgoError};
use crate::jpda::{Config as JpdaConfig, Method};
use crate::tracking::identity::{self, Identity};
use crate::tracking::parameter::{
    TrackerParameter, TrackerParameter as P, finite, finite_slice, invalid, non_negative, positive,
};

/// How plots reach the tracks (seed 001 step 2).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// Serial, with or without Doppler: with the range rate in the serial
    /// update it was the more accurate mode for every network of the
    /// seed-001 Monte Carlo (2, 3 and 4 radars, docs/RESULTS.md). Trackers
    /// stored before that (format 1) resolved `Auto` to parallel when every
    /// radar measured Doppler (the patent's test "do all radar data contain
    /// Doppler?"); they are read back with that mode, so that a resumed
    /// tracker never changes mode.
    Auto,
    /// Steps 3–5: time registration to fusion instants by radial
    /// extrapolation, plot-to-plot GNN, ML fusion, JPDA of fused plots.
    Parallel,
    /// Step 6: plots in time order, one radar scan group at a time, each a
    /// JPDA/EKF update of the tracks predicted to its time.
    Serial,
}

/// The process noise of the constant-velocity model.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NoiseModel {
    /// Continuous white-noise acceleration, spectral density q_i = σ_i²
    /// (m²/s³) per axis: Q = q [[Δt³/3, Δt²/2], [Δt²/2, Δt]]. Consistent
    /// whatever the sampling (Q over 4 s = Q over 4 × 1 s), which serial
    /// fusion of unsynchronised radars needs: the default.
    Cwna,
    /// Discrete white-noise acceleration, piecewise-constant acceleration of
    /// σ_i per interval: Q = σ² [[Δt⁴/4, Δt³/2], [Δt³/2, Δt²]]. Its total
    /// noise depends on how often the track is predicted (more radars, less
    /// noise), so it suits a fixed-period tracker only.
    Dwna,
}

/// One radar of the network. Its index in [`TrackerConfig::radars`] is the
/// radar's id in [`Plot::radar`].
#[derive(Debug, Clone, PartialEq)]
pub struct RadarSpec {
    /// Site in the fusion ENU frame `[e, n, u]` (m): the patent's [a, b].
    pub site: [f64; 3],
    /// Range standard deviation σ_ρ (m), > 0.
    pub sigma_range: f64,
    /// Azimuth standard deviation σ_θ (rad), > 0.
    pub sigma_azimuth: f64,
    /// Elevation standard deviation (rad): `Some` makes this a 3D radar
    /// (its plots must carry an elevation), `None` a 2D radar.
    pub sigma_elevation: Option<f64>,
    /// Radial-velocity standard deviation (m/s): `Some` for a Doppler radar.
    pub sigma_radial_velocity: Option<f64>,
    /// Scan period (s), > 0 (used for the default options only).
    pub scan_period: f64,
    /// Detection probability P_D in (0, 1].
    pub detection_probability: f64,
    /// Clutter density λ > 0: false plots per unit volume of the radar's
    /// polar measurement space (per m·rad for 2D, per m·rad² for 3D).
    pub clutter_density: f64,
}

impl RadarSpec {
    /// `true` for a 3D radar (range, azimuth, elevation).
    pub fn is_3d(&self) -> bool {
        self.sigma_elevation.is_some()
    }

    /// `true` for a radar that measures the radial velocity.
    pub fn has_doppler(&self) -> bool {
        self.sigma_radial_velocity.is_some()
    }
}

/// One plot (detection) of one radar, in that radar's polar coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plot {
    /// Index of the radar in [`TrackerConfig::radars`].
    pub radar: usize,
    /// Detection time τ (s).
    pub t: f64,
    /// Range ρ (m), > 0.
    pub range: f64,
    /// Azimuth θ (rad), clockwise from north.
    pub azimuth: f64,
    /// Elevation (rad); required from a 3D radar, absent from a 2D radar.
    pub elevation: Option<f64>,
    /// Radial (Doppler) velocity ṙ (m/s), positive receding; required from
    /// every radar in parallel mode.
    pub radial_velocity: Option<f64>,
    /// What a secondary reply said of the aircraft (empty for a primary
    /// plot): Mode 3/A code, Mode C, Mode S address and identification.
    pub identity: Identity,
    /// A cooperative report's own position (ADS-B, multilateration, AIS):
    /// `Some` for a report, whose sensor is then `radar` =
    /// [`TrackerConfig::radars`]'s length + its [`ReportKind`]'s index
    /// ([`TrackerConfig::report_sensor`]); the polar fields then hold the
    /// position seen from the fusion frame's origin (range, azimuth,
    /// elevation of `report.position`, [`Plot::report`]), the radial
    /// velocity none. `None` for a radar's plot.
    pub report: Option<Report>,
}

/// The kinds of cooperative report, each one sensor of the tracker after
/// the radars ([`TrackerConfig::report_sensor`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum ReportKind {
    /// ADS-B: the aircraft's own navigation (GNSS) position and velocity,
    /// with its stated quality (NACp, NACv).
    Adsb,
    /// Multilateration (MLAT, WAM): a position from the transponder's
    /// replies' times of arrival at ground stations, with its stated σ.
    Mlat,
    /// AIS: a ship's own GNSS position and its speed and course over
    /// ground.
    Ais,
}

impl ReportKind {
    /// Every kind, in sensor order.
    pub const ALL: [ReportKind; 3] = [ReportKind::Adsb, ReportKind::Mlat, ReportKind::Ais];

    /// Its index among [`ReportKind::ALL`].
    pub fn index(self) -> usize {
        self as usize
    }

    /// Its wire name.
    pub fn name(self) -> &'static str {
        match self {
            ReportKind::Adsb => "adsb",
            ReportKind::Mlat => "mlat",
            ReportKind::Ais => "ais",
        }
    }

    /// The kind of wire name `name`.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.name() == name)
    }

    /// Whether the report is the target's own claim (ADS-B, AIS: what its
    /// navigation says) rather than a measurement by the ground (MLAT):
    /// such a report is checked against independent evidence
    /// ([`crate::tracking::identity::Validation`]).
    pub fn is_self_reported(self) -> bool {
        self != ReportKind::Mlat
    }

    /// How long a track may go without any update before a report sensor
    /// judges it missed, once per this period (s): ADS-B and MLAT update
    /// an airborne aircraft every 0.5–1 s, so 5 s is several lost
    /// reports; AIS reports every 2–10 s under way (Class A), 30 s for a
    /// Class B ship, so 60 s.
    pub fn coast_s(self) -> f64 {
        match self {
            ReportKind::Adsb | ReportKind::Mlat => 5.0,
            ReportKind::Ais => 60.0,
        }
    }
}

/// A cooperative report's measurement, in the fusion ENU frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Report {
    /// Which kind of report.
    pub kind: ReportKind,
    /// Position `[e, n, u]` (m). `u` is used only when `sigma_vertical`
    /// is `Some` (a geometric height in a 3D tracker).
    pub position: [f64; 3],
    /// σ of each horizontal component (m), > 0: from the report's stated
    /// accuracy (ADS-B NACp, MLAT's σ, AIS's accuracy flag).
    pub sigma_horizontal: f64,
    /// σ of the height (m): `Some` when the report gives a geometric
    /// height the tracker may use.
    pub sigma_vertical: Option<f64>,
    /// Velocity `[v_e, v_n, v_u]` (m/s) with σ per horizontal component
    /// (`v_u` is used only with `sigma_vertical_velocity`).
    pub velocity: Option<[f64; 3]>,
    /// σ of each horizontal velocity component (m/s), > 0 when `velocity`
    /// is `Some`.
    pub sigma_velocity: f64,
    /// σ of the vertical rate (m/s) when the report gives a geometric
    /// vertical rate the tracker may use.
    pub sigma_vertical_velocity: Option<f64>,
}

impl Plot {
    /// A cooperative report of sensor `sensor` (the radars' count + the
    /// kind's index) at `t`, its polar fields those of the position seen
    /// from the origin (a report exactly at the origin gets a range of
    /// 1 mm).
    pub fn report(sensor: usize, t: f64, report: Report, identity: Identity) -> Self {
        let [e, n, u] = report.position;
        let horizontal = e.hypot(n);
        Plot {
            radar: sensor,
            t,
            range: horizontal.hypot(u).max(1e-3),
            azimuth: e.atan2(n),
            elevation: Some(u.atan2(horizontal.max(1e-3))),
            radial_velocity: None,
            identity,
            report: Some(report),
        }
    }
}

/// The velocity gate of the logic-based initiation (step 7, 7a).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum VelocityGate {
    /// Speed band [v_min, v_max] (m/s) on the displacement's length: the
    /// patent's gate for a target of unknown heading.
    Speed {
        /// Minimum speed (m/s), ≥ 0.
        v_min: f64,
        /// Maximum speed (m/s), > v_min.
        v_max: f64,
    },
    /// Per-axis bands as printed in the patent (Fig. 6 uses x ∈ [100, 800],
    /// y ∈ [−100, 100] m/s); the z entries are used by 3D plot pairs only.
    PerAxis {
        /// Minimum velocity per axis `[e, n, u]` (m/s).
        v_min: [f64; 3],
        /// Maximum velocity per axis (m/s), ≥ v_min.
        v_max: [f64; 3],
    },
}

/// Logic-based track initiation (step 7).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Initiation {
    /// Confirmation M of M-of-N: hits among the last N frames of a
    /// tentative track (its first two plots count as two hits), ≥ 2.
    pub confirm_m: u32,
    /// Confirmation N, M ≤ N ≤ 64.
    pub confirm_n: u32,
    /// The velocity gate between a root plot and a second plot.
    pub velocity: VelocityGate,
    /// Gate probability of the χ² tests of the initiation (the D_ij ≤ γ
    /// test of 7a and the gate about the extrapolated point of 7b), in (0, 1).
    pub gate_probability: f64,
    /// Smallest time between a root and its second plot (s), > 0; plots
    /// closer in time (e.g. the same target seen by two radars at once)
    /// give no usable velocity and are not paired.
    pub min_dt: f64,
    /// A root waits at most this long for its second plot (s), ≥ `min_dt`.
    pub max_dt: f64,
}

/// Track deletion (step 8 and 7c): any rule that is set deletes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Deletion {
    /// Delete after this many consecutive missed frames (K ≥ 1).
    pub max_consecutive_misses: Option<u32>,
    /// Delete when at least M_d of the last N_d frames were misses
    /// (1 ≤ M_d ≤ N_d ≤ 64).
    pub misses_m_of_n: Option<(u32, u32)>,
    /// Delete when the horizontal position standard deviation
    /// √(P_xx + P_yy) exceeds this (m).
    pub max_position_sigma: Option<f64>,
}

impl Deletion {
    /// Deletion after `k` consecutive missed frames only.
    pub fn after_misses(k: u32) -> Self {
        Self {
            max_consecutive_misses: Some(k),
            misses_m_of_n: None,
            max_position_sigma: None,
        }
    }
}

/// One motion model of the predictor, over the constant-velocity state
/// `[x, vx, y, vy(, z, vz)]`; its process noise takes the tracker's
/// [`NoiseModel`] with this model's σ per axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MotionModel {
    /// Constant velocity, acceleration noise `sigma_a` per axis `[e, n, u]`
    /// (σ for DWNA, √q for CWNA), ≥ 0.
    ConstantVelocity {
        /// Noise per axis.
        sigma_a: [f64; 3],
    },
    /// A horizontal coordinated turn at the known rate `turn_rate` (rad/s,
    /// positive counter-clockwise seen from above, i.e. a left turn;
    /// non-zero), constant velocity vertically; noise per axis as for
    /// constant velocity.
    CoordinatedTurn {
        /// ω (rad/s), non-zero and |ω| ≤ 0.5.
        turn_rate: f64,
        /// Noise per axis.
        sigma_a: [f64; 3],
    },
}

impl TrackerConfig {
    /// The largest horizontal process noise of the motion models, as a
    /// spectral density q = σ² (m²/s³; for DWNA σ² per s): how fast the
    /// most agile model lets a velocity drift.
    pub fn largest_process_noise(&self) -> f64 {
        let horizontal = |s: &[f64; 3]| s[0].max(s[1]).powi(2);
        match &self.motion {
            Motion::ConstantVelocity => horizontal(&self.sigma_a),
            Motion::Imm(imm) => imm
                .models
                .iter()
                .map(|m| match m {
                    MotionModel::ConstantVelocity { sigma_a }
                    | MotionModel::CoordinatedTurn { sigma_a, .. } => horizontal(sigma_a),
                })
                .fold(0.0, f64::max),
        }
    }
}

impl MotionModel {
    /// The model's turn rate (0 for constant velocity).
    pub fn turn_rate(&self) -> f64 {
        match self {
            MotionModel::ConstantVelocity { .. } => 0.0,
            MotionModel::CoordinatedTurn { turn_rate, .. } => *turn_rate,
        }
    }

    /// The model's noise per axis.
    pub fn sigma_a(&self) -> [f64; 3] {
        match self {
            MotionModel::ConstantVelocity { sigma_a }
            | MotionModel::CoordinatedTurn { sigma_a, .. } => *sigma_a,
        }
    }
}

/// An interacting-multiple-model predictor: the models, how long the
/// target stays in each, and the mode split of a new track.
#[derive(Debug, Clone, PartialEq)]
pub struct Imm {
    /// The models (2 to 8).
    pub models: Vec<MotionModel>,
    /// Mean sojourn time τ_i of each model (s), > 0: the target leaves
    /// model i at rate 1/τ_i, into each other model equally (a
    /// continuous-time Markov chain, so irregular serial steps switch
    /// consistently; [`crate::tracking::predictor::switching`]).
    pub mean_sojourn: Vec<f64>,
    /// Mode probabilities of a newly confirmed track (sum 1, each > 0).
    pub initial_probabilities: Vec<f64>,
}

impl Imm {
    /// The default for aircraft, chosen on the seed-001 Monte Carlo (legs
    /// of straight flight and 2–4 m/s² turns at 100–300 m/s,
    /// docs/RESULTS.md) among seven sets of CV, CT ±1.5 °/s and ±3 °/s and
    /// high-noise CV models, and on a 3 °/s turn at 150 m/s (the tracker's
    /// tests): constant velocity √q = 0.5 m/s^1.5 horizontally and 1
    /// vertically for straight legs (mean sojourn 60 s; vertically 0.5 left
    /// climbs and descents overconfident, mean NEES 3.9 of 3 in
    /// `tracker-manoeuvres`, and 1 cost nothing on level legs or on real
    /// traffic), coordinated turns at ±3 °/s, the standard-rate turn,
    /// √q = 3 (20 s; their noise covers gentler turns), and a manoeuvre
    /// model, constant velocity √q = 5 (20 s), for what none of them fits
    /// (other turn rates, speed changes); 70 % of a new track in the first,
    /// 10 % in each other.
    pub fn aircraft() -> Self {
        let rate = 3.0_f64.to_radians();
        Self {
            models: vec![
                MotionModel::ConstantVelocity {
                    sigma_a: [0.5, 0.5, 1.0],
                },
                MotionModel::CoordinatedTurn {
                    turn_rate: rate,
                    sigma_a: [3.0; 3],
                },
                MotionModel::CoordinatedTurn {
                    turn_rate: -rate,
                    sigma_a: [3.0; 3],
                },
                MotionModel::ConstantVelocity { sigma_a: [5.0; 3] },
            ],
            mean_sojourn: vec![60.0, 20.0, 20.0, 20.0],
            initial_probabilities: vec![0.7, 0.1, 0.1, 0.1],
        }
    }
}

/// The predictor of confirmed tracks.
#[derive(Debug, Clone, PartialEq)]
pub enum Motion {
    /// One constant-velocity model with [`TrackerConfig::sigma_a`].
    ConstantVelocity,
    /// An interacting multiple model.
    Imm(Imm),
}

/// Everything the tracker needs; see [`TrackerConfig::new`] for defaults.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackerConfig {
    /// Spatial axes of the tracks: 2 (`[x, vx, y, vy]`) or 3
    /// (`[x, vx, y, vy, z, vz]`). A 2D tracker takes 2D radars only.
    pub axes: usize,
    /// The radars; a plot names its radar by index.
    pub radars: Vec<RadarSpec>,
    /// Parallel, serial or decided from the radars.
    pub mode: Mode,
    /// Parallel mode: period T of the fusion instants t_k = epoch + k·T (s).
    pub fusion_period: f64,
    /// Parallel mode: origin of the fusion instants (s).
    pub fusion_epoch: f64,
    /// Serial mode: consecutive plots of one radar within this time of the
    /// group's first plot are one scan group, processed as simultaneous at
    /// the group's last time (s), ≥ 0.
    pub time_tolerance: f64,
    /// Plot-to-track association (steps 5–6): method and exact-JPDA limits.
    pub association: JpdaConfig,
    /// Gate probability of the plot-to-plot χ² gate of step 4, in (0, 1).
    pub plot_gate_probability: f64,
    /// Gate probability P_G of the plot-to-track gate, in (0, 1).
    pub track_gate_probability: f64,
    /// Track initiation (step 7).
    pub initiation: Initiation,
    /// Track deletion.
    pub deletion: Deletion,
    /// Acceleration noise per axis `[e, n, u]`, ≥ 0: σ (m/s²) for DWNA, √q
    /// (q in m²/s³) for CWNA.
    pub sigma_a: [f64; 3],
    /// The process-noise model.
    pub noise: NoiseModel,
    /// The predictor of confirmed tracks: one constant-velocity model with
    /// `sigma_a`, or an IMM. Tentative tracks always use one
    /// constant-velocity model with `sigma_a`; a track confirmed under an
    /// IMM starts with [`Imm::initial_probabilities`].
    pub motion: Motion,
    /// 3D tracker: height (m, fusion frame `u`) given to 2D plots when a
    /// track is started from them (seed 003's mapping).
    pub default_height: f64,
    /// Standard deviation of `default_height` (m), > 0.
    pub default_height_sigma: f64,
    /// Parallel mode: σ (m/s) of a target's speed across its line of sight,
    /// ≥ 0. Step 3 holds the plot's angles while moving it to the fusion
    /// instant, so a target crossing the line of sight at speed v_t is
    /// displaced by v_t·|t − τ| that the radial velocity cannot see; the
    /// extrapolated plot's covariance gets (σ_t·|t − τ|)² across the line of
    /// sight to stay consistent (0: the patent's covariance, optimistic).
    pub sigma_tangential_speed: f64,
    /// Duplicate deletion: two confirmed tracks whose best plot of a frame
    /// is the same and whose states differ by less than the χ²_n quantile
    /// at this probability are one target; the younger is deleted. In
    /// [0, 1); 0 disables the rule.
    pub duplicate_gate_probability: f64,
    /// Radar registration: online bias estimation and compensation
    /// ([`crate::tracking::registration`]); on with two radars or more.
    pub registration: crate::tracking::registration::RegistrationConfig,
    /// Mode C as a measurement of the geometric height (3D tracker), with
    /// the prior of the pressure-to-geometric offset
    /// ([`crate::tracking::height`]).
    pub mode_c_height: crate::tracking::height::ModeCHeight,
    /// How the frame's `up` relates to the height above the ellipsoid
    /// (flat for local sites; the caller that knows the frame sets it).
    pub height_datum: crate::tracking::height::HeightDatum,
    /// Each radar's σ learnt online and applied once converged
    /// ([`crate::tracking::accuracy`]); on by default.
    pub accuracy: crate::tracking::accuracy::AccuracyConfig,
}

/// A [`TrackerConfig`] that passed its checks: made only by
/// [`TrackerConfig::validated`] (or from a tracker's own configuration),
/// so [`crate::tracking::Tracker::with_config`] takes it as it is; read
/// through `Deref`.
#[derive(Debug, Clone, PartialEq)]
pub struct ValidTrackerConfig(TrackerConfig);

impl ValidTrackerConfig {
    /// The configuration, no longer marked as checked.
    pub fn into_inner(self) -> TrackerConfig {
        self.0
    }

    /// A configuration already checked (a tracker's own).
    pub(crate) fn trusted(config: TrackerConfig) -> Self {
        Self(config)
    }
}

impl std::ops::Deref for ValidTrackerConfig {
    type Target = TrackerConfig;

    fn deref(&self) -> &TrackerConfig {
        &self.0
    }
}

impl TrackerConfig {
    /// Defaults: mode `Auto`; fusion period = the shortest scan period,
    /// epoch 0; time tolerance 0; exact JPDA (clusters up to 12 tracks,
    /// 2·10⁶ hypothesis edges); gates 0.99; confirmation 3-of-4 with a speed
    /// band [0, 600] m/s, pairing 1 s to twice the longest scan period;
    /// CWNA with q = 9 m²/s³ per axis (√q = 3: aircraft turning at 2–4 m/s²
    /// keep a consistent NEES, `seed001-montecarlo`); deletion by
    /// [`TrackerConfig::default_deletion`] (2 × radars, at least 3, missed frames in
    /// serial mode, 3 in parallel mode); default height
    /// 0 ± 1000 m; tangential speed σ 300 m/s (parallel mode; 100 m/s left
    /// its plots overconfident for 100–300 m/s targets); duplicates deleted
    /// inside the 99 % χ² gate.
    pub fn new(axes: usize, radars: Vec<RadarSpec>) -> Self {
        let radars_len = radars.len();
        let misses = default_misses(Mode::Auto, &radars);
        let min_period = radars
            .iter()
            .map(|r| r.scan_period)
            .fold(f64::INFINITY, f64::min);
        let max_period = radars.iter().map(|r| r.scan_period).fold(0.0, f64::max);
        Self {
            axes,
            radars,
            mode: Mode::Auto,
            fusion_period: if min_period.is_finite() {
                min_period
            } else {
                1.0
            },
            fusion_epoch: 0.0,
            time_tolerance: 0.0,
            association: JpdaConfig {
                method: Method::Exact,
                max_exact_tracks: 12,
                max_hypotheses: 2_000_000,
            },
            plot_gate_probability: 0.99,
            track_gate_probability: 0.99,
            initiation: Initiation {
                confirm_m: 3,
                confirm_n: 4,
                velocity: VelocityGate::Speed {
                    v_min: 0.0,
                    v_max: 600.0,
                },
                gate_probability: 0.99,
                min_dt: 1.0,
                max_dt: (2.0 * max_period).max(1.0),
            },
            deletion: Deletion::after_misses(misses),
            sigma_a: [3.0; 3],
            noise: NoiseModel::Cwna,
            motion: Motion::Imm(Imm::aircraft()),
            default_height: 0.0,
            default_height_sigma: 1000.0,
            sigma_tangential_speed: 300.0,
            duplicate_gate_probability: 0.99,
            registration: crate::tracking::registration::RegistrationConfig::for_radars(radars_len),
            mode_c_height: Default::default(),
            height_datum: crate::tracking::height::HeightDatum::Flat,
            accuracy: Default::default(),
        }
    }

    /// Sets the mode and the default deletion rule that goes with it
    /// ([`TrackerConfig::default_deletion`]); set `deletion` afterwards to
    /// override it.
    pub fn set_mode(&mut self, mode: Mode) {
        self.mode = mode;
        self.deletion = self.default_deletion();
    }

    /// The default deletion rule for the configured mode:
    /// [`Deletion::after_misses`] of `2 × radars` (at least 3) missed frames
    /// in serial mode (a frame is one radar's scan group, so about two scans
    /// of each radar; `seed001-montecarlo` compares 3, 2 × and 3 × radars),
    /// 3 in parallel mode (a frame is a fusion instant holding
    /// every radar's plots).
    pub fn default_deletion(&self) -> Deletion {
        Deletion::after_misses(default_misses(self.mode, &self.radars))
    }

    /// `true` when plots are processed in parallel mode (`Auto` is serial).
    pub fn is_parallel(&self) -> bool {
        self.mode == Mode::Parallel
    }

    /// Checks every option: the configuration as a
    /// [`ValidTrackerConfig`], which [`crate::tracking::Tracker::with_config`]
    /// takes without checking it again. The error names the option
    /// ([`AlgoError::InvalidOption`], or [`AlgoError::NonFinite`] for a
    /// value that is not finite).
    pub fn validated(self) -> Result<ValidTrackerConfig, AlgoError> {
        self.validate()?;
        Ok(ValidTrackerConfig(self))
    }

    fn validate(&self) -> Result<(), AlgoError> {
        if !(self.axes == 2 || self.axes == 3) {
            return Err(invalid(
                P::Axes,
                format!("must be 2 or 3, got {}", self.axes),
            ));
        }
        if self.radars.is_empty() {
            return Err(invalid(P::Radars, "at least one radar is needed"));
        }
        for r in &self.radars {
            validate_radar(r, self.axes)?;
        }
        if self.mode == Mode::Parallel && !self.radars.iter().all(RadarSpec::has_doppler) {
            return Err(invalid(
                P::Mode,
                "parallel mode needs the radial velocity of every radar",
            ));
        }
        positive(P::FusionPeriod, self.fusion_period)?;
        finite(P::FusionEpoch, self.fusion_epoch)?;
        non_negative(P::TimeTolerance, self.time_tolerance)?;
        // The JPDA endpoint's bound: exact enumeration beyond 128 tracks
        // in one cluster would never finish.
        if !(1..=128).contains(&self.association.max_exact_tracks) {
            return Err(invalid(
                P::MaxExactTracks,
                format!(
                    "must lie in 1..=128, got {}",
                    self.association.max_exact_tracks
                ),
            ));
        }
        open_probability(P::PlotGateProbability, self.plot_gate_probability)?;
        open_probability(P::TrackGateProbability, self.track_gate_probability)?;
        validate_initiation(&self.initiation)?;
        validate_deletion(&self.deletion)?;
        for &s in &self.sigma_a {
            non_negative(P::SigmaA, s)?;
        }
        if let Motion::Imm(imm) = &self.motion {
            validate_imm(imm)?;
        }
        self.registration.validate(self.radars.len())?;
        finite(P::DefaultHeight, self.default_height)?;
        positive(P::DefaultHeightSigma, self.default_height_sigma)?;
        non_negative(P::SigmaTangentialSpeed, self.sigma_tangential_speed)?;
        let p = self.duplicate_gate_probability;
        if !(0.0..1.0).contains(&p) {
            return Err(invalid(
                P::DuplicateGateProbability,
                format!("must lie in [0, 1), got {p}"),
            ));
        }
        self.mode_c_height.validate()?;
        self.accuracy.validate(self.radars.len())?;
        self.height_datum.validate()?;
        Ok(())
    }

    /// Checks a plot against its radar: radar index, finite values, range
    /// > 0, elevation iff the radar is 3D, radial velocity in parallel mode.
    pub fn validate_plot(&self, plot: &Plot) -> Result<(), AlgoError> {
        if let Some(report) = &plot.report {
            return self.validate_report(plot, report);
        }
        let radar = self
            .radars
            .get(plot.radar)
            .ok_or_else(|| invalid_plot("radar", format!("no radar {}", plot.radar)))?;
        error::finite("t", plot.t)?;
        error::positive("range", plot.range)?;
        error::finite("azimuth", plot.azimuth)?;
        match (radar.is_3d(), plot.elevation) {
            (true, Some(el)) => {
                error::finite("elevation", el)?;
                if el.abs() >= std::f64::consts::FRAC_PI_2 {
                    return Err(invalid_plot(
                        "elevation",
                        format!("must lie in (-pi/2, pi/2), got {el}"),
                    ));
                }
            }
            (true, None) => {
                return Err(invalid_plot("elevation", "required from a 3D radar".into()));
            }
            (false, Some(_)) => {
                return Err(invalid_plot(
                    "elevation",
                    "a 2D radar gives no elevation".into(),
                ));
            }
            (false, None) => {}
        }
        identity::validate(&plot.identity)?;
        if let Some(v) = plot.radial_velocity {
            error::finite("radial_velocity", v)?;
        } else if self.is_parallel() {
            return Err(invalid_plot(
                "radial_velocity",
                "required in parallel mode (time registration)".into(),
            ));
        }
        Ok(())
    }
}

impl TrackerConfig {
    /// The sensor index of a kind of cooperative report: after the radars.
    pub fn report_sensor(&self, kind: ReportKind) -> usize {
        self.radars.len() + kind.index()
    }

    /// The kind of report sensor `sensor` is, if it is one.
    pub fn report_kind(&self, sensor: usize) -> Option<ReportKind> {
        sensor
            .checked_sub(self.radars.len())
            .and_then(|i| ReportKind::ALL.get(i).copied())
    }

    /// Whether sensor `sensor` reports the target's own position (ADS-B,
    /// AIS: [`ReportKind::is_self_reported`]); a radar or MLAT does not.
    pub fn is_self_reported(&self, sensor: usize) -> bool {
        self.report_kind(sensor)
            .is_some_and(ReportKind::is_self_reported)
    }

    /// Every sensor's count: the radars and one per kind of report.
    pub fn sensors(&self) -> usize {
        self.radars.len() + ReportKind::ALL.len()
    }

    /// Checks a cooperative report: its sensor is its kind's, finite
    /// values, σ > 0; serial mode only (parallel mode fuses radar plots at
    /// fusion instants by their Doppler).
    fn validate_report(&self, plot: &Plot, report: &Report) -> Result<(), AlgoError> {
        if self.is_parallel() {
            return Err(invalid_plot(
                "report",
                "cooperative reports need serial mode (parallel mode fuses radar plots only)"
                    .into(),
            ));
        }
        if self.report_kind(plot.radar) != Some(report.kind) {
            return Err(invalid_plot(
                "radar",
                format!(
                    "a {} report's sensor is {}, got {}",
                    report.kind.name(),
                    self.report_sensor(report.kind),
                    plot.radar
                ),
            ));
        }
        error::finite("t", plot.t)?;
        error::finite_slice("report.position", &report.position)?;
        error::positive("report.sigma_horizontal", report.sigma_horizontal)?;
        if let Some(s) = report.sigma_vertical {
            error::positive("report.sigma_vertical", s)?;
        }
        if let Some(v) = &report.velocity {
            error::finite_slice("report.velocity", v)?;
            error::positive("report.sigma_velocity", report.sigma_velocity)?;
            if let Some(s) = report.sigma_vertical_velocity {
                error::positive("report.sigma_vertical_velocity", s)?;
            }
        }
        identity::validate(&plot.identity)
    }
}

fn default_misses(mode: Mode, radars: &[RadarSpec]) -> u32 {
    if mode == Mode::Parallel {
        3
    } else {
        (2 * radars.len().clamp(1, 30) as u32).max(3)
    }
}

fn validate_radar(r: &RadarSpec, axes: usize) -> Result<(), AlgoError> {
    finite_slice(P::RadarSite, &r.site)?;
    positive(P::RadarSigmaRange, r.sigma_range)?;
    positive(P::RadarSigmaAzimuth, r.sigma_azimuth)?;
    if let Some(s) = r.sigma_elevation {
        positive(P::RadarSigmaElevation, s)?;
        if axes == 2 {
            return Err(invalid(
                P::RadarSigmaElevation,
                "a 2D tracker takes 2D radars only; use a 3D tracker",
            ));
        }
    }
    if let Some(s) = r.sigma_radial_velocity {
        positive(P::RadarSigmaRadialVelocity, s)?;
    }
    positive(P::RadarScanPeriod, r.scan_period)?;
    let pd = r.detection_probability;
    if !(pd > 0.0 && pd <= 1.0) {
        return Err(invalid(
            P::RadarDetectionProbability,
            format!("must lie in (0, 1], got {pd}"),
        ));
    }
    positive(P::RadarClutterDensity, r.clutter_density)?;
    Ok(())
}

fn validate_initiation(i: &Initiation) -> Result<(), AlgoError> {
    if !(2 <= i.confirm_m && i.confirm_m <= i.confirm_n && i.confirm_n <= 64) {
        return Err(invalid(
            P::ConfirmMOfN,
            format!(
                "need 2 <= M <= N <= 64, got {}/{}",
                i.confirm_m, i.confirm_n
            ),
        ));
    }
    match i.velocity {
        VelocityGate::Speed { v_min, v_max } => {
            non_negative(P::VMin, v_min)?;
            positive(P::VMax, v_max)?;
            if v_min >= v_max {
                return Err(invalid(P::VMax, format!("must exceed v_min = {v_min}")));
            }
        }
        VelocityGate::PerAxis { v_min, v_max } => {
            finite_slice(P::VMin, &v_min)?;
            finite_slice(P::VMax, &v_max)?;
            if v_min.iter().zip(&v_max).any(|(lo, hi)| lo > hi) {
                return Err(invalid(P::VMax, "must be >= v_min on every axis"));
            }
        }
    }
    open_probability(P::InitiationGateProbability, i.gate_probability)?;
    positive(P::MinDt, i.min_dt)?;
    positive(P::MaxDt, i.max_dt)?;
    if i.max_dt < i.min_dt {
        return Err(invalid(
            P::MaxDt,
            format!("must be >= min_dt = {}", i.min_dt),
        ));
    }
    Ok(())
}

fn validate_imm(imm: &Imm) -> Result<(), AlgoError> {
    let r = imm.models.len();
    if !(2..=8).contains(&r) {
        return Err(invalid(
            P::ImmModels,
            format!("an IMM needs 2 to 8 models, got {r}"),
        ));
    }
    for m in &imm.models {
        for s in m.sigma_a() {
            non_negative(P::SigmaA, s)?;
        }
        if let MotionModel::CoordinatedTurn { turn_rate, .. } = m {
            finite(P::TurnRate, *turn_rate)?;
            if *turn_rate == 0.0 || turn_rate.abs() > 0.5 {
                return Err(invalid(
                    P::TurnRate,
                    format!("must be non-zero with |ω| ≤ 0.5 rad/s, got {turn_rate}"),
                ));
            }
        }
    }
    if imm.mean_sojourn.len() != r {
        return Err(invalid(
            P::MeanSojourn,
            format!(
                "one per model: {r} models, {} values",
                imm.mean_sojourn.len()
            ),
        ));
    }
    for &t in &imm.mean_sojourn {
        positive(P::MeanSojourn, t)?;
    }
    let p = &imm.initial_probabilities;
    if p.len() != r {
        return Err(invalid(
            P::InitialProbabilities,
            format!("one per model: {r} models, {} values", p.len()),
        ));
    }
    let sum: f64 = p.iter().sum();
    if p.iter().any(|v| !(v.is_finite() && *v > 0.0)) || (sum - 1.0).abs() > 1e-9 {
        return Err(invalid(
            P::InitialProbabilities,
            format!("each must be > 0 and they must sum to 1, got {p:?}"),
        ));
    }
    Ok(())
}

fn validate_deletion(d: &Deletion) -> Result<(), AlgoError> {
    if d.max_consecutive_misses == Some(0) {
        return Err(invalid(P::MaxConsecutiveMisses, "must be >= 1"));
    }
    if let Some((m, n)) = d.misses_m_of_n {
        if !(1 <= m && m <= n && n <= 64) {
            return Err(invalid(
                P::DeletionMOfN,
                format!("need 1 <= M <= N <= 64, got {m}/{n}"),
            ));
        }
    }
    if let Some(s) = d.max_position_sigma {
        positive(P::MaxPositionSigma, s)?;
    }
    Ok(())
}

fn open_probability(parameter: TrackerParameter, p: f64) -> Result<(), AlgoError> {
    if !(p > 0.0 && p < 1.0) {
        Err(invalid(parameter, format!("must lie in (0, 1), got {p}")))
    } else if 1.0 - p == 1.0 {
        // The χ² gate is the quantile at 1 − p: below 2⁻⁵³ that is 1 in
        // floating point, a gate of zero width (and no quantile).
        Err(invalid(
            parameter,
            format!("must be at least 1.2e-16 (a gate of this probability has no width), got {p}"),
        ))
    } else {
        Ok(())
    }
}

/// A plot's (not an option's) field outside its domain.
fn invalid_plot(what: &'static str, reason: String) -> AlgoError {
    AlgoError::InvalidParameter { what, reason }
}

#[cfg(test)]
mod probability_tests {
    use super::{P, open_probability};

    #[test]
    fn a_gate_probability_whose_complement_rounds_to_one_is_refused() {
        // 1 − 5e-324 and 1 − 2⁻⁵⁴ round to 1.0 in binary64 (the spacing of
        // doubles just below 1 is 2⁻⁵³): no χ² quantile exists there.
        assert!(open_probability(P::PlotGateProbability, 5e-324).is_err());
        assert!(open_probability(P::PlotGateProbability, 2f64.powi(-54)).is_err());
        // 1 − 2⁻⁵³ = 0.99999999999999989 is a double: a valid, tiny gate.
        assert!(open_probability(P::PlotGateProbability, 2f64.powi(-53)).is_ok());
        assert!(open_probability(P::PlotGateProbability, 0.99).is_ok());
        assert!(open_probability(P::PlotGateProbability, 0.0).is_err());
        assert!(open_probability(P::PlotGateProbability, 1.0).is_err());
    }
}
