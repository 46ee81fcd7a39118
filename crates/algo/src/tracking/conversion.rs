//! Plots converted to the fusion frame: the patent's "spatial
//! registration" (seed 001 step 1, Fig. 2), polar to ENU, and its "time
//! registration" by extrapolation to a fusion instant (step 3, 3a–3b). (In
//! radar literature registration means estimating sensor biases; this
//! module only converts.)
//!
//! Step 1: a plot z′ = (ρ, θ(, φ)) measured in the frame of a radar at
//! [a, b(, c)] becomes the fusion-frame position `[a, b] + ρ[sin θ, cos θ]`
//! (azimuth from north; the patent's figure measures from the x axis, so
//! sine and cosine swap) with the converted covariance J R J′, both by
//! [`crate::polar::plot_to_local`]. A 2D radar's range is taken as
//! horizontal. The patent also re-expresses the Doppler velocity: it is
//! measured along the radar's line of sight u, not along the line of
//! sight u_c from the fusion centre; the registered radial velocity is the
//! projection ṙ (u · u_c) and the Cartesian Doppler components are ṙ u.
//! [`doppler_in_fusion_frame`] computes both; its σ is the radar's own σ_ṙ
//! (the patent gives no other), and the tracker itself only uses ṙ for
//! time registration.
//!
//! Step 3: a plot taken at τ is moved to the fusion instant t along its own
//! radar's line of sight by ṙ (t − τ), the angles held ("only the radial
//! displacement can be obtained; the target's angles are assumed
//! unchanged"). The range variance grows by (t − τ)² σ_ṙ²; the converted
//! covariance is then J R′ J′ at the extrapolated range, plus the unseen
//! cross-range motion (see [`extrapolate`]). If the
//! extrapolated range would not be positive (a target passing over the
//! radar within one period) the plot keeps its measured range.

use nalgebra::{DMatrix, DVector};

use crate::error::AlgoError;
use crate::polar::{PolarMeasurement, plot_to_local, polar_to_enu_2d, polar_to_enu_3d};
use crate::tracking::config::{Plot, RadarSpec};

/// A plot (or a fused plot) as a Cartesian position in the fusion ENU frame:
/// `[e, n]` from 2D radars, `[e, n, u]` when a 3D radar contributed.
#[derive(Debug, Clone, PartialEq)]
pub struct CartesianPlot {
    /// Time of the position (s): the plot's time, or the fusion instant.
    pub t: f64,
    /// Position, 2 or 3 components.
    pub z: DVector<f64>,
    /// Its covariance, symmetric positive definite.
    pub r: DMatrix<f64>,
    /// The radars whose plots make it up, ascending.
    pub radars: Vec<usize>,
    /// The radar plot it was converted from, when it is one radar's plot
    /// (`None` for a fused plot): what a track updated by it reports as
    /// its last measurement (ASTERIX I062/340).
    pub measured: Option<Plot>,
    /// The range rates of the radar plots it was moved from to a fusion
    /// instant (parallel mode with Doppler radars; empty otherwise): the
    /// updater uses them as further measurements.
    pub range_rates: Vec<RangeRate>,
    /// Velocity components a cooperative report measured (ADS-B's ground
    /// vector, AIS's SOG/COG): further linear measurements of the state's
    /// velocity. Empty for a radar's plot.
    pub velocity: Vec<VelocityComponent>,
}

/// One measured velocity component of a [`CartesianPlot`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VelocityComponent {
    /// The axis: 0 east, 1 north, 2 up.
    pub axis: usize,
    /// The velocity along it (m/s).
    pub value: f64,
    /// Its σ (m/s), > 0.
    pub sigma: f64,
}

/// A radar plot's range rate carried by a plot moved to a fusion instant
/// (parallel mode), with what the update needs: the measurement model is
/// ṙ = d·v/|d| with d = p − v·Δt − s, the target's position relative to
/// the radar at the plot's own time τ = t − Δt under constant velocity
/// (so a plot moved by seconds is compared with the range rate it saw,
/// not with the one at the instant). The extrapolated position used ṙ
/// itself (ρ′ = ρ + ṙΔt), so the two are correlated: Cov(z, ṙ) = u Δt σ_ṙ²
/// (u = ∂z/∂ρ, the line of sight), carried through fusion.
#[derive(Debug, Clone, PartialEq)]
pub struct RangeRate {
    /// The radar's site (fusion frame, m).
    pub site: [f64; 3],
    /// The measured range rate ṙ (m/s).
    pub value: f64,
    /// Its σ (m/s): the radar's σ_ṙ and the change of ṙ the motion model
    /// allows over Δt, √(σ_ṙ² + q|Δt|) (see [`extrapolate`]).
    pub sigma: f64,
    /// Δt = t − τ from the plot's time to the position's time (s).
    pub dt: f64,
    /// `true` for a 2D radar: ṙ of the horizontal range.
    pub horizontal: bool,
    /// Cov(z, ṙ), one entry per component of the position z (m²/s).
    pub cross: DVector<f64>,
}

/// A plot's measurement as a track's update sees it: innovation ν, the
/// Jacobian H at the state and the measurement covariance R.
#[derive(Debug, Clone)]
pub struct Linearised {
    /// ν = z − h(x).
    pub innovation: DVector<f64>,
    /// H = ∂h/∂x at x.
    pub h: DMatrix<f64>,
    /// R.
    pub r: DMatrix<f64>,
}

/// Below this distance (m) from a radar a range rate is not used: its
/// direction is undefined.
const MIN_RANGE_FOR_RANGE_RATE: f64 = 1.0;

impl CartesianPlot {
    /// The plot's measurement about the state `x` (`[x, vx, y, vy(, z,
    /// vz)]`): the position z, then each range rate ([`RangeRate`]) with
    /// the EKF Jacobian of ṙ = d·v/|d|, d = p − vΔt − s (over the
    /// horizontal components for a 2D radar):
    /// ∂ṙ/∂p = v/|d| − ṙ d/|d|², ∂ṙ/∂v = (d − Δt v)/|d| + Δt ṙ d/|d|²;
    /// R = [[R_z, C], [C′, diag σ_ṙ²]] with C the columns Cov(z, ṙ).
    pub fn linearise(&self, x: &DVector<f64>) -> Linearised {
        let axes = x.len() / 2;
        let k = self.z.len();
        let rates: Vec<&RangeRate> = self
            .range_rates
            .iter()
            .filter(|rr| range_rate_distance(rr, x) >= MIN_RANGE_FOR_RANGE_RATE)
            .collect();
        let velocity: Vec<&VelocityComponent> =
            self.velocity.iter().filter(|v| v.axis < axes).collect();
        let m = k + rates.len() + velocity.len();
        let mut h = DMatrix::zeros(m, 2 * axes);
        let mut innovation = DVector::zeros(m);
        let mut r = DMatrix::zeros(m, m);
        for i in 0..k {
            h[(i, 2 * i)] = 1.0;
            innovation[i] = self.z[i] - x[2 * i];
        }
        r.view_mut((0, 0), (k, k)).copy_from(&self.r);
        for (row, rr) in rates.iter().enumerate().map(|(i, rr)| (k + i, rr)) {
            let used = if rr.horizontal { 2 } else { axes.min(3) };
            let d: Vec<f64> = (0..used)
                .map(|i| x[2 * i] - rr.dt * x[2 * i + 1] - rr.site[i])
                .collect();
            let norm = d.iter().map(|v| v * v).sum::<f64>().sqrt();
            let pred = (0..used).map(|i| d[i] * x[2 * i + 1]).sum::<f64>() / norm;
            for i in 0..used {
                let v = x[2 * i + 1];
                h[(row, 2 * i)] = v / norm - pred * d[i] / (norm * norm);
                h[(row, 2 * i + 1)] =
                    (d[i] - rr.dt * v) / norm + rr.dt * pred * d[i] / (norm * norm);
            }
            innovation[row] = rr.value - pred;
            r[(row, row)] = rr.sigma * rr.sigma;
            for i in 0..k.min(rr.cross.len()) {
                r[(i, row)] = rr.cross[i];
                r[(row, i)] = rr.cross[i];
            }
        }
        for (row, v) in velocity
            .iter()
            .enumerate()
            .map(|(i, v)| (k + rates.len() + i, v))
        {
            h[(row, 2 * v.axis + 1)] = 1.0;
            innovation[row] = v.value - x[2 * v.axis + 1];
            r[(row, row)] = v.sigma * v.sigma;
        }
        Linearised { innovation, h, r }
    }

    /// The (extended) Kalman update of (x, P) with the plot
    /// ([`CartesianPlot::linearise`]); the linear position update when it
    /// carries no range rate.
    pub fn update(
        &self,
        x: &DVector<f64>,
        p: &DMatrix<f64>,
    ) -> Result<crate::kalman::Update, AlgoError> {
        let lin = self.linearise(x);
        crate::kalman::update_linearised(x, p, lin.innovation, &lin.h, &lin.r)
    }
}

/// A cooperative report ([`Plot::report`]) as a Cartesian measurement of
/// a tracker of `axes` axes: its horizontal position, its height when it
/// gives a geometric one (3D tracker), its velocity's components, each
/// with its stated σ (independent components: the report's quality
/// indicators bound each axis alike). Only for a report (a plot with
/// [`Plot::report`]).
pub(crate) fn report_plot(plot: &Plot, axes: usize) -> CartesianPlot {
    let r = plot
        .report
        .expect("report_plot is given cooperative reports only");
    let vertical = r.sigma_vertical.filter(|_| axes == 3);
    let mut z = vec![r.position[0], r.position[1]];
    let mut var = vec![r.sigma_horizontal.powi(2); 2];
    if let Some(s) = vertical {
        z.push(r.position[2]);
        var.push(s * s);
    }
    let mut velocity = Vec::new();
    if let Some(v) = r.velocity {
        for (axis, &value) in v.iter().enumerate().take(2) {
            velocity.push(VelocityComponent {
                axis,
                value,
                sigma: r.sigma_velocity,
            });
        }
        if let (Some(s), 3) = (r.sigma_vertical_velocity, axes) {
            velocity.push(VelocityComponent {
                axis: 2,
                value: v[2],
                sigma: s,
            });
        }
    }
    CartesianPlot {
        t: plot.t,
        z: DVector::from_vec(z),
        r: DMatrix::from_diagonal(&DVector::from_vec(var)),
        radars: vec![plot.radar],
        measured: Some(*plot),
        range_rates: Vec::new(),
        velocity,
    }
}

/// |d| of a range rate about the state `x` (see [`CartesianPlot::linearise`]).
fn range_rate_distance(rr: &RangeRate, x: &DVector<f64>) -> f64 {
    let used = if rr.horizontal {
        2
    } else {
        (x.len() / 2).min(3)
    };
    (0..used)
        .map(|i| (x[2 * i] - rr.dt * x[2 * i + 1] - rr.site[i]).powi(2))
        .sum::<f64>()
        .sqrt()
}

/// The Doppler measurement re-expressed about the fusion centre (step 1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Doppler {
    /// Radial velocity along the line of sight from the fusion centre's
    /// origin to the plot, ṙ (u · u_c) (m/s).
    pub radial_velocity: f64,
    /// The radar's own σ_ṙ (m/s).
    pub sigma: f64,
    /// Cartesian Doppler components ṙ u in the fusion frame `[e, n, u]` (m/s).
    pub components: [f64; 3],
}

/// The plot in the radar's polar coordinates with the radar's σ.
pub fn polar_measurement(radar: &RadarSpec, plot: &Plot) -> PolarMeasurement {
    PolarMeasurement {
        range: plot.range,
        azimuth: plot.azimuth,
        elevation: plot.elevation,
        sigma_range: radar.sigma_range,
        sigma_azimuth: radar.sigma_azimuth,
        sigma_elevation: radar.sigma_elevation,
    }
}

/// Step 1: the plot as a fusion-frame position at its own time.
pub fn register(
    radar: &RadarSpec,
    radar_index: usize,
    plot: &Plot,
) -> Result<CartesianPlot, AlgoError> {
    let mut out = to_cartesian(radar, radar_index, plot.t, &polar_measurement(radar, plot))?;
    out.measured = Some(*plot);
    Ok(out)
}

/// Steps 1 and 3: the plot moved to time `t` along its radar's line of
/// sight (range ρ + ṙ (t − τ), angles held, σ_ρ² + (t − τ)² σ_ṙ²). Needs the
/// plot's radial velocity and the radar's σ_ṙ. The angles held hide the
/// motion across the line of sight: `sigma_tangential_speed` σ_t adds
/// (σ_t (t − τ))² (I − u u') to the covariance (u the unit line of sight;
/// for a 2D plot its horizontal direction). The patent omits this term
/// (σ_t = 0), which makes plots moved by seconds overconfident by hundreds
/// of metres across the beam.
///
/// The plot carries its range rate ([`RangeRate`]) for the update. Its
/// model assumes constant velocity between τ and t; an acceleration
/// changes ṙ by up to |a|Δt, so its σ grows to √(σ_ṙ² + q|Δt|) with q
/// (m²/s³) the largest spectral density of the tracker's motion models
/// (the velocity variance a CWNA model accrues over |Δt|).
pub fn extrapolate(
    radar: &RadarSpec,
    radar_index: usize,
    plot: &Plot,
    t: f64,
    sigma_tangential_speed: f64,
    manoeuvre_q: f64,
) -> Result<CartesianPlot, AlgoError> {
    let (Some(v), Some(sigma_v)) = (plot.radial_velocity, radar.sigma_radial_velocity) else {
        return Err(AlgoError::InvalidParameter {
            what: "radial_velocity",
            reason: "time registration needs the radial velocity and its sigma".into(),
        });
    };
    let dt = t - plot.t;
    let mut polar = polar_measurement(radar, plot);
    let range = plot.range + v * dt;
    let moved = range > 0.0;
    if moved {
        polar.range = range;
    }
    polar.sigma_range = polar.sigma_range.hypot(dt * sigma_v);
    let mut out = to_cartesian(radar, radar_index, t, &polar)?;
    out.measured = Some(*plot);
    let u = line_of_sight(plot)?;
    let n = out.z.len();
    // ρ′ = ρ + ṙΔt: Cov(ρ′, ṙ) = Δt σ_ṙ², and ∂z/∂ρ′ = u.
    let c = if moved { dt * sigma_v * sigma_v } else { 0.0 };
    out.range_rates.push(RangeRate {
        site: radar.site,
        value: v,
        sigma: (sigma_v * sigma_v + manoeuvre_q * dt.abs()).sqrt(),
        dt,
        horizontal: plot.elevation.is_none(),
        cross: DVector::from_fn(n, |i, _| c * u[i]),
    });
    // The unseen motion across the line of sight: (σ_t Δt)² (I − u u').
    let cross = (dt * sigma_tangential_speed).powi(2);
    if cross > 0.0 {
        for i in 0..n {
            for j in 0..n {
                let identity = if i == j { 1.0 } else { 0.0 };
                out.r[(i, j)] += cross * (identity - u[i] * u[j]);
            }
        }
    }
    Ok(out)
}

/// The radial velocity re-expressed about the fusion centre (step 1), or
/// `None` for a plot without Doppler. A plot at the centre's origin keeps
/// its own radial velocity.
pub fn doppler_in_fusion_frame(radar: &RadarSpec, plot: &Plot) -> Option<Doppler> {
    let v = plot.radial_velocity?;
    let sigma = radar.sigma_radial_velocity?;
    let u = line_of_sight(plot).ok()?;
    let components = [v * u[0], v * u[1], v * u[2]];
    let p: Vec<f64> = (0..3).map(|i| radar.site[i] + plot.range * u[i]).collect();
    let norm = p.iter().map(|x| x * x).sum::<f64>().sqrt();
    let radial_velocity = if norm > 0.0 {
        (0..3).map(|i| components[i] * p[i] / norm).sum()
    } else {
        v
    };
    Some(Doppler {
        radial_velocity,
        sigma,
        components,
    })
}

/// Unit line of sight from the radar (horizontal for a 2D plot).
fn line_of_sight(plot: &Plot) -> Result<[f64; 3], AlgoError> {
    Ok(match plot.elevation {
        Some(el) => polar_to_enu_3d(1.0, plot.azimuth, el)?,
        None => {
            let [e, n] = polar_to_enu_2d(1.0, plot.azimuth)?;
            [e, n, 0.0]
        }
    })
}

fn to_cartesian(
    radar: &RadarSpec,
    radar_index: usize,
    t: f64,
    polar: &PolarMeasurement,
) -> Result<CartesianPlot, AlgoError> {
    let (z, r) = plot_to_local(radar.site, polar)?.into_parts();
    Ok(CartesianPlot {
        t,
        z,
        r,
        radars: vec![radar_index],
        measured: None,
        range_rates: Vec::new(),
        velocity: Vec::new(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::{FRAC_PI_2, FRAC_PI_4};

    fn radar_2d(site: [f64; 3]) -> RadarSpec {
        RadarSpec {
            site,
            sigma_range: 10.0,
            sigma_azimuth: 1e-3,
            sigma_elevation: None,
            sigma_radial_velocity: Some(1.0),
            scan_period: 1.0,
            detection_probability: 1.0,
            clutter_density: 1e-6,
        }
    }

    fn plot(range: f64, azimuth: f64, v: Option<f64>) -> Plot {
        Plot {
            radar: 0,
            t: 0.0,
            range,
            azimuth,
            elevation: None,
            radial_velocity: v,
            identity: Default::default(),
            report: None,
        }
    }

    #[test]
    fn registration_adds_the_site_offset() {
        // Radar at [200, 0], ρ = 1000 m due east (θ = 90°): [200 + 1000, 0].
        // R = J diag(σ_ρ², σ_θ²) J' with J = [[sin θ, ρ cos θ], [cos θ, −ρ sin θ]]
        //   = [[1, 0], [0, −1000]] → diag(100, 1000²·1e-6 = 1).
        let r = radar_2d([200.0, 0.0, 0.0]);
        let c = register(&r, 3, &plot(1000.0, FRAC_PI_2, None)).unwrap();
        assert!((c.z[0] - 1200.0).abs() < 1e-9 && c.z[1].abs() < 1e-9);
        assert!((c.r[(0, 0)] - 100.0).abs() < 1e-9);
        assert!((c.r[(1, 1)] - 1.0).abs() < 1e-9);
        assert!(c.r[(0, 1)].abs() < 1e-9);
        assert_eq!(c.radars, vec![3]);
    }

    #[test]
    fn a_pure_range_error_lies_along_the_line_of_sight() {
        // θ = 45°: R = σ_ρ² u u' + ρ²σ_θ² w w' with u = [1, 1]/√2 and w ⟂ u;
        // σ_ρ² u u' = 100/2 [[1, 1], [1, 1]] = 50 everywhere, and the
        // cross-range term ρ²σ_θ² = 1000²·1e-18 = 1e-12 is negligible.
        let mut r = radar_2d([0.0; 3]);
        r.sigma_azimuth = 1e-9;
        let c = register(&r, 0, &plot(1000.0, FRAC_PI_4, None)).unwrap();
        for (i, j) in [(0, 0), (0, 1), (1, 0), (1, 1)] {
            assert!((c.r[(i, j)] - 50.0).abs() < 1e-6, "{:?}", c.r);
        }
    }

    #[test]
    fn extrapolation_moves_along_the_line_of_sight() {
        // Radar at [200, 0], ρ = 1000, θ = 90°, ṙ = 10 m/s, τ = 0 → t = 2:
        // ρ' = 1000 + 20 = 1020, position [1220, 0];
        // σ_ρ'² = 10² + 2²·1² = 104 along x (east); cross-range 1020²·1e-6.
        let r = radar_2d([200.0, 0.0, 0.0]);
        let c = extrapolate(&r, 0, &plot(1000.0, FRAC_PI_2, Some(10.0)), 2.0, 0.0, 0.0).unwrap();
        assert_eq!(c.t, 2.0);
        assert!((c.z[0] - 1220.0).abs() < 1e-9 && c.z[1].abs() < 1e-9);
        assert!((c.r[(0, 0)] - 104.0).abs() < 1e-9);
        assert!((c.r[(1, 1)] - 1020.0f64.powi(2) * 1e-6).abs() < 1e-9);
        // Backwards in time as well: ρ' = 1000 − 10 = 990 at t = −1.
        let c = extrapolate(&r, 0, &plot(1000.0, FRAC_PI_2, Some(10.0)), -1.0, 0.0, 0.0).unwrap();
        assert!((c.z[0] - 1190.0).abs() < 1e-9);
        assert!((c.r[(0, 0)] - 101.0).abs() < 1e-9);
        assert!(extrapolate(&r, 0, &plot(1000.0, 0.0, None), 1.0, 0.0, 0.0).is_err());
    }

    #[test]
    fn unseen_cross_range_motion_grows_the_covariance_across_the_beam_only() {
        // θ = 90° (due east): the line of sight is x, across it is y.
        // σ_t = 50 m/s over Δt = 2 s adds (50·2)² = 10⁴ m² to P_yy only:
        // P_yy = 1020²·1e-6 + 10⁴, P_xx = 104 as without it.
        let r = radar_2d([200.0, 0.0, 0.0]);
        let c = extrapolate(&r, 0, &plot(1000.0, FRAC_PI_2, Some(10.0)), 2.0, 50.0, 0.0).unwrap();
        assert!((c.r[(0, 0)] - 104.0).abs() < 1e-9);
        assert!((c.r[(1, 1)] - (1020.0f64.powi(2) * 1e-6 + 1e4)).abs() < 1e-6);
        assert!(c.r[(0, 1)].abs() < 1e-9);
    }

    #[test]
    fn doppler_is_projected_on_the_centre_line_of_sight() {
        // Radar at [200, 0], plot due north at 1000 m → position [200, 1000];
        // u = [0, 1], components ṙ u = [0, −5]; u_c = [200, 1000]/√(200² + 1000²),
        // projection −5·1000/1019.8039 = −4.902903...
        let r = radar_2d([200.0, 0.0, 0.0]);
        let d = doppler_in_fusion_frame(&r, &plot(1000.0, 0.0, Some(-5.0))).unwrap();
        assert!(d.components[0].abs() < 1e-12 && (d.components[1] + 5.0).abs() < 1e-12);
        let want = -5.0 * 1000.0 / (200.0f64 * 200.0 + 1000.0 * 1000.0).sqrt();
        assert!((d.radial_velocity - want).abs() < 1e-12);
        assert_eq!(d.sigma, 1.0);
        assert!(doppler_in_fusion_frame(&r, &plot(1000.0, 0.0, None)).is_none());
    }

    #[test]
    fn a_moved_plot_carries_its_range_rate_and_their_correlation() {
        // Radar at [200, 0], θ = 90°, ṙ = 10, σ_ṙ = 1, moved by Δt = 2 s:
        // ρ′ = ρ + 2ṙ so Cov(ρ′, ṙ) = 2·1² = 2, along u = [1, 0].
        let r = radar_2d([200.0, 0.0, 0.0]);
        let c = extrapolate(&r, 0, &plot(1000.0, FRAC_PI_2, Some(10.0)), 2.0, 0.0, 0.0).unwrap();
        assert_eq!(c.range_rates.len(), 1);
        let rr = &c.range_rates[0];
        assert_eq!(
            (rr.value, rr.sigma, rr.dt, rr.horizontal),
            (10.0, 1.0, 2.0, true)
        );
        assert!((rr.cross[0] - 2.0).abs() < 1e-12 && rr.cross[1].abs() < 1e-12);
        // With q = 4 m²/s³: σ = √(1 + 4·2) = 3; the correlation keeps the
        // radar's σ_ṙ (the manoeuvre term is not in ρ′).
        let c = extrapolate(&r, 0, &plot(1000.0, FRAC_PI_2, Some(10.0)), 2.0, 0.0, 4.0).unwrap();
        assert!((c.range_rates[0].sigma - 3.0).abs() < 1e-12);
        assert!((c.range_rates[0].cross[0] - 2.0).abs() < 1e-12);
        // A plotted position that is not a moved one carries none.
        assert!(
            register(&r, 0, &plot(1000.0, FRAC_PI_2, Some(10.0)))
                .unwrap()
                .range_rates
                .is_empty()
        );
    }

    #[test]
    fn the_range_rate_jacobian_matches_finite_differences() {
        // A 3D radar's range rate with Δt = 1.5 s, and a 2D radar's
        // (horizontal) with Δt = −0.7 s, about a 3D state.
        let x = DVector::from_vec(vec![12_000.0, 180.0, -4_000.0, 60.0, 9_000.0, -8.0]);
        for (dt, horizontal) in [(1.5, false), (-0.7, true)] {
            let plot = CartesianPlot {
                t: 0.0,
                z: DVector::from_vec(vec![12_010.0, -3_990.0, 9_005.0]),
                r: DMatrix::identity(3, 3) * 100.0,
                radars: vec![0],
                measured: None,
                range_rates: vec![RangeRate {
                    site: [500.0, 300.0, 20.0],
                    value: 150.0,
                    sigma: 1.0,
                    dt,
                    horizontal,
                    cross: DVector::from_vec(vec![0.5, -0.2, 0.1]),
                }],
                velocity: Vec::new(),
            };
            let lin = plot.linearise(&x);
            assert_eq!(lin.innovation.len(), 4);
            // ṙ(x) = ṙ_measured − ν₃(x).
            let h = |x: &DVector<f64>| 150.0 - plot.linearise(x).innovation[3];
            for j in 0..6 {
                let e = if j % 2 == 0 { 1e-2 } else { 1e-4 };
                let (mut a, mut b) = (x.clone(), x.clone());
                a[j] += e;
                b[j] -= e;
                let numeric = (h(&a) - h(&b)) / (2.0 * e);
                assert!(
                    (lin.h[(3, j)] - numeric).abs() < 1e-7,
                    "column {j}: {} against {numeric}",
                    lin.h[(3, j)]
                );
            }
            if horizontal {
                assert_eq!((lin.h[(3, 4)], lin.h[(3, 5)]), (0.0, 0.0));
            }
            assert_eq!(lin.r[(0, 3)], 0.5);
            assert_eq!(lin.r[(3, 1)], -0.2);
            assert_eq!(lin.r[(3, 3)], 1.0);
        }
    }

    #[test]
    fn the_stated_correlation_of_position_and_range_rate_is_the_sampled_one() {
        // Independent check by sampling: draw ρ, θ, ṙ with their σ, move the
        // plot by Δt = 3 s and compare the sample Cov(z, ṙ) with `cross`.
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut gauss = || {
            let (u1, u2): (f64, f64) = (rng.random::<f64>().max(1e-300), rng.random());
            (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
        };
        let mut r = radar_2d([0.0; 3]);
        r.sigma_radial_velocity = Some(2.0);
        let az = 0.6f64;
        let n = 100_000;
        let (mut sz, mut sv, mut szv) = ([0.0; 2], 0.0, [0.0; 2]);
        for _ in 0..n {
            let p = Plot {
                radar: 0,
                t: 0.0,
                range: 20_000.0 + 10.0 * gauss(),
                azimuth: az + 1e-3 * gauss(),
                elevation: None,
                radial_velocity: Some(-100.0 + 2.0 * gauss()),
                identity: Default::default(),
                report: None,
            };
            let c = extrapolate(&r, 0, &p, 3.0, 0.0, 0.0).unwrap();
            let v = p.radial_velocity.unwrap();
            for i in 0..2 {
                sz[i] += c.z[i];
                szv[i] += c.z[i] * v;
            }
            sv += v;
        }
        let nf = n as f64;
        let want = extrapolate(
            &r,
            0,
            &Plot {
                radar: 0,
                t: 0.0,
                range: 20_000.0,
                azimuth: az,
                elevation: None,
                radial_velocity: Some(-100.0),
                identity: Default::default(),
                report: None,
            },
            3.0,
            0.0,
            0.0,
        )
        .unwrap();
        for i in 0..2 {
            let cov = szv[i] / nf - (sz[i] / nf) * (sv / nf);
            // Δt σ_ṙ² u_i = 3·4·(sin 0.6, cos 0.6) = (6.78, 9.90); sampling
            // error of a covariance of σ ≈ 13 m and 2 m/s over 10⁵ draws ≈ 0.1.
            assert!(
                (cov - want.range_rates[0].cross[i]).abs() < 0.4,
                "{i}: {cov}"
            );
        }
    }
}
