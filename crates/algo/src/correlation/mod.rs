//! Track-to-track correlation (seed 000): L/R rules, the two-node engine
//! (statistics, double-threshold logic, baselines), grouping across M nodes
//! and the fusion of correlated tracks into system tracks.

pub mod align;
pub mod engine;
pub mod fusion;
pub mod grouping;
pub mod rules;
pub mod scene;
