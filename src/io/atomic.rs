//! Output files are written atomically: into a temporary file beside the target, then renamed,
//! so a failed run never leaves a half-written file behind.

use std::io::Write;
use std::path::Path;

/// The folder a path's temporary sibling is made in.
fn parent_of(path: &Path) -> &Path {
    path.parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."))
}

/// Write `bytes` to `path` through a temporary sibling file (tempfile) and a rename. The file
/// gets the permissions a plain write would (0666 less the umask), not tempfile's private 0600.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let prefix = format!(".{name}.");
    let mut builder = tempfile::Builder::new();
    builder.prefix(&prefix).suffix(".tmp");
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(0o666));
    }
    let mut tmp = builder.tempfile_in(parent_of(path))?;
    tmp.write_all(bytes)?;
    tmp.persist(path).map_err(|e| e.error)?;
    Ok(())
}

/// Whether the output folder `out` holds anything already (a folder that cannot be read counts
/// when it exists): an earlier result's files would mix with a new one's.
pub fn out_in_use(out: &Path) -> bool {
    match std::fs::read_dir(out) {
        Ok(mut entries) => entries.next().is_some(),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => false,
        Err(_) => out.exists(),
    }
}

/// Whether an output folder `out` can be made and written, asked before the work that fills it
/// (so that a long run does not end in "cannot write"): the nearest folder above it that exists
/// (or `out` itself) must be a folder this process can make a file in. Nothing is left behind.
pub fn check_writable(out: &Path) -> std::io::Result<()> {
    let mut at = out;
    let existing = loop {
        if at.exists() {
            break at;
        }
        match at.parent().filter(|p| !p.as_os_str().is_empty()) {
            Some(up) => at = up,
            None => break Path::new("."),
        }
    };
    if !existing.is_dir() {
        return Err(std::io::Error::new(
            std::io::ErrorKind::NotADirectory,
            format!("{} is not a folder", existing.display()),
        ));
    }
    tempfile::Builder::new()
        .prefix(".acetab-write-check-")
        .tempfile_in(existing)
        .map(drop)
}

/// Fill an output folder all at once: `fill` writes into a staging folder beside `out`
/// (tempfile, removed whatever happens); only when it succeeds are its entries moved into `out`
/// (created if needed, with the folders above it, same-named entries replaced). On failure `out`
/// is left as it was (folders made above it stay).
pub fn fill_dir_atomically<E>(
    out: &Path,
    fill: impl FnOnce(&Path) -> Result<(), E>,
    io_err: impl Fn(&Path, std::io::Error) -> E,
) -> Result<(), E> {
    let parent = parent_of(out);
    let name = out
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "out".into());
    std::fs::create_dir_all(parent).map_err(|e| io_err(parent, e))?;
    let stage = tempfile::Builder::new()
        .prefix(&format!(".{name}.partial-"))
        .tempdir_in(parent)
        .map_err(|e| io_err(parent, e))?;
    fill(stage.path())?;
    std::fs::create_dir_all(out).map_err(|e| io_err(out, e))?;
    let entries: Vec<_> = std::fs::read_dir(stage.path())
        .map_err(|e| io_err(stage.path(), e))?
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
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failed_fill_leaves_no_folder_and_a_good_one_moves_everything() {
        let tmp = tempfile::tempdir().unwrap();
        let root = tmp.path();
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
            std::fs::read_dir(root).unwrap().count(),
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
            std::fs::read_dir(root).unwrap().count(),
            1,
            "only out remains"
        );
    }

    #[test]
    fn an_output_below_missing_folders_is_made_and_one_below_a_file_is_refused_early() {
        let tmp = tempfile::tempdir().unwrap();
        let root = tmp.path();
        let out = root.join("a/b/out");
        check_writable(&out).unwrap();
        assert_eq!(
            std::fs::read_dir(root).unwrap().count(),
            0,
            "the check leaves nothing"
        );
        let r: Result<(), String> = fill_dir_atomically(
            &out,
            |d| std::fs::write(d.join("x.csv"), b"x").map_err(|e| e.to_string()),
            |p, e| format!("{}: {e}", p.display()),
        );
        r.unwrap();
        assert!(out.join("x.csv").is_file());
        // The companion: below a file nothing can be made, and the check says so.
        std::fs::write(root.join("file"), b"f").unwrap();
        let e = check_writable(&root.join("file/out")).unwrap_err();
        assert!(e.to_string().contains("is not a folder"), "{e}");
    }

    #[test]
    fn atomic_write_replaces_and_leaves_no_temporary() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path();
        let p = dir.join("a.txt");
        write_atomic(&p, b"one").unwrap();
        write_atomic(&p, b"two").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"two");
        assert_eq!(std::fs::read_dir(dir).unwrap().count(), 1);
        assert!(write_atomic(&dir.join("missing/x.txt"), b"x").is_err());
        assert_eq!(std::fs::read_dir(dir).unwrap().count(), 1);
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = std::fs::metadata(&p).unwrap().permissions().mode() & 0o777;
            assert_ne!(mode, 0o600, "tempfile's private mode leaked onto an output");
        }
    }
}
