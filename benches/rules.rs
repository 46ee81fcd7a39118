//! Benchmarks of the L/R rule computations (seed 000 eq. 23): the numerical
//! core alone, and the service-layer call the adapters make.

use std::hint::black_box;

use algo::correlation::rules::{LrRule, miss_probability, recommend};
use criterion::{Criterion, criterion_group, criterion_main};
use service::rules::{EvaluateRulesInput, RuleInput, evaluate};

fn bench_rules(c: &mut Criterion) {
    let rule = LrRule::new(6, 8).expect("valid rule");
    c.bench_function("miss_probability 6/8", |b| {
        b.iter(|| miss_probability(black_box(rule), black_box(0.05)))
    });
    let wide = LrRule::new(64, 128).expect("valid rule");
    c.bench_function("miss_probability 64/128", |b| {
        b.iter(|| miss_probability(black_box(wide), black_box(0.05)))
    });
    c.bench_function("recommend max_r=32", |b| {
        b.iter(|| recommend(black_box(0.05), black_box(1e-3), 0.75, 32))
    });
    c.bench_function("service evaluate 2 rules", |b| {
        b.iter(|| {
            evaluate(EvaluateRulesInput {
                alpha: Some(0.05),
                rules: vec![
                    RuleInput {
                        l: Some(3),
                        r: Some(4),
                    },
                    RuleInput {
                        l: Some(6),
                        r: Some(8),
                    },
                ],
            })
        })
    });
}

criterion_group!(benches, bench_rules);
criterion_main!(benches);
