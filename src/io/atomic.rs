//! Output files are written atomically: into a temporary file beside the target, then renamed,
//! so a failed run never leaves a half-written file behind.

use std::path::{Path, PathBuf};

/// Write `bytes` to `path` through a temporary sibling file and a rename.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let tmp = temp_sibling(path);
    let result = std::fs::write(&tmp, bytes).and_then(|_| std::fs::rename(&tmp, path));
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

fn temp_sibling(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!(".{name}.tmp-{}", std::process::id()))
}

/// Fill an output folder all at once: `fill` writes into a staging folder beside `out`; only
/// when it succeeds are its entries moved into `out` (created if needed, same-named entries
/// replaced). On failure the staging folder is removed and `out` is left as it was.
pub fn fill_dir_atomically<E>(
    out: &Path,
    fill: impl FnOnce(&Path) -> Result<(), E>,
    io_err: impl Fn(&Path, std::io::Error) -> E,
) -> Result<(), E> {
    let parent = out
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let name = out
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "out".into());
    let stage = parent.join(format!(".{name}.partial-{}", std::process::id()));
    let result = (|| {
        std::fs::create_dir_all(&stage).map_err(|e| io_err(&stage, e))?;
        fill(&stage)?;
        std::fs::create_dir_all(out).map_err(|e| io_err(out, e))?;
        let entries: Vec<_> = std::fs::read_dir(&stage)
            .map_err(|e| io_err(&stage, e))?
            .filter_map(|e| e.ok())
            .collect();
        for e in entries {
            let to = out.join(e.file_name());
            if to.is_dir() {
                std::fs::remove_dir_all(&to).map_err(|err| io_err(&to, err))?;
            }
            std::fs::rename(e.path(), &to).map_err(|err| io_err(&to, err))?;
        }
        Ok(())
    })();
    let _ = std::fs::remove_dir_all(&stage);
    result
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failed_fill_leaves_no_folder_and_a_good_one_moves_everything() {
        let root = std::env::temp_dir().join(format!("acetab-filldir-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        std::fs::create_dir_all(&root).unwrap();
        let out = root.join("out");
        let r: Result<(), String> = fill_dir_atomically(
            &out,
            |d| {
                std::fs::write(d.join("half.csv"), b"a").unwrap();
                Err("plot failed".into())
            },
            |p, e| format!("{}: {e}", p.display()),
        );
        assert!(r.is_err());
        assert!(!out.exists());
        assert_eq!(
            std::fs::read_dir(&root).unwrap().count(),
            0,
            "no staging left"
        );
        let r: Result<(), String> = fill_dir_atomically(
            &out,
            |d| {
                std::fs::write(d.join("a.csv"), b"a").unwrap();
                std::fs::create_dir(d.join("sub")).unwrap();
                std::fs::write(d.join("sub/b.png"), b"b").unwrap();
                Ok(())
            },
            |p, e| format!("{}: {e}", p.display()),
        );
        r.unwrap();
        assert!(out.join("a.csv").is_file() && out.join("sub/b.png").is_file());
        assert_eq!(
            std::fs::read_dir(&root).unwrap().count(),
            1,
            "only out remains"
        );
        std::fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn atomic_write_replaces_and_leaves_no_temporary() {
        let dir = std::env::temp_dir().join(format!("acetab-fsutil-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("a.txt");
        write_atomic(&p, b"one").unwrap();
        write_atomic(&p, b"two").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"two");
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
        assert!(write_atomic(&dir.join("missing/x.txt"), b"x").is_err());
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
