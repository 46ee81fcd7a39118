//! What an experiment writes: a Markdown report, a CSV of the raw per-run
//! figures and SVG line plots, all produced by hand (no plotting or CSV
//! crates): `DIR/<name>.md`, `DIR/<name>.csv`, `DIR/<name>-<plot>.svg`.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use super::SimError;

/// The outputs of one experiment.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Report {
    /// The Markdown report (title, settings, tables, notes).
    pub markdown: String,
    /// Raw per-run figures, header line first.
    pub csv: String,
    /// Plots as `(suffix, svg)`; written to `<name>-<suffix>.svg`.
    pub plots: Vec<(String, String)>,
}

impl Report {
    /// Writes the files into `dir` (created if needed) and returns their paths.
    pub fn write(&self, dir: &Path, name: &str) -> Result<Vec<PathBuf>, SimError> {
        std::fs::create_dir_all(dir)?;
        let mut out = Vec::new();
        let md = dir.join(format!("{name}.md"));
        std::fs::write(&md, &self.markdown)?;
        out.push(md);
        let csv = dir.join(format!("{name}.csv"));
        std::fs::write(&csv, &self.csv)?;
        out.push(csv);
        for (suffix, svg) in &self.plots {
            let p = dir.join(format!("{name}-{suffix}.svg"));
            std::fs::write(&p, svg)?;
            out.push(p);
        }
        Ok(out)
    }
}

/// A Markdown table from a header and rows of cells.
pub fn markdown_table(header: &[&str], rows: &[Vec<String>]) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "| {} |", header.join(" | "));
    let _ = writeln!(
        s,
        "|{}|",
        header.iter().map(|_| "---").collect::<Vec<_>>().join("|")
    );
    for r in rows {
        let _ = writeln!(s, "| {} |", r.join(" | "));
    }
    s
}

/// One line of a plot.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend entry.
    pub name: String,
    /// `(x, y)` points, drawn in order.
    pub points: Vec<(f64, f64)>,
    /// Dashed line (for reference values such as bounds).
    pub dashed: bool,
}

/// A line plot.
#[derive(Debug, Clone, PartialEq)]
pub struct LinePlot {
    /// Title above the plot.
    pub title: String,
    /// Label of the x axis.
    pub x_label: String,
    /// Label of the y axis.
    pub y_label: String,
    /// The lines.
    pub series: Vec<Series>,
    /// Fixed y range; `None` fits the data (with 0 included).
    pub y_range: Option<(f64, f64)>,
}

const COLOURS: [&str; 8] = [
    "#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f",
];

impl LinePlot {
    /// The plot as a standalone 720x440 SVG document.
    pub fn to_svg(&self) -> String {
        // The legend column is as wide as its longest entry (about 7 px a
        // character at 12 px), the plot area 480 × 350.
        let longest = self
            .series
            .iter()
            .map(|s| s.name.chars().count())
            .max()
            .unwrap_or(0);
        let (left, top, bottom) = (70.0, 40.0, 50.0);
        let right = (50.0 + 7.0 * longest as f64).max(120.0);
        let (pw, ph) = (480.0, 350.0);
        let (w, h) = (left + pw + right, top + ph + bottom);
        let pts = self.series.iter().flat_map(|s| s.points.iter());
        let finite: Vec<(f64, f64)> = pts
            .copied()
            .filter(|(x, y)| x.is_finite() && y.is_finite())
            .collect();
        let (x0, x1) = min_max(finite.iter().map(|p| p.0)).unwrap_or((0.0, 1.0));
        let (x0, x1, x_step) = nice_axis(x0, x1, true);
        let (y0, y1, y_step) = match self.y_range {
            Some((a, b)) => nice_axis(a, b, false),
            None => {
                let (a, b) = min_max(finite.iter().map(|p| p.1)).unwrap_or((0.0, 1.0));
                nice_axis(a.min(0.0), b * 1.05, true)
            }
        };
        let sx = |x: f64| left + (x - x0) / (x1 - x0) * pw;
        let sy = |y: f64| top + (1.0 - (y.clamp(y0, y1) - y0) / (y1 - y0)) * ph;
        let mut s = String::new();
        let _ = writeln!(
            s,
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}" font-family="sans-serif" font-size="12">"#
        );
        let _ = writeln!(s, r#"<rect width="{w}" height="{h}" fill="white"/>"#);
        let _ = writeln!(
            s,
            r#"<text x="{}" y="22" text-anchor="middle" font-size="14">{}</text>"#,
            left + pw / 2.0,
            escape(&self.title)
        );
        // Axes box and ticks at round values.
        let _ = writeln!(
            s,
            r##"<rect x="{left}" y="{top}" width="{pw}" height="{ph}" fill="none" stroke="#333"/>"##
        );
        for fx in ticks(x0, x1, x_step) {
            let px = sx(fx);
            let _ = writeln!(
                s,
                r##"<line x1="{px:.1}" y1="{top}" x2="{px:.1}" y2="{}" stroke="#ddd"/><text x="{px:.1}" y="{}" text-anchor="middle">{}</text>"##,
                top + ph,
                top + ph + 16.0,
                tick_label(fx, x_step)
            );
        }
        for fy in ticks(y0, y1, y_step) {
            let py = sy(fy);
            let _ = writeln!(
                s,
                r##"<line x1="{left}" y1="{py:.1}" x2="{}" y2="{py:.1}" stroke="#ddd"/><text x="{}" y="{:.1}" text-anchor="end">{}</text>"##,
                left + pw,
                left - 6.0,
                py + 4.0,
                tick_label(fy, y_step)
            );
        }
        let _ = writeln!(
            s,
            r#"<text x="{}" y="{}" text-anchor="middle">{}</text>"#,
            left + pw / 2.0,
            h - 12.0,
            escape(&self.x_label)
        );
        let _ = writeln!(
            s,
            r#"<text x="16" y="{}" text-anchor="middle" transform="rotate(-90 16 {})">{}</text>"#,
            top + ph / 2.0,
            top + ph / 2.0,
            escape(&self.y_label)
        );
        for (k, series) in self.series.iter().enumerate() {
            let colour = COLOURS[k % COLOURS.len()];
            let path: Vec<String> = series
                .points
                .iter()
                .filter(|(x, y)| x.is_finite() && y.is_finite())
                .map(|&(x, y)| format!("{:.1},{:.1}", sx(x), sy(y)))
                .collect();
            let dash = if series.dashed {
                r#" stroke-dasharray="6 4""#
            } else {
                ""
            };
            let _ = writeln!(
                s,
                r#"<polyline fill="none" stroke="{colour}" stroke-width="1.8"{dash} points="{}"/>"#,
                path.join(" ")
            );
            let ly = top + 14.0 + 18.0 * k as f64;
            let lx = left + pw + 10.0;
            let _ = writeln!(
                s,
                r#"<line x1="{lx}" y1="{ly}" x2="{}" y2="{ly}" stroke="{colour}" stroke-width="2"{dash}/><text x="{}" y="{}">{}</text>"#,
                lx + 22.0,
                lx + 28.0,
                ly + 4.0,
                escape(&series.name)
            );
        }
        s.push_str("</svg>\n");
        s
    }
}

fn min_max(it: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    it.fold(None, |acc, v| match acc {
        None => Some((v, v)),
        Some((a, b)) => Some((a.min(v), b.max(v))),
    })
}

/// A round tick step (1, 2, 2.5 or 5 times a power of ten) giving about
/// five intervals over [lo, hi], and the range widened to multiples of it
/// when `widen` (a fixed range is kept).
fn nice_axis(lo: f64, hi: f64, widen: bool) -> (f64, f64, f64) {
    let (lo, hi) = if hi > lo {
        (lo, hi)
    } else {
        (lo - 0.5, hi + 0.5)
    };
    let raw = (hi - lo) / 5.0;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 2.5, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|&s| s >= raw * (1.0 - 1e-9))
        .unwrap_or(10.0 * mag);
    if widen {
        (
            (lo / step + 1e-9).floor() * step,
            (hi / step - 1e-9).ceil() * step,
            step,
        )
    } else {
        (lo, hi, step)
    }
}

/// The multiples of `step` in [lo, hi].
fn ticks(lo: f64, hi: f64, step: f64) -> Vec<f64> {
    let first = (lo / step - 1e-9).ceil() as i64;
    let last = (hi / step + 1e-9).floor() as i64;
    (first..=last).map(|i| i as f64 * step).collect()
}

/// A tick's label with as many decimals as its step needs.
fn tick_label(v: f64, step: f64) -> String {
    let a = step.abs();
    if a != 0.0 && !(1e-4..1e6).contains(&a) {
        return format!("{v:.1e}");
    }
    // Decimals of the step (2.5e-k needs one more than 1e-k).
    let decimals = (0..6)
        .find(|&d| {
            let scaled = step * 10f64.powi(d);
            (scaled - scaled.round()).abs() < 1e-6 * scaled.abs().max(1.0)
        })
        .unwrap_or(6) as usize;
    let v = if v.abs() < step * 1e-9 { 0.0 } else { v };
    format!("{v:.decimals$}")
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axes_get_round_ticks_and_the_legend_fits() {
        // Data up to 61.7 (×1.05 = 64.8): ticks every 20 up to 80, not at
        // 12.96, 25.9, …, 64.8.
        assert_eq!(nice_axis(0.0, 64.8, true), (0.0, 80.0, 20.0));
        assert_eq!(ticks(0.0, 80.0, 20.0), vec![0.0, 20.0, 40.0, 60.0, 80.0]);
        assert_eq!(nice_axis(-3.0, 34.4, true), (-10.0, 40.0, 10.0));
        assert_eq!(nice_axis(0.0, 1.0, false).2, 0.2);
        assert_eq!(nice_axis(0.0, 12.0, true).2, 2.5);
        assert_eq!(tick_label(7.5, 2.5), "7.5");
        assert_eq!(tick_label(0.30000000000000004, 0.1), "0.3");
        assert_eq!(tick_label(40.0, 10.0), "40");
        let name = "clusters 0.5 s (a rather long legend entry)";
        let plot = LinePlot {
            title: "t".into(),
            x_label: "x".into(),
            y_label: "y".into(),
            series: vec![Series {
                name: name.into(),
                points: vec![(0.0, 1.0), (1.0, 2.0)],
                dashed: false,
            }],
            y_range: None,
        };
        let svg = plot.to_svg();
        let width: f64 = svg
            .split("width=\"")
            .nth(1)
            .and_then(|r| r.split('"').next())
            .unwrap()
            .parse()
            .unwrap();
        // The entry starts 28 px right of the plot's edge + 10 and needs
        // about 7 px a character.
        assert!(
            width >= 70.0 + 480.0 + 38.0 + 7.0 * name.len() as f64 - 1.0,
            "{width}"
        );
    }

    #[test]
    fn table_and_svg_are_well_formed() {
        let t = markdown_table(&["a", "b"], &[vec!["1".into(), "2".into()]]);
        assert_eq!(t, "| a | b |\n|---|---|\n| 1 | 2 |\n");
        let plot = LinePlot {
            title: "E_c < 1 & more".into(),
            x_label: "t (s)".into(),
            y_label: "rate".into(),
            series: vec![Series {
                name: "m".into(),
                points: vec![(0.0, 0.5), (4.0, 0.75), (8.0, f64::NAN)],
                dashed: false,
            }],
            y_range: Some((0.0, 1.0)),
        };
        let svg = plot.to_svg();
        assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"));
        assert!(svg.contains("E_c &lt; 1 &amp; more"));
        // Round ticks: y 0, 0.2, …, 1 on the fixed range; x 0, 1, …, 4
        // (the finite points span 0–4), not 0, 0.8, 1.6, ….
        assert!(svg.contains(">0.2</text>") && svg.contains(">0.6</text>"));
        assert!(svg.contains(">3</text>") && !svg.contains(">1.6</text>"));
        // Two finite points on the polyline, the NaN dropped.
        let line = svg.lines().find(|l| l.starts_with("<polyline")).unwrap();
        let points = line.split("points=\"").nth(1).unwrap();
        assert_eq!(points.split_whitespace().count(), 2);
    }
}
