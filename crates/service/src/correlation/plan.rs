//! A validated request's configuration (`Plan`): the method, the layout,
//! the motion models and how samples are carried to the common instants.

use nalgebra::DMatrix;

use algo::{
    correlation::{align::Estimate, engine::Config},
    motion::{ConstantVelocity, MotionModel},
};

use super::{Layout, SampleInput, nodes::estimate};

/// How a track's samples are carried to the common instants.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum AlignMode {
    /// A fusion-time grid (`algo::correlation::align`): each track brought
    /// from its latest sample at or before each instant.
    Grid {
        period: Option<f64>,
        epoch: f64,
        max_staleness: Option<f64>,
    },
    /// The latest sample of the cluster, predicted forward with the model.
    Predict,
    /// The latest sample of the cluster, as reported.
    Nearest,
    /// Linear interpolation between the samples around the instant, at most
    /// this many seconds apart; never extrapolated.
    Interpolate { max_gap: f64 },
}

/// Default widest gap interpolated across.
pub const DEFAULT_MAX_GAP_S: f64 = 10.0;

/// A validated request.
pub(crate) struct Plan {
    pub(crate) layout: Layout,
    pub(crate) method_name: String,
    pub(crate) config: Config,
    pub(crate) model: Option<ConstantVelocity>,
    /// The model that brings samples to instants: the motion model, or
    /// without one a constant-velocity model without process noise when the
    /// layout has velocities (positions are then held as reported).
    pub(crate) align_model: Option<ConstantVelocity>,
    pub(crate) alignment: AlignMode,
    pub(crate) tolerance: f64,
    pub(crate) h: Option<DMatrix<f64>>,
    pub(crate) fuse: bool,
}

impl Plan {
    /// A reported sample (valid) at time `t` as an estimate in canonical
    /// order, with its update factor I − K H when it carries a gain.
    pub(crate) fn estimate(&self, t: f64, s: &SampleInput) -> Estimate {
        estimate(&self.layout, self.h.as_ref(), t, s)
    }

    /// The model that brings samples to their instants: the alignment
    /// model in the `predict` and `grid` modes; none (as reported) else.
    pub(crate) fn bring_model(&self) -> Option<&dyn MotionModel> {
        match self.alignment {
            AlignMode::Predict | AlignMode::Grid { .. } => {
                self.align_model.as_ref().map(|m| m as &dyn MotionModel)
            }
            AlignMode::Nearest | AlignMode::Interpolate { .. } => None,
        }
    }
}
