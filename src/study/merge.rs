//! Shards of one study joined: their summary.json settings must agree and make the whole set,
//! their runs.csv files hold every run of the study once.

use super::error::StudyError;
use super::method::StudyMethod;
use super::runs_csv::{read_csv, Row};
use std::path::{Path, PathBuf};

/// Every run the study of merged settings `meta` (summary.json's `study`, as `merge_meta` gives
/// it) makes, levels x runs x methods, must be among `rows`; a study whose settings do not say
/// (an older summary.json) is not checked.
pub fn check_complete(rows: &[Row], meta: &serde_json::Value) -> Result<(), StudyError> {
    let (Some(levels), Some(runs), Some(methods)) = (
        meta.get("levels").and_then(|v| v.as_array()),
        meta.get("runs").and_then(|v| v.as_u64()),
        meta.get("methods").and_then(|v| v.as_array()),
    ) else {
        return Ok(());
    };
    let held: std::collections::BTreeSet<(StudyMethod, u32, usize)> =
        rows.iter().map(|r| r.key()).collect();
    let mut missing = Vec::new();
    let mut expected = 0;
    for m in methods
        .iter()
        .filter_map(|m| m.as_str().and_then(StudyMethod::from_name))
    {
        for l in levels.iter().filter_map(|l| l.as_u64()) {
            for r in 0..runs as usize {
                expected += 1;
                if !held.contains(&(m, l as u32, r)) {
                    missing.push(format!("{} level {l} run {r}", m.name()));
                }
            }
        }
    }
    if missing.is_empty() {
        return Ok(());
    }
    let more = missing.len().saturating_sub(3);
    let mut first = missing[..missing.len().min(3)].join(", ");
    if more > 0 {
        first += &format!(" and {more} more");
    }
    Err(StudyError::Incomplete {
        held: expected - missing.len(),
        expected,
        first,
    })
}

/// The study settings shards share, from their summary.json files (folders without one are
/// skipped): every field but `shard`, `seconds` and `merged` must agree, or the shards are not of
/// one study (so merged folders can be merged again). The result lists the folders under
/// `merged`.
pub fn merge_meta(dirs: &[PathBuf]) -> Result<serde_json::Value, StudyError> {
    let mut common: Option<(PathBuf, Settings)> = None;
    let mut shards: Vec<(PathBuf, usize, usize)> = Vec::new();
    let mut all_sharded = true;
    for d in dirs {
        let path = d.join("summary.json");
        let Some((study, shard)) = study_settings(&path)? else {
            continue;
        };
        match shard_of(&path, shard.as_ref())? {
            Some((i, n)) => shards.push((path.clone(), i, n)),
            // A merged folder (or one from before shards were recorded) holds shards of its
            // own: the set cannot be checked.
            None => all_sharded = false,
        }
        let Some((first, c)) = &common else {
            common = Some((path, study));
            continue;
        };
        if let Some((field, expected, value)) = first_difference(c, &study) {
            return Err(StudyError::Mismatch {
                path,
                field,
                value,
                first: first.clone(),
                expected,
            });
        }
    }
    if all_sharded {
        check_shard_set(&shards)?;
    }
    let mut meta = common.map(|(_, c)| c).unwrap_or_default();
    meta.insert("merged".into(), serde_json::json!(dirs));
    Ok(serde_json::Value::Object(meta))
}

/// The shard "I/N" a summary.json's study names (`shard`, its value in the file at `path`), if
/// it names one (a merged folder names none); one that is not "I/N" with 0 <= I < N is an error
/// naming the file and the value.
fn shard_of(
    path: &Path,
    shard: Option<&serde_json::Value>,
) -> Result<Option<(usize, usize)>, StudyError> {
    let Some(shard) = shard else {
        return Ok(None);
    };
    let parsed = shard.as_str().and_then(|s| {
        let (i, n) = s.split_once('/')?;
        let (i, n): (usize, usize) = (i.trim().parse().ok()?, n.trim().parse().ok()?);
        (i < n).then_some((i, n))
    });
    match parsed {
        Some(p) => Ok(Some(p)),
        None => Err(StudyError::Parse {
            path: path.to_path_buf(),
            line: 1,
            reason: format!("study.shard is {shard}: expected \"I/N\" with 0 <= I < N"),
        }),
    }
}

/// Shards named by the summaries (path, I, N) must share N and be the whole set 0..N: shards of
/// different counts, or a merge with a gap, are refused.
fn check_shard_set(shards: &[(PathBuf, usize, usize)]) -> Result<(), StudyError> {
    let Some((first, i0, count)) = shards.first() else {
        return Ok(());
    };
    if let Some((path, i, n)) = shards.iter().find(|s| s.2 != *count) {
        return Err(StudyError::Mismatch {
            path: path.clone(),
            field: "shard".into(),
            value: format!("\"{i}/{n}\""),
            first: first.clone(),
            expected: format!("\"{i0}/{count}\""),
        });
    }
    let mut present: Vec<usize> = shards.iter().map(|s| s.1).collect();
    present.sort_unstable();
    present.dedup();
    let missing: Vec<String> = (0..*count)
        .filter(|i| present.binary_search(i).is_err())
        .map(|i| format!("{i}/{count}"))
        .collect();
    if missing.is_empty() {
        return Ok(());
    }
    Err(StudyError::ShardGap {
        missing: missing.join(", "),
        count: *count,
        present: present
            .iter()
            .map(|i| format!("{i}/{count}"))
            .collect::<Vec<_>>()
            .join(", "),
    })
}

/// The settings of one study, as a summary.json's `study` object holds them.
type Settings = serde_json::Map<String, serde_json::Value>;

/// The `study` object of a summary.json without the fields that differ between shards, and its
/// `shard` if it names one; None when the file does not exist.
fn study_settings(
    path: &Path,
) -> Result<Option<(Settings, Option<serde_json::Value>)>, StudyError> {
    let text = match std::fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(source) => {
            return Err(StudyError::Read {
                path: path.to_path_buf(),
                source,
            })
        }
    };
    let bad = |reason: String| StudyError::Parse {
        path: path.to_path_buf(),
        line: 1,
        reason,
    };
    let v: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| bad(format!("not JSON: {e}")))?;
    let Some(serde_json::Value::Object(study)) = v.get("study") else {
        return Err(bad("no \"study\" object".into()));
    };
    let mut study = study.clone();
    let shard = study.remove("shard");
    // What differs between shards of one study: the shard, its time, its command line and
    // engine counts.
    for k in ["seconds", "merged", "provenance", "engine"] {
        study.remove(k);
    }
    Ok(Some((study, shard)))
}

/// The first field (in name order) whose value differs between `a` and `b`, with both values
/// as JSON text ("missing" where absent).
fn first_difference(a: &Settings, b: &Settings) -> Option<(String, String, String)> {
    let show =
        |x: Option<&serde_json::Value>| x.map_or_else(|| "missing".into(), |v| v.to_string());
    let keys: std::collections::BTreeSet<&String> = a.keys().chain(b.keys()).collect();
    keys.into_iter()
        .find(|k| a.get(*k) != b.get(*k))
        .map(|k| (k.clone(), show(a.get(k)), show(b.get(k))))
}

/// Join the runs.csv of several shard folders, in canonical order; a run present twice is an error.
pub fn merge_dirs(dirs: &[PathBuf]) -> Result<Vec<Row>, StudyError> {
    let mut rows: Vec<(Row, PathBuf)> = Vec::new();
    for d in dirs {
        let p = d.join("runs.csv");
        for r in read_csv(&p)? {
            rows.push((r, p.clone()));
        }
    }
    rows.sort_by_key(|a| a.0.key());
    for w in rows.windows(2) {
        if w[0].0.key() == w[1].0.key() {
            let r = &w[1].0;
            return Err(StudyError::Duplicate {
                method: r.method.name().into(),
                level: r.level,
                run: r.run,
                path: w[1].1.clone(),
            });
        }
    }
    Ok(rows.into_iter().map(|(r, _)| r).collect())
}

#[cfg(test)]
mod tests {
    use super::super::runs_csv::{test_row as row, write_csv};
    use super::*;

    #[test]
    fn merge_meta_keeps_the_shared_settings_and_rejects_another_study() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path();
        let write = |name: &str, seed: u64, shard: &str| {
            let d = dir.join(name);
            std::fs::create_dir_all(&d).unwrap();
            let v = serde_json::json!({"study": {"gt": "phantom", "seed": seed, "shard": shard,
                "seconds": 1.5, "w_reg": 10.0}, "summary": []});
            std::fs::write(d.join("summary.json"), v.to_string()).unwrap();
            d
        };
        let (a, b, c) = (
            write("a", 1, "0/2"),
            write("b", 1, "1/2"),
            write("c", 2, "1/2"),
        );
        let plain = dir.join("plain");
        std::fs::create_dir_all(&plain).unwrap();
        let m = merge_meta(&[a.clone(), b.clone(), plain.clone()]).unwrap();
        assert_eq!(m["seed"], 1);
        assert_eq!(m["w_reg"], 10.0);
        assert!(m.get("shard").is_none() && m.get("seconds").is_none());
        assert_eq!(m["merged"].as_array().unwrap().len(), 3);
        // A merged folder (its own `merged` list, no `shard`) merges with a shard of its study.
        let joined = dir.join("joined");
        std::fs::create_dir_all(&joined).unwrap();
        let v = serde_json::json!({"study": m.clone(), "summary": []});
        std::fs::write(joined.join("summary.json"), v.to_string()).unwrap();
        assert_eq!(merge_meta(&[joined, a.clone()]).unwrap()["seed"], 1);
        // A shard set with a gap is refused, naming what is missing; one shard of a study made
        // in one shard is whole.
        let e = merge_meta(std::slice::from_ref(&b))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("shards 0/2 of 2 are missing") && e.contains("hold 1/2"),
            "{e}"
        );
        let whole = write("whole", 1, "0/1");
        assert!(merge_meta(&[whole]).is_ok());
        // The companion: a shard of another study (seed 2) is refused, naming the field.
        let e = merge_meta(&[a, c]).unwrap_err().to_string();
        assert!(e.contains("\"seed\" is 2") && e.contains("has 1"), "{e}");
        // A shard that is not "I/N" with I < N is refused, naming the file and the value, not
        // taken for a merged folder (which would skip the set's check).
        for (name, shard) in [("odd1", "2/2"), ("odd2", "half"), ("odd3", "1/0")] {
            let d = write(name, 1, shard);
            let e = merge_meta(std::slice::from_ref(&d))
                .unwrap_err()
                .to_string();
            assert!(
                e.contains(&format!("study.shard is \"{shard}\""))
                    && e.contains(&d.join("summary.json").display().to_string()),
                "{e}"
            );
        }
        std::fs::write(plain.join("summary.json"), "{").unwrap();
        assert!(merge_meta(&[plain])
            .unwrap_err()
            .to_string()
            .contains("not JSON"));
    }

    #[test]
    fn merge_joins_shards_in_order_and_rejects_a_run_twice() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path();
        let (a, b) = (dir.join("a"), dir.join("b"));
        std::fs::create_dir_all(&a).unwrap();
        std::fs::create_dir_all(&b).unwrap();
        let r1 = vec![
            row(StudyMethod::Srvf, 1, 0, 0.5),
            row(StudyMethod::Icp, 1, 0, 2.0),
        ];
        write_csv(&r1, &a.join("runs.csv")).unwrap();
        write_csv(&[row(StudyMethod::Srvf, 1, 1, 0.7)], &b.join("runs.csv")).unwrap();
        let merged = merge_dirs(&[b.clone(), a.clone()]).unwrap();
        assert_eq!(
            merged.iter().map(|r| r.key()).collect::<Vec<_>>(),
            vec![
                (StudyMethod::Srvf, 1, 0),
                (StudyMethod::Srvf, 1, 1),
                (StudyMethod::Icp, 1, 0)
            ]
        );
        // Companion: the same shard twice holds every run twice.
        assert!(matches!(
            merge_dirs(&[a.clone(), a.clone()]),
            Err(StudyError::Duplicate { .. })
        ));
        std::fs::write(b.join("runs.csv"), "nonsense\n").unwrap();
        assert!(matches!(
            merge_dirs(std::slice::from_ref(&b)),
            Err(StudyError::Parse { line: 1, .. })
        ));
    }

    /// A merge whose shards hold every run of their study passes; one that lacks runs (a shard
    /// cut short: its runs.csv only a header) is refused, naming the first missing ones; an
    /// older summary.json without the settings is not checked.
    #[test]
    fn a_merge_missing_runs_of_its_study_is_refused() {
        let meta = serde_json::json!({"levels": [1, 3], "runs": 2, "methods": ["srvf", "icp"]});
        let all: Vec<Row> = [StudyMethod::Srvf, StudyMethod::Icp]
            .into_iter()
            .flat_map(|m| {
                [1, 3]
                    .into_iter()
                    .flat_map(move |l| (0..2).map(move |r| row(m, l, r, 0.5)))
            })
            .collect();
        assert_eq!(all.len(), 8);
        assert!(check_complete(&all, &meta).is_ok());
        let cut: Vec<Row> = all.iter().filter(|r| r.run == 0).cloned().collect();
        let e = check_complete(&cut, &meta).unwrap_err().to_string();
        assert!(
            e.contains("4 of the study's 8 runs")
                && e.contains("srvf level 1 run 1")
                && e.contains("1 more"),
            "{e}"
        );
        assert!(check_complete(&cut, &serde_json::json!({"seed": 3})).is_ok());
    }
}
