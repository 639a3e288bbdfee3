//! Whether a run can write where it will, checked before anything long starts: a folder the
//! run writes into (`--out`; the world folder of the streamed scenarios, which write their
//! deformations back) is probed by creating and removing a file in it. A read-only folder is a
//! usage error (exit status 2) that names it, instead of a failure after minutes of work.

use crate::usage_error::usage;
use anyhow::{Result, anyhow};
use std::path::Path;

/// Checks that files can be created in `dir`, or, while it does not exist, in the nearest
/// folder above it that does (the run creates the rest). `flag` names the flag that chose it.
///
/// The probe is created with `O_CREAT | O_EXCL` (`create_new`), which never follows a link
/// and never opens what is already there, under a name of this process's own, and removed.
pub fn check_dir(dir: &Path, flag: &str) -> Result<()> {
    let refuse = |why: String| {
        usage(anyhow!(
            "{flag} {}: {why}; choose another {flag} or make it writable",
            dir.display()
        ))
    };
    // The nearest existing folder: `dir` itself, or what the run will create it under.
    let mut existing = dir;
    let meta = loop {
        match std::fs::metadata(existing) {
            Ok(meta) => break meta,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                match existing.parent() {
                    Some(p) if !p.as_os_str().is_empty() => existing = p,
                    // A relative path whose first component is missing: the working folder.
                    _ => {
                        existing = Path::new(".");
                    }
                }
            }
            Err(e) => return Err(refuse(format!("cannot check {}: {e}", existing.display()))),
        }
    };
    if !meta.is_dir() {
        return Err(refuse(format!("{} is not a folder", existing.display())));
    }
    let probe = existing.join(format!(".terrain-demo-write-probe-{}", std::process::id()));
    match std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&probe)
    {
        Ok(file) => {
            drop(file);
            std::fs::remove_file(&probe).map_err(|e| {
                refuse(format!(
                    "the probe file {} could be created but not removed: {e}",
                    probe.display()
                ))
            })
        }
        Err(e) if existing == dir => Err(refuse(format!("cannot create a file in it: {e}"))),
        Err(e) => Err(refuse(format!(
            "it does not exist and cannot be created in {}: {e}",
            existing.display()
        ))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_writable_folder_passes_and_leaves_nothing() {
        let dir = std::env::temp_dir().join(format!("terrain_writable_{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        check_dir(&dir, "--out").unwrap();
        // A folder still to be made is probed in its existing parent.
        check_dir(&dir.join("a/b"), "--out").unwrap();
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 0);
        // A file where the folder should be is refused, naming the flag.
        std::fs::write(dir.join("file"), b"x").unwrap();
        let e = check_dir(&dir.join("file/sub"), "--world").unwrap_err();
        assert!(format!("{e:#}").contains("--world"), "{e:#}");
        assert_eq!(crate::usage_error::exit_status(&e), 2);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
