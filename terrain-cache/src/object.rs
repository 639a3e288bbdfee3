//! The [`TileStore`] backend over the `object_store` crate (Apache Arrow's): local files,
//! memory, and S3 / GCS / Azure buckets by URL when the `aws` / `gcp` / `azure` features are on.
//!
//! `object_store` is async; this backend owns a small current-thread tokio runtime and blocks on
//! it inside each call. Calls are made only from the pool's worker threads and the builder's
//! rayon threads, never from the frame thread; a call made from inside another async runtime is
//! refused with [`CacheError::InsideAsyncRuntime`] instead of deadlocking.
//!
//! Atomicity comes from the store: `put` replaces an object whole (buckets), and
//! `LocalFileSystem` stages the bytes in a temp file and renames it (with fsync when built with
//! [`ObjectTileStore::local`]).

use crate::CacheError;
use crate::store::{TileStore, check_key, check_prefix};
use futures_util::TryStreamExt;
use object_store::path::Path as ObjectPath;
use object_store::{ObjectStore, ObjectStoreExt, PutPayload};
use std::fmt;
use std::sync::Arc;

/// Tiles in an `object_store` store, under a key prefix.
pub struct ObjectTileStore {
    store: Arc<dyn ObjectStore>,
    prefix: String,
    runtime: tokio::runtime::Runtime,
}

impl fmt::Debug for ObjectTileStore {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("ObjectTileStore")
            .field("store", &self.store.to_string())
            .field("prefix", &self.prefix)
            .finish()
    }
}

impl ObjectTileStore {
    /// Wraps any `object_store` store; keys are placed under `prefix` (may be empty).
    pub fn new(store: Arc<dyn ObjectStore>, prefix: &str) -> Result<Self, CacheError> {
        let prefix = prefix.trim_matches('/').to_owned();
        check_prefix(&prefix)?;
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .map_err(|e| CacheError::Worker {
                what: "object store runtime",
                reason: e.to_string(),
            })?;
        Ok(Self {
            store,
            prefix,
            runtime,
        })
    }

    /// An in-memory store (tests, scratch worlds).
    pub fn in_memory() -> Result<Self, CacheError> {
        Self::new(Arc::new(object_store::memory::InMemory::new()), "")
    }

    /// `object_store`'s `LocalFileSystem` rooted at `root` (created if missing), with fsync on.
    pub fn local(root: impl AsRef<std::path::Path>) -> Result<Self, CacheError> {
        let root = root.as_ref();
        std::fs::create_dir_all(root).map_err(|source| CacheError::Io {
            path: root.to_path_buf(),
            source,
        })?;
        let fs = object_store::local::LocalFileSystem::new_with_prefix(root)
            .map_err(|source| CacheError::ObjectStore {
                op: "open",
                key: root.display().to_string(),
                source,
            })?
            .with_fsync(true);
        Self::new(Arc::new(fs), "")
    }

    /// A store from a URL: `file:///path`, `memory:///`, and with the matching feature
    /// `s3://bucket/prefix`, `gs://bucket/prefix`, `az://container/prefix`. Credentials and
    /// regions come from the environment as `object_store` reads them.
    pub fn from_url(url: &str) -> Result<Self, CacheError> {
        let invalid = |reason: String| CacheError::InvalidUrl {
            url: url.to_owned(),
            reason,
        };
        let parsed = url::Url::parse(url).map_err(|e| invalid(e.to_string()))?;
        let (store, path) = object_store::parse_url(&parsed).map_err(|e| invalid(e.to_string()))?;
        Self::new(Arc::from(store), path.as_ref())
    }

    /// The wrapped store.
    pub fn inner(&self) -> &Arc<dyn ObjectStore> {
        &self.store
    }

    fn path(&self, key: &str) -> Result<ObjectPath, CacheError> {
        check_key(key)?;
        let full = if self.prefix.is_empty() {
            key.to_owned()
        } else {
            format!("{}/{key}", self.prefix)
        };
        ObjectPath::parse(&full).map_err(|e| CacheError::InvalidKey {
            key: key.to_owned(),
            reason: if e.to_string().is_empty() {
                "rejected by object_store"
            } else {
                "not a valid object_store path"
            },
        })
    }

    fn block_on<F: std::future::Future>(
        &self,
        op: &'static str,
        fut: F,
    ) -> Result<F::Output, CacheError> {
        if tokio::runtime::Handle::try_current().is_ok() {
            return Err(CacheError::InsideAsyncRuntime { op });
        }
        Ok(self.runtime.block_on(fut))
    }

    fn os_err<'k>(
        op: &'static str,
        key: &'k str,
    ) -> impl FnOnce(object_store::Error) -> CacheError + 'k {
        move |source| CacheError::ObjectStore {
            op,
            key: key.to_owned(),
            source,
        }
    }
}

impl TileStore for ObjectTileStore {
    fn read(&self, key: &str, max_len: u64) -> Result<Option<Vec<u8>>, CacheError> {
        let path = self.path(key)?;
        self.block_on("get", async {
            let got = match self.store.get(&path).await {
                Ok(g) => g,
                Err(object_store::Error::NotFound { .. }) => return Ok(None),
                Err(e) => return Err(Self::os_err("get", key)(e)),
            };
            let len = got.meta.size;
            if len > max_len {
                return Err(CacheError::TooLarge {
                    key: key.to_owned(),
                    len,
                    max: max_len,
                });
            }
            let bytes = got.bytes().await.map_err(Self::os_err("get", key))?;
            if bytes.len() as u64 > max_len {
                return Err(CacheError::TooLarge {
                    key: key.to_owned(),
                    len: bytes.len() as u64,
                    max: max_len,
                });
            }
            Ok(Some(bytes.to_vec()))
        })?
    }

    fn write(&self, key: &str, bytes: &[u8]) -> Result<(), CacheError> {
        let path = self.path(key)?;
        let payload = PutPayload::from(bytes.to_vec());
        self.block_on("put", self.store.put(&path, payload))?
            .map(|_| ())
            .map_err(Self::os_err("put", key))
    }

    fn remove(&self, key: &str) -> Result<(), CacheError> {
        let path = self.path(key)?;
        match self.block_on("delete", self.store.delete(&path))? {
            Ok(()) | Err(object_store::Error::NotFound { .. }) => Ok(()),
            Err(e) => Err(Self::os_err("delete", key)(e)),
        }
    }

    fn exists(&self, key: &str) -> Result<bool, CacheError> {
        let path = self.path(key)?;
        match self.block_on("head", self.store.head(&path))? {
            Ok(_) => Ok(true),
            Err(object_store::Error::NotFound { .. }) => Ok(false),
            Err(e) => Err(Self::os_err("head", key)(e)),
        }
    }

    fn list(&self, prefix: &str) -> Result<Vec<String>, CacheError> {
        check_prefix(prefix)?;
        let prefix = prefix.trim_end_matches('/');
        let full = [self.prefix.as_str(), prefix]
            .into_iter()
            .filter(|s| !s.is_empty())
            .collect::<Vec<_>>()
            .join("/");
        let list_path = if full.is_empty() {
            None
        } else {
            Some(
                ObjectPath::parse(&full).map_err(|_| CacheError::InvalidKey {
                    key: prefix.to_owned(),
                    reason: "not a valid object_store path",
                })?,
            )
        };
        let metas: Vec<object_store::ObjectMeta> = self
            .block_on("list", self.store.list(list_path.as_ref()).try_collect())?
            .map_err(Self::os_err("list", prefix))?;
        let strip = if self.prefix.is_empty() {
            0
        } else {
            self.prefix.len() + 1
        };
        let mut keys: Vec<String> = metas
            .into_iter()
            .map(|m| {
                m.location
                    .as_ref()
                    .get(strip..)
                    .unwrap_or_default()
                    .to_owned()
            })
            .filter(|k| !k.is_empty() && !k.split('/').any(|p| p.starts_with('.')))
            .collect();
        keys.sort();
        Ok(keys)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::tests::{exercise_store, temp_dir};

    #[test]
    fn in_memory_contract() {
        exercise_store(&ObjectTileStore::in_memory().unwrap());
    }

    #[test]
    fn local_file_system_contract() {
        let dir = temp_dir("os-local");
        exercise_store(&ObjectTileStore::local(&dir).unwrap());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn urls() {
        let s = ObjectTileStore::from_url("memory:///some/prefix").unwrap();
        s.write("k.png", b"1").unwrap();
        assert_eq!(s.list("").unwrap(), vec!["k.png"]);
        assert!(matches!(
            ObjectTileStore::from_url("not a url"),
            Err(CacheError::InvalidUrl { .. })
        ));
        #[cfg(not(feature = "aws"))]
        assert!(matches!(
            ObjectTileStore::from_url("s3://bucket/x"),
            Err(CacheError::InvalidUrl { .. })
        ));
    }
}
