//! REST routes for the L/R double-threshold rules of seed 000 section 4.

use axum::{extract::State, response::Response};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::{
    Timing,
    problem::{JsonBody, Problem},
};
use crate::state::AppState;
use service::rules as svc;

/// An L/R rule: correlated when at least `l` of `r` samples pass the first threshold.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct LrRule {
    /// Second threshold L, 1 ≤ l ≤ r.
    #[schema(example = 6, minimum = 1)]
    pub l: u32,
    /// Window R, 1 ≤ r ≤ 128.
    #[schema(example = 8, minimum = 1, maximum = 128)]
    pub r: u32,
}

#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct EvaluateRulesRequest {
    /// Significance level α of the first (χ²) threshold, Pr{τ > δ | H0} (eq. 14), in (0, 1).
    #[schema(example = 0.05, exclusive_minimum = 0.0, exclusive_maximum = 1.0)]
    pub alpha: f64,
    /// The rules to evaluate (1 to 1024).
    pub rules: Vec<LrRule>,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct RuleEvaluation {
    pub l: u32,
    pub r: u32,
    /// R − L + 1: exceedances among R same-target samples that make the rule miss.
    pub misses_from: u32,
    /// Probability that two tracks of one target are not correlated (eq. 23).
    #[schema(example = 0.0057882179296875)]
    pub miss_probability: f64,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct EvaluateRulesResponse {
    pub evaluations: Vec<RuleEvaluation>,
    pub timing: Timing,
    pub warnings: Vec<String>,
}

#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct RecommendRuleRequest {
    /// Significance level α of the first threshold, in (0, 1).
    #[schema(example = 0.05, exclusive_minimum = 0.0, exclusive_maximum = 1.0)]
    pub alpha: f64,
    /// Upper bound on the missed-correlation probability, in (0, 1).
    #[schema(example = 0.01, exclusive_minimum = 0.0, exclusive_maximum = 1.0)]
    pub max_miss_probability: f64,
    /// Smallest acceptable l / r, in (0, 1]; default 0.75 (the paper's 3/4 and 6/8).
    #[schema(example = 0.75, exclusive_minimum = 0.0, maximum = 1.0)]
    pub min_l_over_r: Option<f64>,
    /// Largest window considered, 1 to 128; default 32.
    #[schema(example = 32, minimum = 1, maximum = 128)]
    pub max_r: Option<u32>,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct RecommendRuleResponse {
    /// The shortest window meeting the bound, with the largest l for it;
    /// null when no rule up to `max_r` meets it (a warning says so).
    pub recommended: Option<RuleEvaluation>,
    /// For every r from 1 to max_r, the strictest admissible rule and its miss probability.
    pub considered: Vec<RuleEvaluation>,
    pub timing: Timing,
    pub warnings: Vec<String>,
}

/// Missed-correlation probability of L/R double-threshold rules (seed 000 eq. 23).
#[utoipa::path(
    post,
    path = "/v1/correlation/rules/evaluate",
    tag = "correlation",
    request_body = EvaluateRulesRequest,
    responses(
        (status = 200, description = "Every rule with its miss probability", body = EvaluateRulesResponse),
        (status = 400, description = "Malformed JSON", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "Invalid field values", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn evaluate(
    State(_state): State<AppState>,
    body: JsonBody<EvaluateRulesRequest>,
) -> Result<Response, Problem> {
    body.compute(evaluate_on_lane).await
}

fn evaluate_on_lane(req: EvaluateRulesRequest) -> Result<EvaluateRulesResponse, Problem> {
    let input = svc::EvaluateRulesInput {
        alpha: Some(req.alpha),
        rules: req
            .rules
            .into_iter()
            .map(|r| svc::RuleInput {
                l: Some(r.l),
                r: Some(r.r),
            })
            .collect(),
    };
    let out = svc::evaluate(input)?;
    Ok(EvaluateRulesResponse {
        evaluations: out.evaluations.into_iter().map(Into::into).collect(),
        timing: Timing {
            compute_us: out.compute_us,
        },
        warnings: out.warnings,
    })
}

/// The shortest L/R rule whose missed-correlation probability stays under a bound.
#[utoipa::path(
    post,
    path = "/v1/correlation/rules/recommend",
    tag = "correlation",
    request_body = RecommendRuleRequest,
    responses(
        (status = 200, description = "The recommended rule and the trade-off table", body = RecommendRuleResponse),
        (status = 400, description = "Malformed JSON", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "Invalid field values", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn recommend(
    State(_state): State<AppState>,
    body: JsonBody<RecommendRuleRequest>,
) -> Result<Response, Problem> {
    body.compute(recommend_on_lane).await
}

fn recommend_on_lane(req: RecommendRuleRequest) -> Result<RecommendRuleResponse, Problem> {
    let input = svc::RecommendRuleInput {
        alpha: Some(req.alpha),
        max_miss_probability: Some(req.max_miss_probability),
        min_l_over_r: req.min_l_over_r,
        max_r: req.max_r,
    };
    let out = svc::recommend(input)?;
    Ok(RecommendRuleResponse {
        recommended: out.recommended.map(Into::into),
        considered: out.considered.into_iter().map(Into::into).collect(),
        timing: Timing {
            compute_us: out.compute_us,
        },
        warnings: out.warnings,
    })
}

impl From<svc::RuleEvaluation> for RuleEvaluation {
    fn from(e: svc::RuleEvaluation) -> Self {
        Self {
            l: e.l,
            r: e.r,
            misses_from: e.misses_from,
            miss_probability: e.miss_probability,
        }
    }
}
