//! The disk pool: the [`TileStore`] trait (read, atomic write, remove, exists, list by key) and
//! its local-filesystem backend [`FsStore`].
//!
//! Keys are relative, `/`-separated paths of plain names (`height/00/0003/0005.png`); a key
//! with an empty, `.` or `..` component, a backslash, a NUL or a leading `/` is rejected with
//! [`CacheError::InvalidKey`], so no key can reach outside the store. Names starting with `.`
//! are reserved for temp files and never listed.

use crate::CacheError;
use crate::lock::{LOCK_FILE, WorldLock, lock_world};
use std::fmt;
use std::fs::{self, File};
use std::io::{self, Read};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Where tiles live: a local folder, a bucket, memory.
///
/// Contract for implementers:
/// - [`write`](TileStore::write) is atomic: a concurrent or later reader sees the old bytes or
///   the new ones, never a mix, even if the process dies in the middle.
/// - [`read`](TileStore::read) returns `Ok(None)` for a missing key and refuses (with
///   [`CacheError::TooLarge`]) an object longer than `max_len` without reading it whole.
/// - Every method may be called from many threads at once. Calls block; none is ever made from
///   the frame thread by this crate.
pub trait TileStore: Send + Sync + fmt::Debug {
    /// The bytes of `key`, `None` if there is no such object.
    fn read(&self, key: &str, max_len: u64) -> Result<Option<Vec<u8>>, CacheError>;
    /// Replaces (or creates) `key` with `bytes`, atomically. A store that detects concurrent
    /// writers (a bucket with conditional puts, `ObjectTileStore::s3`) refuses a write over a
    /// version it has not seen with [`CacheError::Conflict`]; read the key again first.
    fn write(&self, key: &str, bytes: &[u8]) -> Result<(), CacheError>;
    /// Removes `key`; removing a missing key is not an error.
    fn remove(&self, key: &str) -> Result<(), CacheError>;
    /// Whether `key` exists.
    fn exists(&self, key: &str) -> Result<bool, CacheError>;
    /// Every key under `prefix` (a folder prefix such as `height/00`, or `""` for all), sorted.
    fn list(&self, prefix: &str) -> Result<Vec<String>, CacheError>;
}

/// Checks that `key` is a clean relative path of plain names.
pub fn check_key(key: &str) -> Result<(), CacheError> {
    let bad = |reason| {
        Err(CacheError::InvalidKey {
            key: key.to_owned(),
            reason,
        })
    };
    if key.is_empty() {
        return bad("empty");
    }
    if key.contains('\\') || key.contains('\0') {
        return bad("contains a backslash or NUL");
    }
    for part in key.split('/') {
        if part.is_empty() || part == "." || part == ".." {
            return bad("has an empty, '.' or '..' component, or a leading or trailing '/'");
        }
        if part.starts_with('.') {
            return bad("a name starting with '.' (reserved for temp files)");
        }
    }
    Ok(())
}

/// Checks a list prefix: empty, or a clean key.
pub(crate) fn check_prefix(prefix: &str) -> Result<(), CacheError> {
    if prefix.is_empty() {
        Ok(())
    } else {
        check_key(prefix.trim_end_matches('/'))
    }
}

/// Tiles as files under a root folder, written atomically with terrain-core's writer (temp file
/// in the same folder, write, fsync, rename, folder fsync).
///
/// - **One writer per folder.** [`open`](FsStore::open) takes the folder's lock
///   ([`crate::lock`]) for as long as the store (or a clone) lives; a second process gets
///   [`CacheError::WorldLocked`] naming the owner. Tools that only read use
///   [`open_read_only`](FsStore::open_read_only), which takes no lock and refuses writes.
/// - **No links.** A key whose file or any folder on the way is a symbolic link is refused
///   with [`CacheError::LinkInWorld`]: a link could lead reads and writes out of the world.
/// - **Own temp files only.** A write whose process dies leaves at most a
///   `.{name}.{pid}.{n}.tmp` file beside the target; such files are never listed, and
///   [`open`](FsStore::open) removes them, but only in a folder that is a world (it holds a
///   manifest or an earlier store's lock file) and only names of exactly that pattern.
#[derive(Debug, Clone)]
pub struct FsStore {
    root: PathBuf,
    /// The folder's lock, `None` when opened read-only.
    lock: Option<Arc<WorldLock>>,
}

impl FsStore {
    /// A writing store over `root`, created if missing, holding the folder's lock. Temp files
    /// left by writers that died are removed (safe: no other process writes while we hold the
    /// lock).
    pub fn open(root: impl AsRef<Path>) -> Result<Self, CacheError> {
        let root = root.as_ref().to_path_buf();
        fs::create_dir_all(&root).map_err(|source| CacheError::Io {
            path: root.clone(),
            source,
        })?;
        // Decided before the lock file is created: a folder our lock file was already in has
        // had one of our stores writing to it, even if the manifest never came.
        let ours = root.join(crate::manifest::MANIFEST_KEY).is_file()
            || fs::symlink_metadata(root.join(LOCK_FILE)).is_ok_and(|m| m.is_file());
        let lock = lock_world(&root)?;
        let store = Self {
            root,
            lock: Some(lock),
        };
        if ours {
            store.remove_temp_files()?;
        }
        Ok(store)
    }

    /// A store over the existing folder `root` that only reads: no lock is taken, nothing is
    /// created or cleaned, and [`write`](TileStore::write) and [`remove`](TileStore::remove)
    /// fail with [`CacheError::ReadOnly`]. For viewers and checking tools; a writer may be
    /// replacing tiles meanwhile (each read still sees a whole file, old or new).
    pub fn open_read_only(root: impl AsRef<Path>) -> Result<Self, CacheError> {
        let root = root.as_ref().to_path_buf();
        match fs::metadata(&root) {
            Ok(m) if m.is_dir() => Ok(Self { root, lock: None }),
            Ok(_) => Err(CacheError::Io {
                path: root,
                source: io::Error::new(io::ErrorKind::InvalidInput, "not a folder"),
            }),
            Err(source) => Err(CacheError::Io { path: root, source }),
        }
    }

    /// The root folder.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// Whether this store may write (it was opened with [`open`](FsStore::open)).
    pub fn is_writable(&self) -> bool {
        self.lock.is_some()
    }

    /// The file of `key`, refused if it or a folder between the root and it is a link.
    pub fn path_of(&self, key: &str) -> Result<PathBuf, CacheError> {
        check_key(key)?;
        let mut path = self.root.clone();
        for part in key.split('/') {
            path.push(part);
            match fs::symlink_metadata(&path) {
                Ok(m) if m.file_type().is_symlink() => {
                    return Err(CacheError::LinkInWorld { path });
                }
                Ok(_) => {}
                // The rest does not exist yet (a missing tile, a write creating its folders).
                Err(e) if e.kind() == io::ErrorKind::NotFound => break,
                Err(source) => return Err(CacheError::Io { path, source }),
            }
        }
        Ok(self.root.join(key))
    }

    /// The error for a write on a read-only store.
    fn check_writable(&self, op: &'static str, key: &str) -> Result<(), CacheError> {
        match self.lock {
            Some(_) => Ok(()),
            None => Err(CacheError::ReadOnly {
                op,
                key: key.to_owned(),
            }),
        }
    }

    /// Removes leftover temp files of this crate's atomic writer (names `.{name}.{pid}.{n}.tmp`)
    /// in the root and its folders, never through a link; returns how many were removed.
    /// Fails with [`CacheError::ReadOnly`] on a read-only store.
    pub fn remove_temp_files(&self) -> Result<usize, CacheError> {
        self.check_writable("remove temp files in", "")?;
        let mut removed = 0;
        let mut stack = vec![self.root.clone()];
        while let Some(dir) = stack.pop() {
            for (path, kind, name) in read_dir(&dir)? {
                match kind {
                    EntryKind::Dir if !name.starts_with('.') => stack.push(path),
                    // This process's own temp files may belong to writes in flight through
                    // another store over the same folder (stores in one process share the lock).
                    EntryKind::File if is_writer_temp(&name) && !is_own_temp(&name) => {
                        match fs::remove_file(&path) {
                            Ok(()) => removed += 1,
                            Err(e) if e.kind() == io::ErrorKind::NotFound => {}
                            Err(source) => return Err(CacheError::Io { path, source }),
                        }
                    }
                    _ => {}
                }
            }
        }
        Ok(removed)
    }

    /// Creates the parent folders of `path` and syncs each folder that got a new entry, so the
    /// new path survives a power cut once the file itself is synced.
    fn ensure_parent(&self, path: &Path) -> Result<(), CacheError> {
        let Some(parent) = path.parent() else {
            return Ok(());
        };
        if parent.is_dir() {
            return Ok(());
        }
        // Walk up to the first existing ancestor, then create downwards, syncing each parent.
        let mut missing = Vec::new();
        let mut p = parent;
        while !p.is_dir() {
            missing.push(p.to_path_buf());
            match p.parent() {
                Some(q) => p = q,
                None => break,
            }
        }
        for dir in missing.iter().rev() {
            match fs::create_dir(dir) {
                Ok(()) => {}
                Err(e) if e.kind() == io::ErrorKind::AlreadyExists => continue,
                Err(source) => {
                    return Err(CacheError::Io {
                        path: dir.clone(),
                        source,
                    });
                }
            }
            if let Some(up) = dir.parent() {
                sync_dir(up)?;
            }
        }
        Ok(())
    }
}

fn sync_dir(dir: &Path) -> Result<(), CacheError> {
    #[cfg(unix)]
    {
        match File::open(dir).and_then(|d| d.sync_all()) {
            Ok(()) => Ok(()),
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::InvalidInput | io::ErrorKind::Unsupported
                ) =>
            {
                Ok(())
            }
            Err(source) => Err(CacheError::Io {
                path: dir.to_path_buf(),
                source,
            }),
        }
    }
    #[cfg(not(unix))]
    {
        let _ = dir;
        Ok(())
    }
}

/// What a folder entry is, without following links.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum EntryKind {
    Dir,
    File,
    Link,
    /// A named pipe, socket or device.
    Special,
}

/// Whether `name` is a temp file of terrain-core's atomic writer: `.{name}.{pid}.{n}.tmp`
/// with a non-empty name and decimal pid and counter. Nothing else is ever cleaned up.
fn is_writer_temp(name: &str) -> bool {
    let Some(inner) = name
        .strip_prefix('.')
        .and_then(|rest| rest.strip_suffix(".tmp"))
    else {
        return false;
    };
    let mut parts = inner.rsplitn(3, '.');
    let digits = |p: Option<&str>| {
        p.is_some_and(|p| !p.is_empty() && p.len() <= 20 && p.bytes().all(|b| b.is_ascii_digit()))
    };
    digits(parts.next()) && digits(parts.next()) && parts.next().is_some_and(|n| !n.is_empty())
}

/// Whether the writer temp file `name` was made by this process (`.{name}.{pid}.{n}.tmp`).
fn is_own_temp(name: &str) -> bool {
    let pid = std::process::id().to_string();
    name.strip_suffix(".tmp")
        .and_then(|rest| rest.rsplit_once('.'))
        .and_then(|(rest, _n)| rest.rsplit_once('.'))
        .is_some_and(|(_, p)| p == pid)
}

/// Entries of `dir` as (path, kind, name); a missing folder has none.
fn read_dir(dir: &Path) -> Result<Vec<(PathBuf, EntryKind, String)>, CacheError> {
    let io_err = |source| CacheError::Io {
        path: dir.to_path_buf(),
        source,
    };
    let iter = match fs::read_dir(dir) {
        Ok(it) => it,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(io_err(e)),
    };
    let mut out = Vec::new();
    for entry in iter {
        let entry = entry.map_err(io_err)?;
        let ft = entry.file_type().map_err(io_err)?;
        let name = entry.file_name().to_string_lossy().into_owned();
        let kind = if ft.is_symlink() {
            EntryKind::Link
        } else if ft.is_dir() {
            EntryKind::Dir
        } else if ft.is_file() {
            EntryKind::File
        } else {
            EntryKind::Special
        };
        out.push((entry.path(), kind, name));
    }
    Ok(out)
}

/// The error for a tile path that is not a regular file.
fn not_regular(path: &Path) -> CacheError {
    CacheError::Io {
        path: path.to_path_buf(),
        source: io::Error::new(
            io::ErrorKind::InvalidInput,
            "not a regular file (a directory, a named pipe or a device is no tile)",
        ),
    }
}

impl TileStore for FsStore {
    fn read(&self, key: &str, max_len: u64) -> Result<Option<Vec<u8>>, CacheError> {
        let path = self.path_of(key)?;
        let io_err = |source| CacheError::Io {
            path: path.clone(),
            source,
        };
        // Only regular files are tiles: opening a named pipe would block the loader until
        // something writes to it, and a directory or a device is no tile either. Checked
        // without opening (stat follows links), then again on the open handle.
        match fs::metadata(&path) {
            Ok(m) if !m.is_file() => return Err(not_regular(&path)),
            Ok(_) => {}
            Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(io_err(e)),
        }
        let file = match File::open(&path) {
            Ok(f) => f,
            Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(io_err(e)),
        };
        let meta = file.metadata().map_err(io_err)?;
        if !meta.is_file() {
            return Err(not_regular(&path));
        }
        let len = meta.len();
        if len > max_len {
            return Err(CacheError::TooLarge {
                key: key.to_owned(),
                len,
                max: max_len,
            });
        }
        let mut bytes = Vec::with_capacity(len as usize);
        // `take` bounds the read even if the file grows meanwhile.
        file.take(max_len.saturating_add(1))
            .read_to_end(&mut bytes)
            .map_err(io_err)?;
        if bytes.len() as u64 > max_len {
            return Err(CacheError::TooLarge {
                key: key.to_owned(),
                len: bytes.len() as u64,
                max: max_len,
            });
        }
        Ok(Some(bytes))
    }

    fn write(&self, key: &str, bytes: &[u8]) -> Result<(), CacheError> {
        self.check_writable("write", key)?;
        let path = self.path_of(key)?;
        self.ensure_parent(&path)?;
        terrain_core::io::write_atomic(&path, bytes).map_err(|source| CacheError::Write {
            key: key.to_owned(),
            source,
        })
    }

    fn remove(&self, key: &str) -> Result<(), CacheError> {
        self.check_writable("remove", key)?;
        let path = self.path_of(key)?;
        match fs::remove_file(&path) {
            Ok(()) => {
                if let Some(dir) = path.parent() {
                    sync_dir(dir)?;
                }
                Ok(())
            }
            Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(()),
            Err(source) => Err(CacheError::Io { path, source }),
        }
    }

    fn exists(&self, key: &str) -> Result<bool, CacheError> {
        let path = self.path_of(key)?;
        match fs::metadata(&path) {
            Ok(m) => Ok(m.is_file()),
            Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(false),
            Err(source) => Err(CacheError::Io { path, source }),
        }
    }

    fn list(&self, prefix: &str) -> Result<Vec<String>, CacheError> {
        check_prefix(prefix)?;
        let prefix = prefix.trim_end_matches('/');
        let start = if prefix.is_empty() {
            self.root.clone()
        } else {
            self.path_of(prefix)?
        };
        let mut out = Vec::new();
        if start.is_file() {
            out.push(prefix.to_owned());
            return Ok(out);
        }
        let mut stack = vec![(start, prefix.to_owned())];
        while let Some((dir, key_prefix)) = stack.pop() {
            for (path, kind, name) in read_dir(&dir)? {
                if name.starts_with('.') {
                    continue;
                }
                let key = if key_prefix.is_empty() {
                    name
                } else {
                    format!("{key_prefix}/{name}")
                };
                match kind {
                    EntryKind::Dir => stack.push((path, key)),
                    EntryKind::File => out.push(key),
                    EntryKind::Link => return Err(CacheError::LinkInWorld { path }),
                    // Not a tile and never one: a pipe or device is skipped, as readers refuse it.
                    EntryKind::Special => {}
                }
            }
        }
        out.sort();
        Ok(out)
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A fresh, unique temp folder (removed by the caller when it matters).
    pub(crate) fn temp_dir(tag: &str) -> PathBuf {
        use std::sync::atomic::{AtomicU32, Ordering};
        static N: AtomicU32 = AtomicU32::new(0);
        let dir = std::env::temp_dir().join(format!(
            "terrain-cache-{tag}-{}-{}",
            std::process::id(),
            N.fetch_add(1, Ordering::Relaxed)
        ));
        let _ = fs::remove_dir_all(&dir);
        dir
    }

    /// The behaviour every backend must have.
    pub(crate) fn exercise_store(store: &dyn TileStore) {
        assert_eq!(store.read("a/b.png", 100).unwrap(), None);
        assert!(!store.exists("a/b.png").unwrap());
        store.write("a/b.png", b"hello").unwrap();
        store.write("a/c/d.png", b"x").unwrap();
        store.write("top.json", b"{}").unwrap();
        assert!(store.exists("a/b.png").unwrap());
        assert_eq!(store.read("a/b.png", 100).unwrap().unwrap(), b"hello");
        assert!(matches!(
            store.read("a/b.png", 3),
            Err(CacheError::TooLarge { len: 5, max: 3, .. })
        ));
        store.write("a/b.png", b"bye").unwrap();
        assert_eq!(store.read("a/b.png", 100).unwrap().unwrap(), b"bye");
        assert_eq!(store.list("a").unwrap(), vec!["a/b.png", "a/c/d.png"]);
        assert_eq!(
            store.list("").unwrap(),
            vec!["a/b.png", "a/c/d.png", "top.json"]
        );
        assert_eq!(store.list("zzz").unwrap(), Vec::<String>::new());
        store.remove("a/b.png").unwrap();
        store.remove("a/b.png").unwrap();
        assert_eq!(store.read("a/b.png", 100).unwrap(), None);
        for bad in [
            "", "/abs", "a/../b", "a//b", "a/./b", ".hidden", "a\\b", "a/",
        ] {
            assert!(
                matches!(store.write(bad, b"x"), Err(CacheError::InvalidKey { .. })),
                "{bad:?}"
            );
            assert!(store.read(bad, 10).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn fs_store_contract() {
        let dir = temp_dir("fs");
        let store = FsStore::open(&dir).unwrap();
        exercise_store(&store);
        // A leftover temp file is not listed and is removed on open.
        fs::write(dir.join("a/.d.png.1.2.tmp"), b"partial").unwrap();
        assert_eq!(store.list("a").unwrap(), vec!["a/c/d.png"]);
        let store = FsStore::open(&dir).unwrap();
        assert!(!dir.join("a/.d.png.1.2.tmp").exists());
        assert_eq!(store.remove_temp_files().unwrap(), 0);
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn only_the_writers_own_temp_files_in_a_world_are_cleaned() {
        let dir = temp_dir("clean");
        fs::create_dir_all(dir.join("height/00")).unwrap();
        let temps = ["height/00/.0001.tile.77.3.tmp", ".manifest.json.1.0.tmp"];
        let kept = [
            "height/00/.notes.tmp",
            "height/00/.x.tmp",
            "height/00/.a.b.c.tmp",
            "height/00/.a.1.x.tmp",
            ".hidden/.a.1.2.tmp",
        ];
        fs::create_dir_all(dir.join(".hidden")).unwrap();
        for name in temps.iter().chain(&kept) {
            fs::write(dir.join(name), b"x").unwrap();
        }
        // Not a world yet (no manifest, no lock file): nothing is touched.
        drop(FsStore::open(&dir).unwrap());
        for name in temps.iter().chain(&kept) {
            assert!(
                dir.join(name).exists(),
                "{name} was removed from a non-world"
            );
        }
        // This process's own temps may be writes in flight of another store: kept.
        let own = format!("height/00/.0002.tile.{}.5.tmp", std::process::id());
        fs::write(dir.join(&own), b"x").unwrap();
        // Now it has our lock file: the writer's temps go, nothing else does.
        drop(FsStore::open(&dir).unwrap());
        for name in temps {
            assert!(!dir.join(name).exists(), "{name} was kept");
        }
        for name in kept.iter().copied().chain([own.as_str()]) {
            assert!(dir.join(name).exists(), "{name} was removed");
        }
        #[cfg(unix)]
        {
            // A linked folder is not followed.
            let outside = temp_dir("clean-outside");
            fs::create_dir_all(&outside).unwrap();
            fs::write(outside.join(".t.1.2.tmp"), b"x").unwrap();
            std::os::unix::fs::symlink(&outside, dir.join("height/01")).unwrap();
            drop(FsStore::open(&dir).unwrap());
            assert!(outside.join(".t.1.2.tmp").exists());
            fs::remove_dir_all(&outside).unwrap();
        }
        fs::remove_dir_all(&dir).unwrap();
    }

    #[cfg(unix)]
    #[test]
    fn links_inside_the_world_are_refused() {
        let dir = temp_dir("links");
        let outside = temp_dir("links-outside");
        fs::create_dir_all(outside.join("00")).unwrap();
        fs::write(outside.join("00/0000.tile"), b"secret").unwrap();
        let store = FsStore::open(&dir).unwrap();
        std::os::unix::fs::symlink(&outside, dir.join("height")).unwrap();
        let link = |r: Result<_, CacheError>| matches!(r, Err(CacheError::LinkInWorld { .. }));
        assert!(link(store.read("height/00/0000.tile", 100).map(|_| ())));
        assert!(link(store.write("height/00/0001.tile", b"x")));
        assert!(link(store.exists("height/00/0000.tile").map(|_| ())));
        assert!(link(store.list("").map(|_| ())));
        assert!(link(store.list("height").map(|_| ())));
        assert!(!outside.join("00/0001.tile").exists());
        // A tile file that is a link is refused too.
        fs::remove_file(dir.join("height")).unwrap();
        fs::create_dir_all(dir.join("height/00")).unwrap();
        std::os::unix::fs::symlink(
            outside.join("00/0000.tile"),
            dir.join("height/00/0000.tile"),
        )
        .unwrap();
        assert!(link(store.read("height/00/0000.tile", 100).map(|_| ())));
        drop(store);
        fs::remove_dir_all(&dir).unwrap();
        fs::remove_dir_all(&outside).unwrap();
    }

    #[test]
    fn a_read_only_store_reads_and_refuses_every_change() {
        let dir = temp_dir("ro");
        let writer = FsStore::open(&dir).unwrap();
        writer.write("a/b.tile", b"bytes").unwrap();
        fs::write(dir.join("a/.b.tile.1.2.tmp"), b"x").unwrap();
        let reader = FsStore::open_read_only(&dir).unwrap();
        assert!(!reader.is_writable() && writer.is_writable());
        assert_eq!(reader.read("a/b.tile", 100).unwrap().unwrap(), b"bytes");
        assert_eq!(reader.list("").unwrap(), vec!["a/b.tile"]);
        let ro = |r: Result<_, CacheError>| matches!(r, Err(CacheError::ReadOnly { .. }));
        assert!(ro(reader.write("a/c.tile", b"x")));
        assert!(ro(reader.remove("a/b.tile")));
        assert!(ro(reader.remove_temp_files().map(|_| ())));
        assert!(dir.join("a/.b.tile.1.2.tmp").exists());
        assert!(FsStore::open_read_only(dir.join("missing")).is_err());
        assert!(!dir.join("missing").exists());
        drop(writer);
        fs::remove_dir_all(&dir).unwrap();
    }
}
