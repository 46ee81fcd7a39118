//! What this machine does per second, for the inherent-work ratios of
//! docs/RESULTS.md (issue 54): the rate of the operations the stateless
//! endpoints are made of, each timed on its own, single-threaded, in plain
//! Rust (no crate of the workspace):
//! - a gated 4 × 4 test: S = P_a + P_b, its Cholesky factor, the forward
//!   solve and d'S⁻¹d against a threshold (the correlation statistic);
//! - a 4 × 4 matrix product in a dependent chain (the modified test's
//!   cross-covariance step is four of them);
//! - parsing a decimal number of ~18 characters into an f64, correctly
//!   rounded (std's parser): the floor for reading a JSON request's numbers;
//! - one sin_cos, sinh, cosh and atan2 (a projection's transcendental
//!   budget).
//!
//! ```sh
//! cargo run --release --example machine_rates
//! ```

use std::hint::black_box;
use std::time::Instant;

/// d'S⁻¹d of a 4 × 4 SPD matrix by its Cholesky factor.
#[allow(clippy::needless_range_loop)] // index form of the matrix algebra
fn quad4(p: &[f64; 16], d: &[f64; 4]) -> f64 {
    let mut l = [0.0f64; 16];
    for j in 0..4 {
        let mut s = p[j * 4 + j];
        for k in 0..j {
            s -= l[j * 4 + k] * l[j * 4 + k];
        }
        let ljj = s.sqrt();
        l[j * 4 + j] = ljj;
        for i in j + 1..4 {
            let mut s = p[i * 4 + j];
            for k in 0..j {
                s -= l[i * 4 + k] * l[j * 4 + k];
            }
            l[i * 4 + j] = s / ljj;
        }
    }
    let mut y = [0.0; 4];
    let mut q = 0.0;
    for i in 0..4 {
        let mut s = d[i];
        for k in 0..i {
            s -= l[i * 4 + k] * y[k];
        }
        y[i] = s / l[i * 4 + i];
        q += y[i] * y[i];
    }
    q
}

fn main() {
    let n = 2_000_000;
    let mut pa = [0.0; 16];
    for i in 0..4 {
        pa[i * 4 + i] = 100.0 + i as f64;
    }
    pa[1] = 3.0;
    pa[4] = 3.0;
    let t = Instant::now();
    let mut hits = 0u64;
    for k in 0..n {
        let mut s = pa;
        for v in s.iter_mut() {
            *v += black_box(1e-3) * (k & 7) as f64;
        }
        let d = [black_box(1.0), 2.0, 3.0, (k & 3) as f64];
        if quad4(&s, &d) < 9.49 {
            hits += 1;
        }
    }
    let e = t.elapsed().as_secs_f64();
    println!(
        "gated 4x4 test: {:.1} ns ({:.1} M/s) [{hits} passed]",
        e / n as f64 * 1e9,
        n as f64 / e / 1e6
    );

    let a: [f64; 16] = std::array::from_fn(|i| i as f64 * 0.1);
    let mut c: [f64; 16] = std::array::from_fn(|i| (i % 5) as f64);
    let t = Instant::now();
    for _ in 0..n {
        let b = black_box(c);
        let mut r = [0.0; 16];
        for i in 0..4 {
            for j in 0..4 {
                let mut s = 0.0;
                for k in 0..4 {
                    s += a[i * 4 + k] * b[k * 4 + j];
                }
                r[i * 4 + j] = s;
            }
        }
        c = r;
        c[0] = c[0].min(1.0);
    }
    let e = t.elapsed().as_secs_f64();
    println!(
        "4x4 product: {:.1} ns ({:.1} M/s) [{}]",
        e / n as f64 * 1e9,
        n as f64 / e / 1e6,
        c[0]
    );

    let texts: Vec<String> = (0..200_000)
        .map(|i| {
            format!(
                "{}",
                (i as f64 * 1.234_567_890_123_456_7e-3).sin() * 12_345.678
            )
        })
        .collect();
    let chars = texts.iter().map(String::len).sum::<usize>() as f64 / texts.len() as f64;
    let t = Instant::now();
    let mut sum = 0.0;
    for _ in 0..5 {
        for s in &texts {
            sum += black_box(s.as_str()).parse::<f64>().unwrap_or(0.0);
        }
    }
    let e = t.elapsed().as_secs_f64();
    let parsed = 5.0 * texts.len() as f64;
    println!(
        "f64 parse of {chars:.1} characters: {:.1} ns ({:.1} M/s) [{sum:.3}]",
        e / parsed * 1e9,
        parsed / e / 1e6
    );

    let t = Instant::now();
    let mut acc = 0.0;
    for k in 0..n {
        let x = black_box(k as f64 * 1e-7);
        let (s, c) = x.sin_cos();
        acc += s * x.sinh() + c * x.cosh() + x.atan2(c);
    }
    let e = t.elapsed().as_secs_f64();
    println!(
        "sin_cos + sinh + cosh + atan2: {:.1} ns [{acc:.3}]",
        e / n as f64 * 1e9
    );
}
