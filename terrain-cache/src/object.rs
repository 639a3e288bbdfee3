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
//!
//! # Over a network: retries, timeouts, conflicts
//!
//! Bucket stores are configured by an [`ObjectStoreConfig`] (its defaults are documented per
//! field); `ObjectTileStore::s3` (feature `aws`) and [`ObjectTileStore::from_url`] apply it.
//!
//! - **Each HTTP request** is bounded by `request_timeout` (a stalled server is abandoned) and
//!   `connect_timeout`, and retried by `object_store`'s own `RetryConfig` (set explicitly from
//!   `max_retries`, `retry_timeout` and the backoff fields, never left to the crate's defaults):
//!   5xx answers (`503 SlowDown`, `500 InternalError`), 429, 408 and connection failures are
//!   retried with exponential backoff; a GET body cut off midway is resumed by a ranged GET
//!   pinned to the same ETag. `object_store` does not retry a *conditional* PUT whose
//!   connection dropped after the request was sent (it cannot know whether it landed).
//! - **Each store operation** (read, write, remove, exists, list) is then tried up to
//!   `attempts` times in all when it failed for a transient reason (`object_store`'s
//!   `Generic` error: retries exhausted, a timeout, a dropped connection), sleeping
//!   `init_backoff`, doubled per attempt up to `max_backoff`, between tries. Errors that
//!   retrying cannot fix (not found, permission, a precondition) are returned at once. So a
//!   read fails only after `attempts x (max_retries + 1)` requests at most, bounded in time by
//!   `attempts x retry_timeout` plus the backoffs; the RAM pool then treats the tile as
//!   failed and a coarser loaded tile stands in for it until it is retried
//!   ([`PoolConfig::retry_failed_frames`](crate::PoolConfig::retry_failed_frames)).
//! - **Writes land whole or not at all**: one PUT of the whole object (a tile is far below
//!   the multipart threshold), which S3 applies atomically; a write that failed is retried as
//!   above. A retried conditional PUT can find its own earlier attempt already landed (the
//!   answer was lost): when the store then refuses the precondition, the object is read back
//!   and, if it holds exactly the bytes being written, the write counts as done.
//!
//! ## Two writers of one tile
//!
//! With `conflict_detection` on (the default of bucket stores; off for [`ObjectTileStore::new`],
//! [`ObjectTileStore::in_memory`] and [`ObjectTileStore::local`], which serve one process),
//! the store remembers, per key, the version it last saw: the ETag (and version id, where the
//! bucket has versioning) of the object a [`read`](TileStore::read) returned or a
//! [`write`](TileStore::write) created, or that the key was absent (a read found nothing, or
//! this store removed it). A write is then conditional on that version:
//!
//! | last seen | the PUT is | refused when |
//! |---|---|---|
//! | a version | `PutMode::Update` (`If-Match: <etag>`) | the object changed or was deleted |
//! | absent | `PutMode::Create` (`If-None-Match: *`) | someone created it meanwhile |
//! | nothing (never read, or forgotten) | `PutMode::Overwrite` (blind) | never |
//!
//! A refused write fails with [`CacheError::Conflict`] and the remembered version is kept, so
//! writing the same stale data again fails again: the writer must read the key again (taking
//! the other writer's version) and reapply its change. A RAM pool whose write-back conflicts
//! keeps the tile dirty and reports the error in [`RamPool::errors`](crate::RamPool::errors).
//! The rule holds between store instances (processes, machines); threads sharing one instance
//! share its memory of each key, and the pool already writes each tile from one thread at a
//! time. The memory is bounded: at most `version_capacity` keys (65 536 by default, a few MB),
//! the oldest forgotten first, after which a write of a forgotten key is blind again; keep it
//! above the number of tiles a pool holds. Removing a key (`World::write_tile` of an all-zero
//! tile) is not conditional: `object_store` has no conditional delete.
//!
//! Tiles derived from others (coarser levels and each level's `bounds.bin`, which
//! `rebuild_ancestors` rewrites after a write-back) follow the same rule: if another machine
//! rewrote such a tile since this store last read it, the rewrite conflicts even when the
//! two changed different children.

use crate::CacheError;
use crate::store::{TileStore, check_key, check_prefix};
use futures_util::TryStreamExt;
use object_store::path::Path as ObjectPath;
use object_store::{
    ObjectStore, ObjectStoreExt, PutMode, PutOptions, PutPayload, PutResult, UpdateVersion,
};
use std::collections::{HashMap, VecDeque};
use std::fmt;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

/// How an [`ObjectTileStore`] talks to a remote store: timeouts, the two levels of retries
/// and conflict detection (see the [module documentation](self)).
#[derive(Debug, Clone, PartialEq)]
pub struct ObjectStoreConfig {
    /// Longest one HTTP request may take, answer body included (30 s): a server that stalls
    /// longer is abandoned and the request retried.
    pub request_timeout: Duration,
    /// Longest a connection may take to open (5 s).
    pub connect_timeout: Duration,
    /// `object_store`'s retries of one request after 5xx / 429 / 408 answers and connection
    /// failures (4).
    pub max_retries: usize,
    /// `object_store` stops retrying one request once this much time has passed since its
    /// first try (60 s).
    pub retry_timeout: Duration,
    /// First backoff, both for `object_store`'s request retries and for this store's
    /// operation attempts; doubled after each (100 ms).
    pub init_backoff: Duration,
    /// Largest backoff (5 s).
    pub max_backoff: Duration,
    /// Tries of one store operation in all, when it failed for a transient reason (3, at
    /// least 1).
    pub attempts: u32,
    /// Whether writes are conditional on the version last seen (true).
    pub conflict_detection: bool,
    /// Most keys whose last seen version is remembered (65 536).
    pub version_capacity: usize,
}

impl Default for ObjectStoreConfig {
    fn default() -> Self {
        Self {
            request_timeout: Duration::from_secs(30),
            connect_timeout: Duration::from_secs(5),
            max_retries: 4,
            retry_timeout: Duration::from_secs(60),
            init_backoff: Duration::from_millis(100),
            max_backoff: Duration::from_secs(5),
            attempts: 3,
            conflict_detection: true,
            version_capacity: 1 << 16,
        }
    }
}

impl ObjectStoreConfig {
    /// `object_store`'s retry settings for one request, from these fields.
    #[cfg(any(feature = "aws", feature = "gcp", feature = "azure"))]
    pub fn retry_config(&self) -> object_store::RetryConfig {
        object_store::RetryConfig {
            backoff: object_store::BackoffConfig {
                init_backoff: self.init_backoff,
                max_backoff: self.max_backoff,
                base: 2.0,
            },
            max_retries: self.max_retries,
            retry_timeout: self.retry_timeout,
        }
    }

    /// The backoff before operation attempt `attempt + 1` (after `attempt` failures).
    fn backoff(&self, attempt: u32) -> Duration {
        let factor = 1u32 << attempt.saturating_sub(1).min(16);
        self.init_backoff
            .saturating_mul(factor)
            .min(self.max_backoff)
    }

    fn check(&self) -> Result<(), CacheError> {
        let bad = |what, value: f64, expected| {
            Err(CacheError::OutOfRange {
                what,
                value,
                expected,
            })
        };
        if self.attempts == 0 || self.attempts > 100 {
            return bad(
                "ObjectStoreConfig::attempts",
                self.attempts as f64,
                "1..=100",
            );
        }
        if self.request_timeout.is_zero() {
            return bad("ObjectStoreConfig::request_timeout", 0.0, "more than 0 s");
        }
        if self.connect_timeout.is_zero() {
            return bad("ObjectStoreConfig::connect_timeout", 0.0, "more than 0 s");
        }
        if self.version_capacity == 0 && self.conflict_detection {
            return bad(
                "ObjectStoreConfig::version_capacity",
                0.0,
                "at least 1 with conflict detection on",
            );
        }
        Ok(())
    }
}

/// What a store last saw of a key.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Seen {
    /// The key did not exist.
    Absent,
    /// The object's version.
    Version(UpdateVersion),
}

/// The last seen version per key, bounded: the oldest entries are forgotten first.
#[derive(Debug, Default)]
struct Versions {
    map: HashMap<String, (Seen, u64)>,
    /// Keys in the order they were last set, with the tick they were set at; entries whose
    /// tick no longer matches the map's are stale and skipped.
    order: VecDeque<(String, u64)>,
    tick: u64,
}

impl Versions {
    fn get(&self, key: &str) -> Option<&Seen> {
        self.map.get(key).map(|(s, _)| s)
    }

    fn set(&mut self, key: &str, seen: Option<Seen>, capacity: usize) {
        let Some(seen) = seen else {
            self.map.remove(key);
            return;
        };
        self.tick += 1;
        self.map.insert(key.to_owned(), (seen, self.tick));
        self.order.push_back((key.to_owned(), self.tick));
        while self.map.len() > capacity {
            let Some((k, t)) = self.order.pop_front() else {
                break;
            };
            if self.map.get(&k).is_some_and(|(_, mt)| *mt == t) {
                self.map.remove(&k);
            }
        }
        // Keep the order queue within twice the map (stale entries of rewritten keys).
        if self.order.len() > 2 * capacity.max(self.map.len()) + 16 {
            let map = &self.map;
            self.order
                .retain(|(k, t)| map.get(k).is_some_and(|(_, mt)| mt == t));
        }
    }
}

/// The version an object store reported, `None` when it reported none (a later write of the
/// key is then blind).
fn seen_of(e_tag: Option<String>, version: Option<String>) -> Option<Seen> {
    (e_tag.is_some() || version.is_some())
        .then_some(Seen::Version(UpdateVersion { e_tag, version }))
}

/// An object's bytes and the version it was read at, `None` for a missing key.
type Fetched = Option<(Vec<u8>, Option<Seen>)>;

/// Whether retrying the operation may help: `object_store`'s catch-all for failed requests
/// (retries exhausted, timeouts, dropped connections, 5xx) as opposed to definite answers.
fn transient(e: &object_store::Error) -> bool {
    matches!(
        e,
        object_store::Error::Generic { .. } | object_store::Error::JoinError { .. }
    )
}

/// Tiles in an `object_store` store, under a key prefix.
pub struct ObjectTileStore {
    store: Arc<dyn ObjectStore>,
    prefix: String,
    runtime: tokio::runtime::Runtime,
    config: ObjectStoreConfig,
    versions: Mutex<Versions>,
}

impl fmt::Debug for ObjectTileStore {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("ObjectTileStore")
            .field("store", &self.store.to_string())
            .field("prefix", &self.prefix)
            .field("config", &self.config)
            .finish()
    }
}

impl ObjectTileStore {
    /// Wraps any `object_store` store; keys are placed under `prefix` (may be empty). Each
    /// operation is tried once and writes are not conditional (a store of one process); see
    /// [`with_config`](Self::with_config) for a shared remote store.
    pub fn new(store: Arc<dyn ObjectStore>, prefix: &str) -> Result<Self, CacheError> {
        let config = ObjectStoreConfig {
            attempts: 1,
            conflict_detection: false,
            ..ObjectStoreConfig::default()
        };
        Self::with_config(store, prefix, config)
    }

    /// Wraps any `object_store` store with the operation attempts and conflict detection of
    /// `config` (its timeouts and request retries belong to the store, which was built
    /// already: for S3 use `ObjectTileStore::s3`, feature `aws`). Conflict detection needs a store that
    /// implements `PutMode::Create` and `PutMode::Update` (S3 with conditional puts,
    /// `InMemory`; not `LocalFileSystem`).
    pub fn with_config(
        store: Arc<dyn ObjectStore>,
        prefix: &str,
        config: ObjectStoreConfig,
    ) -> Result<Self, CacheError> {
        config.check()?;
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
            config,
            versions: Mutex::new(Versions::default()),
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

    /// An S3 (or S3-compatible) bucket from `builder` (bucket, region, credentials, endpoint
    /// as the caller set them), with `config`'s timeouts and request retries applied and
    /// conditional puts on (`S3ConditionalPut::ETagMatch`: `If-Match` / `If-None-Match`,
    /// which AWS S3 has honoured since 2024), keys under `prefix`.
    ///
    /// ```no_run
    /// use object_store::aws::AmazonS3Builder;
    /// use terrain_cache::ObjectTileStore;
    /// use terrain_cache::object::ObjectStoreConfig;
    /// let builder = AmazonS3Builder::from_env().with_bucket_name("worlds");
    /// let store = ObjectTileStore::s3(builder, "alps", ObjectStoreConfig::default())?;
    /// # Ok::<(), terrain_cache::CacheError>(())
    /// ```
    #[cfg(feature = "aws")]
    pub fn s3(
        builder: object_store::aws::AmazonS3Builder,
        prefix: &str,
        config: ObjectStoreConfig,
    ) -> Result<Self, CacheError> {
        use object_store::ClientConfigKey;
        use object_store::aws::{AmazonS3ConfigKey, S3ConditionalPut};
        config.check()?;
        let ms = |d: Duration| format!("{}ms", d.as_millis().max(1));
        let s3 = builder
            .with_retry(config.retry_config())
            .with_config(
                AmazonS3ConfigKey::Client(ClientConfigKey::Timeout),
                ms(config.request_timeout),
            )
            .with_config(
                AmazonS3ConfigKey::Client(ClientConfigKey::ConnectTimeout),
                ms(config.connect_timeout),
            )
            .with_conditional_put(S3ConditionalPut::ETagMatch)
            .build()
            .map_err(|source| CacheError::ObjectStore {
                op: "open",
                key: prefix.to_owned(),
                source,
            })?;
        Self::with_config(Arc::new(s3), prefix, config)
    }

    /// A store from a URL: `file:///path`, `memory:///`, and with the matching feature
    /// `s3://bucket/prefix`, `gs://bucket/prefix`, `az://container/prefix`. Credentials and
    /// regions come from the environment as `object_store` reads them (for S3 also
    /// `AWS_ENDPOINT` and `AWS_ALLOW_HTTP`, for S3-compatible servers); S3 buckets get
    /// [`ObjectStoreConfig::default`] through `ObjectTileStore::s3`.
    pub fn from_url(url: &str) -> Result<Self, CacheError> {
        let invalid = |reason: String| CacheError::InvalidUrl {
            url: url.to_owned(),
            reason,
        };
        let parsed = url::Url::parse(url).map_err(|e| invalid(e.to_string()))?;
        #[cfg(feature = "aws")]
        if let Ok((object_store::ObjectStoreScheme::AmazonS3, path)) =
            object_store::ObjectStoreScheme::parse(&parsed)
        {
            let builder = object_store::aws::AmazonS3Builder::from_env().with_url(url);
            return Self::s3(builder, path.as_ref(), ObjectStoreConfig::default()).map_err(|e| {
                match e {
                    CacheError::ObjectStore { source, .. } => invalid(source.to_string()),
                    e => e,
                }
            });
        }
        let (store, path) = object_store::parse_url(&parsed).map_err(|e| invalid(e.to_string()))?;
        Self::new(Arc::from(store), path.as_ref())
    }

    /// The wrapped store.
    pub fn inner(&self) -> &Arc<dyn ObjectStore> {
        &self.store
    }

    /// The store's settings.
    pub fn config(&self) -> &ObjectStoreConfig {
        &self.config
    }

    /// Forgets the version last seen of `key`: the next write of it is blind (an explicit
    /// decision to overwrite whatever another writer put there).
    pub fn forget_version(&self, key: &str) {
        self.versions
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .set(key, None, self.config.version_capacity);
    }

    /// How many keys have a remembered version (at most
    /// [`version_capacity`](ObjectStoreConfig::version_capacity)).
    pub fn remembered_versions(&self) -> usize {
        self.versions
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .map
            .len()
    }

    /// The versions' clock now: a read notes it before its GET.
    fn version_clock(&self) -> u64 {
        self.versions
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .tick
    }

    /// [`remember`](Self::remember) for a read whose GET started at `started` (the clock):
    /// skipped when the key was set since (a write, or a later read, saw a newer state; the
    /// older answer arriving last must not replace it, or the next write would conflict with
    /// our own).
    fn remember_read(&self, key: &str, seen: Option<Seen>, started: u64) {
        if !self.config.conflict_detection {
            return;
        }
        let mut versions = self.versions.lock().unwrap_or_else(PoisonError::into_inner);
        if versions
            .map
            .get(key)
            .is_some_and(|(_, set_at)| *set_at > started)
        {
            return;
        }
        versions.set(key, seen, self.config.version_capacity);
    }

    fn remember(&self, key: &str, seen: Option<Seen>) {
        if self.config.conflict_detection {
            self.versions
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .set(key, seen, self.config.version_capacity);
        }
    }

    fn put_mode(&self, key: &str) -> PutMode {
        if !self.config.conflict_detection {
            return PutMode::Overwrite;
        }
        let versions = self.versions.lock().unwrap_or_else(PoisonError::into_inner);
        match versions.get(key) {
            Some(Seen::Absent) => PutMode::Create,
            Some(Seen::Version(v)) => PutMode::Update(v.clone()),
            None => PutMode::Overwrite,
        }
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

    /// Runs `f` up to `attempts` times while it fails with a transient `object_store` error,
    /// backing off between tries.
    fn attempt<T>(
        &self,
        op: &'static str,
        key: &str,
        mut f: impl FnMut() -> Result<Result<T, object_store::Error>, CacheError>,
    ) -> Result<Result<T, object_store::Error>, CacheError> {
        let mut tries = 0;
        loop {
            tries += 1;
            match f()? {
                Err(e) if transient(&e) && tries < self.config.attempts => {
                    let wait = self.config.backoff(tries);
                    tracing::debug!(op, key, tries, error = %e, ?wait, "object store operation failed; trying again");
                    std::thread::sleep(wait);
                }
                r => return Ok(r),
            }
        }
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

    /// One GET of `key`: its bytes and version, `None` if missing. Transient failures are
    /// returned inside, for [`attempt`](Self::attempt).
    fn get_once(
        &self,
        path: &ObjectPath,
        key: &str,
        max_len: u64,
    ) -> Result<Result<Fetched, object_store::Error>, CacheError> {
        self.block_on("get", async {
            let got = match self.store.get(path).await {
                Ok(g) => g,
                Err(object_store::Error::NotFound { .. }) => return Ok(Ok(None)),
                Err(e) => return Ok(Err(e)),
            };
            let len = got.meta.size;
            if len > max_len {
                return Err(CacheError::TooLarge {
                    key: key.to_owned(),
                    len,
                    max: max_len,
                });
            }
            let seen = seen_of(got.meta.e_tag.clone(), got.meta.version.clone());
            let bytes = match got.bytes().await {
                Ok(b) => b,
                Err(e) => return Ok(Err(e)),
            };
            if bytes.len() as u64 > max_len {
                return Err(CacheError::TooLarge {
                    key: key.to_owned(),
                    len: bytes.len() as u64,
                    max: max_len,
                });
            }
            Ok(Ok(Some((bytes.to_vec(), seen))))
        })?
    }

    /// Reads `key` and returns its bytes and version, with retries, remembering nothing.
    fn fetch(&self, key: &str, max_len: u64) -> Result<Fetched, CacheError> {
        let path = self.path(key)?;
        self.attempt("get", key, || self.get_once(&path, key, max_len))?
            .map_err(Self::os_err("get", key))
    }
}

impl TileStore for ObjectTileStore {
    fn read(&self, key: &str, max_len: u64) -> Result<Option<Vec<u8>>, CacheError> {
        let started = self.version_clock();
        match self.fetch(key, max_len)? {
            Some((bytes, seen)) => {
                self.remember_read(key, seen, started);
                Ok(Some(bytes))
            }
            None => {
                self.remember_read(key, Some(Seen::Absent), started);
                Ok(None)
            }
        }
    }

    fn write(&self, key: &str, bytes: &[u8]) -> Result<(), CacheError> {
        let path = self.path(key)?;
        let payload = PutPayload::from(bytes.to_vec());
        let mode = self.put_mode(key);
        let conditional = !matches!(mode, PutMode::Overwrite);
        let put = || {
            let opts = PutOptions::from(mode.clone());
            self.block_on("put", self.store.put_opts(&path, payload.clone(), opts))
        };
        let done = |r: PutResult| {
            self.remember(key, seen_of(r.e_tag, r.version));
            Ok(())
        };
        match self.attempt("put", key, put)? {
            Ok(r) => done(r),
            Err(
                e @ (object_store::Error::Precondition { .. }
                | object_store::Error::AlreadyExists { .. }
                | object_store::Error::NotFound { .. }),
            ) if conditional => {
                // Refused: another writer's version, or our own earlier attempt that landed
                // while its answer was lost. Only the bytes can tell.
                let max = bytes.len() as u64;
                match self.fetch(key, max) {
                    Ok(Some((now, seen))) if now == bytes => {
                        tracing::debug!(
                            key,
                            "conditional put refused, but the object holds our bytes: an earlier attempt landed"
                        );
                        self.remember(key, seen);
                        Ok(())
                    }
                    Ok(_) | Err(CacheError::TooLarge { .. }) => {
                        tracing::warn!(key, error = %e, "tile changed by another writer since read; not overwritten");
                        Err(CacheError::Conflict {
                            key: key.to_owned(),
                        })
                    }
                    Err(other) => Err(other),
                }
            }
            Err(e) => Err(Self::os_err("put", key)(e)),
        }
    }

    fn remove(&self, key: &str) -> Result<(), CacheError> {
        let path = self.path(key)?;
        let r = self.attempt("delete", key, || {
            self.block_on("delete", self.store.delete(&path))
        })?;
        match r {
            Ok(()) | Err(object_store::Error::NotFound { .. }) => {
                self.remember(key, Some(Seen::Absent));
                Ok(())
            }
            Err(e) => Err(Self::os_err("delete", key)(e)),
        }
    }

    fn exists(&self, key: &str) -> Result<bool, CacheError> {
        let path = self.path(key)?;
        match self.attempt("head", key, || {
            self.block_on("head", self.store.head(&path))
        })? {
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
            .attempt("list", prefix, || {
                self.block_on("list", self.store.list(list_path.as_ref()).try_collect())
            })?
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
        // S3 URLs get the network settings (nothing is sent until the first call).
        #[cfg(feature = "aws")]
        {
            let s = ObjectTileStore::from_url("s3://bucket/some/prefix").unwrap();
            assert_eq!(s.config(), &ObjectStoreConfig::default());
            assert_eq!(s.prefix, "some/prefix");
        }
    }

    fn shared(mem: &Arc<object_store::memory::InMemory>, capacity: usize) -> ObjectTileStore {
        let config = ObjectStoreConfig {
            version_capacity: capacity,
            ..ObjectStoreConfig::default()
        };
        ObjectTileStore::with_config(mem.clone(), "w", config).unwrap()
    }

    #[test]
    fn conditional_contract() {
        let mem = Arc::new(object_store::memory::InMemory::new());
        exercise_store(&shared(&mem, 8));
    }

    #[test]
    fn two_writers_of_one_key_conflict() {
        let mem = Arc::new(object_store::memory::InMemory::new());
        let (a, b) = (shared(&mem, 64), shared(&mem, 64));
        // Both see the key missing; the second creation is refused.
        assert_eq!(a.read("t", 100).unwrap(), None);
        assert_eq!(b.read("t", 100).unwrap(), None);
        a.write("t", b"a1").unwrap();
        assert!(matches!(b.write("t", b"b1"), Err(CacheError::Conflict { key }) if key == "t"));
        // Writing the same stale data again still fails; reading takes the new version.
        assert!(matches!(
            b.write("t", b"b1"),
            Err(CacheError::Conflict { .. })
        ));
        assert_eq!(b.read("t", 100).unwrap().unwrap(), b"a1");
        b.write("t", b"b2").unwrap();
        // a's version is stale now: refused, the object keeps b's bytes.
        assert!(matches!(
            a.write("t", b"a2"),
            Err(CacheError::Conflict { .. })
        ));
        assert_eq!(a.read("t", 100).unwrap().unwrap(), b"b2");
        // Our own writes advance our version: successive writes without reads succeed.
        a.write("t", b"a3").unwrap();
        a.write("t", b"a4").unwrap();
        // A refused write whose bytes are already there (a lost answer) counts as done.
        assert!(b.write("t", b"a4").is_ok());
        // Removal makes the next write a creation; forgetting makes it blind.
        a.remove("t").unwrap();
        b.write("t", b"b5").unwrap_err();
        b.forget_version("t");
        b.write("t", b"b5").unwrap();
        assert_eq!(a.read("t", 100).unwrap().unwrap(), b"b5");
    }

    #[test]
    fn a_read_answered_after_a_write_does_not_replace_the_writes_version() {
        let s = shared(&Arc::new(object_store::memory::InMemory::new()), 8);
        let started = s.version_clock();
        s.remember("k", Some(Seen::Absent));
        // A GET that began before that write and answers after it: ignored.
        s.remember_read("k", None, started);
        assert_eq!(s.versions.lock().unwrap().get("k"), Some(&Seen::Absent));
        // One that began after it is taken.
        let later = s.version_clock();
        s.remember_read("k", None, later);
        assert_eq!(s.versions.lock().unwrap().get("k"), None);
    }

    #[test]
    fn versions_are_bounded() {
        let mem = Arc::new(object_store::memory::InMemory::new());
        let s = shared(&mem, 4);
        for round in 0..3 {
            for i in 0..10 {
                s.write(&format!("k{i}"), format!("{round}").as_bytes())
                    .unwrap();
                assert!(s.remembered_versions() <= 4);
            }
        }
        let v = s.versions.lock().unwrap();
        assert!(v.order.len() <= 2 * 4 + 16, "{}", v.order.len());
        // The newest keys are the ones remembered.
        assert!(v.get("k9").is_some() && v.get("k0").is_none());
    }

    #[test]
    fn config_is_checked() {
        let mem = Arc::new(object_store::memory::InMemory::new());
        for bad in [
            ObjectStoreConfig {
                attempts: 0,
                ..ObjectStoreConfig::default()
            },
            ObjectStoreConfig {
                version_capacity: 0,
                ..ObjectStoreConfig::default()
            },
            ObjectStoreConfig {
                request_timeout: Duration::ZERO,
                ..ObjectStoreConfig::default()
            },
        ] {
            assert!(matches!(
                ObjectTileStore::with_config(mem.clone(), "", bad),
                Err(CacheError::OutOfRange { .. })
            ));
        }
        let c = ObjectStoreConfig::default();
        assert_eq!(c.backoff(1), c.init_backoff);
        assert_eq!(c.backoff(2), c.init_backoff * 2);
        assert_eq!(c.backoff(u32::MAX), c.max_backoff);
    }
}
