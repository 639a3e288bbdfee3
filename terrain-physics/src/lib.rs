//! Heightfield collision over a double-buffered CPU mirror of the coarse-map, kept current by
//! asynchronous readback of dirty regions (Flower 2010, sec. 3.2.1 and 3.2.5).
//!
//! Conventions (the workspace's): metres, Y up, right-handed. Heightmap column `x` maps to
//! world X and row `y` to world Z; texel `(x, y)` stands at `(x * texel_size, height,
//! y * texel_size)`. The coarse-map wraps (toroidal addressing), so every query does.
//!
//! ```
//! use glam::{IVec2, UVec2, Vec2, Vec3};
//! use std::time::{Duration, Instant};
//! use terrain_core::{
//!     apply_stamp, Blend, CoarseMap, GaussianStamp, Grid, HeightEncoding, StampPlacement,
//! };
//! use terrain_physics::{
//!     CameraBody, CollisionMirror, CpuRegionSource, DeformationBound, ReadbackScheduler,
//!     SchedulerConfig,
//! };
//!
//! // A flat 64 x 64 coarse-map at 0.5 m per texel, 10 m high.
//! let enc = HeightEncoding::spanning::<u16>(0.0, 50.0)?;
//! let grid = Grid::new(64, 64, enc.to_raw(10.0).round() as u16)?;
//! let map = CoarseMap::coarse(grid, enc, 0.5)?;
//!
//! // The mirror collision reads, the source readbacks come from (here: the map on the CPU;
//! // terrain-gpu provides one over its RegionReadback), and the scheduler between them.
//! let mirror = CollisionMirror::from_map(&map)?;
//! let mut source = CpuRegionSource::new(map);
//! let mut scheduler = ReadbackScheduler::for_mirror(&mirror, SchedulerConfig::default())?;
//!
//! // A 2 m mound is stamped under the camera.
//! let t0 = Instant::now();
//! let placement = StampPlacement::new(Vec2::new(16.0, 16.0), Vec2::splat(8.0), 2.0)?;
//! let dirty = apply_stamp(source.map_mut(), &mut GaussianStamp::default(), &placement, Blend::Add)?;
//! for rect in dirty {
//!     scheduler.note_deformation(rect, DeformationBound::additive(2.0, enc)?, t0)?;
//! }
//!
//! // Before the readback the camera is kept above the mound by the deformation's bound.
//! let mut camera = CameraBody::new(Vec3::new(16.0, 11.7, 16.0));
//! let collider = mirror.collider();
//! camera.step(1.0 / 60.0, Vec3::ZERO, &scheduler.ground(&collider))?;
//! assert!(camera.position.y >= 12.0 + camera.eye_height - 1e-3);
//!
//! // After the 20 ms quiet gap one merged region is requested; it arrives on the next poll.
//! let report = scheduler.update(t0 + Duration::from_millis(25), &mut source, &mirror)?;
//! assert_eq!(report.requested.len(), 1);
//! scheduler.update(t0 + Duration::from_millis(40), &mut source, &mirror)?;
//! let collider = mirror.collider();
//! assert!((collider.height(Vec2::new(16.0, 16.0))? - 12.0).abs() < 0.01);
//!
//! // Raycast and sphere contact against the new surface.
//! let hit = collider.raycast(Vec3::new(16.0, 30.0, 16.0), Vec3::NEG_Y, 100.0)?.unwrap();
//! assert!((hit.distance - 18.0).abs() < 0.01);
//! let contact = collider.sphere_contact(Vec3::new(16.0, 12.5, 16.0), 1.0)?.unwrap();
//! assert!(contact.depth > 0.4 && contact.normal.y > 0.9);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! Layout (as parry lays out collision queries): [`HeightField`] is the shape, an immutable
//! snapshot holding the map's u16 samples, with one local-space method per query kind, each in
//! its own module ([`field`]: height and normal, [`ray`], [`contact`]);
//! [`HeightfieldCollider`] places a snapshot in the world and wraps each query with input
//! checks. [`CollisionMirror`] publishes snapshots; [`ReadbackScheduler`] feeds it through a
//! [`RegionSource`] (terrain-core's readback contract, re-exported here), and hands a source's
//! failure back in the source's own error type ([`UpdateError`]); [`CameraBody`] and
//! [`SphereBody`] move over any [`GroundQuery`], such as the [`BoundedGround`] that covers the
//! gap between a deformation and its readback. [`CameraRig`] is a camera built on the body: a
//! follower behind a moving subject, or a [`CameraPath`] (orbit, flyover) sized from a map's
//! extent that frames any terrain, for repeatable captures and benchmark flights.
//!
//! Surface model: the bilinear patch of listing 3.2 over every cell; heights, normals,
//! raycasts and contacts all use it.
//!
//! Feature `parry` (off by default): the `parry_adapter` module's `ParryTerrain` holds the
//! snapshots as tiled `parry3d` heightfields for a parry or rapier world, rebuilt per dirty
//! rect, with the difference between parry's triangles and the bilinear surface bounded
//! (`|h00 - h10 - h01 + h11| / 4` per cell) and tested; its module docs have a runnable example.

// docs.rs: label feature-gated items with the features they need.
#![cfg_attr(docsrs, feature(doc_cfg))]
#![warn(missing_docs)]
#![warn(clippy::unwrap_used)]

pub mod camera;
pub mod camera_path;
pub mod camera_rig;
pub mod collider;
pub mod contact;
pub mod detail_ground;
pub mod error;
pub mod field;
pub mod ground;
pub mod merge;
pub mod mirror;
#[cfg(feature = "parry")]
pub mod parry_adapter;
pub mod ray;
pub mod scheduler;
pub mod source;
pub mod sphere;
pub mod window;

pub use camera::{CameraBody, GroundClamp, STANDARD_GRAVITY};
pub use camera_path::{CameraPath, MAX_FLYOVER_HEIGHT, MAX_FRAME_M, MapFrame, PathParams, Pose};
pub use camera_rig::{CameraRig, FollowShape, RigView};
pub use collider::{GroundQuery, HeightfieldCollider};
pub use contact::Contact;
pub use detail_ground::DetailGround;
pub use error::PhysicsError;
pub use field::{HeightField, MAX_FIELD_SIDE};
pub use ground::{BoundedGround, DeformationBound, PendingDeformation};
pub use merge::DirtyRegions;
pub use mirror::{CollisionMirror, RegionUpdate};
#[cfg(feature = "parry")]
pub use parry_adapter::{MAX_PARRY_TILE_SIZE, MAX_PARRY_TILES, ParryTerrain, ParryTile};
/// The parry version the `parry` feature builds on (its shapes and poses are parry's types).
#[cfg(feature = "parry")]
pub use parry3d;
pub use ray::{Ray, RayHit};
pub use scheduler::{
    MAX_PENDING_DEFORMATIONS, ReadbackScheduler, SchedulerConfig, UpdateError, UpdateReport,
};
pub use source::{ArrivedRegion, CpuRegionSource, RegionSource, RequestId, read_region};
pub use sphere::{CONTACT_TOLERANCE, SOLID_SPHERE_ROLLING_FACTOR, SphereBody};
pub use window::{CollisionWindow, MAX_WINDOW_SIDE, WINDOW_STEP, WindowError};

/// The README's code blocks, compiled and run as doc tests so that they cannot go stale.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
struct ReadmeDoctests;

/// The glam of this crate's public API (its vectors), so callers use the same version.
pub use glam;

// Engines keep collision state shared across threads (Bevy's `Resource` is `Send + Sync`): a
// type that loses either fails this build.
const _: () = {
    const fn send_sync<T: Send + Sync>() {}
    send_sync::<CollisionMirror>();
    send_sync::<CollisionWindow>();
    send_sync::<ReadbackScheduler>();
    send_sync::<CameraBody>();
};
