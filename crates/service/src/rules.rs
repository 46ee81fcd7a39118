//! L/R double-threshold rules of seed 000 section 4: the missed-correlation
//! probability of a rule (eq. 23) and the recommendation of a rule for a bound.

use std::time::Instant;

use super::{Interval, ServiceError, Violations, micros_since};
use algo::correlation::rules::{self, LrRule};

/// Most rules one evaluation request may name.
pub const MAX_RULES: usize = 1024;
/// Default smallest L/R of a recommended rule: the ratio of the paper's 3/4 and 6/8.
pub const DEFAULT_MIN_L_OVER_R: f64 = 0.75;
/// Default largest window R considered by a recommendation.
pub const DEFAULT_MAX_R: u32 = 32;

/// A rule as a client sent it.
#[derive(Debug, Clone, Default)]
pub struct RuleInput {
    pub l: Option<u32>,
    pub r: Option<u32>,
}

/// An evaluation request as a client sent it, before validation.
#[derive(Debug, Clone, Default)]
pub struct EvaluateRulesInput {
    pub alpha: Option<f64>,
    pub rules: Vec<RuleInput>,
}

/// A recommendation request as a client sent it, before validation.
#[derive(Debug, Clone, Default)]
pub struct RecommendRuleInput {
    pub alpha: Option<f64>,
    pub max_miss_probability: Option<f64>,
    pub min_l_over_r: Option<f64>,
    pub max_r: Option<u32>,
}

/// One rule with its missed-correlation probability.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RuleEvaluation {
    pub l: u32,
    pub r: u32,
    /// R − L + 1, the number of exceedances that makes the rule miss.
    pub misses_from: u32,
    pub miss_probability: f64,
}

#[derive(Debug, Clone, PartialEq)]
pub struct EvaluateRulesOutput {
    pub evaluations: Vec<RuleEvaluation>,
    pub compute_us: f64,
    pub warnings: Vec<String>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct RecommendRuleOutput {
    pub recommended: Option<RuleEvaluation>,
    pub considered: Vec<RuleEvaluation>,
    pub compute_us: f64,
    pub warnings: Vec<String>,
}

/// An evaluation request, parsed.
struct Evaluate {
    alpha: f64,
    rules: Vec<LrRule>,
}

/// A recommendation request, parsed.
struct Recommend {
    alpha: f64,
    max_miss: f64,
    min_ratio: f64,
    max_r: u32,
}

/// A rule's L and R, both required, with L ≤ R ≤ the longest window.
pub(super) fn parse_rule(
    v: &mut Violations,
    prefix: &str,
    l: Option<u32>,
    r: Option<u32>,
) -> Option<LrRule> {
    let l = v.required(format!("{prefix}.l"), l);
    let r = v.required(format!("{prefix}.r"), r);
    v.param(&format!("{prefix}."), LrRule::new(l?, r?))
}

fn parse_evaluate(input: &EvaluateRulesInput) -> Result<Evaluate, ServiceError> {
    let mut v = Violations::new();
    let alpha = v.number("alpha", input.alpha, Interval::OPEN_UNIT);
    v.count_within("rules", input.rules.len(), MAX_RULES, "rule");
    let rules: Option<Vec<LrRule>> = input
        .rules
        .iter()
        .take(MAX_RULES)
        .enumerate()
        .map(|(i, r)| parse_rule(&mut v, &format!("rules[{i}]"), r.l, r.r))
        .collect::<Vec<_>>()
        .into_iter()
        .collect();
    v.finish_with(
        alpha
            .zip(rules)
            .map(|(alpha, rules)| Evaluate { alpha, rules }),
    )
}

fn parse_recommend(input: &RecommendRuleInput) -> Result<Recommend, ServiceError> {
    let mut v = Violations::new();
    let alpha = v.number("alpha", input.alpha, Interval::OPEN_UNIT);
    let max_miss = v.number(
        "max_miss_probability",
        input.max_miss_probability,
        Interval::OPEN_UNIT,
    );
    let min_ratio = v.number_or(
        "min_l_over_r",
        input.min_l_over_r,
        DEFAULT_MIN_L_OVER_R,
        Interval::open_closed(0.0, 1.0),
    );
    let max_r = v.count_or("max_r", input.max_r, DEFAULT_MAX_R, 1, rules::MAX_WINDOW);
    let parsed = (|| {
        Some(Recommend {
            alpha: alpha?,
            max_miss: max_miss?,
            min_ratio: min_ratio?,
            max_r: max_r?,
        })
    })();
    v.finish_with(parsed)
}

/// Evaluates eq. 23 for every rule of the request.
pub fn evaluate(input: EvaluateRulesInput) -> Result<EvaluateRulesOutput, ServiceError> {
    let Evaluate { alpha, rules } = parse_evaluate(&input)?;
    let start = Instant::now();
    let evaluations = rules
        .into_iter()
        .map(|rule| {
            let p = rules::miss_probability(rule, alpha).map_err(internal)?;
            Ok(to_evaluation(rule, p))
        })
        .collect::<Result<Vec<_>, ServiceError>>()?;
    Ok(EvaluateRulesOutput {
        evaluations,
        compute_us: micros_since(start),
        warnings: Vec::new(),
    })
}

/// Recommends the shortest-window rule meeting the requested miss bound.
pub fn recommend(input: RecommendRuleInput) -> Result<RecommendRuleOutput, ServiceError> {
    let Recommend {
        alpha,
        max_miss,
        min_ratio,
        max_r,
    } = parse_recommend(&input)?;
    let start = Instant::now();
    let rec = rules::recommend(alpha, max_miss, min_ratio, max_r)
        .map_err(|e| Violations::from_param("", e))?;
    let considered: Vec<_> = rec
        .considered
        .iter()
        .map(|&(rule, p)| to_evaluation(rule, p))
        .collect();
    let recommended = rec.recommended.map(|(rule, p)| to_evaluation(rule, p));
    let mut warnings = Vec::new();
    if recommended.is_none() {
        warnings.push(format!(
            "no rule with r <= {max_r} and l/r >= {min_ratio} keeps the miss probability \
             at or below {max_miss}; raise max_r or lower min_l_over_r"
        ));
    }
    Ok(RecommendRuleOutput {
        recommended,
        considered,
        compute_us: micros_since(start),
        warnings,
    })
}

fn to_evaluation(rule: LrRule, p: f64) -> RuleEvaluation {
    RuleEvaluation {
        l: rule.l(),
        r: rule.r(),
        misses_from: rule.misses_from(),
        miss_probability: p,
    }
}

fn internal(e: impl std::fmt::Display) -> ServiceError {
    ServiceError::Internal(e.to_string())
}
