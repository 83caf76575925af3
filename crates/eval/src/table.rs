//! Table 1 of the paper as text: rows = methods, columns = the test splits ("mean ± std" of the
//! per-AOI median altitude MAE, metres) and their average.

use super::aggregate::{SplitStat, Table};

/// "mean ± std", "mean ± –" with a single AOI, "–" without data.
pub fn format_stat(s: Option<&SplitStat>) -> String {
    match s {
        None => "–".to_string(),
        Some(s) => match s.std {
            Some(d) => format!("{:.2} ± {:.2}", s.mean, d),
            None => format!("{:.2} ± –", s.mean),
        },
    }
}

fn format_avg(v: Option<f64>) -> String {
    v.map_or("–".to_string(), |v| format!("{v:.2}"))
}

impl Table {
    fn cells(&self) -> (Vec<String>, Vec<Vec<String>>) {
        let mut header = vec!["Method".to_string()];
        header.extend(self.columns.iter().map(|c| c.title.clone()));
        header.push("Avg. MAE".to_string());
        let mut body = Vec::new();
        for r in &self.rows {
            let mut line = vec![r.method.clone()];
            line.extend(r.splits.iter().map(|s| format_stat(s.as_ref())));
            line.push(format_avg(r.average));
            body.push(line);
            // Coverage beside the MAE: the benchmark's number alone rewards holes.
            if r.splits.iter().flatten().any(|s| s.coverage.is_some()) {
                let mut cov = vec![format!("{} (coverage)", r.method)];
                cov.extend(r.splits.iter().map(|s| {
                    s.as_ref()
                        .and_then(|s| s.coverage)
                        .map_or("–".to_string(), |c| format!("{:.1} %", 100.0 * c))
                }));
                cov.push(String::new());
                body.push(cov);
            }
        }
        (header, body)
    }

    /// Aligned plain text, for the terminal.
    pub fn to_text(&self) -> String {
        let (header, body) = self.cells();
        let n = header.len();
        let width: Vec<usize> = (0..n)
            .map(|i| {
                std::iter::once(&header)
                    .chain(&body)
                    .map(|l| l[i].chars().count())
                    .max()
                    .unwrap_or(0)
            })
            .collect();
        let line = |cells: &[String]| {
            cells
                .iter()
                .enumerate()
                .map(|(i, c)| {
                    let pad = width[i] - c.chars().count();
                    if i == 0 {
                        format!("{c}{}", " ".repeat(pad))
                    } else {
                        format!("{}{c}", " ".repeat(pad))
                    }
                })
                .collect::<Vec<_>>()
                .join("  ")
        };
        let total = width.iter().sum::<usize>() + 2 * (n - 1);
        let mut out = String::from("Altitude MAE (m), filtered (foliage and water masked): mean ± sample std over AOIs of the per-AOI median; (coverage): mean share of the truth's cells with a height\n");
        out += &line(&header);
        out.push('\n');
        out += &"-".repeat(total);
        out.push('\n');
        for l in &body {
            out += &line(l);
            out.push('\n');
        }
        out
    }

    /// A markdown table with a short legend.
    pub fn to_markdown(&self) -> String {
        let (header, body) = self.cells();
        let mut out = String::from(
            "Altitude MAE (m) of the DSMs from the predicted disparities, foliage and water masked \
             (`mae_filtered`); per split: mean ± sample std over AOIs of the per-AOI median pair \
             MAE; Avg. MAE: mean over the splits present; rows \"(coverage)\": mean share of the \
             truth's cells with a height over the pairs (an MAE alone rewards holes).\n\n",
        );
        out += &format!("| {} |\n", header.join(" | "));
        out += &format!(
            "|{}\n",
            (0..header.len())
                .map(|i| if i == 0 { ":---|" } else { "---:|" })
                .collect::<String>()
        );
        for l in &body {
            out += &format!("| {} |\n", l.join(" | "));
        }
        out
    }
}
