//! The L/R rule capability over REST and gRPC, checked against values
//! computed independently (seed 000 eq. 23 by hand; see the unit tests of
//! `algo::correlation::rules` for the arithmetic).

use radar_fusion::proto as pb;
use serde_json::json;

use crate::helpers::spawn_app;

/// α = 0.05: 3/4 → 0.01401875 and 6/8 → 0.0057882179296875 (hand sums of the
/// binomial tail; the paper prints 0.002256 and 0.000102, which its eq. 23
/// does not give). Tolerance: a few ulps, since the f64 nearest 0.05 is not 0.05.
const P_3_OF_4: f64 = 0.01401875;
const P_6_OF_8: f64 = 0.0057882179296875;

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 4e-18
}

#[tokio::test]
async fn evaluate_over_rest() {
    let app = spawn_app().await;
    let response = app
        .post_json(
            "/v1/correlation/rules/evaluate",
            &json!({"alpha": 0.05, "rules": [{"l": 3, "r": 4}, {"l": 6, "r": 8}, {"l": 1, "r": 1}]}),
        )
        .await;
    assert_eq!(response.status(), 200);
    let body: serde_json::Value = response.json().await.unwrap();
    let e = body["evaluations"].as_array().unwrap();
    assert_eq!(e.len(), 3);
    assert_eq!((e[0]["l"].as_u64(), e[0]["r"].as_u64()), (Some(3), Some(4)));
    assert_eq!(e[0]["misses_from"], 2);
    assert!(close(e[0]["miss_probability"].as_f64().unwrap(), P_3_OF_4));
    assert!(close(e[1]["miss_probability"].as_f64().unwrap(), P_6_OF_8));
    // 1/1 is the classic single test: it misses with probability α.
    assert_eq!(e[2]["miss_probability"].as_f64().unwrap(), 0.05);
    assert!(body["timing"]["compute_us"].as_f64().unwrap() >= 0.0);
    assert_eq!(body["warnings"], json!([]));
}

#[tokio::test]
async fn recommend_over_rest() {
    let app = spawn_app().await;
    // α = 0.05, bound 0.01, L/R ≥ 0.75 (default): 1/1 → 0.05, 2/2 → 1 − 0.95² =
    // 0.0975, 3/3 → 0.142625, 3/4 → 0.01401875, 4/5 → 1 − 0.95⁵ − 5·0.05·0.95⁴
    // = 0.0225925…, 5/6 → 0.0327738…, 6/7 → 0.0443…, 6/8 → 0.0057882 ≤ 0.01.
    let response = app
        .post_json(
            "/v1/correlation/rules/recommend",
            &json!({"alpha": 0.05, "max_miss_probability": 0.01}),
        )
        .await;
    assert_eq!(response.status(), 200);
    let body: serde_json::Value = response.json().await.unwrap();
    assert_eq!(body["recommended"]["l"], 6);
    assert_eq!(body["recommended"]["r"], 8);
    assert!(close(
        body["recommended"]["miss_probability"].as_f64().unwrap(),
        P_6_OF_8
    ));
    assert_eq!(body["considered"].as_array().unwrap().len(), 32);
    assert!((body["considered"][1]["miss_probability"].as_f64().unwrap() - 0.0975).abs() < 1e-16);
}

#[tokio::test]
async fn recommend_says_when_no_rule_meets_the_bound() {
    let app = spawn_app().await;
    let response = app
        .post_json(
            "/v1/correlation/rules/recommend",
            &json!({"alpha": 0.05, "max_miss_probability": 1e-6, "max_r": 4}),
        )
        .await;
    assert_eq!(response.status(), 200);
    let body: serde_json::Value = response.json().await.unwrap();
    assert!(body["recommended"].is_null());
    assert_eq!(body["warnings"].as_array().unwrap().len(), 1);
}

#[tokio::test]
async fn evaluate_and_recommend_over_grpc_on_both_ports() {
    let app = spawn_app().await;
    let request = pb::EvaluateRulesRequest {
        alpha: Some(0.05),
        rules: vec![
            pb::LrRule {
                l: Some(3),
                r: Some(4),
            },
            pb::LrRule {
                l: Some(6),
                r: Some(8),
            },
        ],
    };
    for addr in [app.grpc_addr, app.http_addr] {
        let mut client = crate::helpers::grpc_client(addr).await;
        let response = client
            .evaluate_rules(request.clone())
            .await
            .expect("evaluates")
            .into_inner();
        assert_eq!(response.evaluations.len(), 2);
        assert!(close(response.evaluations[0].miss_probability, P_3_OF_4));
        assert!(close(response.evaluations[1].miss_probability, P_6_OF_8));
        assert_eq!(response.evaluations[1].misses_from, 3);
        assert!(response.timing.is_some());

        let rec = client
            .recommend_rule(pb::RecommendRuleRequest {
                alpha: Some(0.05),
                max_miss_probability: Some(0.01),
                min_l_over_r: None,
                max_r: None,
            })
            .await
            .expect("recommends")
            .into_inner();
        let best = rec.recommended.expect("a rule meets 0.01");
        assert_eq!((best.l, best.r), (6, 8));
    }
}

#[tokio::test]
async fn rest_and_grpc_give_identical_numbers() {
    let app = spawn_app().await;
    let rest: serde_json::Value = app
        .post_ok(
            "/v1/correlation/rules/evaluate",
            &json!({"alpha": 0.013, "rules": [{"l": 7, "r": 11}]}),
        )
        .await;
    let grpc = app
        .correlation()
        .await
        .evaluate_rules(pb::EvaluateRulesRequest {
            alpha: Some(0.013),
            rules: vec![pb::LrRule {
                l: Some(7),
                r: Some(11),
            }],
        })
        .await
        .unwrap()
        .into_inner();
    assert_eq!(
        rest["evaluations"][0]["miss_probability"].as_f64().unwrap(),
        grpc.evaluations[0].miss_probability
    );
}
