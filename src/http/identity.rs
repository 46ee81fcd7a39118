//! The JSON of secondary surveillance: a track's identity as
//! `service::plot_fusion::ssr` builds it (`FusedTrack.identity`). A plot's
//! SSR and Mode S fields are flat in `PlotIn`.

use serde::Serialize;
use utoipa::ToSchema;

use service::plot_fusion as svc;

/// One identity of a track and its evidence.
#[derive(Debug, Serialize, ToSchema)]
pub struct IdentityItem {
    /// The value: a Mode S address as six hexadecimal digits, a Mode 3/A
    /// code as four octal digits, a callsign as text.
    #[schema(example = "4CA2D1")]
    pub value: String,
    /// Plots associated with the track that gave it.
    pub plots: u32,
    /// Time of the first of them.
    pub first_t: f64,
    /// Time of the last of them.
    pub last_t: f64,
}

/// The track's pressure altitude: Mode C filtered with its own rate of
/// climb, apart from the geometric height (`height_m`, `state`).
#[derive(Debug, Serialize, ToSchema)]
pub struct PressureAltitude {
    /// Time of the estimate: the track's, predicted from the last Mode C
    /// used (`measured_t`).
    pub t: f64,
    /// Flight level (hundreds of feet above the 1013.25 hPa isobar).
    pub flight_level: f64,
    pub flight_level_sigma: f64,
    /// Rate of climb (ft/min, positive up).
    pub rate_of_climb_ftpm: f64,
    pub rate_of_climb_sigma_ftpm: f64,
    /// The last Mode C flight level used, and its time.
    pub measured_flight_level: f64,
    pub measured_t: f64,
}

/// What a track knows of its aircraft from SSR and Mode S plots.
#[derive(Debug, Serialize, ToSchema)]
pub struct TrackIdentity {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mode_s_address: Option<IdentityItem>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mode_3a: Option<IdentityItem>,
    /// A new code that replies have given, not yet adopted (two agreeing
    /// replies adopt it).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pending_mode_3a: Option<IdentityItem>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub callsign: Option<IdentityItem>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pressure_altitude: Option<PressureAltitude>,
    /// `unlawful_interference` (7500), `radio_failure` (7600) or
    /// `emergency` (7700).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub emergency: Option<&'static str>,
    /// Special position identification set in the last 18 s.
    pub spi: bool,
    /// Time of the last update by a radar's secondary plot (a cooperative
    /// report dates none of these three times: `sources` has its time).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub last_secondary_t: Option<f64>,
    /// Time of the last update by a radar's plot with a Mode S address.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub last_mode_s_t: Option<f64>,
    /// Time of the last update by a radar's primary (or combined) plot.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub last_primary_t: Option<f64>,
}

fn item(i: svc::IdentityItem) -> IdentityItem {
    IdentityItem {
        value: i.value,
        plots: i.plots,
        first_t: i.first_t,
        last_t: i.last_t,
    }
}

pub(crate) fn identity_out(v: svc::IdentityView) -> TrackIdentity {
    TrackIdentity {
        mode_s_address: v.mode_s_address.map(item),
        mode_3a: v.mode_3a.map(item),
        pending_mode_3a: v.pending_mode_3a.map(item),
        callsign: v.callsign.map(item),
        pressure_altitude: v.pressure_altitude.map(|a| PressureAltitude {
            t: a.t,
            flight_level: a.flight_level,
            flight_level_sigma: a.flight_level_sigma,
            rate_of_climb_ftpm: a.rate_of_climb_ftpm,
            rate_of_climb_sigma_ftpm: a.rate_of_climb_sigma_ftpm,
            measured_flight_level: a.measured_flight_level,
            measured_t: a.measured_t,
        }),
        emergency: v.emergency,
        spi: v.spi,
        last_secondary_t: v.last_secondary_t,
        last_mode_s_t: v.last_mode_s_t,
        last_primary_t: v.last_primary_t,
    }
}
