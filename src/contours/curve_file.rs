//! Curves as CSV files: one "x,y" pair a line, an optional header line.

use nalgebra::Point2;
use std::path::{Path, PathBuf};

/// Why a curve file cannot be read.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CurveFileError {
    /// The file cannot be read.
    #[error("{path}: cannot read: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A line that is not a point.
    #[error("{path}: line {line}: {reason}: {text:?}")]
    Line {
        /// The file.
        path: PathBuf,
        /// The line.
        line: usize,
        /// What is wrong.
        reason: String,
        /// The line's text.
        text: String,
    },
    /// Fewer than three points.
    #[error("{path}: {count} points; a curve needs at least 3{}", skipped_note(*.skipped))]
    TooFew {
        /// The file.
        path: PathBuf,
        /// Its points.
        count: usize,
        /// Lines before the first point read as a header (no field a number).
        skipped: usize,
    },
}

/// How many leading lines were taken for a header, when any were.
fn skipped_note(skipped: usize) -> String {
    match skipped {
        0 => String::new(),
        1 => " (its first line has no number and was read as a header)".into(),
        n => format!(" ({n} lines without a number were read as a header)"),
    }
}

/// Read x,y points. The first line may be a header (any line whose fields are not numbers).
pub fn read_curve_csv(path: &Path) -> Result<Vec<Point2<f64>>, CurveFileError> {
    let text = std::fs::read_to_string(path).map_err(|source| CurveFileError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let mut pts = Vec::new();
    let mut skipped = 0;
    // A byte-order mark (spreadsheets write one) would make the first point a "header".
    let text = text.strip_prefix('\u{feff}').unwrap_or(&text);
    for (i, line) in text.lines().enumerate() {
        let t = line.trim();
        if t.is_empty() {
            continue;
        }
        // Fields as spreadsheets and data frames write them: quoted or not.
        let f: Vec<&str> = t
            .split([',', ';', '\t', ' '])
            .map(unquoted)
            .filter(|s| !s.is_empty())
            .collect();
        let err = |reason: &str| CurveFileError::Line {
            path: path.to_path_buf(),
            line: i + 1,
            reason: reason.into(),
            text: t.into(),
        };
        let nums: Result<Vec<f64>, _> = f.iter().map(|x| x.parse::<f64>()).collect();
        match nums {
            Err(_) if i == 0 || pts.is_empty() && f.iter().all(|x| x.parse::<f64>().is_err()) => {
                skipped += 1;
                continue;
            } // header
            Err(_) => return Err(err("not a number")),
            Ok(v) if v.len() != 2 => return Err(err("expected two values x,y")),
            Ok(v) if !v.iter().all(|x| x.is_finite()) => return Err(err("non-finite value")),
            Ok(v) => pts.push(Point2::new(v[0], v[1])),
        }
    }
    if pts.len() < 3 {
        return Err(CurveFileError::TooFew {
            path: path.to_path_buf(),
            count: pts.len(),
            skipped,
        });
    }
    Ok(pts)
}

/// A field without the double or single quotes around it, if it has a pair.
fn unquoted(field: &str) -> &str {
    let f = field.trim();
    for q in ['"', '\''] {
        if let Some(inner) = f.strip_prefix(q).and_then(|r| r.strip_suffix(q)) {
            return inner.trim();
        }
    }
    f
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_is_optional_and_bad_lines_are_named() {
        let tmp = tempfile::tempdir().unwrap();
        let d = tmp.path();
        let p = d.join("a.csv");
        std::fs::write(&p, "x,y\n0,0\n1,0\n1,1\n").unwrap();
        assert_eq!(read_curve_csv(&p).unwrap().len(), 3);
        std::fs::write(&p, "0 0\n1 0\n1 1\n0 1\n").unwrap();
        assert_eq!(read_curve_csv(&p).unwrap().len(), 4);
        std::fs::write(&p, "0,0\n1,zero\n1,1\n").unwrap();
        let e = read_curve_csv(&p).unwrap_err().to_string();
        assert!(e.contains("line 2") && e.contains("a.csv"), "{e}");
        std::fs::write(&p, "0,0,0\n").unwrap();
        assert!(read_curve_csv(&p)
            .unwrap_err()
            .to_string()
            .contains("two values"));
        std::fs::write(&p, "0,0\n1,NaN\n2,2\n").unwrap();
        assert!(read_curve_csv(&p)
            .unwrap_err()
            .to_string()
            .contains("non-finite"));
        std::fs::write(&p, "x,y\n0,0\n").unwrap();
        assert!(matches!(
            read_curve_csv(&p),
            Err(CurveFileError::TooFew { count: 1, .. })
        ));
        // As spreadsheets write them: a byte-order mark before the first point (which stays a
        // point, not a header), quoted fields, CRLF line ends.
        std::fs::write(&p, "\u{feff}0,0\r\n\"1\",\"0\"\r\n'1';'1'\r\n").unwrap();
        let q = read_curve_csv(&p).unwrap();
        assert_eq!(
            q,
            vec![
                Point2::new(0.0, 0.0),
                Point2::new(1.0, 0.0),
                Point2::new(1.0, 1.0)
            ]
        );
        // Companion: a quoted word is still not a number, and named.
        std::fs::write(&p, "0,0\n\"1\",\"zero\"\n1,1\n").unwrap();
        let e = read_curve_csv(&p).unwrap_err().to_string();
        assert!(e.contains("line 2") && e.contains("not a number"), "{e}");
        // Lines of words only: said to have been read as a header, not silently empty.
        std::fs::write(&p, "a,b\nc,d\n").unwrap();
        let e = read_curve_csv(&p).unwrap_err().to_string();
        assert!(
            e.contains("0 points") && e.contains("2 lines without a number"),
            "{e}"
        );
    }
}
