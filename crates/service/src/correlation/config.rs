//! Parsing a request's configuration (method, rule or schedule, motion
//! model, alignment, pruning, measurement matrix) into a `Plan`, one small
//! parser per nested input.

use nalgebra::DMatrix;

use crate::{Interval, ServiceError, Violations};
use algo::{
    correlation::{
        engine::{self, Config, Method, Pruning, Resolution, RuleSpec, Statistic},
        rules::LrRule,
    },
    motion::{ConstantVelocity, ProcessNoise},
};

use super::{
    AlignMode, AlignmentInput, CorrelateInput, DEFAULT_ALPHA, DEFAULT_MAX_GAP_S,
    DEFAULT_TOLERANCE_S, Layout, METHODS, MethodInput, MotionModelInput, Plan,
};

/// The parsed configuration of a request, before its nodes.
pub(super) struct ConfigParts {
    pub(super) layout: Option<Layout>,
    pub(super) kind: &'static str,
    pub(super) config_method: Option<Method>,
    pub(super) statistic: Statistic,
    pub(super) alpha: f64,
    pub(super) pruning: Pruning,
    pub(super) model: Option<ConstantVelocity>,
    pub(super) align_model: Option<ConstantVelocity>,
    pub(super) mode: AlignMode,
    pub(super) tolerance: f64,
    pub(super) h: Option<DMatrix<f64>>,
}

/// The wire names of the alignment modes.
#[derive(Debug, Clone, Copy, PartialEq)]
enum ModeName {
    Grid,
    Predict,
    Interpolate,
    Nearest,
}

pub(super) fn validate_config(input: &CorrelateInput, v: &mut Violations) -> ConfigParts {
    let layout = match Layout::parse(&input.state_layout) {
        Ok(l) => Some(l),
        Err(e) => {
            v.add("state_layout", e);
            None
        }
    };
    let method = input.method.clone().unwrap_or_default();
    let ParsedMethod {
        kind,
        alpha,
        statistic,
        method: config_method,
    } = parse_method(v, &method);
    let model = match (&input.motion_model, &layout) {
        (None, _) | (_, None) => None,
        (Some(m), Some(layout)) => motion_model(v, m, layout),
    };
    if statistic == Statistic::Modified && input.motion_model.is_none() {
        v.add(
            "motion_model",
            "is required by the modified statistic (the cross-covariance recursion of eq. 13)",
        );
    }
    let (mode, tolerance) = parse_alignment(v, input);
    // Without a motion model, samples with velocities are extrapolated
    // along them (F without Q); positions alone are held.
    let align_model = match (&model, &layout) {
        (Some(m), _) => Some(*m),
        (None, Some(l)) if l.has_velocity => {
            ConstantVelocity::new(l.axes, ProcessNoise::Cwna { q: 0.0 }).ok()
        }
        _ => None,
    };
    let prunings = [("grid", Pruning::Grid), ("none", Pruning::None)];
    let pruning = v
        .one_of(
            "pruning",
            input.pruning.as_deref(),
            Some(Pruning::Grid),
            &prunings,
        )
        .unwrap_or(Pruning::Grid);
    let h = measurement_matrix(v, input.measurement_matrix.as_ref(), layout.as_ref());
    ConfigParts {
        layout,
        kind,
        config_method,
        statistic,
        alpha,
        pruning,
        model,
        align_model,
        mode,
        tolerance,
        h,
    }
}

/// `method`, parsed: its kind (`""` when invalid), α, the statistic and
/// the engine's method.
struct ParsedMethod {
    kind: &'static str,
    alpha: f64,
    statistic: Statistic,
    method: Option<Method>,
}

/// `method`: the kind with what it takes (a rule or schedule, a window, k).
fn parse_method(v: &mut Violations, method: &MethodInput) -> ParsedMethod {
    let choices: Vec<(&str, &'static str)> = METHODS.iter().map(|&m| (m, m)).collect();
    let kind = v
        .one_of("method.kind", method.kind.as_deref(), None, &choices)
        .unwrap_or("");
    let alpha = v
        .number_or(
            "method.alpha",
            method.alpha,
            DEFAULT_ALPHA,
            Interval::OPEN_UNIT,
        )
        .unwrap_or(DEFAULT_ALPHA);
    let statistic = parse_statistic(v, kind, method.statistic.as_deref());
    let rules = parse_rules(v, method);
    let default_window = match kind {
        "k_nearest_neighbour" => 5,
        _ => 1,
    };
    let window = v
        .count_or("method.window", method.window, default_window, 1, 64)
        .unwrap_or(default_window) as usize;
    let k = method.k.unwrap_or(3) as usize;
    let one = LrRule::new(1, 1).ok();
    let config_method = match kind {
        "weighted" | "modified" => one.map(|one| Method::DoubleThreshold {
            rules: RuleSpec::Fixed(one),
            resolution: Resolution::Greedy,
        }),
        "independent_double_threshold" | "dependent_double_threshold" => {
            rules.map(|rules| Method::DoubleThreshold {
                rules,
                resolution: Resolution::Greedy,
            })
        }
        "double_threshold_assignment" => rules.map(|rules| Method::DoubleThreshold {
            rules,
            resolution: Resolution::Assignment,
        }),
        "nearest_neighbour" => Some(Method::NearestNeighbour { window }),
        "global_assignment" => Some(Method::GlobalAssignment { window }),
        "k_nearest_neighbour" => Some(Method::KNearestNeighbour { k, window }),
        _ => None,
    };
    if matches!(kind, "weighted" | "modified")
        && (method.rule.is_some() || method.schedule.is_some())
    {
        v.add(
            "method.rule",
            format!("'{kind}' is the classic 1/1 test; use independent_double_threshold or dependent_double_threshold for an L/R rule"),
        );
    }
    if method.k.is_some() {
        v.count_or("method.k", method.k, 3, 1, window as u32);
    }
    ParsedMethod {
        kind,
        alpha,
        statistic,
        method: config_method,
    }
}

/// `method.statistic`: fixed by the kinds named for a statistic, else
/// chosen (weighted by default).
fn parse_statistic(v: &mut Violations, kind: &str, given: Option<&str>) -> Statistic {
    let statistics = [
        ("weighted", Statistic::Weighted),
        ("modified", Statistic::Modified),
    ];
    match (kind, given) {
        ("modified" | "dependent_double_threshold", None | Some("modified")) => Statistic::Modified,
        ("weighted" | "independent_double_threshold", None | Some("weighted")) => {
            Statistic::Weighted
        }
        (
            "modified" | "dependent_double_threshold" | "weighted" | "independent_double_threshold",
            Some(_),
        ) => {
            v.add(
                "method.statistic",
                format!("'{kind}' fixes the statistic; leave it out"),
            );
            Statistic::Weighted
        }
        (_, given) => v
            .one_of(
                "method.statistic",
                given,
                Some(Statistic::Weighted),
                &statistics,
            )
            .unwrap_or(Statistic::Weighted),
    }
}

/// `method.rule`, `method.schedule` or `method.dynamic_schedule` (one of
/// them; the 6/8 rule by default).
fn parse_rules(v: &mut Violations, method: &MethodInput) -> Option<RuleSpec> {
    if method.rule.is_some() && (method.schedule.is_some() || method.dynamic_schedule == Some(true))
    {
        v.add(
            "method.schedule",
            "give either rule or a schedule, not both",
        );
        None
    } else if let Some(r) = &method.rule {
        crate::rules::parse_rule(v, "method.rule", r.l, r.r).map(RuleSpec::Fixed)
    } else if let Some(s) = &method.schedule {
        let parsed: Vec<Option<LrRule>> = s
            .iter()
            .enumerate()
            .map(|(i, r)| crate::rules::parse_rule(v, &format!("method.schedule[{i}]"), r.l, r.r))
            .collect();
        if s.is_empty() {
            v.add("method.schedule", "must hold at least one rule");
        }
        parsed
            .into_iter()
            .collect::<Option<Vec<_>>>()
            .map(RuleSpec::Schedule)
    } else if method.dynamic_schedule == Some(true) {
        Some(RuleSpec::Schedule(engine::default_schedule()))
    } else {
        LrRule::new(6, 8).ok().map(RuleSpec::Fixed)
    }
}

/// `alignment`: the mode with its parameters, and the tolerance.
fn parse_alignment(v: &mut Violations, input: &CorrelateInput) -> (AlignMode, f64) {
    let alignment = input.alignment.clone().unwrap_or_default();
    let tolerance = v
        .number_or(
            "alignment.tolerance_s",
            alignment.tolerance_s,
            DEFAULT_TOLERANCE_S,
            Interval::NON_NEGATIVE,
        )
        .unwrap_or(DEFAULT_TOLERANCE_S);
    let grid_only = [
        ("alignment.period_s", alignment.period_s.is_some()),
        ("alignment.epoch_s", alignment.epoch_s.is_some()),
        (
            "alignment.max_staleness_s",
            alignment.max_staleness_s.is_some(),
        ),
    ];
    let modes = [
        ("grid", ModeName::Grid),
        ("predict", ModeName::Predict),
        ("interpolate", ModeName::Interpolate),
        ("nearest", ModeName::Nearest),
    ];
    let mode_name = v.one_of(
        "alignment.mode",
        alignment.mode.as_deref(),
        Some(ModeName::Grid),
        &modes,
    );
    let mode = match mode_name {
        Some(ModeName::Grid) => grid_mode(v, &alignment),
        Some(ModeName::Predict) => {
            if input.motion_model.is_none() {
                v.add("alignment.mode", "predict needs a motion_model");
            }
            AlignMode::Predict
        }
        Some(ModeName::Interpolate) => AlignMode::Interpolate {
            max_gap: v
                .number_or(
                    "alignment.max_gap_s",
                    alignment.max_gap_s,
                    DEFAULT_MAX_GAP_S,
                    Interval::POSITIVE,
                )
                .unwrap_or(DEFAULT_MAX_GAP_S),
        },
        Some(ModeName::Nearest) | None => AlignMode::Nearest,
    };
    if !matches!(mode, AlignMode::Grid { .. }) {
        for (field, given) in grid_only {
            if given {
                v.add(
                    field,
                    "applies to the grid alignment only (alignment.mode: grid)",
                );
            }
        }
    }
    (mode, tolerance)
}

/// The grid alignment's period, epoch and staleness bound.
fn grid_mode(v: &mut Violations, alignment: &AlignmentInput) -> AlignMode {
    let period = alignment
        .period_s
        .and_then(|p| v.within("alignment.period_s", p, Interval::POSITIVE));
    let epoch = v.number_or(
        "alignment.epoch_s",
        alignment.epoch_s,
        0.0,
        Interval::closed(-1e12, 1e12),
    );
    let max_staleness = alignment
        .max_staleness_s
        .and_then(|s| v.within("alignment.max_staleness_s", s, Interval::NON_NEGATIVE));
    AlignMode::Grid {
        period,
        epoch: epoch.unwrap_or(0.0),
        max_staleness,
    }
}

/// `measurement_matrix`: H, for the reported gains, in canonical order.
fn measurement_matrix(
    v: &mut Violations,
    rows: Option<&Vec<Vec<f64>>>,
    layout: Option<&Layout>,
) -> Option<DMatrix<f64>> {
    let (rows, layout) = rows.zip(layout)?;
    if rows.is_empty() {
        v.add("measurement_matrix", "must hold at least one row");
        return None;
    }
    v.matrix("measurement_matrix", rows, rows.len(), layout.dim)
        .map(|_| {
            let flat: Vec<f64> = rows
                .iter()
                .flat_map(|r| layout.vector_to_canonical(r))
                .collect();
            DMatrix::from_row_slice(rows.len(), layout.dim, &flat)
        })
}

pub(super) fn plan_of(parts: ConfigParts, fuse: Option<bool>) -> Option<Plan> {
    let ConfigParts {
        layout,
        kind,
        config_method,
        statistic,
        alpha,
        pruning,
        model,
        align_model,
        mode,
        tolerance,
        h,
    } = parts;
    Some(Plan {
        layout: layout?,
        method_name: kind.to_string(),
        config: Config {
            method: config_method?,
            statistic,
            alpha,
            pruning,
        },
        model,
        align_model,
        alignment: mode,
        tolerance,
        h,
        fuse: fuse.unwrap_or(true),
    })
}

/// Parses the configuration of a request without its nodes (a streaming
/// session's configuration).
pub(crate) fn validate_plan(input: &CorrelateInput) -> Result<Plan, ServiceError> {
    let mut v = Violations::new();
    let parts = validate_config(input, &mut v);
    v.finish_with(plan_of(parts, input.fuse))
}

fn motion_model(
    v: &mut Violations,
    m: &MotionModelInput,
    layout: &Layout,
) -> Option<ConstantVelocity> {
    v.one_of(
        "motion_model.kind",
        m.kind.as_deref(),
        Some(()),
        &[("constant_velocity", ())],
    )?;
    if !layout.has_velocity {
        v.add(
            "motion_model",
            "a constant-velocity model needs velocities in state_layout",
        );
        return None;
    }
    #[derive(Clone, Copy)]
    enum Noise {
        Dwna,
        Cwna,
        VelocityProportional,
    }
    let noise = match v.one_of(
        "motion_model.process_noise",
        m.process_noise.as_deref(),
        Some(Noise::Dwna),
        &[
            ("dwna", Noise::Dwna),
            ("cwna", Noise::Cwna),
            ("velocity_proportional", Noise::VelocityProportional),
        ],
    )? {
        Noise::Dwna => ProcessNoise::Dwna {
            sigma_a: v.required("motion_model.sigma_a_mps2", m.sigma_a_mps2)?,
        },
        Noise::Cwna => ProcessNoise::Cwna {
            q: v.required("motion_model.q_m2ps3", m.q_m2ps3)?,
        },
        Noise::VelocityProportional => ProcessNoise::VelocityProportional {
            factor: m.factor.unwrap_or(0.05),
        },
    };
    v.param("motion_model.", ConstantVelocity::new(layout.axes, noise))
}
