//! Ground truth: target trajectories in the local ENU frame.
//!
//! A target is a [`TargetPlan`]: a birth time, an initial state, a list of
//! manoeuvre [`Leg`]s (constant velocity, coordinated turn at a g-load, speed
//! change, vertical acceleration) followed by constant velocity, and optional random manoeuvres by
//! the process noise of seed 000 eq. 26. [`simulate`] samples it every `dt`
//! seconds into a [`Trajectory`]. [`InitialConditions`] draws random starts
//! as the papers do; [`crossing`], [`parallel`] and [`splitting`] build the
//! geometries that trouble correlators.
//!
//! States are `[x, vx, y, vy, z, vz]` (x east, y north, z up; m, m/s): the
//! interleaved layout of `algo`. Ships have z = vz = 0; aircraft fly at an
//! altitude. Headings are clockwise from north, in radians.

use std::f64::consts::PI;

use rand::RngExt;
use rand_distr::{Distribution, Normal};

use super::{STANDARD_GRAVITY, SimError, SimRng};

/// `[x, vx, y, vy, z, vz]` in metres and metres per second.
pub type State = [f64; 6];

/// What a target does during a leg.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Manoeuvre {
    /// Straight and level at constant velocity.
    ConstantVelocity,
    /// Coordinated (constant speed, constant rate) turn in the horizontal
    /// plane with lateral acceleration `g_load` × 9.80665 m/s². Positive turns
    /// left (counter-clockwise seen from above), negative turns right. The
    /// turn rate is ω = g_load · g / |v_h| (seed 003's 10 g turn is
    /// `g_load = ±10`).
    Turn {
        /// Lateral acceleration in units of standard gravity, signed.
        g_load: f64,
    },
    /// Speed change at constant heading: tangential acceleration (m/s²),
    /// negative to slow down. The horizontal speed never drops below 1 m/s.
    SpeedChange {
        /// Tangential acceleration (m/s²).
        acceleration: f64,
    },
    /// Change of vertical speed at constant horizontal velocity: vertical
    /// acceleration (m/s², positive up). A climb is one leg of it, constant
    /// velocity (climbing), and one leg of the opposite sign (levelling off).
    VerticalAcceleration {
        /// Vertical acceleration (m/s²).
        acceleration: f64,
    },
}

/// A manoeuvre held for `duration` seconds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Leg {
    /// Length of the leg (s), ≥ 0.
    pub duration: f64,
    /// What the target does.
    pub manoeuvre: Manoeuvre,
}

/// Everything that determines one target's motion.
#[derive(Debug, Clone, PartialEq)]
pub struct TargetPlan {
    /// Time of `initial` (s); the target does not exist before.
    pub birth: f64,
    /// State at `birth`.
    pub initial: State,
    /// Manoeuvres from `birth` on; constant velocity after the last one.
    pub legs: Vec<Leg>,
    /// Seed 000 eq. 26: each step of `dt` adds G·V with G = per axis
    /// `[dt/2, 1]'` (eq. 24) and V_i ~ N(0, (factor · v_i)²); the paper uses
    /// 0.05. Zero for a deterministic trajectory.
    pub noise_factor: f64,
}

impl TargetPlan {
    /// A constant-velocity target born at `birth` in `initial`.
    pub fn constant_velocity(birth: f64, initial: State) -> Self {
        Self {
            birth,
            initial,
            legs: Vec::new(),
            noise_factor: 0.0,
        }
    }
}

/// A trajectory sampled every `dt` seconds from `birth`.
#[derive(Debug, Clone, PartialEq)]
pub struct Trajectory {
    /// Time of `states[0]` (s).
    pub birth: f64,
    /// Sampling step (s).
    pub dt: f64,
    /// `states[k]` is the state at `birth + k·dt`.
    pub states: Vec<State>,
}

impl Trajectory {
    /// Time of the last sample.
    pub fn end(&self) -> f64 {
        self.birth + self.dt * (self.states.len().saturating_sub(1)) as f64
    }

    /// The state at time `t`: the sample at or before `t` extrapolated at
    /// constant velocity (exact on a sample time). `None` before birth or
    /// more than `dt` after the last sample.
    pub fn state_at(&self, t: f64) -> Option<State> {
        if self.states.is_empty() || t < self.birth - 1e-9 || t > self.end() + self.dt {
            return None;
        }
        let k = (((t - self.birth) / self.dt + 1e-9).floor().max(0.0) as usize)
            .min(self.states.len() - 1);
        let s = self.states[k];
        let tau = t - (self.birth + k as f64 * self.dt);
        Some(cv_step(&s, tau))
    }
}

/// Samples `plan` every `dt` seconds from its birth until `end` (inclusive
/// when `end − birth` is a multiple of `dt`). Random manoeuvres (eq. 26) draw
/// from `rng`; a plan with `noise_factor == 0` draws nothing.
pub fn simulate(
    plan: &TargetPlan,
    dt: f64,
    end: f64,
    rng: &mut SimRng,
) -> Result<Trajectory, SimError> {
    if !(dt.is_finite() && dt > 0.0) {
        return Err(SimError::InvalidConfig("dt must be positive".into()));
    }
    if !(plan.noise_factor.is_finite() && plan.noise_factor >= 0.0) {
        return Err(SimError::InvalidConfig(
            "noise_factor must be finite and >= 0".into(),
        ));
    }
    if plan.initial.iter().any(|v| !v.is_finite()) {
        return Err(SimError::InvalidConfig(
            "initial state must be finite".into(),
        ));
    }
    let steps = if end >= plan.birth {
        ((end - plan.birth) / dt + 1e-9).floor() as usize
    } else {
        0
    };
    let mut states = Vec::with_capacity(steps + 1);
    let mut s = plan.initial;
    states.push(s);
    for k in 0..steps {
        let t0 = k as f64 * dt;
        s = deterministic_step(&s, &plan.legs, t0, dt);
        if plan.noise_factor > 0.0 {
            s = add_seed000_noise(&s, plan.noise_factor, dt, rng);
        }
        states.push(s);
    }
    Ok(Trajectory {
        birth: plan.birth,
        dt,
        states,
    })
}

/// One step of the seed 000 eq. 24/26 noise on top of a state: for each axis
/// with velocity v, V ~ N(0, (factor·v)²), position += dt/2·V, velocity += V.
pub fn add_seed000_noise(s: &State, factor: f64, dt: f64, rng: &mut SimRng) -> State {
    let mut out = *s;
    for axis in 0..3 {
        let v = s[2 * axis + 1];
        let sd = (factor * v).abs();
        if sd > 0.0 {
            let noise: f64 = rng.sample(rand_distr::StandardNormal);
            let dv = sd * noise;
            out[2 * axis] += dt / 2.0 * dv;
            out[2 * axis + 1] += dv;
        }
    }
    out
}

/// How initial positions are drawn in the horizontal plane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PositionDistribution {
    /// Independent normal east and north with these means and standard deviations (m).
    Normal {
        /// Mean `[east, north]`.
        mean: [f64; 2],
        /// Standard deviations `[east, north]`, > 0.
        sigma: [f64; 2],
    },
    /// Uniform in the rectangle `[min, max]` (m).
    Uniform {
        /// South-west corner `[east, north]`.
        min: [f64; 2],
        /// North-east corner `[east, north]`.
        max: [f64; 2],
    },
}

/// Height of a target.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Altitude {
    /// A ship: z = 0.
    SeaLevel,
    /// An aircraft at this height (m).
    Fixed(f64),
    /// An aircraft at a height uniform in `[lo, hi]` (m).
    Uniform(f64, f64),
}

/// Random initial conditions as in the papers: position normal or uniform in
/// a region, speed and heading uniform in ranges, level flight.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InitialConditions {
    /// Horizontal position distribution.
    pub position: PositionDistribution,
    /// Speed range `[lo, hi]` (m/s), uniform.
    pub speed: (f64, f64),
    /// Heading range `[lo, hi]` (rad, clockwise from north), uniform.
    pub heading: (f64, f64),
    /// Height.
    pub altitude: Altitude,
}

impl InitialConditions {
    /// Seed 000 §5.1: normal positions about `mean` with `sigma` per axis,
    /// speeds uniform in 4–1200 m/s, headings uniform in [0, 2π), sea level
    /// (the paper's scene is a plane).
    pub fn seed000(mean: [f64; 2], sigma: f64) -> Self {
        Self {
            position: PositionDistribution::Normal {
                mean,
                sigma: [sigma, sigma],
            },
            speed: (4.0, 1200.0),
            heading: (0.0, 2.0 * PI),
            altitude: Altitude::SeaLevel,
        }
    }

    /// Draws one initial state.
    pub fn sample(&self, rng: &mut SimRng) -> Result<State, SimError> {
        let (e, n) = match self.position {
            PositionDistribution::Normal { mean, sigma } => {
                let ne = normal(mean[0], sigma[0])?;
                let nn = normal(mean[1], sigma[1])?;
                (ne.sample(rng), nn.sample(rng))
            }
            PositionDistribution::Uniform { min, max } => {
                (uniform(rng, min[0], max[0])?, uniform(rng, min[1], max[1])?)
            }
        };
        let speed = uniform(rng, self.speed.0, self.speed.1)?;
        let heading = uniform(rng, self.heading.0, self.heading.1)?;
        let z = match self.altitude {
            Altitude::SeaLevel => 0.0,
            Altitude::Fixed(h) => h,
            Altitude::Uniform(lo, hi) => uniform(rng, lo, hi)?,
        };
        let (vx, vy) = velocity(speed, heading);
        Ok([e, vx, n, vy, z, 0.0])
    }
}

/// Horizontal velocity `(v_east, v_north)` of a speed and a heading
/// clockwise from north.
pub fn velocity(speed: f64, heading: f64) -> (f64, f64) {
    (speed * heading.sin(), speed * heading.cos())
}

/// `n` constant-velocity targets at `speed` whose straight paths all pass
/// through `point` at time `t_cross`, with headings spread evenly over half
/// a turn (k·π/n from north), born at `t0`.
pub fn crossing(n: usize, point: [f64; 3], t0: f64, t_cross: f64, speed: f64) -> Vec<TargetPlan> {
    (0..n)
        .map(|k| {
            let (vx, vy) = velocity(speed, k as f64 * PI / n as f64);
            let back = t_cross - t0;
            let s = [
                point[0] - vx * back,
                vx,
                point[1] - vy * back,
                vy,
                point[2],
                0.0,
            ];
            TargetPlan::constant_velocity(t0, s)
        })
        .collect()
}

/// `n` constant-velocity targets abreast: the same heading and speed,
/// starting at `start` and offset `spacing` metres apart to the right of
/// the heading, born at `t0`.
pub fn parallel(
    n: usize,
    start: [f64; 3],
    t0: f64,
    heading: f64,
    speed: f64,
    spacing: f64,
) -> Vec<TargetPlan> {
    let (vx, vy) = velocity(speed, heading);
    // Unit vector to the right of the heading: heading + 90°.
    let (rx, ry) = velocity(1.0, heading + PI / 2.0);
    (0..n)
        .map(|k| {
            let off = k as f64 * spacing;
            let s = [
                start[0] + rx * off,
                vx,
                start[1] + ry * off,
                vy,
                start[2],
                0.0,
            ];
            TargetPlan::constant_velocity(t0, s)
        })
        .collect()
}

/// One target becomes two: `parent` flies at constant velocity from `t0`;
/// at `t_split` a second target is born at the parent's position whose
/// velocity is the parent's turned by `angle` (rad, positive to the right).
/// Returns `[parent, child]`.
pub fn splitting(parent: State, t0: f64, t_split: f64, angle: f64) -> [TargetPlan; 2] {
    let at_split = cv_step(&parent, t_split - t0);
    let (s, c) = angle.sin_cos();
    // Clockwise rotation of (v_east, v_north) by `angle`.
    let vx = at_split[1] * c + at_split[3] * s;
    let vy = -at_split[1] * s + at_split[3] * c;
    let child = [at_split[0], vx, at_split[2], vy, at_split[4], at_split[5]];
    [
        TargetPlan::constant_velocity(t0, parent),
        TargetPlan::constant_velocity(t_split, child),
    ]
}

/// Constant-velocity extrapolation by `tau` seconds.
pub fn cv_step(s: &State, tau: f64) -> State {
    [
        s[0] + s[1] * tau,
        s[1],
        s[2] + s[3] * tau,
        s[3],
        s[4] + s[5] * tau,
        s[5],
    ]
}

/// Exact deterministic motion over [t0, t0 + dt] (times since birth),
/// splitting the step at leg boundaries.
fn deterministic_step(s: &State, legs: &[Leg], t0: f64, dt: f64) -> State {
    let mut s = *s;
    let mut t = t0;
    let t_end = t0 + dt;
    let mut leg_start = 0.0;
    for leg in legs {
        let leg_end = leg_start + leg.duration;
        if leg_end > t && leg_start < t_end {
            let a = t.max(leg_start);
            let b = t_end.min(leg_end);
            if a > t {
                s = cv_step(&s, a - t);
            }
            s = manoeuvre_step(&s, leg.manoeuvre, b - a);
            t = b;
        }
        leg_start = leg_end;
    }
    if t_end > t {
        s = cv_step(&s, t_end - t);
    }
    s
}

fn manoeuvre_step(s: &State, m: Manoeuvre, tau: f64) -> State {
    match m {
        Manoeuvre::ConstantVelocity => cv_step(s, tau),
        Manoeuvre::Turn { g_load } => {
            let speed = s[1].hypot(s[3]);
            if speed < 1e-9 || g_load == 0.0 {
                return cv_step(s, tau);
            }
            let w = g_load * STANDARD_GRAVITY / speed;
            let (sn, cs) = (w * tau).sin_cos();
            let (vx, vy) = (s[1], s[3]);
            [
                s[0] + sn / w * vx - (1.0 - cs) / w * vy,
                cs * vx - sn * vy,
                s[2] + (1.0 - cs) / w * vx + sn / w * vy,
                sn * vx + cs * vy,
                s[4] + s[5] * tau,
                s[5],
            ]
        }
        Manoeuvre::VerticalAcceleration { acceleration } => [
            s[0] + s[1] * tau,
            s[1],
            s[2] + s[3] * tau,
            s[3],
            s[4] + s[5] * tau + 0.5 * acceleration * tau * tau,
            s[5] + acceleration * tau,
        ],
        Manoeuvre::SpeedChange { acceleration } => {
            let speed = s[1].hypot(s[3]);
            if speed < 1e-9 {
                return cv_step(s, tau);
            }
            let (ux, uy) = (s[1] / speed, s[3] / speed);
            // Constant acceleration until the 1 m/s floor, then constant speed.
            let floor = 1.0;
            let t_acc = if acceleration < 0.0 {
                ((speed - floor).max(0.0) / -acceleration).min(tau)
            } else {
                tau
            };
            let dist = speed * t_acc + 0.5 * acceleration * t_acc * t_acc;
            let v1 = speed + acceleration * t_acc;
            let dist = dist + v1 * (tau - t_acc);
            [
                s[0] + ux * dist,
                ux * v1,
                s[2] + uy * dist,
                uy * v1,
                s[4] + s[5] * tau,
                s[5],
            ]
        }
    }
}

fn normal(mean: f64, sd: f64) -> Result<Normal<f64>, SimError> {
    Normal::new(mean, sd).map_err(|e| SimError::InvalidConfig(format!("normal({mean}, {sd}): {e}")))
}

fn uniform(rng: &mut SimRng, lo: f64, hi: f64) -> Result<f64, SimError> {
    if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
        return Err(SimError::InvalidConfig(format!(
            "uniform range [{lo}, {hi}] is empty or not finite"
        )));
    }
    Ok(if lo == hi {
        lo
    } else {
        rng.random_range(lo..hi)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::montecarlo::run_rng;

    fn mean_var(xs: &[f64]) -> (f64, f64) {
        let n = xs.len() as f64;
        let m = xs.iter().sum::<f64>() / n;
        let v = xs.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0);
        (m, v)
    }

    #[test]
    fn initial_conditions_match_their_distributions() {
        // n = 20000 draws. Bounds are 5 standard errors of each estimator:
        // mean of N(μ, σ²): σ/√n; sample variance of a normal: σ²·√(2/(n−1));
        // U(a, b): mean (a+b)/2 with sd (b−a)/√(12 n), variance (b−a)²/12 with
        // sd √((μ4 − σ⁴)/n), μ4 = (b−a)⁴/80, σ⁴ = (b−a)⁴/144.
        let n = 20_000;
        let ic = InitialConditions::seed000([1000.0, -2000.0], 15_000.0);
        let mut rng = run_rng(11, 0);
        let draws: Vec<State> = (0..n).map(|_| ic.sample(&mut rng).unwrap()).collect();
        let nf = n as f64;
        let east: Vec<f64> = draws.iter().map(|s| s[0]).collect();
        let (m, v) = mean_var(&east);
        assert!((m - 1000.0).abs() < 5.0 * 15_000.0 / nf.sqrt(), "mean {m}");
        let s2 = 15_000.0f64.powi(2);
        assert!(
            (v - s2).abs() < 5.0 * s2 * (2.0 / (nf - 1.0)).sqrt(),
            "var {v}"
        );
        let north: Vec<f64> = draws.iter().map(|s| s[2]).collect();
        let (m, _) = mean_var(&north);
        assert!((m + 2000.0).abs() < 5.0 * 15_000.0 / nf.sqrt(), "mean {m}");

        let speed: Vec<f64> = draws.iter().map(|s| s[1].hypot(s[3])).collect();
        let (a, b) = (4.0, 1200.0);
        let (m, v) = mean_var(&speed);
        assert!((m - (a + b) / 2.0).abs() < 5.0 * (b - a) / (12.0 * nf).sqrt());
        let w4 = (b - a).powi(4);
        let sd_var = ((w4 / 80.0 - w4 / 144.0) / nf).sqrt();
        assert!((v - (b - a).powi(2) / 12.0).abs() < 5.0 * sd_var, "var {v}");
        assert!(speed.iter().all(|&s| (a..b).contains(&(s + 1e-9))));

        // Heading U(0, 2π): mean π, sd of the mean 2π/√(12 n).
        let heading: Vec<f64> = draws
            .iter()
            .map(|s| s[1].atan2(s[3]).rem_euclid(2.0 * PI))
            .collect();
        let (m, _) = mean_var(&heading);
        assert!((m - PI).abs() < 5.0 * 2.0 * PI / (12.0 * nf).sqrt());
        assert!(draws.iter().all(|s| s[4] == 0.0 && s[5] == 0.0));
    }

    #[test]
    fn seed000_noise_has_the_eq26_variance_and_eq24_gain() {
        // From [0, 400, 0, −300] over T = 4 s with factor 0.05, eq. 26 gives
        // velocity perturbations with sd 0.05·400 = 20 and 0.05·300 = 15 m/s,
        // and eq. 24 moves the position by T/2 = 2 s times the perturbation.
        let s = [0.0, 400.0, 0.0, -300.0, 0.0, 0.0];
        let mut rng = run_rng(3, 0);
        let n = 20_000;
        let mut dvx = Vec::with_capacity(n);
        let mut dvy = Vec::with_capacity(n);
        for _ in 0..n {
            let o = add_seed000_noise(&s, 0.05, 4.0, &mut rng);
            assert!((o[0] - 2.0 * (o[1] - 400.0)).abs() < 1e-9);
            assert!((o[2] - 2.0 * (o[3] + 300.0)).abs() < 1e-9);
            assert_eq!(o[5], 0.0);
            dvx.push(o[1] - 400.0);
            dvy.push(o[3] + 300.0);
        }
        let nf = n as f64;
        for (d, sd) in [(&dvx, 20.0), (&dvy, 15.0)] {
            let (m, v) = mean_var(d);
            assert!(m.abs() < 5.0 * sd / nf.sqrt(), "mean {m}");
            let s2: f64 = sd * sd;
            assert!(
                (v - s2).abs() < 5.0 * s2 * (2.0 / (nf - 1.0)).sqrt(),
                "var {v}"
            );
        }
    }

    #[test]
    fn half_of_a_ten_g_turn_reverses_the_velocity_two_radii_aside() {
        // 300 m/s east, 10 g left: a = 98.0665 m/s², R = v²/a = 917.724…,
        // ω = a/v; after π/ω s the target heads west, displaced 2R north.
        let v = 300.0;
        let a = 10.0 * STANDARD_GRAVITY;
        let r = v * v / a;
        let half = PI / (a / v);
        let plan = TargetPlan {
            birth: 0.0,
            initial: [0.0, v, 0.0, 0.0, 5000.0, 0.0],
            legs: vec![Leg {
                duration: half,
                manoeuvre: Manoeuvre::Turn { g_load: 10.0 },
            }],
            noise_factor: 0.0,
        };
        let mut rng = run_rng(0, 0);
        // One sample exactly at the end of the turn, one 10 s later.
        let tr = simulate(&plan, half, 2.0 * half, &mut rng).unwrap();
        let s = tr.states[1];
        assert!(s[0].abs() < 1e-6 && (s[2] - 2.0 * r).abs() < 1e-6, "{s:?}");
        assert!((s[1] + v).abs() < 1e-9 && s[3].abs() < 1e-9);
        assert_eq!(s[4], 5000.0);
        // After the turn, straight flight west.
        let later = tr.state_at(half + 10.0).unwrap();
        assert!((later[0] + 3000.0).abs() < 1e-6);
    }

    #[test]
    fn turn_split_across_steps_equals_one_step() {
        let plan = TargetPlan {
            birth: 0.0,
            initial: [0.0, 200.0, 0.0, 100.0, 0.0, 0.0],
            legs: vec![
                Leg {
                    duration: 3.0,
                    manoeuvre: Manoeuvre::ConstantVelocity,
                },
                Leg {
                    duration: 10.0,
                    manoeuvre: Manoeuvre::Turn { g_load: -3.0 },
                },
            ],
            noise_factor: 0.0,
        };
        let mut rng = run_rng(0, 0);
        let coarse = simulate(&plan, 20.0, 20.0, &mut rng).unwrap();
        let fine = simulate(&plan, 0.5, 20.0, &mut rng).unwrap();
        let a = coarse.states[1];
        let b = *fine.states.last().unwrap();
        for i in 0..6 {
            assert!((a[i] - b[i]).abs() < 1e-6, "{a:?} vs {b:?}");
        }
        // A coordinated turn keeps the speed.
        assert!((a[1].hypot(a[3]) - 200.0f64.hypot(100.0)).abs() < 1e-9);
    }

    #[test]
    fn a_climb_ramps_holds_and_levels_off() {
        // 1 m/s² up for 10 s: vz 10 m/s, z = ½·1·10² = 50 m; 20 s climbing at
        // 10 m/s: z = 250 m; −1 m/s² for 10 s: vz 0, z = 250 + 100 − 50 = 300 m.
        // The horizontal motion is untouched: x = 150 m/s × 40 s = 6000 m.
        let up = Manoeuvre::VerticalAcceleration { acceleration: 1.0 };
        let down = Manoeuvre::VerticalAcceleration { acceleration: -1.0 };
        let plan = TargetPlan {
            birth: 0.0,
            initial: [0.0, 150.0, 0.0, 0.0, 3000.0, 0.0],
            legs: vec![
                Leg {
                    duration: 10.0,
                    manoeuvre: up,
                },
                Leg {
                    duration: 20.0,
                    manoeuvre: Manoeuvre::ConstantVelocity,
                },
                Leg {
                    duration: 10.0,
                    manoeuvre: down,
                },
            ],
            noise_factor: 0.0,
        };
        let mut rng = run_rng(0, 0);
        let tr = simulate(&plan, 0.25, 40.0, &mut rng).unwrap();
        let at = |t: f64| tr.state_at(t).unwrap();
        assert!((at(10.0)[5] - 10.0).abs() < 1e-9 && (at(10.0)[4] - 3050.0).abs() < 1e-6);
        assert!((at(30.0)[4] - 3250.0).abs() < 1e-6);
        let end = at(40.0);
        assert!(
            end[5].abs() < 1e-9 && (end[4] - 3300.0).abs() < 1e-6,
            "{end:?}"
        );
        assert!((end[0] - 6000.0).abs() < 1e-6 && end[1] == 150.0 && end[2] == 0.0);
    }

    #[test]
    fn speed_change_follows_constant_acceleration_to_the_floor() {
        // 100 m/s north, −10 m/s² for 20 s: speed reaches 1 m/s after 9.9 s
        // having covered 100·9.9 − 5·9.9² = 499.95 m, then 10.1 s at 1 m/s.
        let plan = TargetPlan {
            birth: 0.0,
            initial: [0.0, 0.0, 0.0, 100.0, 0.0, 0.0],
            legs: vec![Leg {
                duration: 20.0,
                manoeuvre: Manoeuvre::SpeedChange {
                    acceleration: -10.0,
                },
            }],
            noise_factor: 0.0,
        };
        let tr = simulate(&plan, 20.0, 20.0, &mut run_rng(0, 0)).unwrap();
        let s = tr.states[1];
        assert!((s[2] - (499.95 + 10.1)).abs() < 1e-9, "{s:?}");
        assert!((s[3] - 1.0).abs() < 1e-12);
    }

    #[test]
    fn geometries_cross_run_abreast_and_split() {
        let plans = crossing(4, [1000.0, 2000.0, 0.0], 0.0, 50.0, 250.0);
        for p in &plans {
            let s = cv_step(&p.initial, 50.0);
            assert!((s[0] - 1000.0).abs() < 1e-6 && (s[2] - 2000.0).abs() < 1e-6);
        }
        // Heading east (π/2): abreast means offset to the south (right).
        let par = parallel(3, [0.0, 0.0, 0.0], 0.0, PI / 2.0, 100.0, 500.0);
        assert!((par[2].initial[2] + 1000.0).abs() < 1e-9);
        assert!(par[2].initial[0].abs() < 1e-9);
        let [p, c] = splitting([0.0, 0.0, 0.0, 100.0, 0.0, 0.0], 0.0, 10.0, PI / 2.0);
        assert_eq!(c.birth, 10.0);
        assert!((c.initial[2] - 1000.0).abs() < 1e-9);
        // Turned 90° right from north: east.
        assert!((c.initial[1] - 100.0).abs() < 1e-9 && c.initial[3].abs() < 1e-9);
        assert_eq!(p.initial[3], 100.0);
        let tr = simulate(&c, 1.0, 20.0, &mut run_rng(0, 0)).unwrap();
        assert!(tr.state_at(9.0).is_none());
        assert!(tr.state_at(10.0).is_some());
    }

    #[test]
    fn same_seed_same_trajectory() {
        let plan = TargetPlan {
            noise_factor: 0.05,
            ..TargetPlan::constant_velocity(0.0, [0.0, 300.0, 0.0, -50.0, 0.0, 0.0])
        };
        let a = simulate(&plan, 4.0, 200.0, &mut run_rng(5, 2)).unwrap();
        let b = simulate(&plan, 4.0, 200.0, &mut run_rng(5, 2)).unwrap();
        let c = simulate(&plan, 4.0, 200.0, &mut run_rng(5, 3)).unwrap();
        assert_eq!(a, b);
        assert_ne!(a, c);
    }
}
