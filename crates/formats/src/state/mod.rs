//! The stored-state codecs: the bytes a streaming session keeps of the
//! numerical core's state between batches. Each codec reads the state
//! through the core's public parts and rebuilds it with the core's own
//! checks, so a corrupt stored session is a [`wire_formats::wire::FormatError`]
//! (never an algorithm error, never a panic).
//!
//! - [`tracker`]: a plot-fusion `Tracker`, configuration included.
//! - [`scene`]: a correlation session's window of aligned local tracks.
//! - [`correlator`]: a pair correlator's candidate pairs and decisions.
//! - [`window`]: a tracker that takes late plots within a lag (two
//!   trackers and the plots between them).
//! - `identity`: what secondary surveillance says of a plot and a track,
//!   inside the tracker's and the window's formats.

pub mod correlator;
mod identity;
pub mod scene;
pub mod tracker;
pub mod window;
