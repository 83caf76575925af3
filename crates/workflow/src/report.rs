//! A small self-contained HTML report: headings, figures, tables and SVG histograms. Images are
//! referenced by relative path so the report folder can be moved or zipped as a whole.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Context, Result};

/// An HTML page built section by section.
pub struct Report {
    title: String,
    body: String,
}

/// Escapes text for HTML.
pub fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

impl Report {
    pub fn new(title: &str) -> Self {
        Report {
            title: title.to_string(),
            body: String::new(),
        }
    }

    pub fn heading(&mut self, text: &str) -> &mut Self {
        let _ = writeln!(self.body, "<h2>{}</h2>", escape(text));
        self
    }

    pub fn paragraph(&mut self, text: &str) -> &mut Self {
        let _ = writeln!(self.body, "<p>{}</p>", escape(text));
        self
    }

    /// A row of images (relative paths) with captions.
    pub fn figures(&mut self, items: &[(&str, &str)]) -> &mut Self {
        self.body.push_str("<div class=\"row\">\n");
        for (src, caption) in items {
            let _ = writeln!(
                self.body,
                "<figure><img src=\"{}\" alt=\"{c}\"><figcaption>{c}</figcaption></figure>",
                escape(src),
                c = escape(caption)
            );
        }
        self.body.push_str("</div>\n");
        self
    }

    /// A table with a header row.
    pub fn table(&mut self, header: &[&str], rows: &[Vec<String>]) -> &mut Self {
        self.body.push_str("<table>\n<tr>");
        for h in header {
            let _ = write!(self.body, "<th>{}</th>", escape(h));
        }
        self.body.push_str("</tr>\n");
        for row in rows {
            self.body.push_str("<tr>");
            for cell in row {
                let _ = write!(self.body, "<td>{}</td>", escape(cell));
            }
            self.body.push_str("</tr>\n");
        }
        self.body.push_str("</table>\n");
        self
    }

    /// A histogram of `values` over [0, max] in `bins` bins, the last bin collecting everything above.
    pub fn histogram(&mut self, values: &[f32], max: f32, bins: usize, x_label: &str) -> &mut Self {
        self.body
            .push_str(&svg_histogram(&[("", values)], max, bins, x_label));
        self
    }

    /// Histograms of several named series on the same bins (side-by-side bars, each series as a
    /// share of its own finite values), with a legend.
    pub fn histograms(
        &mut self,
        series: &[(&str, &[f32])],
        max: f32,
        bins: usize,
        x_label: &str,
    ) -> &mut Self {
        self.body
            .push_str(&svg_histogram(series, max, bins, x_label));
        self
    }

    /// A block of preformatted text (commands), escaped.
    pub fn code(&mut self, text: &str) -> &mut Self {
        let _ = writeln!(self.body, "<pre><code>{}</code></pre>", escape(text));
        self
    }

    /// A line plot of one or more series against their index + 1 (e.g. scores sorted by rank),
    /// with an optional dashed vertical marker (e.g. the K of a top-K selection).
    pub fn line_plot(
        &mut self,
        series: &[(&str, &[f64])],
        x_label: &str,
        y_label: &str,
        marker_x: Option<f64>,
    ) -> &mut Self {
        self.body
            .push_str(&svg_line_plot(series, x_label, y_label, marker_x));
        self
    }

    /// Writes the page atomically.
    pub fn write(&self, path: &Path) -> Result<()> {
        let html = format!(
            "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{t}</title>\n<style>{STYLE}</style></head>\n<body><h1>{t}</h1>\n{}</body></html>\n",
            self.body,
            t = escape(&self.title)
        );
        raster::formats::write_atomically(path, |f| std::io::Write::write_all(f, html.as_bytes()))
            .with_context(|| format!("writing the report {}", path.display()))
    }
}

const STYLE: &str = "body{font-family:sans-serif;max-width:1400px;margin:2em auto;color:#222}\
.row{display:flex;flex-wrap:wrap;gap:12px}figure{margin:0}img{width:320px;image-rendering:pixelated;border:1px solid #ccc}\
figcaption{font-size:90%;text-align:center}table{border-collapse:collapse;margin:1em 0}\
td,th{border:1px solid #bbb;padding:4px 10px;text-align:right}th{background:#eee}\
pre{background:#f4f4f4;border:1px solid #ddd;padding:8px;overflow-x:auto;font-size:90%}";

fn svg_histogram(series: &[(&str, &[f32])], max: f32, bins: usize, x_label: &str) -> String {
    let bins = bins.max(1);
    let shares: Vec<Vec<f64>> = series
        .iter()
        .map(|(_, values)| {
            let mut counts = vec![0usize; bins];
            for &v in values.iter().filter(|v| v.is_finite()) {
                let i = if max > 0.0 {
                    ((v / max) * bins as f32) as usize
                } else {
                    bins - 1
                };
                counts[i.min(bins - 1)] += 1;
            }
            let total = counts.iter().sum::<usize>().max(1) as f64;
            counts.iter().map(|&c| c as f64 / total).collect()
        })
        .collect();
    let peak = shares
        .iter()
        .flatten()
        .copied()
        .fold(0.0f64, f64::max)
        .max(1e-12);
    let (w, h, left, bottom) = (600.0, 220.0, 50.0, 40.0);
    let bar = (w - left - 10.0) / bins as f64;
    let n = series.len().max(1) as f64;
    let mut svg =
        format!("<svg width=\"{w}\" height=\"{h}\" xmlns=\"http://www.w3.org/2000/svg\">\n");
    for (k, ((name, _), shares)) in series.iter().zip(&shares).enumerate() {
        let colour = SERIES_COLOURS[k % SERIES_COLOURS.len()];
        let label = if name.is_empty() {
            String::new()
        } else {
            format!("{}: ", escape(name))
        };
        for (i, &s) in shares.iter().enumerate() {
            let bh = (h - bottom - 10.0) * s / peak;
            let _ = writeln!(
                svg,
                "<rect x=\"{:.1}\" y=\"{:.1}\" width=\"{:.1}\" height=\"{:.1}\" fill=\"{colour}\"><title>{label}{:.1}%</title></rect>",
                left + i as f64 * bar + k as f64 * bar / n,
                h - bottom - bh,
                (bar / n - 1.0 / n).max(0.5),
                bh,
                100.0 * s
            );
        }
        if !name.is_empty() {
            let _ = writeln!(
                svg,
                "<text x=\"{:.1}\" y=\"{:.1}\" font-size=\"12\" fill=\"{colour}\" text-anchor=\"end\">{}</text>",
                w - 10.0,
                20.0 + 16.0 * k as f64,
                escape(name)
            );
        }
    }
    let _ = writeln!(
        svg,
        "<line x1=\"{left}\" y1=\"{y}\" x2=\"{x2}\" y2=\"{y}\" stroke=\"#222\"/>\
<text x=\"{left}\" y=\"{t}\" font-size=\"12\">0</text><text x=\"{x2}\" y=\"{t}\" font-size=\"12\" text-anchor=\"end\">≥{max}</text>\
<text x=\"{mid}\" y=\"{t}\" font-size=\"12\" text-anchor=\"middle\">{}</text>\
<text x=\"10\" y=\"20\" font-size=\"12\">share of pixels (peak {:.1}%)</text></svg>",
        escape(x_label),
        100.0 * peak,
        y = h - bottom,
        x2 = w - 10.0,
        t = h - bottom + 20.0,
        mid = (left + w - 10.0) / 2.0,
    );
    svg
}

const SERIES_COLOURS: [&str; 4] = ["#4a7bd0", "#d0674a", "#3a9a5a", "#8a5ac0"];

fn svg_line_plot(
    series: &[(&str, &[f64])],
    x_label: &str,
    y_label: &str,
    marker_x: Option<f64>,
) -> String {
    let finite = || {
        series
            .iter()
            .flat_map(|(_, v)| v.iter().copied().filter(|v| v.is_finite()))
    };
    let n = series
        .iter()
        .map(|(_, v)| v.len())
        .max()
        .unwrap_or(0)
        .max(1) as f64;
    let lo = finite().fold(f64::INFINITY, f64::min);
    let hi = finite().fold(f64::NEG_INFINITY, f64::max);
    let (lo, hi) = if lo.is_finite() && hi > lo {
        (lo, hi)
    } else if lo.is_finite() {
        (lo - 0.5, lo + 0.5)
    } else {
        (0.0, 1.0)
    };
    let (w, h, left, bottom, top, right) = (640.0, 260.0, 60.0, 40.0, 24.0, 110.0);
    let px = |i: f64| left + (w - left - right) * (i - 1.0) / (n - 1.0).max(1.0);
    let py = |v: f64| h - bottom - (h - bottom - top) * (v - lo) / (hi - lo);
    let mut svg =
        format!("<svg width=\"{w}\" height=\"{h}\" xmlns=\"http://www.w3.org/2000/svg\">\n");
    for (k, (name, values)) in series.iter().enumerate() {
        let colour = SERIES_COLOURS[k % SERIES_COLOURS.len()];
        let points: Vec<String> = values
            .iter()
            .enumerate()
            .filter(|(_, v)| v.is_finite())
            .map(|(i, &v)| format!("{:.1},{:.1}", px(i as f64 + 1.0), py(v)))
            .collect();
        let _ = writeln!(
            svg,
            "<polyline fill=\"none\" stroke=\"{colour}\" stroke-width=\"1.5\" points=\"{}\"/>\
<text x=\"{:.1}\" y=\"{:.1}\" font-size=\"12\" fill=\"{colour}\">{}</text>",
            points.join(" "),
            w - right + 8.0,
            top + 16.0 * (k as f64 + 1.0),
            escape(name)
        );
    }
    if let Some(m) = marker_x.filter(|m| m.is_finite()) {
        let x = px(m.clamp(1.0, n));
        let _ = writeln!(
            svg,
            "<line x1=\"{x:.1}\" y1=\"{top}\" x2=\"{x:.1}\" y2=\"{:.1}\" stroke=\"#888\" stroke-dasharray=\"4 3\"/>\
<text x=\"{x:.1}\" y=\"{:.1}\" font-size=\"11\" text-anchor=\"middle\">{m}</text>",
            h - bottom,
            top - 6.0
        );
    }
    let _ = writeln!(
        svg,
        "<line x1=\"{left}\" y1=\"{yb}\" x2=\"{xr}\" y2=\"{yb}\" stroke=\"#222\"/>\
<line x1=\"{left}\" y1=\"{top}\" x2=\"{left}\" y2=\"{yb}\" stroke=\"#222\"/>\
<text x=\"{left}\" y=\"{t}\" font-size=\"12\">1</text>\
<text x=\"{xr}\" y=\"{t}\" font-size=\"12\" text-anchor=\"end\">{n}</text>\
<text x=\"{mid}\" y=\"{t}\" font-size=\"12\" text-anchor=\"middle\">{}</text>\
<text x=\"{lx}\" y=\"{yb}\" font-size=\"11\" text-anchor=\"end\">{lo:.3}</text>\
<text x=\"{lx}\" y=\"{ty}\" font-size=\"11\" text-anchor=\"end\">{hi:.3}</text>\
<text x=\"4\" y=\"14\" font-size=\"12\">{}</text></svg>",
        escape(x_label),
        escape(y_label),
        yb = h - bottom,
        xr = w - right,
        t = h - bottom + 20.0,
        mid = (left + w - right) / 2.0,
        lx = left - 4.0,
        ty = top + 4.0,
    );
    svg
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn report_escapes_and_counts() {
        let mut r = Report::new("a <b>");
        r.table(&["k"], &[vec!["x&y".into()]])
            .histogram(&[0.1, 0.2, 5.0, f32::NAN], 1.0, 4, "err");
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("r.html");
        r.write(&path).unwrap();
        let html = std::fs::read_to_string(path).unwrap();
        assert!(html.contains("a &lt;b&gt;") && html.contains("x&amp;y"));
        // 0.1 and 0.2 fall in the first bin (2 of 3 finite values), 5.0 in the last.
        assert!(html.contains("<title>66.7%</title>") && html.contains("<title>33.3%</title>"));
    }

    #[test]
    fn histograms_share_bins_and_code_is_escaped() {
        let mut r = Report::new("t");
        r.histograms(
            &[("a", &[0.1, 0.1, 0.9]), ("b <2>", &[0.9, f32::NAN])],
            1.0,
            2,
            "err",
        )
        .code("x < y && z");
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("r.html");
        r.write(&path).unwrap();
        let html = std::fs::read_to_string(path).unwrap();
        // Each series is a share of its own finite values, bars named by their series.
        for t in [
            "a: 66.7%",
            "a: 33.3%",
            "b &lt;2&gt;: 0.0%",
            "b &lt;2&gt;: 100.0%",
        ] {
            assert!(html.contains(&format!("<title>{t}</title>")), "{t}");
        }
        assert_eq!(html.matches("<rect").count(), 4);
        assert!(html.contains("<pre><code>x &lt; y &amp;&amp; z</code></pre>"));
    }
}
