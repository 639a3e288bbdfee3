//! Atomic file replacement: every writer of this crate writes a temp file next to the target,
//! syncs it and renames it over the target, so a reader (or a crash) sees the old file or the
//! new one, never a partial one.

use super::MapIoError;
use std::fs::{self, File, OpenOptions};
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU32, Ordering};

/// Distinguishes temp files of concurrent writes from the same process.
static TEMP_COUNTER: AtomicU32 = AtomicU32::new(0);

/// The most bytes of the target's name a temp file name repeats: with the dot, process id,
/// counter and `.tmp` around it the temp name stays far below the 255 bytes most file systems
/// allow, however long the target's name is.
const TEMP_STEM_MAX: usize = 128;

/// The start of `name`, at most [`TEMP_STEM_MAX`] bytes, cut at a character boundary.
fn temp_stem(name: &str) -> &str {
    let mut end = name.len().min(TEMP_STEM_MAX);
    while !name.is_char_boundary(end) {
        end -= 1;
    }
    &name[..end]
}

/// Creates a new, uniquely named temp file next to the target.
fn create_temp_file(dir: &Path, file_name: &str) -> io::Result<(PathBuf, File)> {
    let pid = std::process::id();
    let stem = temp_stem(file_name);
    let mut last_err = None;
    for _ in 0..64 {
        let n = TEMP_COUNTER.fetch_add(1, Ordering::Relaxed);
        let temp = dir.join(format!(".{stem}.{pid}.{n}.tmp"));
        match OpenOptions::new().write(true).create_new(true).open(&temp) {
            Ok(f) => return Ok((temp, f)),
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => last_err = Some(e),
            Err(e) => return Err(e),
        }
    }
    Err(last_err.unwrap_or_else(|| io::Error::other("could not create a unique temp file")))
}

/// The file-system steps of an atomic write. Tests replace them to make each one fail.
struct AtomicSteps {
    write: fn(&mut File, &[u8]) -> io::Result<()>,
    sync_file: fn(&File) -> io::Result<()>,
    rename: fn(&Path, &Path) -> io::Result<()>,
    sync_dir: fn(&Path) -> io::Result<()>,
}

fn os_write(file: &mut File, bytes: &[u8]) -> io::Result<()> {
    file.write_all(bytes)
}

fn os_sync_file(file: &File) -> io::Result<()> {
    file.sync_all()
}

fn os_rename(from: &Path, to: &Path) -> io::Result<()> {
    fs::rename(from, to)
}

/// The steps as the operating system does them.
const OS_STEPS: AtomicSteps = AtomicSteps {
    write: os_write,
    sync_file: os_sync_file,
    rename: os_rename,
    sync_dir,
};

/// Writes, syncs and renames the temp file over the target.
fn write_and_replace(
    temp: &Path,
    mut file: File,
    bytes: &[u8],
    target: &Path,
    steps: &AtomicSteps,
) -> io::Result<()> {
    (steps.write)(&mut file, bytes)?;
    (steps.sync_file)(&file)?;
    drop(file);
    (steps.rename)(temp, target)
}

/// Makes the rename durable by syncing the directory (unix only; elsewhere a no-op).
fn sync_dir(dir: &Path) -> io::Result<()> {
    #[cfg(unix)]
    {
        match File::open(dir).and_then(|d| d.sync_all()) {
            // Some file systems cannot sync directories; the rename has happened regardless.
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::InvalidInput | io::ErrorKind::Unsupported
                ) =>
            {
                Ok(())
            }
            other => other,
        }
    }
    #[cfg(not(unix))]
    {
        let _ = dir;
        Ok(())
    }
}

/// What a successful atomic write leaves to say.
#[derive(Debug)]
pub struct AtomicWrite {
    /// Why the directory could not be synced after the rename, if it could not: the new
    /// content is in place and every reader sees it, but after a power loss the old file may
    /// come back. A warning, not a failure: reporting the write as failed would claim the old
    /// file is still there, and it is not.
    pub dir_sync_error: Option<io::Error>,
}

/// Writes bytes atomically: temp file in the same directory, write, fsync, rename over the
/// target, fsync the directory (on unix). On any error before the rename the temp file is
/// removed and the old target is untouched; once the rename succeeded the write is done
/// (see [`write_atomic_report`] for a failed directory sync after it).
///
/// Readers of `path` see either the old content or the new one, never a partial file. The
/// parent directory must exist; it is not created. Only a regular file is replaced: a device,
/// a named pipe, a socket, a folder or a symbolic link at `path` is refused untouched (the
/// rename would put a file in place of `/dev/null`, or of a link instead of writing through
/// it). File names up to the file system's limit
/// (255 bytes on most) work: the temp file's name repeats at most the first 128 bytes.
pub fn write_atomic(path: impl AsRef<Path>, bytes: &[u8]) -> Result<(), MapIoError> {
    write_atomic_with(path.as_ref(), bytes, &OS_STEPS).map(|_| ())
}

/// [`write_atomic`], also saying whether the directory sync after the rename failed (for
/// callers that warn about it).
pub fn write_atomic_report(
    path: impl AsRef<Path>,
    bytes: &[u8],
) -> Result<AtomicWrite, MapIoError> {
    write_atomic_with(path.as_ref(), bytes, &OS_STEPS)
}

fn write_atomic_with(
    path: &Path,
    bytes: &[u8],
    steps: &AtomicSteps,
) -> Result<AtomicWrite, MapIoError> {
    let io_err = |source| MapIoError::Io {
        path: path.to_path_buf(),
        source,
    };
    let file_name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .ok_or_else(|| {
            io_err(io::Error::new(
                io::ErrorKind::InvalidInput,
                "the path does not name a file",
            ))
        })?;
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    match fs::symlink_metadata(path) {
        Ok(meta) if !meta.file_type().is_file() => {
            return Err(io_err(io::Error::new(
                io::ErrorKind::InvalidInput,
                format!(
                    "a {} is there, not a regular file: it is not replaced",
                    super::guard::file_kind(&meta.file_type())
                ),
            )));
        }
        Ok(_) => {}
        Err(e) if e.kind() == io::ErrorKind::NotFound => {}
        Err(e) => return Err(io_err(e)),
    }

    let (temp, file) = create_temp_file(dir, &file_name).map_err(io_err)?;
    if let Err(e) = write_and_replace(&temp, file, bytes, path, steps) {
        // Best effort: the original error is the one worth reporting.
        let _ = fs::remove_file(&temp);
        return Err(io_err(e));
    }
    // The target is the new file from here on, whatever the directory sync says.
    Ok(AtomicWrite {
        dir_sync_error: (steps.sync_dir)(dir).err(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fresh folder for the atomic-write tests, removed at the end.
    struct Scratch(PathBuf);

    impl Scratch {
        fn new(name: &str) -> Self {
            let dir = std::env::temp_dir().join(format!(
                "terrain-core-io-unit-{}-{name}",
                std::process::id()
            ));
            let _ = fs::remove_dir_all(&dir);
            fs::create_dir_all(&dir).unwrap();
            Self(dir)
        }

        fn names(&self) -> Vec<String> {
            let mut n: Vec<String> = fs::read_dir(&self.0)
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect();
            n.sort();
            n
        }
    }

    impl Drop for Scratch {
        fn drop(&mut self) {
            let _ = fs::remove_dir_all(&self.0);
        }
    }

    fn fails<T>() -> io::Result<T> {
        Err(io::Error::other("injected failure"))
    }

    /// Only regular files are replaced: a folder, a link and (on unix) a named pipe at the
    /// path are refused and left as they were; the device test reads /dev/null's type only.
    #[test]
    fn only_a_regular_file_is_replaced() {
        let dir = Scratch::new("special");
        let folder = dir.0.join("folder");
        fs::create_dir(&folder).unwrap();
        let e = write_atomic(&folder, b"x").unwrap_err();
        assert!(e.to_string().contains("a directory"), "{e}");
        assert!(folder.is_dir());
        #[cfg(unix)]
        {
            let target = dir.0.join("target");
            fs::write(&target, b"kept").unwrap();
            let link = dir.0.join("link");
            std::os::unix::fs::symlink(&target, &link).unwrap();
            let e = write_atomic(&link, b"x").unwrap_err();
            assert!(e.to_string().contains("symbolic link"), "{e}");
            assert!(
                fs::symlink_metadata(&link)
                    .unwrap()
                    .file_type()
                    .is_symlink()
            );
            assert_eq!(fs::read(&target).unwrap(), b"kept");
            let null = Path::new("/dev/null");
            if let Ok(meta) = fs::symlink_metadata(null) {
                use std::os::unix::fs::FileTypeExt;
                if meta.file_type().is_char_device() {
                    assert_eq!(
                        super::super::guard::file_kind(&meta.file_type()),
                        "character device"
                    );
                }
            }
        }
        assert_eq!(
            dir.names().len(),
            if cfg!(unix) { 3 } else { 1 },
            "no temp file left"
        );
        let file = dir.0.join("file");
        write_atomic(&file, b"one").unwrap();
        write_atomic(&file, b"two").unwrap();
        assert_eq!(fs::read(&file).unwrap(), b"two");
    }

    #[test]
    fn a_failed_directory_sync_after_the_rename_still_reports_the_write_as_done() {
        let dir = Scratch::new("dir-sync");
        let target = dir.0.join("map.png");
        fs::write(&target, b"old").unwrap();
        let steps = AtomicSteps {
            sync_dir: |_| fails(),
            ..OS_STEPS
        };
        let written = write_atomic_with(&target, b"new", &steps)
            .expect("the rename happened: the write is done");
        // The new content is in place; only its durability over a power loss is in doubt.
        assert_eq!(fs::read(&target).unwrap(), b"new");
        let warning = written.dir_sync_error.expect("the failed sync is reported");
        assert!(warning.to_string().contains("injected"), "{warning}");
        assert_eq!(dir.names(), ["map.png"]);
        let clean = write_atomic_with(&target, b"newer", &OS_STEPS).unwrap();
        assert!(clean.dir_sync_error.is_none());
    }

    #[test]
    fn every_failing_step_before_the_rename_removes_the_temp_file_and_keeps_the_old_file() {
        let broken = [
            AtomicSteps {
                write: |_, _| fails(),
                ..OS_STEPS
            },
            AtomicSteps {
                // Half the bytes reach the temp file, then the disk is full.
                write: |f, b| {
                    f.write_all(&b[..b.len() / 2])?;
                    fails()
                },
                ..OS_STEPS
            },
            AtomicSteps {
                sync_file: |_| fails(),
                ..OS_STEPS
            },
            AtomicSteps {
                rename: |_, _| fails(),
                ..OS_STEPS
            },
        ];
        for (i, steps) in broken.iter().enumerate() {
            let dir = Scratch::new(&format!("steps-{i}"));
            let target = dir.0.join("map.png");
            fs::write(&target, b"old").unwrap();
            let e = write_atomic_with(&target, b"new content", steps)
                .expect_err("a failed step fails the write");
            assert!(
                matches!(&e, MapIoError::Io { path, .. } if *path == target),
                "{e}"
            );
            assert_eq!(fs::read(&target).unwrap(), b"old", "step {i}");
            assert_eq!(dir.names(), ["map.png"], "step {i}: temp file left");
        }
    }
}
