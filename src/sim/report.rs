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
        let (w, h) = (720.0, 440.0);
        let (left, right, top, bottom) = (70.0, 170.0, 40.0, 50.0);
        let pts = self.series.iter().flat_map(|s| s.points.iter());
        let finite: Vec<(f64, f64)> = pts
            .copied()
            .filter(|(x, y)| x.is_finite() && y.is_finite())
            .collect();
        let (mut x0, mut x1) = min_max(finite.iter().map(|p| p.0)).unwrap_or((0.0, 1.0));
        let (mut y0, mut y1) = self.y_range.unwrap_or_else(|| {
            let (a, b) = min_max(finite.iter().map(|p| p.1)).unwrap_or((0.0, 1.0));
            (a.min(0.0), b * 1.05)
        });
        if x1 <= x0 {
            x0 -= 0.5;
            x1 += 0.5;
        }
        if y1 <= y0 {
            y0 -= 0.5;
            y1 += 0.5;
        }
        let pw = w - left - right;
        let ph = h - top - bottom;
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
        // Axes box and ticks.
        let _ = writeln!(
            s,
            r##"<rect x="{left}" y="{top}" width="{pw}" height="{ph}" fill="none" stroke="#333"/>"##
        );
        for i in 0..=5 {
            let fx = x0 + (x1 - x0) * i as f64 / 5.0;
            let fy = y0 + (y1 - y0) * i as f64 / 5.0;
            let (px, py) = (sx(fx), sy(fy));
            let _ = writeln!(
                s,
                r##"<line x1="{px:.1}" y1="{top}" x2="{px:.1}" y2="{}" stroke="#ddd"/><text x="{px:.1}" y="{}" text-anchor="middle">{}</text>"##,
                top + ph,
                top + ph + 16.0,
                tick(fx)
            );
            let _ = writeln!(
                s,
                r##"<line x1="{left}" y1="{py:.1}" x2="{}" y2="{py:.1}" stroke="#ddd"/><text x="{}" y="{:.1}" text-anchor="end">{}</text>"##,
                left + pw,
                left - 6.0,
                py + 4.0,
                tick(fy)
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

fn tick(v: f64) -> String {
    let a = v.abs();
    if a != 0.0 && !(1e-3..1e5).contains(&a) {
        format!("{v:.1e}")
    } else if a >= 100.0 {
        format!("{v:.0}")
    } else {
        let s = format!("{v:.3}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    }
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
        // Two finite points on the polyline, the NaN dropped.
        let line = svg.lines().find(|l| l.starts_with("<polyline")).unwrap();
        let points = line.split("points=\"").nth(1).unwrap();
        assert_eq!(points.split_whitespace().count(), 2);
    }
}
