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
pub fn extrapolate(
    radar: &RadarSpec,
    radar_index: usize,
    plot: &Plot,
    t: f64,
    sigma_tangential_speed: f64,
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
    if range > 0.0 {
        polar.range = range;
    }
    polar.sigma_range = polar.sigma_range.hypot(dt * sigma_v);
    let mut out = to_cartesian(radar, radar_index, t, &polar)?;
    out.measured = Some(*plot);
    // The unseen motion across the line of sight: (σ_t Δt)² (I − u u').
    let cross = (dt * sigma_tangential_speed).powi(2);
    if cross > 0.0 {
        let u = line_of_sight(plot)?;
        let n = out.z.len();
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
        let c = extrapolate(&r, 0, &plot(1000.0, FRAC_PI_2, Some(10.0)), 2.0, 0.0).unwrap();
        assert_eq!(c.t, 2.0);
        assert!((c.z[0] - 1220.0).abs() < 1e-9 && c.z[1].abs() < 1e-9);
        assert!((c.r[(0, 0)] - 104.0).abs() < 1e-9);
        assert!((c.r[(1, 1)] - 1020.0f64.powi(2) * 1e-6).abs() < 1e-9);
        // Backwards in time as well: ρ' = 1000 − 10 = 990 at t = −1.
        let c = extrapolate(&r, 0, &plot(1000.0, FRAC_PI_2, Some(10.0)), -1.0, 0.0).unwrap();
        assert!((c.z[0] - 1190.0).abs() < 1e-9);
        assert!((c.r[(0, 0)] - 101.0).abs() < 1e-9);
        assert!(extrapolate(&r, 0, &plot(1000.0, 0.0, None), 1.0, 0.0).is_err());
    }

    #[test]
    fn unseen_cross_range_motion_grows_the_covariance_across_the_beam_only() {
        // θ = 90° (due east): the line of sight is x, across it is y.
        // σ_t = 50 m/s over Δt = 2 s adds (50·2)² = 10⁴ m² to P_yy only:
        // P_yy = 1020²·1e-6 + 10⁴, P_xx = 104 as without it.
        let r = radar_2d([200.0, 0.0, 0.0]);
        let c = extrapolate(&r, 0, &plot(1000.0, FRAC_PI_2, Some(10.0)), 2.0, 50.0).unwrap();
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
}
