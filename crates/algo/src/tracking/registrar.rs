//! The registrar: the tracker's component that learns each radar's bias
//! online from the tracks' updates ([`super::registration`] holds the
//! estimator's mathematics) and gives the bias the tracker applies to a
//! radar's plots.
//!
//! A frame's pairs: in serial mode, a confirmed track updated by a plot of
//! one radar whose previous update was another radar's plot; in parallel
//! mode, every two time-consecutive plots of a fused cluster of several
//! radars that updated a confirmed track; in a report frame, a confirmed
//! track updated by a cooperative report it trusts, with its last radar
//! plot (the report is the reference). At most
//! [`registration::MAX_PAIRS_PER_FRAME`] pairs a frame are used.

use nalgebra::{DMatrix, DVector};

use crate::error::AlgoError;
use crate::tracking::config::{Plot, RadarSpec, TrackerConfig};
use crate::tracking::registration::{self, RadarBias, RegistrationState};
use crate::tracking::track::Track;

/// A track a plot updated in a frame.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Hit {
    /// Its index in the tracks.
    pub slot: usize,
    /// The plot (index in the frame's plots).
    pub plot: usize,
    /// Its last radar plot before this update.
    pub previous: Option<Plot>,
}

/// The registration's data, the biases applied now and the last solution.
#[derive(Debug, Clone)]
pub(crate) struct Registrar {
    /// The estimator's data (stored with the tracker).
    pub state: RegistrationState,
    /// Each radar's bias as applied now (derived from `state`).
    pub biases: Vec<RadarBias>,
    /// The solution for `state` once solved (derived: it depends on the
    /// data alone, which change only when a pair is added).
    solved: Option<(DVector<f64>, DMatrix<f64>)>,
    /// Cooperative reports have reached the tracker (derived: the
    /// tracker's own flag), so a lone radar has a reference.
    references: bool,
}

impl PartialEq for Registrar {
    /// The data (the biases and the solution follow from it).
    fn eq(&self, other: &Self) -> bool {
        self.state == other.state
    }
}

impl Registrar {
    /// The registrar of `cfg` from the estimator's data `state`, with
    /// cooperative reports seen (`references`) or not.
    pub(crate) fn new(
        cfg: &TrackerConfig,
        state: RegistrationState,
        references: bool,
    ) -> Result<Self, AlgoError> {
        let solved = registration::solve(&cfg.registration, &cfg.radars, &state)?;
        let biases =
            registration::applied(&cfg.registration, &cfg.radars, &state, &solved, references);
        Ok(Self {
            state,
            biases,
            solved: Some(solved),
            references,
        })
    }

    /// Cooperative reports have come: a lone radar's bias is now
    /// uncertain against them (its prior widens its plots until the
    /// reports register it).
    pub(crate) fn refer(&mut self, cfg: &TrackerConfig) -> Result<(), AlgoError> {
        if self.references {
            return Ok(());
        }
        *self = Self::new(cfg, self.state.clone(), true)?;
        Ok(())
    }

    /// Whether frames learn: registration on (a lone radar's frames find
    /// no pairs; its report frames do).
    pub(crate) fn learns(cfg: &TrackerConfig) -> bool {
        cfg.registration.enabled
    }

    /// Serial mode: the pairs of a frame of radar `radar` (`hits` on
    /// `tracks`, their slots after the frame), then the estimate solved
    /// again.
    pub(crate) fn learn_serial(
        &mut self,
        cfg: &TrackerConfig,
        radars: &[RadarSpec],
        tracks: &[std::sync::Arc<Track>],
        radar: usize,
        hits: &[Hit],
    ) -> Result<(), AlgoError> {
        let pairs: Vec<(usize, Plot, Plot, bool)> = hits
            .iter()
            .filter_map(|h| {
                let newer = tracks[h.slot].last_plot.filter(|p| p.radar == radar)?;
                let older = h.previous.filter(|p| p.radar != radar)?;
                Some((h.slot, newer, older, true))
            })
            .collect();
        self.learn(cfg, radars, tracks, &pairs)
    }

    /// A report frame's pairs (`frame`'s reports, `hits` on `tracks`, the
    /// hits the tracker chose as references: trusted, isolated, with a
    /// last radar plot): each report with that plot; then the estimate is
    /// solved again.
    pub(crate) fn learn_reports(
        &mut self,
        cfg: &TrackerConfig,
        radars: &[RadarSpec],
        tracks: &[std::sync::Arc<Track>],
        frame: &[Plot],
        hits: &[Hit],
    ) -> Result<(), AlgoError> {
        let pairs: Vec<(usize, Plot, Plot, bool)> = hits
            .iter()
            .filter_map(|h| Some((h.slot, frame[h.plot], h.previous?, true)))
            .collect();
        self.learn(cfg, radars, tracks, &pairs)
    }

    /// Parallel mode: every cluster of several radars' plots (`members`,
    /// indices in `frame`) that updated a confirmed track (`hits`) gives a
    /// pair per two of its plots consecutive in time; then the estimate is
    /// solved again.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn learn_parallel(
        &mut self,
        cfg: &TrackerConfig,
        radars: &[RadarSpec],
        tracks: &[std::sync::Arc<Track>],
        frame: &[Plot],
        members: &[Vec<usize>],
        hits: &[Hit],
    ) -> Result<(), AlgoError> {
        let mut pairs = Vec::new();
        for h in hits {
            let j = h.plot;
            if members[j].len() < 2 {
                continue;
            }
            let mut plots: Vec<Plot> = members[j].iter().map(|&i| frame[i]).collect();
            plots.sort_by(|a, b| a.t.total_cmp(&b.t));
            let shares_plots = plots.len() > 2;
            for w in plots.windows(2) {
                pairs.push((h.slot, w[1], w[0], shares_plots));
            }
        }
        self.learn(cfg, radars, tracks, &pairs)
    }

    /// Adds the pairs (track index, newer plot, older plot, whether the
    /// plots are in other pairs too; raw plots; their noise that of
    /// `radars`, the radars as the tracker applies them) to the registration, the
    /// motion between them from the track's velocity, and solves again
    /// when any was used. Of a frame's pairs at most
    /// [`registration::MAX_PAIRS_PER_FRAME`] are used, every k-th when
    /// there are more (tracks in creation order: spread over the
    /// coverage), so that a dense picture costs no more than a sparse one.
    fn learn(
        &mut self,
        cfg: &TrackerConfig,
        radars: &[RadarSpec],
        tracks: &[std::sync::Arc<Track>],
        pairs: &[(usize, Plot, Plot, bool)],
    ) -> Result<(), AlgoError> {
        if pairs.is_empty() {
            return Ok(());
        }
        let stride = pairs.len().div_ceil(registration::MAX_PAIRS_PER_FRAME);
        let mut solved = match self.solved.take() {
            Some(s) => s,
            None => registration::solve(&cfg.registration, radars, &self.state)?,
        };
        let q = cfg.largest_process_noise();
        let axes = cfg.axes;
        let mut added = false;
        for (k, newer, older, shares_plots) in pairs.iter().step_by(stride) {
            let tr = &tracks[*k];
            let velocity: Vec<f64> = (0..axes).map(|i| tr.x[2 * i + 1]).collect();
            let velocity_cov = DMatrix::from_fn(axes, axes, |i, k| tr.p[(2 * i + 1, 2 * k + 1)]);
            let pair = registration::Pair {
                newer,
                older,
                velocity: &velocity,
                velocity_cov: &velocity_cov,
                q,
                shares_plots: *shares_plots,
            };
            if registration::add_pair(&cfg.registration, radars, &mut self.state, &solved, &pair)? {
                added = true;
            }
        }
        if added {
            solved = registration::solve(&cfg.registration, radars, &self.state)?;
            self.biases = registration::applied(
                &cfg.registration,
                radars,
                &self.state,
                &solved,
                self.references,
            );
        }
        self.solved = Some(solved);
        Ok(())
    }
}
