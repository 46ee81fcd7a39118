//! L/R double-threshold rules of seed 000 section 4: the missed-correlation
//! probability of a rule (eq. 23) and the recommendation of a rule for a bound.

use std::time::Instant;

use super::{ServiceError, Violations, micros_since};
use crate::algo::correlation::rules::{self, LrRule};

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

/// Evaluates eq. 23 for every rule of the request.
pub fn evaluate(input: EvaluateRulesInput) -> Result<EvaluateRulesOutput, ServiceError> {
    let mut v = Violations::new();
    let alpha = v.required("alpha", input.alpha);
    if let Some(a) = alpha {
        v.param("", rules::check_alpha(a));
    }
    if input.rules.is_empty() {
        v.add("rules", "must name at least one rule");
    } else if input.rules.len() > MAX_RULES {
        v.add("rules", format!("at most {MAX_RULES} rules per request"));
    }
    let mut parsed = Vec::with_capacity(input.rules.len().min(MAX_RULES));
    for (i, rule) in input.rules.iter().enumerate().take(MAX_RULES) {
        let l = v.required(&format!("rules[{i}].l"), rule.l);
        let r = v.required(&format!("rules[{i}].r"), rule.r);
        if let (Some(l), Some(r)) = (l, r)
            && let Some(rule) = v.param(&format!("rules[{i}]."), LrRule::new(l, r))
        {
            parsed.push(rule);
        }
    }
    v.finish()?;
    let alpha = alpha.expect("validated above");

    let start = Instant::now();
    let evaluations = parsed
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
    let mut v = Violations::new();
    let alpha = v.required("alpha", input.alpha);
    let max_miss = v.required("max_miss_probability", input.max_miss_probability);
    let min_ratio = input.min_l_over_r.unwrap_or(DEFAULT_MIN_L_OVER_R);
    let max_r = input.max_r.unwrap_or(DEFAULT_MAX_R);
    v.finish()?;
    let (alpha, max_miss) = (alpha.expect("required"), max_miss.expect("required"));

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
