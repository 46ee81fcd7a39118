#![warn(missing_docs)]
//! The numerical core: pure functions over nalgebra and std. No I/O, no async,
//! no serialisation; every later algorithm builds on these pieces.

pub mod assignment;
pub mod bias;
pub mod correlation;
pub mod dimension;
pub mod error;
pub mod gating;
pub mod gaussian;
pub mod geo;
pub mod jpda;
pub mod kalman;
pub mod motion;
pub mod polar;
pub mod small;
pub mod tracking;

pub use error::AlgoError;
pub use gaussian::Gaussian;
pub use kalman::{PositionLayout, Update};
pub use polar::PolarMeasurement;
