//! Experiment lists: the release's `experiments/<name>.csv` with a `filename` column (`<stem>.npy`)
//! and an optional `diachronic` column.

use std::collections::HashSet;
use std::io::Write;
use std::path::Path;

use crate::stem::PairStem;
use crate::{DatasetError, Result};

/// One line of an experiment list.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ExperimentRow {
    pub stem: PairStem,
    /// The `diachronic` column when present (else derive it with [`PairStem::is_diachronic`]).
    pub diachronic: Option<bool>,
}

impl ExperimentRow {
    /// A row for `stem` with its diachronic flag.
    pub fn of(stem: PairStem) -> Self {
        let diachronic = Some(stem.is_diachronic());
        ExperimentRow { stem, diachronic }
    }

    /// The flag, derived from the tags when the column was absent.
    pub fn is_diachronic(&self) -> bool {
        self.diachronic.unwrap_or_else(|| self.stem.is_diachronic())
    }
}

/// The release's boolean parsing (`true/1/yes/y`, `false/0/no/n`, empty = absent).
fn parse_bool(s: &str) -> Option<std::result::Result<bool, ()>> {
    match s.trim().to_ascii_lowercase().as_str() {
        "" => None,
        "true" | "1" | "yes" | "y" => Some(Ok(true)),
        "false" | "0" | "no" | "n" => Some(Ok(false)),
        _ => Some(Err(())),
    }
}

/// The stem of a `filename` entry: the file name without its last extension (as Python's
/// `Path(filename).stem`).
fn stem_of(filename: &str) -> &str {
    let name = filename.rsplit('/').next().unwrap_or(filename);
    match name.rfind('.') {
        Some(i) if i > 0 => &name[..i],
        _ => name,
    }
}

/// Reads a text file the stages write; a missing one is an error that says which stage writes it
/// (`hint`).
pub(crate) fn read_text(path: &Path, hint: &str) -> Result<String> {
    std::fs::read_to_string(path).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => DatasetError::missing(path, hint),
        _ => DatasetError::io(path, e),
    })
}

/// A CSV reader over `text` (cells trimmed) and its header row; errors name `path`.
fn csv_with_headers<'t>(
    path: &Path,
    text: &'t str,
) -> Result<(csv::Reader<&'t [u8]>, csv::StringRecord)> {
    let mut reader = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .from_reader(text.as_bytes());
    let headers = reader
        .headers()
        .map_err(|e| DatasetError::format(path, e.to_string()))?
        .clone();
    Ok((reader, headers))
}

/// Reads an experiment list. As the release: duplicate stems are dropped (first kept) and blank
/// filenames skipped; unlike it, a malformed stem or flag is an error naming the line.
pub fn read_experiment_csv(path: &Path) -> Result<Vec<ExperimentRow>> {
    let text = read_text(
        path,
        "write experiment lists with `seasonstereo dataset build` or `dataset world`",
    )?;
    let (mut reader, headers) = csv_with_headers(path, &text)?;
    let col = |name: &str| headers.iter().position(|h| h == name);
    let file_col = col("filename")
        .ok_or_else(|| DatasetError::format(path, "must contain at least a 'filename' column"))?;
    let diach_col = col("diachronic");
    let mut seen = HashSet::new();
    let mut rows = Vec::new();
    for (i, record) in reader.records().enumerate() {
        let line = i + 2;
        let record = record.map_err(|e| DatasetError::format(path, format!("line {line}: {e}")))?;
        let filename = record.get(file_col).unwrap_or("").trim();
        if filename.is_empty() {
            continue;
        }
        let stem = PairStem::parse(stem_of(filename))
            .map_err(|e| DatasetError::format(path, format!("line {line}: {e}")))?;
        let diachronic = match diach_col.and_then(|c| record.get(c)).and_then(parse_bool) {
            None => None,
            Some(Ok(b)) => Some(b),
            Some(Err(())) => {
                return Err(DatasetError::format(
                    path,
                    format!("line {line}: cannot read a boolean from the diachronic column"),
                ))
            }
        };
        if seen.insert(stem.to_string()) {
            rows.push(ExperimentRow { stem, diachronic });
        }
    }
    Ok(rows)
}

/// Writes an experiment list `filename,diachronic` (`<stem>.npy`, `True`/`False`) atomically.
pub fn write_experiment_csv(path: &Path, rows: &[ExperimentRow]) -> Result<()> {
    raster::formats::write_atomically(path, |w| {
        writeln!(w, "filename,diachronic")?;
        for r in rows {
            let flag = if r.is_diachronic() { "True" } else { "False" };
            writeln!(w, "{}.{},{flag}", r.stem, crate::layout::IMAGE_EXT)?;
        }
        Ok(())
    })?;
    Ok(())
}

/// Writes one AOI per line (the release's `train_aois.csv` / `val_aois.csv`), sorted, unique.
pub fn write_aois(path: &Path, stems: &[PairStem]) -> Result<()> {
    let aois: std::collections::BTreeSet<&str> = stems.iter().map(PairStem::aoi).collect();
    raster::formats::write_atomically(path, |w| {
        for a in aois {
            writeln!(w, "{a}")?;
        }
        Ok(())
    })?;
    Ok(())
}

/// Reads a list of pairs: a text file of stems (one per line, `#` comments, curate's
/// `selected.txt`) or a CSV with a stem column (`id` as curate's `selected.csv`, `stem`, `pair` or
/// `filename`). Only real pairs are accepted; duplicates are dropped, order is kept.
pub fn read_pair_list(path: &Path) -> Result<Vec<PairStem>> {
    let text = read_text(
        path,
        "the selected pairs are written by `seasonstereo curate`",
    )?;
    let is_csv = path.extension().and_then(|e| e.to_str()) == Some("csv");
    let mut names: Vec<(usize, String)> = Vec::new();
    if is_csv {
        let (mut reader, headers) = csv_with_headers(path, &text)?;
        let col = ["id", "stem", "pair", "filename"]
            .iter()
            .find_map(|c| headers.iter().position(|h| h == *c))
            .ok_or_else(|| {
                DatasetError::format(path, "needs a pair column: id, stem, pair or filename")
            })?;
        for (i, r) in reader.records().enumerate() {
            let r = r.map_err(|e| DatasetError::format(path, format!("line {}: {e}", i + 2)))?;
            let v = r.get(col).unwrap_or("").trim();
            let v = if headers.get(col) == Some("filename") {
                stem_of(v)
            } else {
                v
            };
            names.push((i + 2, v.to_string()));
        }
    } else {
        for (i, l) in text.lines().enumerate() {
            names.push((i + 1, l.trim().to_string()));
        }
    }
    let mut seen = HashSet::new();
    let mut out = Vec::new();
    for (line, n) in names {
        if n.is_empty() || n.starts_with('#') {
            continue;
        }
        let s = PairStem::parse(&n)
            .map_err(|e| DatasetError::format(path, format!("line {line}: {e}")))?;
        if !s.is_real() {
            return Err(DatasetError::format(
                path,
                format!("line {line}: {s} is not a real pair (no __tag expected in a pair list)"),
            ));
        }
        if seen.insert(s.clone()) {
            out.push(s);
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_release_rules() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("e.csv");
        let rows = vec![
            ExperimentRow::of(PairStem::parse("A-B").unwrap()),
            ExperimentRow::of(PairStem::parse("A__winter-B").unwrap()),
        ];
        write_experiment_csv(&p, &rows).unwrap();
        let text = std::fs::read_to_string(&p).unwrap();
        assert_eq!(
            text,
            "filename,diachronic\nA-B.npy,False\nA__winter-B.npy,True\n"
        );
        assert_eq!(read_experiment_csv(&p).unwrap(), rows);

        // Filename-only lists (build_experiment_csv.py), duplicates and blank lines.
        std::fs::write(
            &p,
            "filename\nA-B.npy\n\nA-B.npy\nA__summer-B__summer.npy\n",
        )
        .unwrap();
        let r = read_experiment_csv(&p).unwrap();
        assert_eq!(r.len(), 2);
        assert_eq!(r[1].diachronic, None);
        assert!(!r[1].is_diachronic());
    }

    #[test]
    fn errors_name_the_problem() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("e.csv");
        std::fs::write(&p, "name\nA-B.npy\n").unwrap();
        assert!(read_experiment_csv(&p)
            .unwrap_err()
            .to_string()
            .contains("filename"));
        std::fs::write(&p, "filename,diachronic\nA-B.npy,maybe\n").unwrap();
        assert!(read_experiment_csv(&p)
            .unwrap_err()
            .to_string()
            .contains("line 2"));
        std::fs::write(&p, "filename\nAB.npy\n").unwrap();
        assert!(read_experiment_csv(&p).is_err());
        let missing = read_experiment_csv(&dir.path().join("none.csv")).unwrap_err();
        assert!(missing.to_string().contains("dataset build"), "{missing}");
    }

    #[test]
    fn pair_lists_from_curate() {
        let dir = tempfile::tempdir().unwrap();
        let txt = dir.path().join("selected.txt");
        std::fs::write(&txt, "A-B\n# note\n\nC-D\nA-B\n").unwrap();
        let l = read_pair_list(&txt).unwrap();
        assert_eq!(l, vec![PairStem::real("A", "B"), PairStem::real("C", "D")]);
        let csv = dir.path().join("selected.csv");
        std::fs::write(&csv, "id,left,right\nC-D,L/C-D.iio,R/C-D.iio\n").unwrap();
        assert_eq!(
            read_pair_list(&csv).unwrap(),
            vec![PairStem::real("C", "D")]
        );
        std::fs::write(&txt, "A__winter-B\n").unwrap();
        assert!(read_pair_list(&txt)
            .unwrap_err()
            .to_string()
            .contains("line 1"));
    }
}
