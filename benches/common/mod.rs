//! Helpers shared by the benchmarks' hand-written tables.

// Helpers shared by test targets: `pub` is for the modules that use them.
#![allow(unreachable_pub)]

/// The median of `v` (the upper one of an even count).
pub fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// The median and the minimum of `v`.
pub fn median_min(v: &[f64]) -> (f64, f64) {
    let min = v.iter().copied().fold(f64::INFINITY, f64::min);
    (median(v.to_vec()), min)
}
