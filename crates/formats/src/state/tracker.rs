//! Binary encoding of an `algo` [`Tracker`] (configuration and state) with
//! [`wire_formats::wire`], so that a service can keep a tracker in a session. The
//! tracker lends its parts ([`Tracker::state`]) and is rebuilt from them
//! ([`Tracker::from_parts`], which checks them).
//!
//! Layout: magic `RFTK`, format version (u32, currently 9), the
//! configuration, then the state: confirmed tracks, roots, tentative
//! tracks, pending plots, next id, last time, last instant, counters.
//! Format 2 adds the predictor (`motion`) after the configuration, each
//! track's IMM modes after the track and, at the end, each radar's last
//! beam position (serial frames' sweeps); format 1 (trackers stored before the
//! IMM) is read as one constant-velocity model without modes, so such a
//! tracker continues exactly as it would have. Format 3 adds each
//! track's start time and last measured plot, and each root's radar plot
//! (provenance only, for ASTERIX I062/290 and I062/340); formats 1 and 2
//! read them as unknown. Format 4 adds, at the end, the registration's
//! configuration (on or off, per-radar priors, reference radars, minimum
//! pairs, longest pair interval, time constant) and its estimator's data
//! (information matrix and vector, pair counts, last pair time); formats
//! 1 to 3 read as registration by default (on; a lone radar learns only
//! against cooperative reports, which those formats never held)
//! from no data. Format 5 adds, at the end, each radar's beam position
//! when its sweep was last judged for misses (trackers since issue 48
//! judge a sweep in slices, not at every frame); formats 1 to 4 read it as
//! the last beam position, where they had judged. Format 6 adds each
//! plot's identity (Mode S address, Mode 3/A, Mode C, callsign, detection
//! type, SPI) after its radial velocity and each track's identity after
//! its last plot ([`super::identity`]); formats 1 to 5 read primary plots
//! and tracks that have learnt no identity. Format 7 adds, at the end,
//! the Mode C height's configuration (on, learning, prior offset and
//! slope with their σ), the height datum (flat, or the tangent frame's
//! origin height and radii of curvature) and the pressure offset's data
//! ([`algo::tracking::height`]), then per radar whether it has given a
//! Mode S address; formats 1 to 6 read Mode C heights off (so such a
//! tracker continues as it would have, but for the Mode S radars, which
//! it learns again), a flat datum and no data. Format 8 adds, at the
//! end, the accuracy estimator's configuration (on, time constant, pinned
//! radars) and per radar its data (last time; per component the decayed
//! count, sums of the innovation, the information, the excess and the
//! sandwich variance's, and the winsorised count;
//! [`algo::tracking::accuracy`]); formats 1 to 7 read it off (the
//! declared σ applied, as that release did) without data. Format 9 adds
//! each track's last hit per radar after its identity
//! and, at the end, each radar's detection trials (decayed trials and
//! detections, last time); format 8 reads them as none (the detection
//! probability is then learnt from the next scans on). Format 11 stores
//! each plot's cooperative report (`Plot::report`, after its identity)
//! and each track's check of its self-reported positions (after its last
//! Mode A/C time); format 10 reads radar plots and unchecked tracks.
//! Every f64 is stored bit for bit, so a decoded tracker continues exactly
//! as the original would. Decoding validates the configuration, every plot
//! against it, every state dimension and every covariance (finite,
//! symmetric, positive definite).

use algo::jpda::{Config as JpdaConfig, Method};
use algo::tracking::{
    CartesianPlot, Counters, Deletion, Disagreement, Identity, Imm, Initiation, Mode, Motion,
    MotionModel, NoiseModel, Plot, RadarHit, RadarSpec, Report, ReportKind, Track, TrackIdentity,
    Tracker, TrackerConfig, TrackerParts, Validation, VelocityGate,
    accuracy::{AccuracyConfig, AccuracyState, ComponentData, DetectionData, RadarAccuracyData},
    height::{HeightDatum, ModeCHeight, PressureOffset},
    identity::Evidence,
    predictor::ModeState,
    registration::{BiasPrior, RegistrationConfig, RegistrationState},
};
use nalgebra::{DMatrix, DVector};

use super::identity::{
    TRACKER_FORMAT, evidence, read_evidence, read_identity, read_track_identity, write_identity,
    write_track_identity,
};
use wire_formats::wire::{FormatError, Reader, Writer, corrupt, invalid};

const MAGIC: &[u8; 4] = b"RFTK";
/// Version of the encoding written by [`encode_tracker`].
pub const FORMAT_VERSION: u32 = 11;
/// The format from which tracks keep their last hit per radar and the
/// radars their detection trials.
const DETECTION_FORMAT: u32 = 9;
/// The format from which tracks keep the time of their last Mode A/C-only
/// reply to a Mode S radar (`TrackIdentity::last_mode_ac`).
const MODE_AC_FORMAT: u32 = 10;
/// The format from which plots may be cooperative reports (`Plot::report`)
/// and tracks keep the check of their self-reported positions
/// (`TrackIdentity::validation`).
pub(crate) const REPORT_FORMAT: u32 = 11;

/// The tracker as bytes (configuration included), for [`decode_tracker`].
pub fn encode_tracker(tr: &Tracker) -> Vec<u8> {
    encode_tracker_as(tr, FORMAT_VERSION)
}

/// The tracker in format 5 to 11 (5: without identities, 6: without
/// Mode C heights, 7: without the accuracy estimator, 8: without the
/// detection trials, 9: without the tracks' Mode A/C-only replies, 10:
/// without reports, as earlier releases wrote them; for the tests of
/// older formats).
pub(crate) fn encode_tracker_as(tr: &Tracker, version: u32) -> Vec<u8> {
    assert!((5..=FORMAT_VERSION).contains(&version));
    let s = tr.state();
    let mut w = Writer::default();
    w.buf.extend_from_slice(MAGIC);
    w.u32(version);
    config(&mut w, s.config);
    w.usize(s.tracks.len());
    for t in s.tracks {
        track(&mut w, t, version);
    }
    w.usize(s.roots.len());
    for r in s.roots {
        cartesian(&mut w, r, version);
    }
    w.usize(s.tentatives.len());
    for t in s.tentatives {
        track(&mut w, t, version);
    }
    w.usize(s.pending.len());
    for p in s.pending {
        plot_as(&mut w, p, version);
    }
    w.u64(s.next_id);
    w.opt(s.last_time, Writer::f64);
    w.opt(s.last_instant, |w, k| w.u64(k as u64));
    encode_counters(&mut w, &s.counters);
    beams(&mut w, s.beams);
    registration(&mut w, &s.config.registration, s.registration);
    beams(&mut w, s.judged);
    if version >= 7 {
        mode_c_height(&mut w, s.config, s.pressure_offset);
        flags(&mut w, s.mode_s_radars);
    }
    if version >= 8 {
        accuracy(&mut w, &s.config.accuracy, s.accuracy, version);
    }
    w.buf
}

/// The accuracy estimator's options and data (format 8), with the
/// detection trials after them from [`DETECTION_FORMAT`] on.
fn accuracy(w: &mut Writer, c: &AccuracyConfig, data: &AccuracyState, version: u32) {
    w.bool(c.enabled);
    w.f64(c.time_constant);
    radars(w, &c.pinned);
    w.usize(data.radars.len());
    for d in &data.radars {
        w.opt(d.t, Writer::f64);
        for k in &d.components {
            w.f64_run(&[k.weight, k.sum, k.information, k.excess]);
            w.f64_run(&k.sandwich);
            w.u64(k.clipped);
        }
    }
    if version >= DETECTION_FORMAT {
        for d in &data.radars {
            let d = &d.detection;
            w.f64_run(&[d.trials, d.detections]);
            w.opt(d.t, Writer::f64);
        }
    }
}

fn read_accuracy(
    r: &mut Reader<'_>,
    version: u32,
) -> Result<(AccuracyConfig, AccuracyState), FormatError> {
    let enabled = r.bool()?;
    let time_constant = r.f64()?;
    let pinned = read_radars(r)?;
    let n = r.len(8)?;
    let mut radars = (0..n)
        .map(|_| {
            let t = r.opt(Reader::f64)?;
            let mut d = RadarAccuracyData {
                t,
                ..Default::default()
            };
            for k in &mut d.components {
                let [weight, sum, information, excess] = r.f64_run::<4>()?;
                *k = ComponentData {
                    weight,
                    sum,
                    information,
                    excess,
                    sandwich: r.f64_run::<3>()?,
                    clipped: r.u64()?,
                };
            }
            Ok(d)
        })
        .collect::<Result<Vec<RadarAccuracyData>, FormatError>>()?;
    if version >= DETECTION_FORMAT {
        for d in &mut radars {
            let [trials, detections] = r.f64_run::<2>()?;
            d.detection = DetectionData {
                trials,
                detections,
                t: r.opt(Reader::f64)?,
            };
        }
    }
    let config = AccuracyConfig {
        enabled,
        time_constant,
        pinned,
    };
    Ok((config, AccuracyState { radars }))
}

fn mode_c_height(w: &mut Writer, c: &TrackerConfig, data: &PressureOffset) {
    let m = &c.mode_c_height;
    w.u8(u8::from(m.enabled) | (u8::from(m.learn) << 1));
    w.f64_run(&[m.offset, m.sigma_offset, m.slope, m.sigma_slope]);
    match c.height_datum {
        HeightDatum::Flat => w.u8(0),
        HeightDatum::Tangent {
            origin_height,
            meridian,
            prime_vertical,
        } => {
            w.u8(1);
            w.f64_run(&[origin_height, meridian, prime_vertical]);
        }
    }
    w.f64_run(&data.information);
    w.f64_run(&data.vector);
    w.opt(data.t, Writer::f64);
    w.u64(data.plots);
    w.u64(data.rejected);
}

fn flags(w: &mut Writer, v: &[bool]) {
    w.usize(v.len());
    for &b in v {
        w.bool(b);
    }
}

fn read_flags(r: &mut Reader<'_>) -> Result<Vec<bool>, FormatError> {
    let n = r.len(1)?;
    (0..n).map(|_| r.bool()).collect()
}

fn read_mode_c_height(
    r: &mut Reader<'_>,
) -> Result<(ModeCHeight, HeightDatum, PressureOffset), FormatError> {
    let flags = r.u8()?;
    if flags > 3 {
        return Err(corrupt("Mode C height flags"));
    }
    let [offset, sigma_offset, slope, sigma_slope] = r.f64_run()?;
    let config = ModeCHeight {
        enabled: flags & 1 != 0,
        learn: flags & 2 != 0,
        offset,
        sigma_offset,
        slope,
        sigma_slope,
    };
    let datum = match r.u8()? {
        0 => HeightDatum::Flat,
        1 => {
            let [origin_height, meridian, prime_vertical] = r.f64_run()?;
            HeightDatum::Tangent {
                origin_height,
                meridian,
                prime_vertical,
            }
        }
        _ => return Err(corrupt("height datum")),
    };
    let information = r.f64_run()?;
    let vector = r.f64_run()?;
    let data = PressureOffset {
        information,
        vector,
        t: r.opt(Reader::f64)?,
        plots: r.u64()?,
        rejected: r.u64()?,
    };
    Ok((config, datum, data))
}

fn beams(w: &mut Writer, beams: &[Option<(f64, f64)>]) {
    w.usize(beams.len());
    for b in beams {
        w.opt(*b, |w, (t, az)| {
            w.f64(t);
            w.f64(az);
        });
    }
}

fn read_beams(r: &mut Reader<'_>) -> Result<Vec<Option<(f64, f64)>>, FormatError> {
    let n = r.len(1)?;
    (0..n)
        .map(|_| r.opt(|r| Ok((r.f64()?, r.f64()?))))
        .collect()
}

fn registration(w: &mut Writer, c: &RegistrationConfig, s: &RegistrationState) {
    w.u8(u8::from(c.enabled));
    w.usize(c.priors.len());
    for p in &c.priors {
        w.f64_run(&[
            p.range,
            p.azimuth,
            p.elevation,
            p.sigma_range,
            p.sigma_azimuth,
            p.sigma_elevation,
        ]);
    }
    w.usize(c.reference.len());
    for &r in &c.reference {
        w.usize(r);
    }
    w.u32(c.min_pairs);
    w.f64(c.max_pair_dt);
    w.f64(c.time_constant);
    w.usize(s.vector.len());
    w.f64_run(s.information.as_slice());
    w.f64_run(s.vector.as_slice());
    w.f64_run(&s.pairs);
    w.opt(s.last_t, Writer::f64);
}

fn read_registration(
    r: &mut Reader<'_>,
    radars: usize,
) -> Result<(RegistrationConfig, RegistrationState), FormatError> {
    let enabled = r.u8()? != 0;
    let n = r.len(48)?;
    let mut priors = Vec::with_capacity(n);
    for _ in 0..n {
        let mut v = [0.0; 6];
        for x in &mut v {
            *x = r.f64()?;
        }
        priors.push(BiasPrior {
            range: v[0],
            azimuth: v[1],
            elevation: v[2],
            sigma_range: v[3],
            sigma_azimuth: v[4],
            sigma_elevation: v[5],
        });
    }
    let n = r.len(8)?;
    let reference = (0..n).map(|_| r.usize()).collect::<Result<_, _>>()?;
    let config = RegistrationConfig {
        enabled,
        priors,
        reference,
        min_pairs: r.u32()?,
        max_pair_dt: r.f64()?,
        time_constant: r.f64()?,
    };
    let n = r.len(8)?;
    let read = |r: &mut Reader<'_>, k: usize| -> Result<Vec<f64>, FormatError> {
        (0..k).map(|_| r.f64()).collect()
    };
    let information = DMatrix::from_vec(n, n, read(r, n * n)?);
    let vector = DVector::from_vec(read(r, n)?);
    let pairs = read(r, radars)?;
    let last_t = r.opt(Reader::f64)?;
    Ok((
        config,
        RegistrationState {
            information,
            vector,
            pairs,
            last_t,
        },
    ))
}

/// The counters, nine u64 in declaration order.
pub fn encode_counters(w: &mut Writer, c: &Counters) {
    for v in [
        c.plots,
        c.late,
        c.frames,
        c.fused_plots,
        c.started,
        c.confirmed,
        c.dropped,
        c.deleted,
        c.merged,
    ] {
        w.u64(v);
    }
}

/// What [`encode_counters`] wrote.
pub fn decode_counters(r: &mut Reader<'_>) -> Result<Counters, FormatError> {
    Ok(Counters {
        plots: r.u64()?,
        late: r.u64()?,
        frames: r.u64()?,
        fused_plots: r.u64()?,
        started: r.u64()?,
        confirmed: r.u64()?,
        dropped: r.u64()?,
        deleted: r.u64()?,
        merged: r.u64()?,
    })
}

/// A tracker from [`encode_tracker`]'s bytes. Bytes that are not such an
/// encoding are [`FormatError::Corrupt`]; parts the tracker rejects (the
/// configuration, a covariance, a plot, an index) are
/// [`FormatError::Invalid`].
pub fn decode_tracker(bytes: &[u8]) -> Result<Tracker, FormatError> {
    if bytes.len() < 4 || &bytes[..4] != MAGIC {
        return Err(corrupt("not an encoded tracker"));
    }
    let mut r = Reader::new(&bytes[4..]);
    let version = r.u32()?;
    if !(1..=FORMAT_VERSION).contains(&version) {
        return Err(corrupt(&format!("unknown tracker format {version}")));
    }
    let config = read_config(&mut r, version)?;
    let n = r.len(8)?;
    let tracks = (0..n)
        .map(|_| read_track(&mut r, version))
        .collect::<Result<_, _>>()?;
    let n = r.len(8)?;
    let roots = (0..n)
        .map(|_| read_cartesian(&mut r, version))
        .collect::<Result<_, _>>()?;
    let n = r.len(8)?;
    let tentatives = (0..n)
        .map(|_| read_track(&mut r, version))
        .collect::<Result<_, _>>()?;
    let n = r.len(8)?;
    let pending = (0..n)
        .map(|_| read_plot(&mut r, version))
        .collect::<Result<_, _>>()?;
    let next_id = r.u64()?;
    let last_time = r.opt(Reader::f64)?;
    let last_instant = r.opt(|r| r.u64().map(|k| k as i64))?;
    let counters = decode_counters(&mut r)?;
    let beams = if version >= 2 {
        read_beams(&mut r)?
    } else {
        Vec::new()
    };
    let mut config = config;
    let registration = if version >= 4 {
        let (c, state) = read_registration(&mut r, config.radars.len())?;
        config.registration = c;
        Some(state)
    } else {
        None
    };
    let judged = if version >= 5 {
        read_beams(&mut r)?
    } else {
        Vec::new()
    };
    let (pressure_offset, mode_s_radars) = if version >= 7 {
        let (c, datum, data) = read_mode_c_height(&mut r)?;
        config.mode_c_height = c;
        config.height_datum = datum;
        (data, read_flags(&mut r)?)
    } else {
        // A 3D tracker of an earlier release took no height from Mode C
        // (in 2D the option changes nothing).
        config.mode_c_height.enabled = config.axes != 3;
        (PressureOffset::default(), Vec::new())
    };
    let accuracy = if version >= 8 {
        let (c, data) = read_accuracy(&mut r, version)?;
        config.accuracy = c;
        Some(data)
    } else {
        // A tracker of an earlier release applied the declared σ.
        config.accuracy.enabled = false;
        None
    };
    if !r.is_empty() {
        return Err(corrupt("trailing bytes"));
    }
    Tracker::from_parts(TrackerParts {
        accuracy,
        config,
        registration,
        tracks,
        roots,
        tentatives,
        pending,
        next_id,
        last_time,
        last_instant,
        counters,
        beams,
        judged,
        pressure_offset,
        mode_s_radars,
    })
    .map_err(invalid)
}

fn config(w: &mut Writer, c: &TrackerConfig) {
    w.usize(c.axes);
    w.usize(c.radars.len());
    for r in &c.radars {
        for v in r.site {
            w.f64(v);
        }
        w.f64(r.sigma_range);
        w.f64(r.sigma_azimuth);
        w.opt(r.sigma_elevation, Writer::f64);
        w.opt(r.sigma_radial_velocity, Writer::f64);
        w.f64(r.scan_period);
        w.f64(r.detection_probability);
        w.f64(r.clutter_density);
    }
    w.u8(match c.mode {
        Mode::Auto => 0,
        Mode::Parallel => 1,
        Mode::Serial => 2,
    });
    w.f64(c.fusion_period);
    w.f64(c.fusion_epoch);
    w.f64(c.time_tolerance);
    w.u8(match c.association.method {
        Method::Exact => 0,
        Method::Amsjpda => 1,
        Method::NearestNeighbour => 2,
        Method::GlobalNearestNeighbour => 3,
    });
    w.usize(c.association.max_exact_tracks);
    w.u64(c.association.max_hypotheses);
    w.f64(c.plot_gate_probability);
    w.f64(c.track_gate_probability);
    let i = &c.initiation;
    w.u32(i.confirm_m);
    w.u32(i.confirm_n);
    match i.velocity {
        VelocityGate::Speed { v_min, v_max } => {
            w.u8(0);
            w.f64(v_min);
            w.f64(v_max);
        }
        VelocityGate::PerAxis { v_min, v_max } => {
            w.u8(1);
            for v in v_min.iter().chain(&v_max) {
                w.f64(*v);
            }
        }
    }
    w.f64(i.gate_probability);
    w.f64(i.min_dt);
    w.f64(i.max_dt);
    let d = &c.deletion;
    w.opt(d.max_consecutive_misses, Writer::u32);
    w.opt(d.misses_m_of_n, |w, (m, n)| {
        w.u32(m);
        w.u32(n);
    });
    w.opt(d.max_position_sigma, Writer::f64);
    for v in c.sigma_a {
        w.f64(v);
    }
    w.u8(match c.noise {
        NoiseModel::Cwna => 0,
        NoiseModel::Dwna => 1,
    });
    w.f64(c.default_height);
    w.f64(c.default_height_sigma);
    w.f64(c.sigma_tangential_speed);
    w.f64(c.duplicate_gate_probability);
    match &c.motion {
        Motion::ConstantVelocity => w.u8(0),
        Motion::Imm(imm) => {
            w.u8(1);
            w.usize(imm.models.len());
            for m in &imm.models {
                match m {
                    MotionModel::ConstantVelocity { sigma_a } => {
                        w.u8(0);
                        w.f64_run(sigma_a);
                    }
                    MotionModel::CoordinatedTurn { turn_rate, sigma_a } => {
                        w.u8(1);
                        w.f64(*turn_rate);
                        w.f64_run(sigma_a);
                    }
                }
            }
            w.f64_run(&imm.mean_sojourn);
            w.f64_run(&imm.initial_probabilities);
        }
    }
}

fn read_motion(r: &mut Reader<'_>) -> Result<Motion, FormatError> {
    match r.u8()? {
        0 => Ok(Motion::ConstantVelocity),
        1 => {
            let n = r.len(8)?;
            let mut models = Vec::with_capacity(n);
            for _ in 0..n {
                models.push(match r.u8()? {
                    0 => MotionModel::ConstantVelocity {
                        sigma_a: [r.f64()?, r.f64()?, r.f64()?],
                    },
                    1 => MotionModel::CoordinatedTurn {
                        turn_rate: r.f64()?,
                        sigma_a: [r.f64()?, r.f64()?, r.f64()?],
                    },
                    _ => return Err(corrupt("bad motion model")),
                });
            }
            let mean_sojourn = (0..n).map(|_| r.f64()).collect::<Result<_, _>>()?;
            let initial_probabilities = (0..n).map(|_| r.f64()).collect::<Result<_, _>>()?;
            Ok(Motion::Imm(Imm {
                models,
                mean_sojourn,
                initial_probabilities,
            }))
        }
        _ => Err(corrupt("bad motion")),
    }
}

fn read_config(r: &mut Reader<'_>, version: u32) -> Result<TrackerConfig, FormatError> {
    let axes = r.usize()?;
    let n = r.len(8)?;
    let radars_len = n;
    let mut radars = Vec::with_capacity(n);
    for _ in 0..n {
        radars.push(RadarSpec {
            site: [r.f64()?, r.f64()?, r.f64()?],
            sigma_range: r.f64()?,
            sigma_azimuth: r.f64()?,
            sigma_elevation: r.opt(Reader::f64)?,
            sigma_radial_velocity: r.opt(Reader::f64)?,
            scan_period: r.f64()?,
            detection_probability: r.f64()?,
            clutter_density: r.f64()?,
        });
    }
    let mode = match r.u8()? {
        0 => Mode::Auto,
        1 => Mode::Parallel,
        2 => Mode::Serial,
        _ => return Err(corrupt("bad mode")),
    };
    let fusion_period = r.f64()?;
    let fusion_epoch = r.f64()?;
    let time_tolerance = r.f64()?;
    let method = match r.u8()? {
        0 => Method::Exact,
        1 => Method::Amsjpda,
        2 => Method::NearestNeighbour,
        3 => Method::GlobalNearestNeighbour,
        _ => return Err(corrupt("bad association method")),
    };
    let association = JpdaConfig {
        method,
        max_exact_tracks: r.usize()?,
        max_hypotheses: r.u64()?,
    };
    let plot_gate_probability = r.f64()?;
    let track_gate_probability = r.f64()?;
    let confirm_m = r.u32()?;
    let confirm_n = r.u32()?;
    let velocity = match r.u8()? {
        0 => VelocityGate::Speed {
            v_min: r.f64()?,
            v_max: r.f64()?,
        },
        1 => VelocityGate::PerAxis {
            v_min: [r.f64()?, r.f64()?, r.f64()?],
            v_max: [r.f64()?, r.f64()?, r.f64()?],
        },
        _ => return Err(corrupt("bad velocity gate")),
    };
    let initiation = Initiation {
        confirm_m,
        confirm_n,
        velocity,
        gate_probability: r.f64()?,
        min_dt: r.f64()?,
        max_dt: r.f64()?,
    };
    let deletion = Deletion {
        max_consecutive_misses: r.opt(Reader::u32)?,
        misses_m_of_n: r.opt(|r| Ok((r.u32()?, r.u32()?)))?,
        max_position_sigma: r.opt(Reader::f64)?,
    };
    let sigma_a = [r.f64()?, r.f64()?, r.f64()?];
    let noise = match r.u8()? {
        0 => NoiseModel::Cwna,
        1 => NoiseModel::Dwna,
        _ => return Err(corrupt("bad noise model")),
    };
    let default_height = r.f64()?;
    let default_height_sigma = r.f64()?;
    let sigma_tangential_speed = r.f64()?;
    let duplicate_gate_probability = r.f64()?;
    let motion = if version >= 2 {
        read_motion(r)?
    } else {
        Motion::ConstantVelocity
    };
    // Format 1 resolved `Auto` to parallel when every radar gave Doppler:
    // keep the mode such a tracker ran in.
    let mode = if version == 1 && mode == Mode::Auto && radars.iter().all(RadarSpec::has_doppler) {
        Mode::Parallel
    } else {
        mode
    };
    Ok(TrackerConfig {
        axes,
        radars,
        mode,
        fusion_period,
        fusion_epoch,
        time_tolerance,
        association,
        plot_gate_probability,
        track_gate_probability,
        initiation,
        deletion,
        sigma_a,
        noise,
        motion,
        default_height,
        default_height_sigma,
        sigma_tangential_speed,
        duplicate_gate_probability,
        // Formats 1 to 3: the default; format 4 reads its own at the end.
        registration: RegistrationConfig::for_radars(radars_len),
        // Read from format 7's end, else off (decode_tracker).
        mode_c_height: ModeCHeight::default(),
        height_datum: HeightDatum::Flat,
        // Read from format 8's end, else off (decode_tracker).
        accuracy: AccuracyConfig::default(),
    })
}

fn track(w: &mut Writer, t: &Track, version: u32) {
    let ids = version >= TRACKER_FORMAT;
    w.u64(t.id);
    w.f64s(t.x.as_slice());
    w.f64s(t.p.as_slice());
    w.f64(t.t);
    w.u64(t.history);
    w.u32(t.age);
    w.u32(t.hits);
    w.u32(t.misses);
    w.u32(t.consecutive_misses);
    radars(w, &t.radars);
    w.f64(t.last_update);
    w.usize(t.modes.len());
    for m in &t.modes {
        w.f64(m.probability);
        w.f64_run(m.x.as_slice());
        w.f64_run(m.p.as_slice());
    }
    w.opt(t.started, Writer::f64);
    w.opt(t.last_plot.as_ref(), |w, p| plot_as(w, p, version));
    if ids {
        write_track_identity(w, &t.identity);
    }
    if version >= DETECTION_FORMAT {
        w.usize(t.detections.len());
        for h in &t.detections {
            w.usize(h.radar);
            w.f64(h.last);
        }
    }
    if version >= MODE_AC_FORMAT {
        w.opt(t.identity.last_mode_ac, Writer::f64);
    }
    if version >= REPORT_FORMAT {
        write_validation(w, &t.identity.validation, t.identity.mmsi);
    }
}

fn write_validation(w: &mut Writer, v: &Validation, mmsi: Option<Evidence<u32>>) {
    evidence(w, mmsi, Writer::u32);
    for t in [v.last_independent, v.last_self_reported, v.distrusted_since] {
        w.opt(t, Writer::f64);
    }
    w.u32(v.disagreements);
    w.u32(v.agreements);
    w.opt(v.last_disagreement, |w, d| {
        w.f64(d.t);
        w.f64(d.distance);
        w.f64(d.sigma);
    });
}

fn read_validation(r: &mut Reader<'_>) -> Result<(Validation, Option<Evidence<u32>>), FormatError> {
    let mmsi = read_evidence(r, Reader::u32)?;
    let v = Validation {
        last_independent: r.opt(Reader::f64)?,
        last_self_reported: r.opt(Reader::f64)?,
        distrusted_since: r.opt(Reader::f64)?,
        disagreements: r.u32()?,
        agreements: r.u32()?,
        last_disagreement: r.opt(|r| {
            Ok(Disagreement {
                t: r.f64()?,
                distance: r.f64()?,
                sigma: r.f64()?,
            })
        })?,
    };
    let times = [v.last_independent, v.last_self_reported, v.distrusted_since];
    let finite = times.iter().flatten().all(|t| t.is_finite())
        && v.last_disagreement
            .is_none_or(|d| d.t.is_finite() && d.distance >= 0.0 && d.sigma >= 0.0);
    if finite {
        Ok((v, mmsi))
    } else {
        Err(corrupt("validation of self-reported positions"))
    }
}

/// A track as stored; its dimension, covariance and radar indices are
/// checked by [`Tracker::from_parts`] against the configuration.
fn read_track(r: &mut Reader<'_>, version: u32) -> Result<Track, FormatError> {
    let id = r.u64()?;
    let x = r.f64s()?;
    let p = r.f64s()?;
    let n = x.len();
    if p.len() != n * n {
        return Err(corrupt("track dimension"));
    }
    let mut track = Track {
        id,
        x: DVector::from_vec(x),
        p: DMatrix::from_vec(n, n, p),
        t: r.f64()?,
        history: r.u64()?,
        age: r.u32()?,
        hits: r.u32()?,
        misses: r.u32()?,
        consecutive_misses: r.u32()?,
        radars: read_radars(r)?,
        last_update: r.f64()?,
        modes: if version >= 2 {
            let k = r.len(8 * (1 + n + n * n))?;
            (0..k)
                .map(|_| {
                    Ok(ModeState {
                        probability: r.f64()?,
                        x: DVector::from_vec((0..n).map(|_| r.f64()).collect::<Result<_, _>>()?),
                        p: DMatrix::from_vec(
                            n,
                            n,
                            (0..n * n).map(|_| r.f64()).collect::<Result<_, _>>()?,
                        ),
                    })
                })
                .collect::<Result<_, FormatError>>()?
        } else {
            Vec::new()
        },
        started: None,
        last_plot: None,
        identity: TrackIdentity::default(),
        detections: Vec::new(),
    };
    if version >= 3 {
        track.started = r.opt(Reader::f64)?;
        track.last_plot = r.opt(|r| read_plot(r, version))?;
    }
    if version >= TRACKER_FORMAT {
        track.identity = read_track_identity(r)?;
    }
    if version >= DETECTION_FORMAT {
        let n = r.len(8 + 8)?;
        track.detections = (0..n)
            .map(|_| {
                Ok(RadarHit {
                    radar: r.usize()?,
                    last: r.f64()?,
                })
            })
            .collect::<Result<_, FormatError>>()?;
    }
    if version >= MODE_AC_FORMAT {
        track.identity.last_mode_ac = r.opt(Reader::f64)?;
    }
    if version >= REPORT_FORMAT {
        (track.identity.validation, track.identity.mmsi) = read_validation(r)?;
    }
    Ok(track)
}

fn cartesian(w: &mut Writer, p: &CartesianPlot, version: u32) {
    w.f64(p.t);
    w.f64s(p.z.as_slice());
    w.f64s(p.r.as_slice());
    radars(w, &p.radars);
    w.opt(p.measured.as_ref(), |w, p| plot_as(w, p, version));
}

fn read_cartesian(r: &mut Reader<'_>, version: u32) -> Result<CartesianPlot, FormatError> {
    let t = r.f64()?;
    let z = r.f64s()?;
    let cov = r.f64s()?;
    let k = z.len();
    if cov.len() != k * k {
        return Err(corrupt("plot dimension"));
    }
    Ok(CartesianPlot {
        t,
        z: DVector::from_vec(z),
        r: DMatrix::from_vec(k, k, cov),
        radars: read_radars(r)?,
        measured: if version >= 3 {
            r.opt(|r| read_plot(r, version))?
        } else {
            None
        },
        // The initiator keeps positions only (range rates are the
        // updater's, dropped before initiation).
        range_rates: Vec::new(),
        velocity: Vec::new(),
    })
}

/// A plot as tracker format `version` stores it: its identity from
/// format 6, its report from [`REPORT_FORMAT`] (an earlier format holds
/// radar plots only).
pub(crate) fn plot_as(w: &mut Writer, p: &Plot, version: u32) {
    w.usize(p.radar);
    w.f64(p.t);
    w.f64(p.range);
    w.f64(p.azimuth);
    w.opt(p.elevation, Writer::f64);
    w.opt(p.radial_velocity, Writer::f64);
    if version >= TRACKER_FORMAT {
        write_identity(w, &p.identity);
    }
    if version >= REPORT_FORMAT {
        w.opt(p.report.as_ref(), write_report);
        w.opt(p.identity.mmsi, Writer::u32);
    }
}

fn write_report(w: &mut Writer, r: &Report) {
    w.u8(r.kind.index() as u8);
    for v in r.position {
        w.f64(v);
    }
    w.f64(r.sigma_horizontal);
    w.opt(r.sigma_vertical, Writer::f64);
    w.opt(r.velocity, |w, v| {
        for c in v {
            w.f64(c);
        }
    });
    w.f64(r.sigma_velocity);
    w.opt(r.sigma_vertical_velocity, Writer::f64);
}

fn read_report(r: &mut Reader<'_>) -> Result<Report, FormatError> {
    let kind = ReportKind::ALL
        .get(usize::from(r.u8()?))
        .copied()
        .ok_or_else(|| corrupt("report kind"))?;
    let three = |r: &mut Reader<'_>| -> Result<[f64; 3], FormatError> {
        Ok([r.f64()?, r.f64()?, r.f64()?])
    };
    // Values are checked by the tracker (`TrackerConfig::validate_plot`).
    Ok(Report {
        kind,
        position: three(r)?,
        sigma_horizontal: r.f64()?,
        sigma_vertical: r.opt(Reader::f64)?,
        velocity: r.opt(three)?,
        sigma_velocity: r.f64()?,
        sigma_vertical_velocity: r.opt(Reader::f64)?,
    })
}

/// A plot as tracker format `version` stores it.
pub(crate) fn read_plot(r: &mut Reader<'_>, version: u32) -> Result<Plot, FormatError> {
    Ok(Plot {
        radar: r.usize()?,
        t: r.f64()?,
        range: r.f64()?,
        azimuth: r.f64()?,
        elevation: r.opt(Reader::f64)?,
        radial_velocity: r.opt(Reader::f64)?,
        identity: if version >= TRACKER_FORMAT {
            read_identity(r)?
        } else {
            Identity::default()
        },
        report: if version >= REPORT_FORMAT {
            r.opt(read_report)?
        } else {
            None
        },
    })
    .and_then(|mut p: Plot| {
        if version >= REPORT_FORMAT {
            p.identity.mmsi = r.opt(Reader::u32)?;
        }
        Ok(p)
    })
}

fn radars(w: &mut Writer, v: &[usize]) {
    w.usize(v.len());
    for &i in v {
        w.usize(i);
    }
}

fn read_radars(r: &mut Reader<'_>) -> Result<Vec<usize>, FormatError> {
    let n = r.len(8)?;
    (0..n).map(|_| r.usize()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::TAU;

    fn radar(site: [f64; 3], period: f64, doppler: bool) -> RadarSpec {
        RadarSpec {
            site,
            sigma_range: 100.0,
            sigma_azimuth: 100.0 / 43_000.0,
            sigma_elevation: None,
            sigma_radial_velocity: doppler.then_some(1.0),
            scan_period: period,
            detection_probability: 0.99,
            clutter_density: 1e-7,
        }
    }

    fn config(doppler: bool) -> TrackerConfig {
        let mut c = TrackerConfig::new(
            2,
            vec![
                radar([-200.0, 0.0, 0.0], 10.0, doppler),
                radar([200.0, 0.0, 0.0], 8.0, doppler),
            ],
        );
        c.sigma_a = [0.05; 3];
        c.initiation.velocity = VelocityGate::Speed {
            v_min: 0.0,
            v_max: 150.0,
        };
        c
    }

    /// Two straight targets seen by both radars without noise but for a
    /// fixed sub-sigma wobble (no random generator in this crate).
    fn plots(c: &TrackerConfig, duration: f64) -> Vec<Plot> {
        let targets = [
            ([-25_000.0, 35_000.0], [30.0, -50.0]),
            ([-26_000.0, 31_000.0], [50.0, 20.0]),
        ];
        let mut out = Vec::new();
        for (i, r) in c.radars.iter().enumerate() {
            let mut t = 0.37 * i as f64;
            let mut n = 0u32;
            while t <= duration {
                for (p0, v) in targets {
                    let (e, nn) = (p0[0] + v[0] * t - r.site[0], p0[1] + v[1] * t - r.site[1]);
                    let wobble = f64::from(n % 7) - 3.0;
                    let range = e.hypot(nn) + 20.0 * wobble;
                    let unit = [e / e.hypot(nn), nn / e.hypot(nn)];
                    out.push(Plot {
                        radar: i,
                        t,
                        range,
                        azimuth: e.atan2(nn) + 3e-4 * wobble,
                        elevation: None,
                        radial_velocity: r
                            .sigma_radial_velocity
                            .map(|_| v[0] * unit[0] + v[1] * unit[1]),
                        identity: Default::default(),
                        report: None,
                    });
                    n += 1;
                }
                t += r.scan_period;
            }
        }
        out.sort_by(|a, b| a.t.total_cmp(&b.t));
        out
    }

    /// Format 6: plots and tracks with their SSR and Mode S identity
    /// (address, code with flags, Mode C, callsign, detection, SPI; the
    /// tracks' evidence and pressure altitude) round-trip bit for bit, and
    /// the decoded tracker continues as the original.
    #[test]
    fn identities_round_trip_and_continue() {
        use algo::tracking::{Detection, Mode3A, ModeC};
        let cfg = config(false);
        let mut all = plots(&cfg, 100.0);
        for (k, p) in all.iter_mut().enumerate() {
            // The scene lists each scan's two targets in order.
            let i = k % 2;
            p.identity = Identity {
                address: Some([0x4CA2D1, 0x3C6586][i]),
                mode_3a: Some(Mode3A {
                    code: [0o1234, 0o7000][i],
                    validated: k % 5 != 0,
                    garbled: k % 11 == 0,
                }),
                mode_c: Some(ModeC {
                    flight_level: [300.0, 310.25][i],
                    validated: true,
                    garbled: false,
                }),
                callsign: (i == 0).then_some(*b"EZY12AB "),
                detection: Some([Detection::Combined, Detection::Secondary][i]),
                spi: k % 13 == 0,
                mmsi: None,
            };
        }
        let (first, rest) = all.split_at(all.len() / 2);
        let mut a = Tracker::new(cfg).unwrap();
        a.process(first).unwrap();
        assert!(
            a.state()
                .tracks
                .iter()
                .any(|t| t.identity.altitude.is_some())
        );
        round_trips_and_continues(&mut a, rest);
    }

    /// `a` encoded and decoded is `a` bit for bit and, fed `rest`, goes on
    /// as `a` does; every truncation of its bytes is an error, never a
    /// panic.
    fn round_trips_and_continues(a: &mut Tracker, rest: &[Plot]) {
        let bytes = encode_tracker(a);
        let mut b = decode_tracker(&bytes).unwrap();
        assert_eq!(&b, a);
        a.process(rest).unwrap();
        b.process(rest).unwrap();
        assert_eq!(encode_tracker(a), encode_tracker(&b));
        for cut in 0..bytes.len() {
            assert!(decode_tracker(&bytes[..cut]).is_err(), "cut at {cut}");
        }
    }

    /// Format 7: a 3D tracker of Mode S plots (3D radars, so it learns the
    /// pressure offset; a tangent datum) round-trips bit for bit with its
    /// Mode C height options, offset data and Mode S radars, and continues
    /// as the original; written as format 6 it reads back with Mode C
    /// heights off (what a tracker of that release did).
    #[test]
    fn mode_c_heights_round_trip_and_continue() {
        use algo::tracking::ModeC;
        use algo::tracking::height::HeightDatum;
        let mut cfg = config(false);
        cfg.axes = 3;
        for r in &mut cfg.radars {
            r.sigma_elevation = Some(0.2f64.to_radians());
        }
        cfg.mode_c_height.sigma_offset = 120.0;
        cfg.height_datum = HeightDatum::Tangent {
            origin_height: 400.0,
            meridian: 6_367_000.0,
            prime_vertical: 6_389_000.0,
        };
        let mut all = plots(&cfg, 100.0);
        for (k, p) in all.iter_mut().enumerate() {
            let i = k % 2;
            let h = [9144.0, 9449.0][i];
            let ground = p.range;
            p.range = ground.hypot(h);
            p.elevation = Some(h.atan2(ground));
            p.identity = Identity {
                address: Some([0x4CA2D1, 0x3C6586][i]),
                mode_c: Some(ModeC {
                    flight_level: h / 30.48,
                    validated: true,
                    garbled: false,
                }),
                ..Identity::default()
            };
        }
        let (first, rest) = all.split_at(all.len() / 2);
        let mut a = Tracker::new(cfg).unwrap();
        a.process(first).unwrap();
        assert!(a.state().pressure_offset.plots > 0);
        assert!(a.state().mode_s_radars.iter().all(|&m| m));
        round_trips_and_continues(&mut a, rest);
        let v6 = decode_tracker(&encode_tracker_as(&a, 6)).unwrap();
        assert!(!v6.config().mode_c_height.enabled);
        assert_eq!(v6.state().pressure_offset.plots, 0);
        assert!(v6.pressure_offset().is_none());
    }

    /// Format 8: a tracker with accuracy data and a pinned radar
    /// round-trips bit for bit and continues as the original; written as
    /// format 7 it reads back with the estimator off and no data (the
    /// declared σ applied, as that release did).
    #[test]
    fn accuracy_round_trips_and_continues() {
        let mut cfg = config(true);
        cfg.accuracy.pinned = vec![1];
        cfg.accuracy.time_constant = 600.0;
        let all = plots(&cfg, 100.0);
        let (first, rest) = all.split_at(all.len() / 2);
        let mut a = Tracker::new(cfg).unwrap();
        a.process(first).unwrap();
        let learnt = &a.state().accuracy.radars;
        assert!(
            learnt.iter().all(|d| d.components[0].weight > 0.0),
            "{learnt:?}"
        );
        round_trips_and_continues(&mut a, rest);
        let v7 = decode_tracker(&encode_tracker_as(&a, 7)).unwrap();
        assert!(!v7.config().accuracy.enabled);
        assert!(v7.state().accuracy.radars.iter().all(|d| d.t.is_none()));
    }

    /// Format 9: the tracks' last hits per radar and the radars' detection
    /// trials (beam-timed plots: each plot at scan start + period·θ/2π)
    /// round-trip bit for bit and the decoded tracker continues as the
    /// original; written as format 8 it reads back without them (learnt
    /// again from the next scans).
    #[test]
    fn detection_trials_round_trip_and_continue() {
        let mut cfg = config(false);
        // Pinned: trials count before the σ converge (two aircraft give
        // too few plots in 100 s to converge them).
        cfg.accuracy.pinned = vec![0, 1];
        let mut all = plots(&cfg, 200.0);
        for p in &mut all {
            p.t += cfg.radars[p.radar].scan_period * p.azimuth.rem_euclid(TAU) / TAU;
        }
        all.sort_by(|a, b| a.t.total_cmp(&b.t));
        let (first, rest) = all.split_at(all.len() / 2);
        let mut a = Tracker::new(cfg).unwrap();
        a.process(first).unwrap();
        let trials: Vec<f64> = a
            .accuracy()
            .iter()
            .map(|r| r.detection_probability.samples)
            .collect();
        assert!(trials.iter().all(|&n| n > 0.0), "{trials:?}");
        assert!(a.state().tracks.iter().all(|t| t.detections.len() == 2));
        round_trips_and_continues(&mut a, rest);
        let v8 = decode_tracker(&encode_tracker_as(&a, 8)).unwrap();
        assert!(v8.state().tracks.iter().all(|t| t.detections.is_empty()));
        assert!(
            v8.state()
                .accuracy
                .radars
                .iter()
                .all(|d| d.detection == Default::default() && d.t.is_some())
        );
    }

    /// Format 10: a track whose aircraft answers the Mode S radars in Mode
    /// A/C only (the other aircraft gives its address, so both radars give
    /// addresses) keeps the time of that reply through a round trip and
    /// continues as the original; written as format 9 it reads back
    /// without it.
    #[test]
    fn mode_a_c_replies_round_trip_and_continue() {
        use algo::tracking::{Detection, Mode3A};
        let cfg = config(false);
        let mut all = plots(&cfg, 100.0);
        for (k, p) in all.iter_mut().enumerate() {
            p.identity = Identity {
                address: (k % 2 == 0).then_some(0x4CA2D1),
                mode_3a: Some(Mode3A {
                    code: [0o1234, 0o7000][k % 2],
                    validated: true,
                    garbled: false,
                }),
                detection: Some(Detection::Secondary),
                ..Identity::default()
            };
        }
        let (first, rest) = all.split_at(all.len() / 2);
        let mut a = Tracker::new(cfg).unwrap();
        a.process(first).unwrap();
        assert!(a.state().mode_s_radars.iter().all(|&m| m));
        let mode_ac = |t: &Tracker| {
            t.state()
                .tracks
                .iter()
                .filter(|t| t.identity.last_mode_ac.is_some())
                .count()
        };
        assert_eq!(mode_ac(&a), 1);
        round_trips_and_continues(&mut a, rest);
        let v9 = decode_tracker(&encode_tracker_as(&a, 9)).unwrap();
        assert_eq!(mode_ac(&v9), 0);
    }

    /// Format 11: radar plots with Mode S addresses beside ADS-B reports
    /// of the same aircraft, one aircraft's ADS-B 3 km off from 40 s (its
    /// track distrusts it), cut where reports are pending and tentatives
    /// hold reports: round-trips bit for bit and continues as the original;
    /// written as format 10 the tracks read back unchecked.
    #[test]
    fn reports_round_trip_and_continue() {
        use algo::tracking::{Detection, ModeC};
        let cfg = config(false);
        let sensor = cfg.report_sensor(ReportKind::Adsb);
        let identity = |address| Identity {
            address: Some(address),
            mode_c: Some(ModeC {
                flight_level: 120.0,
                validated: true,
                garbled: false,
            }),
            detection: Some(Detection::Secondary),
            // Not an aircraft's, but stored alike (format 11).
            mmsi: Some(address / 16 + 200_000_000),
            ..Identity::default()
        };
        let mut all = plots(&cfg, 100.0);
        let mut reports = Vec::new();
        for (k, p) in all.iter_mut().enumerate() {
            // Targets alternate within a radar's scan (plots() pushes them
            // in order): address by target.
            let address = [0x4CA2D1, 0x3C6586][k % 2];
            p.identity = identity(address);
            let site = cfg.radars[p.radar].site;
            let spoof = if address == 0x3C6586 && p.t >= 40.0 {
                3000.0
            } else {
                0.0
            };
            let report = Report {
                kind: ReportKind::Adsb,
                position: [
                    site[0] + p.range * p.azimuth.sin(),
                    site[1] + p.range * p.azimuth.cos() + spoof,
                    0.0,
                ],
                sigma_horizontal: 15.0,
                sigma_vertical: None,
                velocity: None,
                sigma_velocity: 0.0,
                sigma_vertical_velocity: None,
            };
            reports.push(Plot::report(sensor, p.t + 0.5, report, identity(address)));
        }
        all.extend(reports);
        all.sort_by(|a, b| a.t.total_cmp(&b.t));
        let (first, rest) = all.split_at(all.len() * 3 / 4);
        let mut a = Tracker::new(cfg).unwrap();
        a.process(first).unwrap();
        let state = a.state();
        assert!(state.pending.iter().any(|p| p.report.is_some()) || !state.pending.is_empty());
        let distrusted = state
            .tracks
            .iter()
            .filter(|t| !t.identity.validation.trusted())
            .count();
        assert_eq!(distrusted, 1);
        assert!(state.tracks.iter().all(|t| t.identity.mmsi.is_some()));
        round_trips_and_continues(&mut a, rest);
        let v10 = decode_tracker(&encode_tracker_as(&a, 10));
        // Format 10 cannot hold a report: its pending reports read back as
        // radar plots of a report's sensor index, which the tracker refuses,
        // or it holds none and its tracks read back unchecked.
        if let Ok(v10) = v10 {
            assert!(
                v10.state()
                    .tracks
                    .iter()
                    .all(|t| t.identity.validation.trusted())
            );
        }
    }

    /// Chunks fed to a tracker that is encoded and decoded between them
    /// give the bytes of one call with every plot (cuts inside a radar's
    /// scan group included); the fixtures of earlier sessions are decoded
    /// by the service's tests.
    #[test]
    fn chunks_with_encode_decode_equal_one_call() {
        for doppler in [false, true] {
            let cfg = config(doppler);
            let plots = plots(&cfg, 100.0);
            let mut whole = Tracker::new(cfg.clone()).unwrap();
            whole.process(&plots).unwrap();
            whole.flush().unwrap();
            assert!(whole.counters().confirmed >= 2, "doppler = {doppler}");
            let cuts = [0, 1, 3, 4, 7, 8, 20, 21, 33, plots.len()];
            let mut bytes = encode_tracker(&Tracker::new(cfg.clone()).unwrap());
            for w in cuts.windows(2) {
                let mut t = decode_tracker(&bytes).unwrap();
                t.process(&plots[w[0]..w[1]]).unwrap();
                bytes = encode_tracker(&t);
            }
            let mut chunked = decode_tracker(&bytes).unwrap();
            chunked.flush().unwrap();
            assert_eq!(chunked, whole, "doppler = {doppler}");
            assert_eq!(encode_tracker(&chunked), encode_tracker(&whole));
        }
    }

    /// Trackers stored in format 1 (before the IMM; written by
    /// `tracker_v1_fixture`, kept in `tests/fixtures`, from this module's
    /// scene without Doppler cut at half its plots) decode as one
    /// constant-velocity model and continue exactly as they would have:
    /// the second half on the decoded mid-run tracker gives the stored end.
    #[test]
    fn format_1_trackers_decode_and_continue() {
        let mid = decode_tracker(include_bytes!(
            "../../../../tests/fixtures/tracker_v1_mid.bin"
        ))
        .unwrap();
        let end = decode_tracker(include_bytes!(
            "../../../../tests/fixtures/tracker_v1_end.bin"
        ))
        .unwrap();
        assert_eq!(mid.config().motion, Motion::ConstantVelocity);
        let plots = plots(mid.config(), 100.0);
        assert_eq!(plots.len(), 48);
        let mut t = mid;
        t.process(&plots[24..]).unwrap();
        t.flush().unwrap();
        // Equal but for the beam positions and the provenance (start
        // times, measured plots) the continued tracker now holds (format 1
        // has none; every frame here is a whole scan; the filter reads no
        // provenance).
        let mut parts = t.state().to_parts();
        parts.beams = vec![None; 2];
        parts.judged = vec![None; 2];
        for tr in parts.tracks.iter_mut().chain(&mut parts.tentatives) {
            tr.started = None;
            tr.last_plot = None;
            tr.detections.clear();
        }
        for root in &mut parts.roots {
            root.measured = None;
        }
        // Registration (format 4) is on for the decoded tracker, as for any
        // tracker of two radars: it learned from this half's pairs. With it
        // off the continuation is the stored end exactly; with it on the
        // tracks stay within 5 m of it (the scene's radars are unbiased).
        let on = parts.clone();
        parts.config.registration.enabled = false;
        parts.registration = None;
        let mut off = end.state().to_parts();
        off.config.registration.enabled = false;
        off.registration = None;
        // Replay with registration off from the decoded mid-run tracker.
        let mut mid_off = decode_tracker(include_bytes!(
            "../../../../tests/fixtures/tracker_v1_mid.bin"
        ))
        .unwrap()
        .state()
        .to_parts();
        mid_off.config.registration.enabled = false;
        let mut t_off = Tracker::from_parts(mid_off).unwrap();
        t_off.process(&plots[24..]).unwrap();
        t_off.flush().unwrap();
        let mut replayed = t_off.state().to_parts();
        replayed.beams = vec![None; 2];
        replayed.judged = vec![None; 2];
        for tr in replayed.tracks.iter_mut().chain(&mut replayed.tentatives) {
            tr.started = None;
            tr.last_plot = None;
            tr.detections.clear();
        }
        for root in &mut replayed.roots {
            root.measured = None;
        }
        replayed.registration = None;
        // The same tracks, lives and counters; the states to rounding
        // (since issue 48 a single-model track takes the IMM update path
        // with one mode, the PDA update in another order of operations).
        let close = |a: &[f64], b: &[f64]| {
            a.iter()
                .zip(b)
                .all(|(x, y)| (x - y).abs() <= 1e-9 * x.abs().max(y.abs()).max(1.0))
        };
        assert_eq!(replayed.tracks.len(), off.tracks.len());
        for (a, b) in replayed.tracks.iter_mut().zip(&off.tracks) {
            assert!(close(a.x.as_slice(), b.x.as_slice()), "track {}", a.id);
            assert!(close(a.p.as_slice(), b.p.as_slice()), "track {}", a.id);
            a.x.clone_from(&b.x);
            a.p.clone_from(&b.p);
        }
        assert_eq!(replayed, off);
        assert_eq!(on.tracks.len(), off.tracks.len());
        for (a, b) in on.tracks.iter().zip(&off.tracks) {
            let d = (a.x[0] - b.x[0]).hypot(a.x[2] - b.x[2]);
            assert!(d < 5.0, "track {}: {d} m", a.id);
        }
        assert_eq!(t.counters().confirmed, 2);
        // Written again it is the current format and reads back the same.
        let bytes = encode_tracker(&t);
        assert_eq!(
            u32::from_le_bytes(bytes[4..8].try_into().unwrap()),
            FORMAT_VERSION
        );
        assert_eq!(decode_tracker(&bytes).unwrap(), t);
    }

    /// A format-1 tracker in mode `Auto` with Doppler on every radar ran in
    /// parallel mode; it is read back as parallel (`Auto` is serial now).
    #[test]
    fn a_format_1_auto_tracker_with_doppler_stays_parallel() {
        let mut cfg = config(true);
        cfg.motion = Motion::ConstantVelocity;
        assert_eq!(cfg.mode, Mode::Auto);
        let fresh = Tracker::new(cfg).unwrap();
        assert_eq!(fresh.mode(), Mode::Serial);
        let mut bytes = encode_tracker_as(&fresh, 6);
        // Format 5's judged beams go first (a count and two absent
        // options), then format 4's registration block.
        bytes.truncate(bytes.len() - 10);
        let mut block = Writer::default();
        registration(
            &mut block,
            &fresh.config().registration,
            fresh.state().registration,
        );
        bytes.truncate(bytes.len() - block.buf.len());
        // Format 1: no beams at the end (a count and two absent options:
        // 8 + 2 bytes) and no motion byte. A fresh tracker ends with four
        // empty lists (4 × 8 bytes), next id (8), two absent options (2)
        // and the counters (72) after the motion byte.
        bytes.truncate(bytes.len() - 10);
        let at = bytes.len() - (32 + 8 + 2 + 72) - 1;
        assert_eq!(bytes[at], 0, "the motion byte of one CV model");
        bytes.remove(at);
        bytes[4..8].copy_from_slice(&1u32.to_le_bytes());
        let old = decode_tracker(&bytes).unwrap();
        assert_eq!(old.mode(), Mode::Parallel);
        assert_eq!(old.config().motion, Motion::ConstantVelocity);
    }

    #[test]
    fn imm_trackers_round_trip() {
        let mut cfg = config(false);
        // As a release before the accuracy estimator (format 7 and
        // earlier read it off).
        cfg.accuracy.enabled = false;
        assert!(matches!(cfg.motion, Motion::Imm(_)));
        let mut t = Tracker::new(cfg.clone()).unwrap();
        t.process(&plots(&cfg, 100.0)).unwrap();
        assert!(t.state().tracks.iter().all(|tr| tr.modes.len() == 4));
        assert!(!t.state().tracks.is_empty());
        let bytes = encode_tracker(&t);
        assert_eq!(decode_tracker(&bytes).unwrap(), t);
        // Format 5 (no identities: none here) reads back the same, but
        // for the tracks' hits per radar (format 9), as format 8 does.
        let v5 = encode_tracker_as(&t, 5);
        let v8 = decode_tracker(&encode_tracker_as(&t, 8)).unwrap();
        assert_eq!(decode_tracker(&v5).unwrap(), v8);
        // Format 4 (no judged beams) reads them as the last beams, where a
        // tracker of that release had judged its misses.
        let mut judged = Writer::default();
        beams(&mut judged, t.state().judged);
        let mut v4 = v5[..v5.len() - judged.buf.len()].to_vec();
        v4[4..8].copy_from_slice(&4u32.to_le_bytes());
        let old = decode_tracker(&v4).unwrap();
        assert_eq!(old.state().judged, t.state().beams);
        assert!(old.state().beams.iter().all(Option::is_some));
    }

    #[test]
    fn corrupt_bytes_are_errors_never_panics() {
        let cfg = config(false);
        let mut tracker = Tracker::new(cfg).unwrap();
        tracker
            .process(&plots(&tracker.config().clone(), 60.0))
            .unwrap();
        assert!(!tracker.state().tracks.is_empty() && !tracker.state().pending.is_empty());
        let bytes = encode_tracker(&tracker);
        assert_eq!(decode_tracker(&bytes).unwrap(), tracker);
        // Every truncation, and a trailing byte.
        for cut in 0..bytes.len() {
            assert!(
                matches!(decode_tracker(&bytes[..cut]), Err(FormatError::Corrupt(_))),
                "cut at {cut}"
            );
        }
        let mut long = bytes.clone();
        long.push(0);
        assert!(matches!(
            decode_tracker(&long),
            Err(FormatError::Corrupt(_))
        ));
        assert!(matches!(
            decode_tracker(b"nope"),
            Err(FormatError::Corrupt(_))
        ));
        let mut next = bytes.clone();
        next[4] = FORMAT_VERSION as u8 + 1;
        assert!(matches!(
            decode_tracker(&next),
            Err(FormatError::Corrupt(_))
        ));
        // Every single-byte flip decodes to an error or to some tracker:
        // never a panic.
        for i in 0..bytes.len() {
            let mut b = bytes.clone();
            b[i] ^= 0xa5;
            let _ = decode_tracker(&b);
        }
        // Well-formed bytes of a state no tracker could hold: a track's
        // first variance made negative. Layout: magic 4, version 4 bytes, then
        // the configuration; find the covariance by its bits.
        let p00 = tracker.state().tracks[0].p[(0, 0)].to_le_bytes();
        let at = bytes
            .windows(8)
            .position(|w| w == p00)
            .expect("the first track's P[0,0] is stored");
        let mut b = bytes.clone();
        b[at..at + 8].copy_from_slice(&(-1.0f64).to_le_bytes());
        assert!(matches!(decode_tracker(&b), Err(FormatError::Invalid(_))));
    }

    /// Valid encodings of trackers with tracks and pending plots, without
    /// and with Doppler (built once).
    fn valid_encodings() -> &'static [Vec<u8>] {
        static ENCODED: std::sync::OnceLock<Vec<Vec<u8>>> = std::sync::OnceLock::new();
        ENCODED.get_or_init(|| {
            [false, true]
                .into_iter()
                .map(|doppler| {
                    let mut tracker = Tracker::new(config(doppler)).unwrap();
                    tracker
                        .process(&plots(&tracker.config().clone(), 60.0))
                        .unwrap();
                    encode_tracker(&tracker)
                })
                .collect()
        })
    }

    proptest::proptest! {
        #![proptest_config(proptest::test_runner::Config::with_cases(256))]

        /// Several edits of a valid encoding (bytes, extreme words where
        /// lengths and counts are, insertions, cuts) decode to an error or
        /// to a tracker that encodes and decodes again: never a panic, and
        /// never an allocation a length in the bytes asked for.
        #[test]
        fn mutated_trackers_are_errors_or_trackers_never_panics(
            which in 0..2usize,
            edits in wire_formats::mutation::edits(),
        ) {
            let bytes = wire_formats::mutation::apply(&valid_encodings()[which], &edits);
            if let Ok(tracker) = decode_tracker(&bytes) {
                let again = encode_tracker(&tracker);
                proptest::prop_assert!(decode_tracker(&again).is_ok());
            }
        }
    }
}
