//! `ReadbackScheduler`: collects the dirty rects of deformations, waits for a quiet gap, asks a
//! [`RegionSource`] for their merged union, and applies what arrives to the
//! [`CollisionMirror`], never blocking the caller (Flower 2010, sec. 3.2.1).
//!
//! Time is passed in: every call takes `now: Instant`, so tests run on synthetic instants.
//!
//! - `note_deformation(rect, bound, now)` marks a rect dirty and records the deformation's
//!   bound (see [`crate::ground`]).
//! - `update(now, source, mirror)` polls the source (non-blocking), applies arrived regions in
//!   request order (a region that arrives early waits for the older ones, so an older readback
//!   never overwrites a newer one), retires the bounds a completed batch covered, and, once no
//!   deformation has been noted for `quiet_gap` (or the oldest dirty rect has waited
//!   `max_delay`), requests the merged dirty rects as one batch.
//!
//! Collision never freezes on a lost readback: a request that has not arrived within
//! `request_timeout` (device loss, a failed mapping, an encoder dropped before submit, a
//! source that drops it) is abandoned: its rect is dirty again and re-requested with the next
//! batch, its deformation bounds stay pending, and the requests behind it no longer wait for
//! it; if it arrives after all it is ignored (the re-request brings newer heights). Memory
//! stays bounded whatever the source does: at most `max_in_flight` requests in flight, a
//! bounded list of abandoned ids, and pending deformation records merged beyond
//! [`MAX_PENDING_DEFORMATIONS`].

use crate::collider::HeightfieldCollider;
use crate::error::{PhysicsError, check_region};
use crate::ground::{BoundedGround, DeformationBound, PendingDeformation};
use crate::merge::DirtyRegions;
use crate::mirror::CollisionMirror;
use glam::UVec2;
use std::collections::VecDeque;
use std::time::{Duration, Instant};
use terrain_core::{Grid, Rect, RegionSource, RequestId};

/// Scheduler parameters. With the `serde` feature the durations are written in milliseconds
/// (`quiet_gap_ms`, `max_delay_ms`, `request_timeout_ms`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields))]
#[cfg_attr(feature = "schemars", derive(schemars::JsonSchema))]
pub struct SchedulerConfig {
    /// How long no deformation must be noted before the dirty rects are requested. Flower 2010
    /// sec. 3.2.1: "the system waits for a gap of approximately 20 milliseconds". Default 20 ms.
    #[cfg_attr(
        feature = "serde",
        serde(rename = "quiet_gap_ms", with = "duration_ms")
    )]
    #[cfg_attr(feature = "schemars", schemars(with = "f64", range(min = 0)))]
    pub quiet_gap: Duration,
    /// The longest a dirty rect waits, even while deformations keep coming (so a continuous
    /// stream of deformations cannot starve collision). Not in the seed; default 250 ms.
    #[cfg_attr(
        feature = "serde",
        serde(rename = "max_delay_ms", with = "duration_ms")
    )]
    #[cfg_attr(feature = "schemars", schemars(with = "f64", range(min = 0)))]
    pub max_delay: Duration,
    /// Dirty rects closer than this many texels are merged into one request. Default 16.
    pub merge_distance: u32,
    /// The most rects one batch requests (the closest are merged beyond it). Default 4.
    pub max_requests: usize,
    /// How long a request may take to arrive before it is abandoned and its rect requested
    /// again. Not in the seed (its readback never fails); default 1 s, about 30 frames.
    #[cfg_attr(
        feature = "serde",
        serde(rename = "request_timeout_ms", with = "duration_ms")
    )]
    #[cfg_attr(feature = "schemars", schemars(with = "f64", range(min = 0)))]
    pub request_timeout: Duration,
    /// The most requests in flight; a batch waits (its rects stay dirty) while it would go
    /// over. Default 16.
    pub max_in_flight: usize,
}

/// A [`Duration`] as milliseconds (a float) in configuration files.
#[cfg(feature = "serde")]
mod duration_ms {
    use serde::{Deserialize, Deserializer, Serializer, de::Error};
    use std::time::Duration;

    pub fn serialize<S: Serializer>(d: &Duration, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_f64(d.as_secs_f64() * 1e3)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Duration, D::Error> {
        let ms = f64::deserialize(d)?;
        Duration::try_from_secs_f64(ms / 1e3)
            .map_err(|e| D::Error::custom(format!("{ms} ms is not a duration: {e}")))
    }
}

impl Default for SchedulerConfig {
    fn default() -> Self {
        Self {
            quiet_gap: Duration::from_millis(20),
            max_delay: Duration::from_millis(250),
            merge_distance: 16,
            max_requests: 4,
            request_timeout: Duration::from_secs(1),
            max_in_flight: 16,
        }
    }
}

/// What one [`ReadbackScheduler::update`] did.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct UpdateReport {
    /// Requests made: id and rect (merged; it may wrap).
    pub requested: Vec<(RequestId, Rect)>,
    /// Regions applied to the mirror: request id and the mirror version it produced.
    pub applied: Vec<(RequestId, u64)>,
    /// The rects of `applied`, in the same order (they may wrap): what changed in the mirror
    /// in this update, e.g. for `ParryTerrain::update` (feature `parry`).
    pub applied_rects: Vec<Rect>,
    /// Requests abandoned this update (not arrived within the timeout, or their id handed out
    /// again by the source); their rects are dirty again.
    pub abandoned: Vec<RequestId>,
    /// Regions of abandoned requests that arrived after all, ignored.
    pub late: usize,
}

/// Pending deformation records kept one by one, waiting and in flight each; beyond this many
/// they are merged into a few records with summed bounds (conservative), so a caller that
/// notes deformations without ever updating, or a source that never delivers, does not grow
/// memory without bound: [`ReadbackScheduler::pending_deformations`] yields at most twice
/// this many (and a few).
pub const MAX_PENDING_DEFORMATIONS: usize = 1024;

/// Abandoned request ids remembered (to ignore their late arrival).
const ABANDONED_MEMORY: usize = 256;

/// Why a [`ReadbackScheduler::update`] failed: one of the scheduler's own checks, or the
/// source's failure in the source's own error type `E` ([`RegionSource::Error`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum UpdateError<E> {
    /// The mirror's size differs from the scheduler's, the source delivered a region nobody
    /// asked for (or twice) or one of the wrong rect or size, or the mirror refused a region.
    #[error(transparent)]
    Physics(#[from] PhysicsError),
    /// The source's `request` or `poll` failed; its error, unchanged.
    #[error("readback source failed")]
    Source(#[source] E),
}

/// A request in flight, and what it has delivered.
#[derive(Debug, Clone)]
struct InFlight {
    id: RequestId,
    rect: Rect,
    requested_at: Instant,
    arrived: Option<Grid<u16>>,
    /// Deformations whose bounds retire when this request is applied (the last request of a
    /// batch carries the batch's deformations; requests apply in order).
    retires: Vec<PendingDeformation>,
}

/// The readback scheduler of one mirrored map.
#[derive(Debug, Clone)]
pub struct ReadbackScheduler {
    config: SchedulerConfig,
    map_size: UVec2,
    dirty: DirtyRegions,
    /// Deformations noted since the last batch was requested.
    waiting: Vec<PendingDeformation>,
    first_dirty: Option<Instant>,
    last_dirty: Option<Instant>,
    in_flight: VecDeque<InFlight>,
    /// Bounds of batches in flight, flattened for [`BoundedGround`].
    in_flight_bounds: Vec<PendingDeformation>,
    /// Ids abandoned lately, oldest first (at most `ABANDONED_MEMORY`).
    abandoned: VecDeque<RequestId>,
}

impl ReadbackScheduler {
    /// A scheduler for a map of `map_size` texels. Fails on a zero side or `max_requests` 0.
    pub fn new(map_size: UVec2, config: SchedulerConfig) -> Result<Self, PhysicsError> {
        if map_size.min_element() == 0 {
            return Err(PhysicsError::Core(terrain_core::CoreError::EmptyGrid {
                width: map_size.x,
                height: map_size.y,
            }));
        }
        if config.max_requests == 0 {
            return Err(PhysicsError::OutOfRange {
                what: "max requests per batch",
                value: 0.0,
                expected: "at least 1",
            });
        }
        if config.request_timeout.is_zero() {
            return Err(PhysicsError::OutOfRange {
                what: "request timeout (seconds)",
                value: 0.0,
                expected: "more than 0",
            });
        }
        if config.max_in_flight < config.max_requests {
            return Err(PhysicsError::OutOfRange {
                what: "max requests in flight",
                value: config.max_in_flight as f64,
                expected: "at least max_requests (one batch)",
            });
        }
        Ok(Self {
            config,
            map_size,
            dirty: DirtyRegions::new(map_size, config.merge_distance, config.max_requests),
            waiting: Vec::new(),
            first_dirty: None,
            last_dirty: None,
            in_flight: VecDeque::new(),
            in_flight_bounds: Vec::new(),
            abandoned: VecDeque::new(),
        })
    }

    /// A scheduler for the map `mirror` holds.
    pub fn for_mirror(
        mirror: &CollisionMirror,
        config: SchedulerConfig,
    ) -> Result<Self, PhysicsError> {
        Self::new(mirror.size(), config)
    }

    /// The parameters.
    pub fn config(&self) -> SchedulerConfig {
        self.config
    }

    /// Records a deformation of `rect` (texels; it may wrap) at `now` with its `bound`.
    ///
    /// Note it after the deformation is submitted to the map the source reads (for the GPU,
    /// recorded in the same or an earlier submission than later readback requests), so that
    /// the readback requested for it sees it. Fails on a rect off the map.
    pub fn note_deformation(
        &mut self,
        rect: Rect,
        bound: DeformationBound,
        now: Instant,
    ) -> Result<(), PhysicsError> {
        check_region(rect, self.map_size)?;
        let bound = DeformationBound::new(bound.raise, bound.lower)?;
        self.dirty.insert(rect);
        self.waiting.push(PendingDeformation { rect, bound });
        if self.waiting.len() > MAX_PENDING_DEFORMATIONS {
            self.waiting = merge_pending(&self.waiting, self.map_size);
        }
        self.first_dirty.get_or_insert(now);
        self.last_dirty = Some(self.last_dirty.map_or(now, |t| t.max(now)));
        Ok(())
    }

    /// Polls `source`, applies what arrived to `mirror`, and requests the dirty rects once the
    /// quiet gap has passed. Never waits: it returns as soon as the source's non-blocking calls
    /// do (applying a region costs a copy of its texels).
    ///
    /// Fails with [`UpdateError::Source`] (the source's own error) when the source's `request`
    /// or `poll` fails, and with [`UpdateError::Physics`] if the mirror's size differs from the
    /// scheduler's, or on a region nobody asked for, or one of the wrong rect or size. Arrivals
    /// that were valid are still kept and applied; a failed request keeps its rects dirty for
    /// the next update. The first error met is returned.
    #[tracing::instrument(level = "debug", name = "collision_update", skip_all)]
    pub fn update<S: RegionSource + ?Sized>(
        &mut self,
        now: Instant,
        source: &mut S,
        mirror: &CollisionMirror,
    ) -> Result<UpdateReport, UpdateError<S::Error>> {
        self.step(now, source, mirror, false)
    }

    /// Brings `mirror` level with the source: requests every dirty rect now, quiet gap or not,
    /// and polls `source` every millisecond until every request has arrived and applied. For
    /// the end of a run or a save, never inside a frame: it waits. The one report covers
    /// every poll.
    ///
    /// Fails as [`ReadbackScheduler::update`] does, and with [`PhysicsError::FlushTimedOut`]
    /// when the source has not delivered within `timeout` (what arrived is applied; the rest
    /// stays dirty or in flight, as after an update).
    pub fn flush<S: RegionSource + ?Sized>(
        &mut self,
        source: &mut S,
        mirror: &CollisionMirror,
        timeout: Duration,
    ) -> Result<UpdateReport, UpdateError<S::Error>> {
        let start = Instant::now();
        let mut all = UpdateReport::default();
        loop {
            let r = self.step(Instant::now(), source, mirror, true)?;
            all.requested.extend(r.requested);
            all.applied.extend(r.applied);
            all.applied_rects.extend(r.applied_rects);
            all.abandoned.extend(r.abandoned);
            all.late += r.late;
            if self.is_idle() {
                return Ok(all);
            }
            if start.elapsed() >= timeout {
                return Err(PhysicsError::FlushTimedOut {
                    timeout,
                    in_flight: self.in_flight.len(),
                    dirty: self.dirty.rects().len(),
                }
                .into());
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    }

    /// One update; `force` requests the dirty rects whether or not they are due.
    fn step<S: RegionSource + ?Sized>(
        &mut self,
        now: Instant,
        source: &mut S,
        mirror: &CollisionMirror,
        force: bool,
    ) -> Result<UpdateReport, UpdateError<S::Error>> {
        if mirror.size() != self.map_size {
            return Err(PhysicsError::SizeMismatch {
                expected: self.map_size,
                actual: mirror.size(),
            }
            .into());
        }
        let mut report = UpdateReport::default();
        let mut first_error: Option<UpdateError<S::Error>> = None;

        for region in source.poll().map_err(UpdateError::Source)? {
            let slot = self
                .in_flight
                .iter_mut()
                .find(|f| f.id == region.id && f.arrived.is_none());
            let result = match slot {
                None if self.abandoned.contains(&region.id) => {
                    report.late += 1;
                    Ok(())
                }
                None => Err(PhysicsError::UnknownRequest { id: region.id }),
                Some(f) if f.rect != region.rect => Err(PhysicsError::WrongRegion {
                    id: f.id,
                    requested: f.rect,
                    delivered: region.rect,
                }),
                Some(f) if region.heights.size() != f.rect.size => {
                    Err(PhysicsError::SizeMismatch {
                        expected: f.rect.size,
                        actual: region.heights.size(),
                    })
                }
                Some(f) => {
                    f.arrived = Some(region.heights);
                    Ok(())
                }
            };
            if let Err(e) = result {
                first_error.get_or_insert(e.into());
            }
        }

        // Apply in request order.
        self.abandon_overdue(now, &mut report);

        while self.in_flight.front().is_some_and(|f| f.arrived.is_some()) {
            let Some(done) = self.in_flight.pop_front() else {
                break;
            };
            let Some(heights) = done.arrived else { break };
            match mirror.apply_next(done.rect, &heights) {
                Ok(version) => {
                    report.applied.push((done.id, version));
                    report.applied_rects.push(done.rect);
                }
                Err(e) => {
                    // Cannot happen for a validated arrival; keep the area dirty if it does, and
                    // its bounds, and those the requests behind it would retire, pending.
                    self.dirty.insert(done.rect);
                    self.waiting.extend(done.retires.iter().copied());
                    for f in self.in_flight.iter_mut() {
                        self.waiting.append(&mut f.retires);
                    }
                    self.rebuild_in_flight_bounds();
                    self.first_dirty.get_or_insert(now);
                    self.last_dirty.get_or_insert(now);
                    first_error.get_or_insert(e.into());
                }
            }
            if !done.retires.is_empty() {
                self.rebuild_in_flight_bounds();
            }
        }

        if (force && !self.dirty.is_empty()) || self.due(now) {
            self.request_batch(source, now, &mut report, &mut first_error);
        }
        match first_error {
            Some(e) => Err(e),
            None => Ok(report),
        }
    }

    /// Whether the dirty rects are due: quiet for `quiet_gap`, or waiting for `max_delay`.
    fn due(&self, now: Instant) -> bool {
        if self.dirty.is_empty() {
            return false;
        }
        let quiet = self
            .last_dirty
            .is_none_or(|t| now.saturating_duration_since(t) >= self.config.quiet_gap);
        let overdue = self
            .first_dirty
            .is_none_or(|t| now.saturating_duration_since(t) >= self.config.max_delay);
        quiet || overdue
    }

    /// Abandons the requests that have not arrived within the timeout: their rects are dirty
    /// again and their bounds pending again; the requests behind them stop waiting for them.
    fn abandon_overdue(&mut self, now: Instant, report: &mut UpdateReport) {
        let timeout = self.config.request_timeout;
        let overdue = |f: &InFlight| {
            f.arrived.is_none() && now.saturating_duration_since(f.requested_at) >= timeout
        };
        let Some(first) = self.in_flight.iter().position(overdue) else {
            return;
        };
        self.keep_bounds_behind(first, &|f: &InFlight| !overdue(f));
        let (lost, kept): (VecDeque<InFlight>, VecDeque<InFlight>) =
            std::mem::take(&mut self.in_flight)
                .into_iter()
                .partition(overdue);
        self.in_flight = kept;
        for f in lost {
            self.abandon(f, now, report);
        }
        self.rebuild_in_flight_bounds();
    }

    /// Moves back to `waiting` the bounds that in-flight requests behind position `i` would
    /// retire when they apply: once the request at `i` is abandoned they would retire them
    /// although its rect's new heights are not in the mirror yet (a batch's bounds ride on its
    /// last request). They retire with the batch that re-requests the rect instead. Only
    /// requests `stays` keeps count (those abandoned too give their bounds back anyway).
    fn keep_bounds_behind(&mut self, i: usize, stays: &dyn Fn(&InFlight) -> bool) {
        let mut behind = Vec::new();
        for f in self.in_flight.iter_mut().skip(i + 1) {
            if stays(f) {
                behind.append(&mut f.retires);
            }
        }
        self.waiting.extend(behind);
        if self.waiting.len() > MAX_PENDING_DEFORMATIONS {
            self.waiting = merge_pending(&self.waiting, self.map_size);
        }
    }

    fn abandon(&mut self, f: InFlight, now: Instant, report: &mut UpdateReport) {
        self.dirty.insert(f.rect);
        self.waiting.extend(f.retires);
        if self.waiting.len() > MAX_PENDING_DEFORMATIONS {
            self.waiting = merge_pending(&self.waiting, self.map_size);
        }
        self.first_dirty.get_or_insert(now);
        self.last_dirty.get_or_insert(now);
        if self.abandoned.len() >= ABANDONED_MEMORY {
            self.abandoned.pop_front();
        }
        self.abandoned.push_back(f.id);
        report.abandoned.push(f.id);
        tracing::warn!(request = ?f.id, rect = ?f.rect, "collision readback abandoned (late); its rect is requested again");
    }

    fn request_batch<S: RegionSource + ?Sized>(
        &mut self,
        source: &mut S,
        now: Instant,
        report: &mut UpdateReport,
        first_error: &mut Option<UpdateError<S::Error>>,
    ) {
        // A full pipeline waits: the rects stay dirty (and merge) until requests come back
        // or are abandoned.
        if self.in_flight.len() + self.dirty.len() > self.config.max_in_flight {
            return;
        }
        let rects = self.dirty.take();
        let mut issued = 0;
        let mut set_aside: Vec<PendingDeformation> = Vec::new();
        for (k, &rect) in rects.iter().enumerate() {
            match source.request(rect) {
                Ok(id) => {
                    // A source that hands out an id again (made anew, or faulty): the older
                    // request can no longer be told apart, so it is abandoned, and a late
                    // arrival under that id is no longer ignored.
                    if let Some(i) = self.in_flight.iter().position(|f| f.id == id) {
                        // The old request's rect is dirty again but not in this batch: its
                        // bounds (and those behind it) must outlive this batch, so they are
                        // set aside and go back to `waiting` after it takes its own.
                        let keep = std::mem::take(&mut self.waiting);
                        self.keep_bounds_behind(i, &|_| true);
                        if let Some(old) = self.in_flight.remove(i) {
                            self.abandon(old, now, report);
                        }
                        set_aside.append(&mut self.waiting);
                        self.waiting = keep;
                        self.rebuild_in_flight_bounds();
                    }
                    self.abandoned.retain(|&a| a != id);
                    self.in_flight.push_back(InFlight {
                        id,
                        rect,
                        requested_at: now,
                        arrived: None,
                        retires: Vec::new(),
                    });
                    report.requested.push((id, rect));
                    tracing::debug!(request = ?id, rect = ?rect, "collision readback requested");
                    issued += 1;
                }
                Err(e) => {
                    // Keep the rest dirty and every bound of the batch pending; retry later.
                    // A busy source is back-pressure, not a failure: nothing to report.
                    for r in &rects[k..] {
                        self.dirty.insert(*r);
                    }
                    if !source.is_busy(&e) {
                        first_error.get_or_insert(UpdateError::Source(e));
                    }
                    return;
                }
            }
        }
        if issued > 0 {
            // Bounds in flight stay within the limit too.
            if self.waiting.len() + self.in_flight_bounds.len() > MAX_PENDING_DEFORMATIONS {
                self.waiting = merge_pending(&self.waiting, self.map_size);
            }
            if let Some(last) = self.in_flight.back_mut() {
                last.retires = std::mem::take(&mut self.waiting);
            }
        }
        self.waiting.append(&mut set_aside);
        if self.dirty.is_empty() {
            self.first_dirty = None;
            self.last_dirty = None;
        }
        self.rebuild_in_flight_bounds();
    }

    fn rebuild_in_flight_bounds(&mut self) {
        self.in_flight_bounds = self
            .in_flight
            .iter()
            .flat_map(|f| f.retires.iter().copied())
            .collect();
    }

    /// Deformations not yet covered by an applied readback: waiting for the quiet gap, then
    /// in flight.
    pub fn pending_deformations(&self) -> impl Iterator<Item = &PendingDeformation> {
        self.waiting.iter().chain(&self.in_flight_bounds)
    }

    /// The dirty rects not yet requested (merged).
    pub fn dirty_rects(&self) -> &[Rect] {
        self.dirty.rects()
    }

    /// Requests made and not yet applied.
    pub fn in_flight(&self) -> usize {
        self.in_flight.len()
    }

    /// Whether nothing is dirty, in flight or pending.
    pub fn is_idle(&self) -> bool {
        self.dirty.is_empty() && self.in_flight.is_empty() && self.waiting.is_empty()
    }

    /// The ground bodies should collide with now: `collider`'s surface raised by the bounds of
    /// every pending deformation (see [`crate::ground`]).
    pub fn ground<'a>(&'a self, collider: &'a HeightfieldCollider) -> BoundedGround<'a> {
        BoundedGround::new(collider, &self.waiting, &self.in_flight_bounds)
    }
}

/// `pending` merged into at most 4 records: the merged rects cover every record's rect, and
/// each carries the sum of the bounds of the records it covers (deformations that overlap
/// add up; a record may count in two merged rects, which is conservative).
fn merge_pending(pending: &[PendingDeformation], map_size: UVec2) -> Vec<PendingDeformation> {
    let mut rects = DirtyRegions::new(map_size, 0, 4);
    for p in pending {
        rects.insert(p.rect);
    }
    rects
        .rects()
        .iter()
        .map(|&rect| {
            // Only the records this rect covers add to its bound (a record lies inside one
            // merged rect; the cell test is conservative at the edges).
            let (mut raise, mut lower) = (0.0f32, 0.0f32);
            let hi = rect.max() - glam::IVec2::ONE;
            for p in pending {
                let cells = (
                    i64::from(rect.min.x),
                    i64::from(hi.x),
                    i64::from(rect.min.y),
                    i64::from(hi.y),
                );
                if p.touches_cells(cells.0, cells.1, cells.2, cells.3, map_size) {
                    raise = (raise + p.bound.raise).min(f32::MAX);
                    lower = (lower + p.bound.lower).min(f32::MAX);
                }
            }
            PendingDeformation {
                rect,
                bound: DeformationBound { raise, lower },
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::source::CpuRegionSource;
    use glam::IVec2;
    use terrain_core::{CoarseMap, HeightEncoding};

    fn setup() -> (CpuRegionSource, CollisionMirror, ReadbackScheduler) {
        let g = Grid::new(32, 32, 0u16).expect("grid");
        let m =
            CoarseMap::coarse(g, HeightEncoding::new(0.01, 0.0).expect("enc"), 1.0).expect("map");
        let mirror = CollisionMirror::from_map(&m).expect("mirror");
        let s = ReadbackScheduler::for_mirror(&mirror, SchedulerConfig::default()).expect("s");
        (CpuRegionSource::new(m), mirror, s)
    }

    #[test]
    fn continuous_deformation_is_requested_after_max_delay() {
        let (mut src, mirror, mut s) = setup();
        let t0 = Instant::now();
        let r = Rect::new(IVec2::new(1, 1), UVec2::new(2, 2));
        let b = DeformationBound::default();
        for ms in (0..=240).step_by(10) {
            let now = t0 + Duration::from_millis(ms);
            s.note_deformation(r, b, now).expect("note");
            let rep = s.update(now, &mut src, &mirror).expect("update");
            assert!(rep.requested.is_empty(), "at {ms} ms");
        }
        let now = t0 + Duration::from_millis(250);
        s.note_deformation(r, b, now).expect("note");
        let rep = s.update(now, &mut src, &mirror).expect("update");
        assert_eq!(rep.requested.len(), 1);
    }

    #[test]
    fn bad_config_and_sizes_are_errors() {
        let cfg = SchedulerConfig {
            max_requests: 0,
            ..SchedulerConfig::default()
        };
        assert!(ReadbackScheduler::new(UVec2::splat(8), cfg).is_err());
        assert!(ReadbackScheduler::new(UVec2::new(0, 8), SchedulerConfig::default()).is_err());
        let (mut src, mirror, _) = setup();
        let mut other = ReadbackScheduler::new(UVec2::splat(16), SchedulerConfig::default())
            .expect("scheduler");
        assert!(matches!(
            other.update(Instant::now(), &mut src, &mirror),
            Err(UpdateError::Physics(PhysicsError::SizeMismatch { .. }))
        ));
        let (_, _, mut s) = setup();
        let off = Rect::new(IVec2::new(100, 0), UVec2::new(2, 2));
        assert!(matches!(
            s.note_deformation(off, DeformationBound::default(), Instant::now()),
            Err(PhysicsError::RegionOffMap { .. })
        ));
        let bad = DeformationBound {
            raise: -1.0,
            lower: 0.0,
        };
        let ok = Rect::new(IVec2::ZERO, UVec2::ONE);
        assert!(s.note_deformation(ok, bad, Instant::now()).is_err());
        assert!(s.is_idle());
    }
}
