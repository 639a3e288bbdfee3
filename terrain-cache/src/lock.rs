//! Ownership of a world folder: one writing process at a time.
//!
//! A world folder is shared state: two processes writing back into it would lose each other's
//! tiles, and two builds of one new world would mix two terrains. Every writer
//! ([`FsStore::open`](crate::FsStore::open): the RAM pool's write-back, the detail cache, a world
//! build) therefore holds the folder's lock for as long as its store lives.
//!
//! The lock is the operating system's advisory lock (`flock` on Unix, `LockFileEx` on Windows)
//! on the file `.terrain-lock` in the folder. The kernel drops it when the owner exits in any
//! way, `kill -9` included, so a stale lock cannot outlive its process and needs no
//! heuristics: the next writer simply gets it. The file's text (pid, host, start time) only
//! names the owner in the error a second writer gets. Viewers and tools that never write open
//! the folder with [`FsStore::open_read_only`](crate::FsStore::open_read_only) and take no lock.
//!
//! Within one process, stores over the same folder share one lock (the OS lock belongs to an
//! open file, so a second open in the same process would otherwise refuse its own owner).
//! Network file systems may not honour the lock (NFS without lock daemon): a world shared over
//! them has no owner check.

use crate::CacheError;
use std::collections::HashMap;
use std::fs::{File, OpenOptions, TryLockError};
use std::io::{self, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, MutexGuard, Weak};

/// The lock file's name inside a world folder (a dot name: never listed as a store key).
pub const LOCK_FILE: &str = ".terrain-lock";

/// The most bytes of an owner's description read back (a foreign file there stays harmless).
const OWNER_MAX_BYTES: u64 = 512;

/// A held world lock: released when the last store of this process over the folder drops it.
#[derive(Debug)]
pub(crate) struct WorldLock {
    /// The locked file; the OS lock lives as long as this handle.
    file: File,
    /// The canonical folder, the registry's key.
    dir: PathBuf,
}

impl Drop for WorldLock {
    fn drop(&mut self) {
        // Released before the registry entry goes, so a store opened meanwhile in this process
        // (which finds the entry dying and waits for the OS lock) gets it at once.
        let _ = self.file.unlock();
        let mut held = held();
        let held = held.get_or_insert_with(HashMap::new);
        if held
            .get(&self.dir)
            .is_some_and(|weak| weak.strong_count() == 0)
        {
            held.remove(&self.dir);
        }
    }
}

/// The locks this process holds, by canonical folder.
static HELD: Mutex<Option<HashMap<PathBuf, Weak<WorldLock>>>> = Mutex::new(None);

/// The registry (a panic elsewhere while holding it leaves it consistent: every change is one
/// insert or remove).
fn held() -> MutexGuard<'static, Option<HashMap<PathBuf, Weak<WorldLock>>>> {
    HELD.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// Takes (or shares, within this process) the lock of the folder `dir`, which must exist.
///
/// Fails with [`CacheError::WorldLocked`] naming the owner when another process holds it.
pub(crate) fn lock_world(dir: &Path) -> Result<Arc<WorldLock>, CacheError> {
    let io_err = |path: &Path| {
        let path = path.to_path_buf();
        move |source| CacheError::Io { path, source }
    };
    let canonical = dir.canonicalize().map_err(io_err(dir))?;
    let path = canonical.join(LOCK_FILE);
    let mut waits = 0;
    loop {
        let mut guard = held();
        let held = guard.get_or_insert_with(HashMap::new);
        if let Some(lock) = held.get(&canonical).and_then(Weak::upgrade) {
            return Ok(lock);
        }
        // An entry that no longer upgrades is this process's own lock being dropped right
        // now: its release is a moment away. It is waited for (at most 1 s, polling with the
        // registry released, so other folders' opens go on), never with a blocking lock,
        // since another process may take the lock in between.
        let ours_dying = held.contains_key(&canonical);
        let mut file = open_lock_file(&path).map_err(io_err(&path))?;
        match file.try_lock() {
            Ok(()) => {
                // Ours now: whatever an earlier (dead) owner wrote is replaced by who we are.
                write_owner(&mut file).map_err(io_err(&path))?;
                let lock = Arc::new(WorldLock {
                    file,
                    dir: canonical.clone(),
                });
                held.insert(canonical, Arc::downgrade(&lock));
                return Ok(lock);
            }
            // Our own lock being dropped, or a checking tool's shared probe (`lock_holder`,
            // held for a moment): waited for, never blocking.
            Err(TryLockError::WouldBlock) if (ours_dying && waits < 200) || waits < 10 => {
                drop(guard);
                waits += 1;
                std::thread::sleep(std::time::Duration::from_millis(5));
            }
            Err(TryLockError::WouldBlock) => {
                return Err(CacheError::WorldLocked {
                    dir: canonical,
                    owner: read_owner(&mut file),
                });
            }
            Err(TryLockError::Error(source)) => return Err(CacheError::Io { path, source }),
        }
    }
}

/// Who holds the lock of the world folder `dir`, if another process does: its lock file as
/// written by it (pid, host, start time). Only reads: nothing is created, taken or written, so
/// a checking tool can say a world is being written meanwhile. `None` where no one holds it,
/// or where there is no lock file to tell.
pub fn lock_holder(dir: &Path) -> Option<String> {
    let mut options = OpenOptions::new();
    options.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.custom_flags(libc_flags::NOFOLLOW | libc_flags::NONBLOCK);
    }
    let mut file = options.open(dir.join(LOCK_FILE)).ok()?;
    if !file.metadata().ok()?.is_file() {
        return None;
    }
    match file.try_lock_shared() {
        Ok(()) => None,
        Err(TryLockError::WouldBlock) => Some(read_owner(&mut file)),
        Err(TryLockError::Error(_)) => None,
    }
}

/// Opens (creating) the lock file without following a link there and refusing anything but a
/// regular file (a named pipe would block, a link could point anywhere).
fn open_lock_file(path: &Path) -> io::Result<File> {
    let mut options = OpenOptions::new();
    options.read(true).write(true).create(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        // O_NOFOLLOW | O_NONBLOCK: a link is refused (ELOOP), a FIFO does not block the open.
        options.custom_flags(libc_flags::NOFOLLOW | libc_flags::NONBLOCK);
    }
    let file = options.open(path)?;
    if !file.metadata()?.is_file() {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            "the lock file is not a regular file",
        ));
    }
    Ok(file)
}

/// `open(2)` flags, by value: std has no names for them and libc is not worth a dependency.
#[cfg(unix)]
mod libc_flags {
    #[cfg(any(target_os = "linux", target_os = "android"))]
    pub const NOFOLLOW: i32 = 0o400000;
    #[cfg(any(target_os = "linux", target_os = "android"))]
    pub const NONBLOCK: i32 = 0o4000;
    #[cfg(not(any(target_os = "linux", target_os = "android")))]
    pub const NOFOLLOW: i32 = 0x0100;
    #[cfg(not(any(target_os = "linux", target_os = "android")))]
    pub const NONBLOCK: i32 = 0x0004;
}

/// Records this process as the owner.
fn write_owner(file: &mut File) -> io::Result<()> {
    let since = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    let text = format!(
        "pid {} on host {} since unix time {since}\n",
        std::process::id(),
        host_name()
    );
    file.set_len(0)?;
    file.seek(SeekFrom::Start(0))?;
    file.write_all(text.as_bytes())?;
    file.sync_all()
}

/// The owner as its lock file describes it, one printable line of bounded length.
fn read_owner(file: &mut File) -> String {
    let mut bytes = Vec::new();
    let read = file
        .seek(SeekFrom::Start(0))
        .and_then(|_| file.take(OWNER_MAX_BYTES).read_to_end(&mut bytes));
    let text: String = String::from_utf8_lossy(&bytes)
        .lines()
        .next()
        .unwrap_or("")
        .chars()
        .filter(|c| !c.is_control())
        .collect();
    match read {
        Ok(_) if !text.is_empty() => text,
        // The owner has the lock but has not written its name yet (or wrote something else).
        _ => "another process (it has not named itself)".to_owned(),
    }
}

/// This machine's name, as far as it can be learnt without a system library.
fn host_name() -> String {
    for path in ["/proc/sys/kernel/hostname", "/etc/hostname"] {
        if let Ok(text) = std::fs::read_to_string(path) {
            let name = text.trim();
            if !name.is_empty() && name.len() <= 255 {
                return name.to_owned();
            }
        }
    }
    std::env::var("COMPUTERNAME")
        .or_else(|_| std::env::var("HOSTNAME"))
        .unwrap_or_else(|_| "unknown".to_owned())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fresh folder, removed at the end of the test.
    struct TempDir(PathBuf);

    impl TempDir {
        fn new() -> Self {
            let dir = crate::store::tests::temp_dir("lock");
            std::fs::create_dir_all(&dir).unwrap();
            Self(dir)
        }
    }

    impl Drop for TempDir {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    #[test]
    fn one_process_shares_its_lock_and_drops_it_with_the_last_store() {
        let dir = TempDir::new();
        let a = lock_world(dir.0.as_path()).unwrap();
        let b = lock_world(dir.0.as_path()).unwrap();
        assert!(Arc::ptr_eq(&a, &b));
        let text = std::fs::read_to_string(dir.0.as_path().join(LOCK_FILE)).unwrap();
        assert!(
            text.starts_with(&format!("pid {} on host ", std::process::id())),
            "{text}"
        );
        drop(a);
        drop(b);
        // Released: a fresh open handle (as another process would hold) gets it.
        let other = File::options()
            .read(true)
            .write(true)
            .open(dir.0.as_path().join(LOCK_FILE))
            .unwrap();
        other.try_lock().unwrap();
    }

    #[test]
    fn a_held_lock_is_refused_naming_its_owner() {
        let dir = TempDir::new();
        // Another owner: a separate open file description holding the lock, as another process.
        let mut other = File::options()
            .read(true)
            .write(true)
            .create(true)
            .truncate(true)
            .open(dir.0.as_path().join(LOCK_FILE))
            .unwrap();
        other.try_lock().unwrap();
        other
            .write_all(b"pid 4242 on host elsewhere since unix time 1\n\x1b[2J")
            .unwrap();
        let err = lock_world(dir.0.as_path()).unwrap_err();
        let msg = err.to_string();
        assert!(matches!(err, CacheError::WorldLocked { .. }), "{err:?}");
        assert!(msg.contains("pid 4242 on host elsewhere"), "{msg}");
        assert!(
            !msg.contains('\x1b'),
            "control characters are dropped: {msg:?}"
        );
        // A checking tool learns the owner without taking or writing anything.
        let before = std::fs::read(dir.0.join(LOCK_FILE)).unwrap();
        let holder = lock_holder(dir.0.as_path()).expect("held");
        assert!(holder.contains("pid 4242"), "{holder}");
        assert_eq!(std::fs::read(dir.0.join(LOCK_FILE)).unwrap(), before);
        other.unlock().unwrap();
        assert_eq!(lock_holder(dir.0.as_path()), None);
        lock_world(dir.0.as_path()).unwrap();
        let empty = TempDir::new();
        assert_eq!(lock_holder(empty.0.as_path()), None);
        assert!(!empty.0.join(LOCK_FILE).exists(), "nothing created");
    }

    #[cfg(unix)]
    #[test]
    fn a_link_or_a_fifo_at_the_lock_path_is_refused() {
        let dir = TempDir::new();
        let outside = TempDir::new();
        let target = outside.0.as_path().join("victim");
        std::fs::write(&target, b"keep").unwrap();
        std::os::unix::fs::symlink(&target, dir.0.as_path().join(LOCK_FILE)).unwrap();
        assert!(matches!(
            lock_world(dir.0.as_path()),
            Err(CacheError::Io { .. })
        ));
        assert_eq!(std::fs::read(&target).unwrap(), b"keep");

        let dir = TempDir::new();
        let status = std::process::Command::new("mkfifo")
            .arg(dir.0.as_path().join(LOCK_FILE))
            .status()
            .unwrap();
        assert!(status.success());
        assert!(matches!(
            lock_world(dir.0.as_path()),
            Err(CacheError::Io { .. })
        ));
    }
}
