//! The tracker's options by name: [`TrackerParameter`] names each option
//! that [`crate::tracking::TrackerConfig::validated`] checks, and an
//! option outside its domain is an [`AlgoError::InvalidOption`] carrying
//! it, so that a caller maps the option to its own field by a total
//! `match`, never by a string.
//!
//! The checks here are the ones of [`crate::error`] with the option typed:
//! a non-finite value stays an [`AlgoError::NonFinite`] naming the option
//! (a numeric error), a value outside its domain becomes an
//! [`AlgoError::InvalidOption`].

use std::fmt;

use crate::error::AlgoError;

/// One option of [`crate::tracking::TrackerConfig`] (or of the
/// [`crate::tracking::LagWindow`] around the tracker).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum TrackerParameter {
    /// `axes`: 2 or 3.
    Axes,
    /// `radars`: at least one.
    Radars,
    /// A radar's `site`.
    RadarSite,
    /// A radar's `sigma_range`.
    RadarSigmaRange,
    /// A radar's `sigma_azimuth`.
    RadarSigmaAzimuth,
    /// A radar's `sigma_elevation`.
    RadarSigmaElevation,
    /// A radar's `sigma_radial_velocity`.
    RadarSigmaRadialVelocity,
    /// A radar's `scan_period`.
    RadarScanPeriod,
    /// A radar's `detection_probability`.
    RadarDetectionProbability,
    /// A radar's `clutter_density`.
    RadarClutterDensity,
    /// `mode`.
    Mode,
    /// `fusion_period`.
    FusionPeriod,
    /// `fusion_epoch`.
    FusionEpoch,
    /// `time_tolerance`.
    TimeTolerance,
    /// `association.max_exact_tracks`.
    MaxExactTracks,
    /// `plot_gate_probability`.
    PlotGateProbability,
    /// `track_gate_probability`.
    TrackGateProbability,
    /// `initiation.confirm_m` and `confirm_n`.
    ConfirmMOfN,
    /// The initiation's lower velocity bound.
    VMin,
    /// The initiation's upper velocity bound.
    VMax,
    /// `initiation.gate_probability`.
    InitiationGateProbability,
    /// `initiation.min_dt`.
    MinDt,
    /// `initiation.max_dt`.
    MaxDt,
    /// `deletion.max_consecutive_misses`.
    MaxConsecutiveMisses,
    /// `deletion.misses_m_of_n`.
    DeletionMOfN,
    /// `deletion.max_position_sigma`.
    MaxPositionSigma,
    /// `sigma_a` (and an IMM model's).
    SigmaA,
    /// The IMM's models (their count).
    ImmModels,
    /// A coordinated-turn model's turn rate.
    TurnRate,
    /// The IMM's mean sojourn times.
    MeanSojourn,
    /// The IMM's initial model probabilities.
    InitialProbabilities,
    /// `default_height`.
    DefaultHeight,
    /// `default_height_sigma`.
    DefaultHeightSigma,
    /// `sigma_tangential_speed`.
    SigmaTangentialSpeed,
    /// `duplicate_gate_probability`.
    DuplicateGateProbability,
    /// `registration.priors`.
    RegistrationPriors,
    /// `registration.reference`.
    RegistrationReference,
    /// `registration.max_pair_dt`.
    RegistrationMaxPairDt,
    /// `registration.time_constant`.
    RegistrationTimeConstant,
    /// `mode_c_height.offset`.
    ModeCHeightOffset,
    /// `mode_c_height.sigma_offset`.
    ModeCHeightSigmaOffset,
    /// `mode_c_height.slope`.
    ModeCHeightSlope,
    /// `mode_c_height.sigma_slope`.
    ModeCHeightSigmaSlope,
    /// `accuracy.time_constant`.
    AccuracyTimeConstant,
    /// `accuracy.pinned`.
    AccuracyPinned,
    /// `height_datum`.
    HeightDatum,
    /// The lag window's `max_lag` (s).
    MaxLag,
}

impl TrackerParameter {
    /// The option's name in the core's vocabulary (as in messages).
    pub fn name(self) -> &'static str {
        use TrackerParameter as P;
        match self {
            P::Axes => "axes",
            P::Radars => "radars",
            P::RadarSite => "site",
            P::RadarSigmaRange => "sigma_range",
            P::RadarSigmaAzimuth => "sigma_azimuth",
            P::RadarSigmaElevation => "sigma_elevation",
            P::RadarSigmaRadialVelocity => "sigma_radial_velocity",
            P::RadarScanPeriod => "scan_period",
            P::RadarDetectionProbability => "detection_probability",
            P::RadarClutterDensity => "clutter_density",
            P::Mode => "mode",
            P::FusionPeriod => "fusion_period",
            P::FusionEpoch => "fusion_epoch",
            P::TimeTolerance => "time_tolerance",
            P::MaxExactTracks => "max_exact_tracks",
            P::PlotGateProbability => "plot_gate_probability",
            P::TrackGateProbability => "track_gate_probability",
            P::ConfirmMOfN => "confirm_m_of_n",
            P::VMin => "v_min",
            P::VMax => "v_max",
            P::InitiationGateProbability => "initiation_gate_probability",
            P::MinDt => "min_dt",
            P::MaxDt => "max_dt",
            P::MaxConsecutiveMisses => "max_consecutive_misses",
            P::DeletionMOfN => "deletion_m_of_n",
            P::MaxPositionSigma => "max_position_sigma",
            P::SigmaA => "sigma_a",
            P::ImmModels => "models",
            P::TurnRate => "turn_rate",
            P::MeanSojourn => "mean_sojourn",
            P::InitialProbabilities => "initial_probabilities",
            P::DefaultHeight => "default_height",
            P::DefaultHeightSigma => "default_height_sigma",
            P::SigmaTangentialSpeed => "sigma_tangential_speed",
            P::DuplicateGateProbability => "duplicate_gate_probability",
            P::RegistrationPriors => "registration_priors",
            P::RegistrationReference => "registration_reference",
            P::RegistrationMaxPairDt => "registration_max_pair_dt",
            P::RegistrationTimeConstant => "registration_time_constant",
            P::ModeCHeightOffset => "mode_c_height.offset",
            P::ModeCHeightSigmaOffset => "mode_c_height.sigma_offset",
            P::ModeCHeightSlope => "mode_c_height.slope",
            P::ModeCHeightSigmaSlope => "mode_c_height.sigma_slope",
            P::AccuracyTimeConstant => "accuracy.time_constant",
            P::AccuracyPinned => "accuracy.pinned",
            P::HeightDatum => "height_datum",
            P::MaxLag => "max_lag_s",
        }
    }
}

impl fmt::Display for TrackerParameter {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The error for option `parameter` outside its domain.
pub(crate) fn invalid(parameter: TrackerParameter, reason: impl Into<String>) -> AlgoError {
    AlgoError::InvalidOption {
        parameter,
        reason: reason.into(),
    }
}

/// `Ok(v)` if `v` is finite.
pub(crate) fn finite(parameter: TrackerParameter, v: f64) -> Result<f64, AlgoError> {
    crate::error::finite(parameter.name(), v)
}

/// `Ok(())` if every entry of `v` is finite.
pub(crate) fn finite_slice(parameter: TrackerParameter, v: &[f64]) -> Result<(), AlgoError> {
    crate::error::finite_slice(parameter.name(), v)
}

/// `Ok(v)` if `v` is finite and strictly positive.
pub(crate) fn positive(parameter: TrackerParameter, v: f64) -> Result<f64, AlgoError> {
    finite(parameter, v)?;
    if v > 0.0 {
        Ok(v)
    } else {
        Err(invalid(parameter, format!("must be > 0, got {v}")))
    }
}

/// `Ok(v)` if `v` is finite and not negative.
pub(crate) fn non_negative(parameter: TrackerParameter, v: f64) -> Result<f64, AlgoError> {
    finite(parameter, v)?;
    if v >= 0.0 {
        Ok(v)
    } else {
        Err(invalid(parameter, format!("must be >= 0, got {v}")))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_invalid_option_reads_as_before_and_names_its_parameter() {
        let e = positive(TrackerParameter::FusionPeriod, -1.0).unwrap_err();
        assert_eq!(e.to_string(), "invalid fusion_period: must be > 0, got -1");
        assert_eq!(e.what(), "fusion_period");
        assert_eq!(
            non_negative(TrackerParameter::TimeTolerance, f64::NAN).unwrap_err(),
            AlgoError::NonFinite {
                what: "time_tolerance"
            }
        );
    }
}
