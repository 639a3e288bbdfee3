//! The disk pool: the [`TileStore`] trait (read, atomic write, remove, exists, list by key) and
//! its local-filesystem backend [`FsStore`].
//!
//! Keys are relative, `/`-separated paths of plain names (`height/00/0003/0005.png`); a key
//! with an empty, `.` or `..` component, a backslash, a NUL or a leading `/` is rejected with
//! [`CacheError::InvalidKey`], so no key can reach outside the store. Names starting with `.`
//! are reserved for temp files and never listed.

use crate::CacheError;
use std::fmt;
use std::fs::{self, File};
use std::io::{self, Read};
use std::path::{Path, PathBuf};

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
    /// Replaces (or creates) `key` with `bytes`, atomically.
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
/// A write whose process dies leaves at most a `.{name}.{pid}.{n}.tmp` file beside the target;
/// such files are never listed, and [`FsStore::open`] removes them.
#[derive(Debug, Clone)]
pub struct FsStore {
    root: PathBuf,
}

impl FsStore {
    /// A store over `root`, created if missing. Temp files left by writers that died are removed
    /// (only call this when no other process writes to the same folder).
    pub fn open(root: impl AsRef<Path>) -> Result<Self, CacheError> {
        let root = root.as_ref().to_path_buf();
        fs::create_dir_all(&root).map_err(|source| CacheError::Io {
            path: root.clone(),
            source,
        })?;
        let store = Self { root };
        store.remove_temp_files()?;
        Ok(store)
    }

    /// The root folder.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// The file of `key`.
    pub fn path_of(&self, key: &str) -> Result<PathBuf, CacheError> {
        check_key(key)?;
        Ok(self.root.join(key))
    }

    /// Removes leftover temp files (names starting with `.` and ending in `.tmp`) anywhere under
    /// the root; returns how many were removed.
    pub fn remove_temp_files(&self) -> Result<usize, CacheError> {
        let mut removed = 0;
        let mut stack = vec![self.root.clone()];
        while let Some(dir) = stack.pop() {
            for entry in read_dir(&dir)? {
                let (path, is_dir, name) = entry;
                if is_dir {
                    stack.push(path);
                } else if name.starts_with('.') && name.ends_with(".tmp") {
                    match fs::remove_file(&path) {
                        Ok(()) => removed += 1,
                        Err(e) if e.kind() == io::ErrorKind::NotFound => {}
                        Err(source) => return Err(CacheError::Io { path, source }),
                    }
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

/// Entries of `dir` as (path, is_dir, name); a missing folder has none.
fn read_dir(dir: &Path) -> Result<Vec<(PathBuf, bool, String)>, CacheError> {
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
        out.push((entry.path(), ft.is_dir(), name));
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
        file.take(max_len + 1)
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
        let path = self.path_of(key)?;
        self.ensure_parent(&path)?;
        terrain_core::io::write_atomic(&path, bytes).map_err(|source| CacheError::Write {
            key: key.to_owned(),
            source,
        })
    }

    fn remove(&self, key: &str) -> Result<(), CacheError> {
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
            self.root.join(prefix)
        };
        let mut out = Vec::new();
        if start.is_file() {
            out.push(prefix.to_owned());
            return Ok(out);
        }
        let mut stack = vec![(start, prefix.to_owned())];
        while let Some((dir, key_prefix)) = stack.pop() {
            for (path, is_dir, name) in read_dir(&dir)? {
                if name.starts_with('.') {
                    continue;
                }
                let key = if key_prefix.is_empty() {
                    name
                } else {
                    format!("{key_prefix}/{name}")
                };
                if is_dir {
                    stack.push((path, key));
                } else {
                    out.push(key);
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
}
