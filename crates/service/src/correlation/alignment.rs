//! Alignment: every node's tracks carried to common instants (a
//! fusion-time grid, or clusters of report times), with a report of what
//! that did and warnings when the nodes end up apart.

use algo::{
    AlgoError,
    correlation::{
        align::{self, Estimate},
        scene::{Scene, Track},
    },
};

use crate::{ServiceError, Violations};

use super::{AlignMode, Plan};

/// Most track-instants (tracks × instants) an aligned scene may hold.
pub const MAX_SCENE_CELLS: usize = 8_000_000;

/// What alignment did, for a client to test.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct AlignmentReport {
    /// `grid`, `predict`, `nearest` or `interpolate`.
    pub mode: &'static str,
    /// `grid`: the fusion period used (`None`: no node had two samples of a
    /// track, so one instant at the latest time).
    pub period_s: Option<f64>,
    /// `grid`: whether the period was estimated from the data.
    pub period_estimated: bool,
    pub epoch_s: Option<f64>,
    /// `predict`, `nearest`, `interpolate`.
    pub tolerance_s: Option<f64>,
    pub max_gap_s: Option<f64>,
    pub nodes: Vec<NodeAlignment>,
    pub instants: usize,
    /// Node pairs that share no instant where both hold a track.
    pub node_pairs_without_common_instant: usize,
    /// Tracks present at no instant where another node holds a track.
    pub tracks_without_partner_instant: usize,
    pub tracks: usize,
    /// Estimates brought across a gap to an instant (predicted, or held).
    pub brought: usize,
    /// Samples not used (superseded by a later sample of the same track
    /// before the next instant).
    pub unused_samples: usize,
}

#[derive(Debug, Clone, PartialEq)]
pub struct NodeAlignment {
    pub node: String,
    pub tracks: usize,
    /// Median interval between consecutive samples of the node's tracks.
    pub scan_period_s: Option<f64>,
    /// `grid`: the oldest a sample may be at an instant.
    pub max_staleness_s: Option<f64>,
}

pub(crate) fn mode_name(m: AlignMode) -> &'static str {
    match m {
        AlignMode::Grid { .. } => "grid",
        AlignMode::Predict => "predict",
        AlignMode::Nearest => "nearest",
        AlignMode::Interpolate { .. } => "interpolate",
    }
}

/// The grid's period and each node's staleness bound: given, or estimated
/// from node scan periods (`None` period: nothing to estimate from).
pub(crate) fn grid_parameters(
    period: Option<f64>,
    max_staleness: Option<f64>,
    node_periods: &[Option<f64>],
) -> (Option<f64>, Vec<f64>) {
    let grid = period.or_else(|| node_periods.iter().flatten().copied().reduce(f64::max));
    let staleness = node_periods
        .iter()
        .map(|p| {
            max_staleness.unwrap_or_else(|| match p.or(grid) {
                Some(p) => align::STALENESS_PERIODS * p,
                None => f64::INFINITY,
            })
        })
        .collect();
    (grid, staleness)
}

/// Builds the aligned scene; returns it, whether gains were reported,
/// warnings and the alignment report.
pub(super) fn align(
    est: Vec<Vec<Vec<Estimate>>>,
    node_ids: &[String],
    tolerance_given: bool,
    plan: &Plan,
) -> Result<(Scene, bool, Vec<String>, AlignmentReport), ServiceError> {
    let gains_reported = est.iter().flatten().flatten().any(|e| e.factor.is_some());
    let mut times: Vec<f64> = est.iter().flatten().flatten().map(|e| e.t).collect();
    times.sort_by(f64::total_cmp);
    let node_periods: Vec<Option<f64>> = est
        .iter()
        .map(|tracks| {
            let mut iv: Vec<f64> = tracks
                .iter()
                .flat_map(|s| s.windows(2).map(|w| w[1].t - w[0].t))
                .collect();
            align::median_interval(&mut iv)
        })
        .collect();
    let mut report = AlignmentReport {
        mode: mode_name(plan.alignment),
        tracks: est.iter().map(Vec::len).sum(),
        ..AlignmentReport::default()
    };
    let mut warnings = Vec::new();
    if matches!(plan.alignment, AlignMode::Grid { .. }) && tolerance_given {
        warnings.push(
            "alignment.tolerance_s has no effect on the grid alignment of a batch (it is a \
             session's lateness allowance); give alignment.mode predict or nearest for clusters \
             of report times"
                .to_string(),
        );
    }
    let instants = instants(plan, &times, &node_periods, &mut report, &mut warnings)?;
    report.instants = instants.times.len();
    let cells = instants.times.len().saturating_mul(report.tracks);
    if cells > MAX_SCENE_CELLS {
        return Err(ServiceError::TooLarge(format!(
            "alignment gives {} instants for {} tracks ({cells} track-instants; the limit is \
             {MAX_SCENE_CELLS}): give a longer alignment.period_s or split the request in time",
            instants.times.len(),
            report.tracks
        )));
    }
    let scene = fill_scene(plan, &est, &instants, &mut report)?;
    report.nodes = node_ids
        .iter()
        .zip(&est)
        .zip(&node_periods)
        .zip(&instants.staleness)
        .map(|(((id, tracks), &p), &s)| NodeAlignment {
            node: id.clone(),
            tracks: tracks.len(),
            scan_period_s: p,
            max_staleness_s: s.filter(|s| s.is_finite()),
        })
        .collect();
    let empty: Vec<&str> = report
        .nodes
        .iter()
        .filter(|n| n.tracks == 0)
        .map(|n| n.node.as_str())
        .collect();
    if !empty.is_empty() {
        warnings.push(format!(
            "{} node(s) hold no tracks ({}): they take part in no pair",
            empty.len(),
            empty.join(", ")
        ));
    }
    coverage(&scene, node_ids, &mut report, &mut warnings);
    warn_about_bringing(plan, &report, &mut warnings);
    Ok((scene, gains_reported, warnings, report))
}

/// The common instants, with the clusters of report times they stand for
/// (the cluster modes) or each node's staleness bound (the grid).
struct Instants {
    times: Vec<f64>,
    clustered: Vec<(f64, f64)>,
    staleness: Vec<Option<f64>>,
}

/// The common instants of the plan's alignment mode over the sorted
/// report `times`.
fn instants(
    plan: &Plan,
    times: &[f64],
    node_periods: &[Option<f64>],
    report: &mut AlignmentReport,
    warnings: &mut Vec<String>,
) -> Result<Instants, ServiceError> {
    let AlignMode::Grid {
        period,
        epoch,
        max_staleness,
    } = plan.alignment
    else {
        report.tolerance_s = Some(plan.tolerance);
        if let AlignMode::Interpolate { max_gap } = plan.alignment {
            report.max_gap_s = Some(max_gap);
        }
        let clustered = align::clusters(times, plan.tolerance);
        return Ok(Instants {
            times: clustered.iter().map(|c| c.1).collect(),
            clustered,
            staleness: vec![None; node_periods.len()],
        });
    };
    let (grid, bounds) = grid_parameters(period, max_staleness, node_periods);
    report.period_s = grid;
    report.period_estimated = period.is_none() && grid.is_some();
    report.epoch_s = Some(epoch);
    let instants = match grid {
        Some(g) => {
            let widest = bounds.iter().copied().fold(0.0, f64::max);
            let limit = MAX_SCENE_CELLS / report.tracks.max(1);
            align::grid_instants(times, g, epoch, widest, limit).ok_or_else(|| {
                ServiceError::TooLarge(format!(
                    "the grid alignment with a period of {g} s gives more than {limit} \
                     instants for {} tracks (the limit is {MAX_SCENE_CELLS} \
                     track-instants), or the period is below the resolution of the \
                     times: give a longer alignment.period_s or split the request in time",
                    report.tracks
                ))
            })?
        }
        None => {
            if times.len() > 1 {
                warnings.push(
                    "no track has two samples, so no scan period can be estimated: \
                     every track was brought to one instant at the latest sample time; \
                     give alignment.period_s for a grid"
                        .to_string(),
                );
            }
            times.last().map(|&t| vec![t]).unwrap_or_default()
        }
    };
    Ok(Instants {
        times: instants,
        clustered: Vec::new(),
        staleness: bounds.iter().copied().map(Some).collect(),
    })
}

/// The aligned scene: every node's tracks brought to the instants.
fn fill_scene(
    plan: &Plan,
    est: &[Vec<Vec<Estimate>>],
    instants: &Instants,
    report: &mut AlignmentReport,
) -> Result<Scene, ServiceError> {
    let dim = plan.layout.dim;
    let model = plan.bring_model();
    let times = &instants.times;
    let mut scene = Scene::new(dim, plan.layout.positions(), times.clone())
        .map_err(|e| ServiceError::Internal(e.to_string()))?;
    for (ni, node) in est.iter().enumerate() {
        let mut tracks = Vec::with_capacity(node.len());
        for (ti, samples) in node.iter().enumerate() {
            // Track by track, so that an abandoned request stops.
            crate::lanes::checkpoint()?;
            let mut out = Track::new(times.len(), dim);
            let at = |si: usize, e: AlgoError| {
                Violations::from_param(&format!("nodes[{ni}].tracks[{ti}].samples[{si}]."), e)
            };
            match plan.alignment {
                AlignMode::Grid { .. } => {
                    let bound = instants.staleness[ni].unwrap_or(f64::INFINITY);
                    let stats = align::fill_grid(&mut out, samples, times, 0, model, bound)
                        .map_err(|(si, e)| at(si, e))?;
                    report.brought += stats.brought;
                    report.unused_samples += stats.unused;
                }
                AlignMode::Interpolate { max_gap } => {
                    report.brought += align::interpolate(&mut out, samples, times, max_gap);
                }
                AlignMode::Predict | AlignMode::Nearest => {
                    let clustered = &instants.clustered;
                    let mut ci = 0;
                    let mut si = 0;
                    while si < samples.len() {
                        while clustered[ci].1 < samples[si].t {
                            ci += 1;
                        }
                        // The latest sample of this track inside cluster ci.
                        let mut last = si;
                        while last + 1 < samples.len() && samples[last + 1].t <= clustered[ci].1 {
                            last += 1;
                        }
                        report.unused_samples += last - si;
                        let placed =
                            align::place(&mut out, ci, times[ci], &samples[last], model, true)
                                .map_err(|e| at(last, e))?;
                        if placed == align::Placed::Brought && model.is_some() {
                            report.brought += 1;
                        }
                        si = last + 1;
                    }
                }
            }
            tracks.push(out);
        }
        scene
            .add_node(tracks)
            .map_err(|e| ServiceError::Internal(e.to_string()))?;
    }
    Ok(scene)
}

/// Says how many estimates were predicted, interpolated, extrapolated or
/// held to reach their instants, and how many samples were superseded.
fn warn_about_bringing(plan: &Plan, report: &AlignmentReport, warnings: &mut Vec<String>) {
    match plan.alignment {
        AlignMode::Predict if report.brought > 0 => warnings.push(format!(
            "{} sample(s) were predicted forward (at most {} s) to a common instant",
            report.brought, plan.tolerance
        )),
        AlignMode::Interpolate { .. } if report.brought > 0 => warnings.push(format!(
            "{} estimate(s) were interpolated linearly between two samples of their track to a \
             common instant",
            report.brought
        )),
        AlignMode::Grid { .. } if plan.model.is_none() && report.brought > 0 => {
            warnings.push(if plan.layout.has_velocity {
                format!(
                    "no motion_model: {} estimate(s) were extrapolated to their instant along \
                     their velocity without process noise; give motion_model for Q",
                    report.brought
                )
            } else {
                format!(
                    "no velocities in state_layout: {} position(s) were held unchanged up to \
                     their staleness bound to reach an instant; moving targets may fail the test",
                    report.brought
                )
            })
        }
        _ => {}
    }
    if report.unused_samples > 0 && !matches!(plan.alignment, AlignMode::Grid { .. }) {
        warnings.push(format!(
            "{} sample(s) were superseded by a later sample of the same track within one \
             alignment instant (tolerance {} s) and ignored",
            report.unused_samples, plan.tolerance
        ));
    }
}

/// Which nodes meet at which instants: counts the node pairs that never do
/// and the tracks that never meet another node, and warns when alignment
/// left the nodes apart.
pub(crate) fn coverage(
    scene: &Scene,
    node_ids: &[String],
    report: &mut AlignmentReport,
    warnings: &mut Vec<String>,
) {
    let n = scene.nodes().len();
    if n < 2 {
        return;
    }
    let ks = scene.first()..scene.end();
    let node_at: Vec<Vec<bool>> = scene
        .nodes()
        .iter()
        .map(|tracks| {
            ks.clone()
                .map(|k| tracks.iter().any(|t| t.is_present(k)))
                .collect()
        })
        .collect();
    let busy: Vec<usize> = (0..ks.len())
        .map(|i| node_at.iter().filter(|v| v[i]).count())
        .collect();
    let mut apart = Vec::new();
    for a in 0..n {
        for b in a + 1..n {
            let has_tracks = |x: usize| node_at[x].iter().any(|&p| p);
            if has_tracks(a)
                && has_tracks(b)
                && !(0..ks.len()).any(|i| node_at[a][i] && node_at[b][i])
            {
                apart.push((a, b));
            }
        }
    }
    report.node_pairs_without_common_instant = apart.len();
    let present: Vec<&Track> = scene
        .nodes()
        .iter()
        .flatten()
        .filter(|t| ks.clone().any(|k| t.is_present(k)))
        .collect();
    let alone = present
        .iter()
        .filter(|t| {
            !ks.clone()
                .enumerate()
                .any(|(i, k)| t.is_present(k) && busy[i] >= 2)
        })
        .count();
    report.tracks_without_partner_instant = alone;
    let fix = match report.mode {
        "grid" => "raise alignment.max_staleness_s (or alignment.period_s)",
        "interpolate" => "raise alignment.max_gap_s, or use the default grid alignment",
        _ => {
            "use the default grid alignment (alignment.mode: grid), or raise alignment.tolerance_s to the scan offset"
        }
    };
    if !apart.is_empty() {
        let names: Vec<String> = apart
            .iter()
            .take(5)
            .map(|&(a, b)| format!("{}–{}", node_ids[a], node_ids[b]))
            .collect();
        warnings.push(format!(
            "{} node pair(s) share no instant where both hold a track ({}{}) under the {} \
             alignment, so they cannot correlate: {fix}",
            apart.len(),
            names.join(", "),
            if apart.len() > 5 { ", …" } else { "" },
            report.mode
        ));
    } else if alone * 2 > present.len() {
        warnings.push(format!(
            "{alone} of {} tracks are present at no instant where another node holds a track, \
             so they cannot correlate under the {} alignment: {fix}",
            present.len(),
            report.mode
        ));
    }
}
