//! Simulated radars: 2D (range, azimuth) or 3D (plus elevation), optional
//! Doppler radial velocity, coverage limits, detection probability, Gaussian
//! errors, systematic range/azimuth biases and uniform Poisson clutter.
//!
//! Conventions are the service's: the site is in the local ENU frame (a
//! WGS84 site is converted with [`algo::geo::LocalFrame`]); azimuth is
//! clockwise from north in [0, 2π), elevation above the horizontal; range is
//! the slant range from the site. The noise-free measurement is
//! [`algo::polar::polar_measurement_model`], the same function the
//! service's EKF update linearises.

use std::f64::consts::{PI, TAU};

use rand::RngExt;
use rand::seq::SliceRandom;
use rand_distr::{Distribution, Poisson, StandardNormal};

use super::truth::State;
use super::{SimError, SimRng};
use algo::PolarMeasurement;
use algo::geo::LocalFrame;
use algo::polar::{polar_measurement_model, wrap_angle};

/// 2D or 3D radar.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RadarKind {
    /// Range and azimuth.
    TwoD,
    /// Range, azimuth and elevation.
    ThreeD,
}

/// Where a plot came from (the simulation's truth label; never sent to the
/// algorithm under test).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Origin {
    /// Target index in the scenario.
    Target(usize),
    /// A false alarm.
    Clutter,
}

/// One radar plot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plot {
    /// Time of the plot (s).
    pub t: f64,
    /// Slant range (m), biased and noisy.
    pub range: f64,
    /// Azimuth clockwise from north (rad, [0, 2π)).
    pub azimuth: f64,
    /// Elevation (rad) for a 3D radar.
    pub elevation: Option<f64>,
    /// Radial velocity (m/s, positive receding) when the radar has Doppler.
    pub radial_velocity: Option<f64>,
    /// Truth label.
    pub origin: Origin,
}

/// A radar and everything that shapes its plots.
#[derive(Debug, Clone, PartialEq)]
pub struct Radar {
    /// Site in the local ENU frame (m).
    pub site: [f64; 3],
    /// 2D or 3D.
    pub kind: RadarKind,
    /// Measures radial velocity.
    pub doppler: bool,
    /// Scan period (s).
    pub period: f64,
    /// Time of the first scan (s); scans are at `phase + k·period`.
    pub phase: f64,
    /// Probability of detecting a target in coverage, in [0, 1].
    pub pd: f64,
    /// Instrumented range (m); targets beyond it are not seen.
    pub max_range: f64,
    /// Blind range (m): targets closer are not seen (a real radar's minimum
    /// range; it also keeps the polar covariance of eqs. 27–28 definite).
    pub min_range: f64,
    /// Azimuth sector `(centre, half_width)` (rad); `None` for all round.
    pub azimuth_fov: Option<(f64, f64)>,
    /// Highest elevation of the 3D coverage (rad), used for clutter.
    pub max_elevation: f64,
    /// Range error standard deviation (m).
    pub sigma_range: f64,
    /// Azimuth error standard deviation (rad).
    pub sigma_azimuth: f64,
    /// Elevation error standard deviation (rad), 3D only.
    pub sigma_elevation: f64,
    /// Radial-velocity error standard deviation (m/s).
    pub sigma_doppler: f64,
    /// Systematic range error added to every plot (m).
    pub bias_range: f64,
    /// Systematic azimuth error added to every plot (rad).
    pub bias_azimuth: f64,
    /// Expected false plots per km² of horizontal coverage per scan.
    pub clutter_per_km2: f64,
}

impl Radar {
    /// A 2D radar at `site` with the given errors and period: Pd = 1, no
    /// bias, no clutter, all-round coverage to 1000 km, first scan at 0.
    pub fn two_d(site: [f64; 3], sigma_range: f64, sigma_azimuth: f64, period: f64) -> Self {
        Self {
            site,
            kind: RadarKind::TwoD,
            doppler: false,
            period,
            phase: 0.0,
            pd: 1.0,
            max_range: 1.0e6,
            min_range: 1000.0,
            azimuth_fov: None,
            max_elevation: PI / 4.0,
            sigma_range,
            sigma_azimuth,
            sigma_elevation: 0.0,
            sigma_doppler: 0.0,
            bias_range: 0.0,
            bias_azimuth: 0.0,
            clutter_per_km2: 0.0,
        }
    }

    /// The same radar made 3D with elevation error `sigma_elevation` (rad).
    pub fn with_elevation(mut self, sigma_elevation: f64) -> Self {
        self.kind = RadarKind::ThreeD;
        self.sigma_elevation = sigma_elevation;
        self
    }

    /// The ENU position of a site given in WGS84 degrees and metres.
    pub fn site_from_geodetic(
        frame: &LocalFrame,
        lat_deg: f64,
        lon_deg: f64,
        height: f64,
    ) -> Result<[f64; 3], SimError> {
        Ok(frame.geodetic_to_enu(lat_deg.to_radians(), lon_deg.to_radians(), height)?)
    }

    /// Checks the parameters.
    pub fn validate(&self) -> Result<(), SimError> {
        let bad = |what: &str| Err(SimError::InvalidConfig(format!("radar {what}")));
        let nonneg = |v: f64| v.is_finite() && v >= 0.0;
        if self.site.iter().any(|v| !v.is_finite()) {
            return bad("site must be finite");
        }
        if !(self.period.is_finite() && self.period > 0.0 && self.phase.is_finite()) {
            return bad("period must be positive and phase finite");
        }
        if !(0.0..=1.0).contains(&self.pd) {
            return bad("pd must lie in [0, 1]");
        }
        if !(self.max_range.is_finite() && self.max_range > 0.0) {
            return bad("max_range must be positive and finite");
        }
        if !(self.min_range >= 0.0 && self.min_range < self.max_range) {
            return bad("min_range must be in [0, max_range)");
        }
        if ![
            self.sigma_range,
            self.sigma_azimuth,
            self.sigma_elevation,
            self.sigma_doppler,
            self.clutter_per_km2,
        ]
        .into_iter()
        .all(nonneg)
        {
            return bad("standard deviations and clutter density must be >= 0");
        }
        if !(self.bias_range.is_finite() && self.bias_azimuth.is_finite()) {
            return bad("biases must be finite");
        }
        if let Some((c, w)) = self.azimuth_fov
            && !(c.is_finite() && w > 0.0 && w <= PI)
        {
            return bad("azimuth_fov half width must lie in (0, pi]");
        }
        Ok(())
    }

    /// Scan times in `[t0, t1]`.
    pub fn scan_times(&self, t0: f64, t1: f64) -> Vec<f64> {
        let k0 = ((t0 - self.phase) / self.period - 1e-9).ceil() as i64;
        let mut out = Vec::new();
        let mut k = k0;
        loop {
            let t = self.phase + k as f64 * self.period;
            if t > t1 + 1e-9 {
                break;
            }
            out.push(t);
            k += 1;
        }
        out
    }

    /// Whether a target at ENU position `p` is inside the coverage.
    pub fn covers(&self, p: [f64; 3]) -> bool {
        let rel = [
            p[0] - self.site[0],
            p[1] - self.site[1],
            p[2] - self.site[2],
        ];
        let r = (rel[0] * rel[0] + rel[1] * rel[1] + rel[2] * rel[2]).sqrt();
        if r > self.max_range || r < self.min_range {
            return false;
        }
        match self.azimuth_fov {
            None => true,
            Some((c, w)) => wrap_angle(rel[0].atan2(rel[1]) - c).abs() <= w,
        }
    }

    /// Horizontal area of the coverage (km²): a sector of radius `max_range`.
    pub fn coverage_area_km2(&self) -> f64 {
        let half = self.azimuth_fov.map_or(PI, |(_, w)| w);
        half * (self.max_range / 1000.0).powi(2)
    }

    /// One scan at time `t` over targets `(index, state)`: each target in
    /// coverage is detected with probability `pd` and measured with biases
    /// and Gaussian errors; Poisson(`clutter_per_km2` × area) false plots are
    /// spread uniformly over the coverage. The plots come out shuffled.
    pub fn scan(
        &self,
        t: f64,
        targets: &[(usize, State)],
        rng: &mut SimRng,
    ) -> Result<Vec<Plot>, SimError> {
        let mut plots = Vec::new();
        for &(id, s) in targets {
            let pos = [s[0], s[2], s[4]];
            if !self.covers(pos) || !rng.random_bool(self.pd) {
                continue;
            }
            if let Some(p) = self.measure(t, &s, Origin::Target(id), rng)? {
                plots.push(p);
            }
        }
        if self.clutter_per_km2 > 0.0 {
            let lambda = self.clutter_per_km2 * self.coverage_area_km2();
            let n = Poisson::new(lambda)
                .map_err(|e| SimError::InvalidConfig(format!("clutter rate {lambda}: {e}")))?
                .sample(rng) as usize;
            for _ in 0..n {
                plots.push(self.clutter_plot(t, rng));
            }
        }
        plots.shuffle(rng);
        Ok(plots)
    }

    /// The measurement of state `s` (with biases and noise), or `None` for a
    /// target at the site where azimuth is undefined.
    pub fn measure(
        &self,
        t: f64,
        s: &State,
        origin: Origin,
        rng: &mut SimRng,
    ) -> Result<Option<Plot>, SimError> {
        let rel = [
            s[0] - self.site[0],
            s[2] - self.site[1],
            s[4] - self.site[2],
        ];
        let three_d = self.kind == RadarKind::ThreeD;
        let (h, _) = match polar_measurement_model(rel, three_d) {
            Ok(v) => v,
            Err(algo::AlgoError::DegenerateGeometry { .. }) => return Ok(None),
            Err(e) => return Err(e.into()),
        };
        let mut gauss = |sd: f64| -> f64 {
            let z: f64 = rng.sample(StandardNormal);
            sd * z
        };
        let range = (h[0] + self.bias_range + gauss(self.sigma_range)).max(0.0);
        let azimuth = (h[1] + self.bias_azimuth + gauss(self.sigma_azimuth)).rem_euclid(TAU);
        let elevation = three_d.then(|| h[2] + gauss(self.sigma_elevation));
        let radial_velocity = self.doppler.then(|| {
            let r = h[0];
            (rel[0] * s[1] + rel[1] * s[3] + rel[2] * s[5]) / r + gauss(self.sigma_doppler)
        });
        Ok(Some(Plot {
            t,
            range,
            azimuth,
            elevation,
            radial_velocity,
            origin,
        }))
    }

    /// The plot as the service's polar measurement with this radar's
    /// standard deviations.
    pub fn polar_measurement(&self, plot: &Plot) -> PolarMeasurement {
        PolarMeasurement {
            range: plot.range,
            azimuth: plot.azimuth,
            elevation: plot.elevation,
            sigma_range: self.sigma_range,
            sigma_azimuth: self.sigma_azimuth,
            sigma_elevation: plot.elevation.map(|_| self.sigma_elevation),
        }
    }

    fn clutter_plot(&self, t: f64, rng: &mut SimRng) -> Plot {
        // Uniform in area: r = R √u; azimuth uniform in the sector.
        let range = self.max_range * rng.random::<f64>().sqrt();
        let azimuth = match self.azimuth_fov {
            None => rng.random_range(0.0..TAU),
            Some((c, w)) => (c + rng.random_range(-w..w)).rem_euclid(TAU),
        };
        let elevation =
            (self.kind == RadarKind::ThreeD).then(|| rng.random_range(0.0..self.max_elevation));
        let radial_velocity = self.doppler.then(|| rng.random_range(-300.0..300.0));
        Plot {
            t,
            range,
            azimuth,
            elevation,
            radial_velocity,
            origin: Origin::Clutter,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::montecarlo::run_rng;
    use algo::geo::Ellipsoid;

    #[test]
    fn coverage_excludes_the_blind_range_and_beyond_the_instrumented_range() {
        let mut r = Radar::two_d([0.0; 3], 170.0, 1f64.to_radians(), 4.0);
        r.max_range = 100_000.0;
        assert!(!r.covers([500.0, 0.0, 0.0]), "inside the 1 km blind range");
        assert!(r.covers([0.0, 1500.0, 0.0]));
        assert!(!r.covers([0.0, 100_001.0, 0.0]));
        r.min_range = 200_000.0;
        assert!(r.validate().is_err(), "min_range must stay below max_range");
    }

    fn mean_var(xs: &[f64]) -> (f64, f64) {
        let n = xs.len() as f64;
        let m = xs.iter().sum::<f64>() / n;
        (
            m,
            xs.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0),
        )
    }

    #[test]
    fn errors_have_the_configured_bias_and_spread() {
        // Target 30 km north-east of a site at the origin, at 3 km height:
        // true r = √(30000² + 3000²)… computed here as the reference.
        let mut radar =
            Radar::two_d([0.0, 0.0, 0.0], 150.0, 1f64.to_radians(), 4.0).with_elevation(0.01);
        radar.bias_range = 400.0;
        radar.bias_azimuth = 0.5f64.to_radians();
        radar.doppler = true;
        radar.sigma_doppler = 2.0;
        let (e, n, u): (f64, f64, f64) = (30_000.0 * 0.6, 30_000.0 * 0.8, 3000.0);
        let s = [e, 100.0, n, 0.0, u, 0.0];
        let r_true = (e * e + n * n + u * u).sqrt();
        let az_true = e.atan2(n);
        let el_true = u.atan2(e.hypot(n));
        // Radial velocity: (rel · v)/r = 100·e / r.
        let vr_true = 100.0 * e / r_true;
        let mut rng = run_rng(21, 0);
        let n_draws = 20_000;
        let mut dr = Vec::new();
        let mut da = Vec::new();
        let mut de = Vec::new();
        let mut dv = Vec::new();
        for _ in 0..n_draws {
            let p = radar
                .measure(0.0, &s, Origin::Target(0), &mut rng)
                .unwrap()
                .unwrap();
            dr.push(p.range - r_true);
            da.push(wrap_angle(p.azimuth - az_true));
            de.push(p.elevation.unwrap() - el_true);
            dv.push(p.radial_velocity.unwrap() - vr_true);
        }
        // 5 standard errors: σ/√n for the mean, σ²√(2/(n−1)) for the variance.
        let nf = n_draws as f64;
        for (d, bias, sd) in [
            (&dr, 400.0, 150.0),
            (&da, 0.5f64.to_radians(), 1f64.to_radians()),
            (&de, 0.0, 0.01),
            (&dv, 0.0, 2.0),
        ] {
            let (m, v) = mean_var(d);
            assert!(
                (m - bias).abs() < 5.0 * sd / nf.sqrt(),
                "mean {m} vs {bias}"
            );
            let s2 = sd * sd;
            assert!(
                (v - s2).abs() < 5.0 * s2 * (2.0 / (nf - 1.0)).sqrt(),
                "var {v}"
            );
        }
    }

    #[test]
    fn detection_probability_coverage_and_clutter_rate() {
        let mut radar = Radar::two_d([0.0, 0.0, 0.0], 100.0, 0.01, 2.0);
        radar.pd = 0.8;
        radar.max_range = 50_000.0;
        radar.azimuth_fov = Some((0.0, PI / 2.0)); // the northern half plane
        radar.clutter_per_km2 = 0.001;
        // Area = (π/2)·50² km² = 3926.99 km²; λ = 3.92699 false plots per scan.
        let lambda = 0.001 * (PI / 2.0) * 2500.0;
        assert!((radar.coverage_area_km2() - lambda / 0.001).abs() < 1e-9);
        let targets = [
            (0, [0.0, 0.0, 10_000.0, 0.0, 0.0, 0.0]),  // north: covered
            (1, [0.0, 0.0, -10_000.0, 0.0, 0.0, 0.0]), // south: outside the sector
            (2, [60_000.0, 0.0, 1.0, 0.0, 0.0, 0.0]),  // beyond max range
        ];
        let mut rng = run_rng(4, 0);
        let scans = 5000;
        let (mut hits, mut clutter) = (0usize, 0usize);
        for k in 0..scans {
            for p in radar.scan(k as f64 * 2.0, &targets, &mut rng).unwrap() {
                match p.origin {
                    Origin::Target(0) => hits += 1,
                    Origin::Target(i) => panic!("target {i} is outside the coverage"),
                    Origin::Clutter => {
                        clutter += 1;
                        assert!(p.range <= 50_000.0);
                        assert!(wrap_angle(p.azimuth).abs() <= PI / 2.0 + 1e-12);
                    }
                }
            }
        }
        let n = scans as f64;
        // Binomial: sd of the rate √(p(1−p)/n); Poisson mean: sd √(λ/n).
        assert!((hits as f64 / n - 0.8).abs() < 5.0 * (0.8 * 0.2 / n).sqrt());
        assert!((clutter as f64 / n - lambda).abs() < 5.0 * (lambda / n).sqrt());
    }

    #[test]
    fn scan_times_follow_period_and_phase() {
        let mut radar = Radar::two_d([0.0; 3], 1.0, 0.01, 4.0);
        radar.phase = 1.5;
        assert_eq!(radar.scan_times(0.0, 14.0), vec![1.5, 5.5, 9.5, 13.5]);
        assert_eq!(radar.scan_times(5.5, 9.5), vec![5.5, 9.5]);
    }

    #[test]
    fn geodetic_site_is_placed_in_the_local_frame() {
        // 0.01° of latitude north of the origin at 45°N: the meridian arc is
        // M·Δφ with M = a(1−e²)/(1−e² sin²φ)^{3/2} = 6 367 381.8 m, so
        // 1111.318 m north, and the ellipsoid curves away by
        // about d²/(2·6.37e6) ≈ 0.1 m.
        let frame = LocalFrame::new(Ellipsoid::WGS84, 45f64.to_radians(), 0.0, 0.0).unwrap();
        let site = Radar::site_from_geodetic(&frame, 45.01, 0.0, 0.0).unwrap();
        assert!(site[0].abs() < 1e-6, "{site:?}");
        assert!((site[1] - 1111.318).abs() < 0.01, "{site:?}");
        assert!((site[2] + 0.097).abs() < 0.01, "{site:?}");
    }
}
