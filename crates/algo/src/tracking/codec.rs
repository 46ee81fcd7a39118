//! Binary encoding of a [`Tracker`] (configuration and state) with
//! [`crate::wire`], so that a service can keep a tracker in a session.
//!
//! Layout: magic `RFTK`, format version (u32, currently 1), the
//! configuration, then the state: confirmed tracks, roots, tentative
//! tracks, pending plots, next id, last time, last instant, counters.
//! Every f64 is stored bit for bit, so a decoded tracker continues exactly
//! as the original would. Decoding validates the configuration, every plot
//! against it, every state dimension and every covariance (finite,
//! symmetric, positive definite).

use nalgebra::{DMatrix, DVector};

use crate::error::AlgoError;
use crate::gaussian::check_covariance;
use crate::jpda::{Config as JpdaConfig, Method};
use crate::tracking::config::{
    Deletion, Initiation, Mode, Plot, RadarSpec, TrackerConfig, VelocityGate,
};
use crate::tracking::initiator::Initiator;
use crate::tracking::registration::CartesianPlot;
use crate::tracking::track::Track;
use crate::tracking::{Counters, NoiseModel, Tracker};
use crate::wire::{Reader, Writer, corrupt};

const MAGIC: &[u8; 4] = b"RFTK";
/// Version of the encoding written by [`encode`].
pub const FORMAT_VERSION: u32 = 1;

pub(crate) fn encode(tr: &Tracker) -> Vec<u8> {
    let mut w = Writer::default();
    w.buf.extend_from_slice(MAGIC);
    w.u32(FORMAT_VERSION);
    config(&mut w, &tr.config);
    w.usize(tr.tracks.len());
    for t in &tr.tracks {
        track(&mut w, t);
    }
    w.usize(tr.initiator.roots.len());
    for r in &tr.initiator.roots {
        cartesian(&mut w, r);
    }
    w.usize(tr.initiator.tentatives.len());
    for t in &tr.initiator.tentatives {
        track(&mut w, t);
    }
    w.usize(tr.pending.len());
    for p in &tr.pending {
        plot(&mut w, p);
    }
    w.u64(tr.next_id);
    w.opt(tr.last_time, Writer::f64);
    w.opt(tr.last_instant, |w, k| w.u64(k as u64));
    encode_counters(&mut w, &tr.counters);
    w.buf
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
pub fn decode_counters(r: &mut Reader<'_>) -> Result<Counters, AlgoError> {
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

pub(crate) fn decode(bytes: &[u8]) -> Result<Tracker, AlgoError> {
    if bytes.len() < 4 || &bytes[..4] != MAGIC {
        return Err(corrupt("not an encoded tracker"));
    }
    let mut r = Reader::new(&bytes[4..]);
    let version = r.u32()?;
    if version != FORMAT_VERSION {
        return Err(corrupt(&format!("unknown tracker format {version}")));
    }
    let config = read_config(&mut r)?;
    let mut tr = Tracker::new(config)?;
    let n = r.len(8)?;
    tr.tracks = (0..n)
        .map(|_| read_track(&mut r, &tr.config))
        .collect::<Result<_, _>>()?;
    let n = r.len(8)?;
    let roots = (0..n)
        .map(|_| read_cartesian(&mut r, &tr.config))
        .collect::<Result<_, _>>()?;
    let n = r.len(8)?;
    let tentatives = (0..n)
        .map(|_| read_track(&mut r, &tr.config))
        .collect::<Result<_, _>>()?;
    tr.initiator = Initiator { roots, tentatives };
    let n = r.len(8)?;
    tr.pending = (0..n)
        .map(|_| read_plot(&mut r, &tr.config))
        .collect::<Result<_, _>>()?;
    tr.next_id = r.u64()?;
    tr.last_time = r.opt(Reader::f64)?;
    tr.last_instant = r.opt(|r| r.u64().map(|k| k as i64))?;
    tr.counters = decode_counters(&mut r)?;
    if !r.is_empty() {
        return Err(corrupt("trailing bytes"));
    }
    Ok(tr)
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
    w.f64(c.duplicate_probability);
}

fn read_config(r: &mut Reader<'_>) -> Result<TrackerConfig, AlgoError> {
    let axes = r.usize()?;
    let n = r.len(8)?;
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
        default_height: r.f64()?,
        default_height_sigma: r.f64()?,
        sigma_tangential_speed: r.f64()?,
        duplicate_probability: r.f64()?,
    })
}

fn track(w: &mut Writer, t: &Track) {
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
}

fn read_track(r: &mut Reader<'_>, c: &TrackerConfig) -> Result<Track, AlgoError> {
    let id = r.u64()?;
    let n = 2 * c.axes;
    let x = r.f64s()?;
    let p = r.f64s()?;
    if x.len() != n || p.len() != n * n {
        return Err(corrupt("track dimension"));
    }
    let x = DVector::from_vec(x);
    let p = DMatrix::from_vec(n, n, p);
    check_covariance("track covariance", &p)?;
    if x.iter().any(|v| !v.is_finite()) {
        return Err(corrupt("track state not finite"));
    }
    Ok(Track {
        id,
        x,
        p,
        t: r.f64()?,
        history: r.u64()?,
        age: r.u32()?,
        hits: r.u32()?,
        misses: r.u32()?,
        consecutive_misses: r.u32()?,
        radars: read_radars(r, c)?,
        last_update: r.f64()?,
    })
}

fn cartesian(w: &mut Writer, p: &CartesianPlot) {
    w.f64(p.t);
    w.f64s(p.z.as_slice());
    w.f64s(p.r.as_slice());
    radars(w, &p.radars);
}

fn read_cartesian(r: &mut Reader<'_>, c: &TrackerConfig) -> Result<CartesianPlot, AlgoError> {
    let t = r.f64()?;
    let z = r.f64s()?;
    let cov = r.f64s()?;
    let k = z.len();
    if !(2..=c.axes).contains(&k) || cov.len() != k * k {
        return Err(corrupt("plot dimension"));
    }
    let cov = DMatrix::from_vec(k, k, cov);
    check_covariance("plot covariance", &cov)?;
    Ok(CartesianPlot {
        t,
        z: DVector::from_vec(z),
        r: cov,
        radars: read_radars(r, c)?,
    })
}

fn plot(w: &mut Writer, p: &Plot) {
    w.usize(p.radar);
    w.f64(p.t);
    w.f64(p.range);
    w.f64(p.azimuth);
    w.opt(p.elevation, Writer::f64);
    w.opt(p.radial_velocity, Writer::f64);
}

fn read_plot(r: &mut Reader<'_>, c: &TrackerConfig) -> Result<Plot, AlgoError> {
    let p = Plot {
        radar: r.usize()?,
        t: r.f64()?,
        range: r.f64()?,
        azimuth: r.f64()?,
        elevation: r.opt(Reader::f64)?,
        radial_velocity: r.opt(Reader::f64)?,
    };
    c.validate_plot(&p)?;
    Ok(p)
}

fn radars(w: &mut Writer, v: &[usize]) {
    w.usize(v.len());
    for &i in v {
        w.usize(i);
    }
}

fn read_radars(r: &mut Reader<'_>, c: &TrackerConfig) -> Result<Vec<usize>, AlgoError> {
    let n = r.len(8)?;
    let v = (0..n).map(|_| r.usize()).collect::<Result<Vec<_>, _>>()?;
    if v.iter().any(|&i| i >= c.radars.len()) {
        return Err(corrupt("radar index"));
    }
    Ok(v)
}
