//! A deterministic trace simulator (no GPU, no disk) that compares tile policies on camera
//! paths: frustum with margin, band regions, spherical distance, LRU on demand, and Belady's
//! offline optimum (MIN) as the bound.
//!
//! Model. One level of `tiles` tiles of `tile_m` metres, wrapping. Each frame the renderer
//! *demands* the tiles within `demand_radius` metres (3D) that the camera's exact frustum
//! touches, plus the camera's own tile. A cache of `capacity` tiles is filled by loads that
//! take `latency_frames` to arrive, at most `loads_per_frame` issued per frame (Fikkan 2013, sec. 5.3's
//! per-frame transfer budget), each slot reserved when its load is issued. Every online policy
//! requests the demanded tiles it misses first (demand fetch), then its own selection in its
//! priority order (prefetch); victims are resident tiles neither demanded nor selected, the
//! farthest first (LRU: least recently demanded first). Belady's MIN knows the whole demand
//! trace, loads a demanded tile the moment it is needed (zero latency, no bandwidth limit) and
//! evicts the tile whose next demand is farthest: its loads are the fewest any cache of that
//! capacity needs to hold every demanded tile when used, and its hit rate the most any
//! demand-fetch policy reaches.

use crate::policy::{
    BandSelection, CameraState, FrustumSelection, SelectionPolicy, SphericalSelection, TileGrid,
    Want,
};
use crate::tile::TileId;
use glam::{UVec2, Vec3};
use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::fmt::Write as _;
use terrain_core::WrapMode;

/// A camera path of the simulator.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CameraPath {
    /// 1.5 m/s at eye height 1.8 m, heading drifting slowly.
    Walk,
    /// 20 m/s at 1.5 m along a winding road.
    Drive,
    /// 60 m/s at 30 m, banking turns.
    Fly,
    /// Standing (drifting 2 m/s), turning 180 degrees per second.
    FastTurn,
}

impl CameraPath {
    /// All paths.
    pub const ALL: [CameraPath; 4] = [
        CameraPath::Walk,
        CameraPath::Drive,
        CameraPath::Fly,
        CameraPath::FastTurn,
    ];

    /// The camera of every frame at 60 frames per second, starting at `start`.
    pub fn cameras(self, frames: u32, start: Vec3) -> Vec<CameraState> {
        let dt = 1.0 / 60.0;
        let (speed, height): (f64, f32) = match self {
            CameraPath::Walk => (1.5, 1.8),
            CameraPath::Drive => (20.0, 1.5),
            CameraPath::Fly => (60.0, 30.0),
            CameraPath::FastTurn => (2.0, 1.8),
        };
        let mut pos = glam::DVec2::new(f64::from(start.x), f64::from(start.z));
        let mut heading: f64 = 0.3;
        (0..frames)
            .map(|f| {
                let t = f64::from(f) * dt;
                let turn_rate = match self {
                    CameraPath::Walk => 0.2 * (t * 0.5).sin(),
                    CameraPath::Drive => 0.35 * (t * 0.25).sin() + 0.15 * (t * 1.3).sin(),
                    CameraPath::Fly => 0.25 * (t * 0.2).sin(),
                    CameraPath::FastTurn => std::f64::consts::PI,
                };
                heading += turn_rate * dt;
                let dir = glam::DVec2::new(heading.cos(), heading.sin());
                let move_dir = if self == CameraPath::FastTurn {
                    glam::DVec2::X
                } else {
                    dir
                };
                pos += move_dir * speed * dt;
                CameraState {
                    position: Vec3::new(pos.x as f32, height, pos.y as f32),
                    forward: Vec3::new(
                        dir.x as f32,
                        if self == CameraPath::Fly { -0.3 } else { 0.0 },
                        dir.y as f32,
                    ),
                    ..CameraState::at(Vec3::ZERO)
                }
            })
            .collect()
    }

    /// A short name.
    pub fn name(self) -> &'static str {
        match self {
            CameraPath::Walk => "walk",
            CameraPath::Drive => "drive",
            CameraPath::Fly => "fly",
            CameraPath::FastTurn => "fast turn",
        }
    }
}

/// A policy of the simulator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SimPolicy {
    /// [`FrustumSelection`] out to the demand radius plus `margin_m`, `margin_deg` wider,
    /// widened further while turning.
    Frustum {
        /// Extra distance in metres.
        margin_m: f64,
        /// Extra half-angle in degrees.
        margin_deg: f64,
    },
    /// [`BandSelection`] with this band width (fraction of the tile).
    Band {
        /// Band width.
        band_width: f64,
    },
    /// [`SphericalSelection`] of radius demand radius plus `margin_m`.
    Spherical {
        /// Extra distance in metres.
        margin_m: f64,
    },
    /// No prefetch: load what is demanded, evict the least recently demanded.
    LruOnDemand,
    /// Belady's offline optimum (MIN), the bound.
    Belady,
}

impl SimPolicy {
    /// The default set compared by [`comparison_table`].
    pub fn defaults() -> [SimPolicy; 5] {
        [
            SimPolicy::Frustum {
                margin_m: 32.0,
                margin_deg: 15.0,
            },
            SimPolicy::Band {
                band_width: 1.0 / 3.0,
            },
            SimPolicy::Spherical { margin_m: 32.0 },
            SimPolicy::LruOnDemand,
            SimPolicy::Belady,
        ]
    }

    /// A short name.
    pub fn name(&self) -> String {
        match self {
            SimPolicy::Frustum {
                margin_m,
                margin_deg,
            } => format!("frustum +{margin_m} m +{margin_deg} deg"),
            SimPolicy::Band { band_width } => format!("band regions w={band_width:.2}"),
            SimPolicy::Spherical { margin_m } => format!("spherical +{margin_m} m"),
            SimPolicy::LruOnDemand => "LRU on demand".into(),
            SimPolicy::Belady => "Belady MIN (bound)".into(),
        }
    }
}

/// Settings of a simulation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimConfig {
    /// Frames simulated (60 per second).
    pub frames: u32,
    /// Tiles across and down.
    pub tiles: UVec2,
    /// Tile side in metres.
    pub tile_m: f64,
    /// Demanded tiles lie within this 3D distance (and the exact frustum).
    pub demand_radius: f64,
    /// Cache capacity in tiles.
    pub capacity: usize,
    /// Frames from issuing a load to its arrival (Flower 2010, table 4.7: ~47 ms, 3 frames).
    pub latency_frames: u32,
    /// Loads issued per frame at most (Fikkan 2013, sec. 5.3).
    pub loads_per_frame: usize,
    /// Bytes per tile (a 256^2 u16 tile: 128 KiB).
    pub tile_bytes: u64,
}

impl Default for SimConfig {
    fn default() -> Self {
        Self {
            frames: 1200,
            tiles: UVec2::splat(64),
            tile_m: 64.0,
            demand_radius: 48.0,
            capacity: 12,
            latency_frames: 3,
            loads_per_frame: 2,
            tile_bytes: 256 * 256 * 2,
        }
    }
}

/// What a simulation measured.
#[derive(Debug, Clone, PartialEq)]
pub struct SimResult {
    /// The path.
    pub path: CameraPath,
    /// The policy.
    pub policy: SimPolicy,
    /// Demanded tiles resident when demanded, over all demands.
    pub hit_rate: f64,
    /// Frames with at least one demanded tile missing.
    pub missing_frames: u32,
    /// Loads issued.
    pub loads: u64,
    /// Bytes moved (loads times tile bytes).
    pub bytes_moved: u64,
    /// Mean frames from a tile's first missed demand to its arrival.
    pub mean_latency: f64,
    /// Largest such latency.
    pub max_latency: u32,
}

fn demand_sets(cfg: &SimConfig, cams: &[CameraState]) -> Vec<Vec<TileId>> {
    let grid = TileGrid::flat(cfg.tiles, cfg.tile_m, WrapMode::Repeat);
    let mut exact = FrustumSelection {
        level: 0,
        far: cfg.demand_radius,
        near: 1e-6,
        fov_margin: 0.0,
        turn_gain: 0.0,
        last_forward: None,
    };
    let mut out = Vec::new();
    cams.iter()
        .map(|c| {
            out.clear();
            exact.select(c, &grid, &mut out);
            let mut ids: Vec<TileId> = out.iter().map(|w| w.id).collect();
            ids.sort();
            ids.dedup();
            ids
        })
        .collect()
}

/// Simulates `policy` on `path`.
pub fn simulate(cfg: &SimConfig, path: CameraPath, policy: SimPolicy) -> SimResult {
    let extent = cfg.tiles.as_dvec2() * cfg.tile_m;
    let start = Vec3::new(
        (extent.x * 0.5 + 7.0) as f32,
        0.0,
        (extent.y * 0.5 + 11.0) as f32,
    );
    let cams = path.cameras(cfg.frames, start);
    let demand = demand_sets(cfg, &cams);
    if policy == SimPolicy::Belady {
        return belady(cfg, path, &demand);
    }
    let grid = TileGrid::flat(cfg.tiles, cfg.tile_m, WrapMode::Repeat);
    let mut selector: Option<Box<dyn SelectionPolicy>> = match policy {
        SimPolicy::Frustum {
            margin_m,
            margin_deg,
        } => Some(Box::new(FrustumSelection {
            level: 0,
            far: cfg.demand_radius + margin_m,
            near: cfg.tile_m * 0.25,
            fov_margin: margin_deg.to_radians(),
            turn_gain: 8.0,
            last_forward: None,
        })),
        SimPolicy::Band { band_width } => Some(Box::new(BandSelection {
            level: 0,
            band_width,
        })),
        SimPolicy::Spherical { margin_m } => {
            let r = cfg.demand_radius + margin_m;
            Some(Box::new(SphericalSelection {
                view_distance: r,
                lod0_range: r,
                lod_ratio: 2.0,
            }))
        }
        _ => None,
    };
    let mut resident: BTreeMap<TileId, u32> = BTreeMap::new(); // id -> last demanded frame
    let mut in_flight: BTreeMap<TileId, u32> = BTreeMap::new(); // id -> arrival frame
    let mut first_miss: HashMap<TileId, u32> = HashMap::new();
    let (mut hits, mut refs, mut missing_frames, mut loads) = (0u64, 0u64, 0u32, 0u64);
    let (mut lat_sum, mut lat_n, mut lat_max) = (0u64, 0u64, 0u32);
    let mut wants: Vec<Want> = Vec::new();
    for (f, cam) in cams.iter().enumerate() {
        let f = f as u32;
        let arrived: Vec<TileId> = in_flight
            .iter()
            .filter(|&(_, &a)| a <= f)
            .map(|(&id, _)| id)
            .collect();
        for id in arrived {
            in_flight.remove(&id);
            resident.insert(id, 0);
            if let Some(m) = first_miss.remove(&id) {
                let l = f - m;
                lat_sum += u64::from(l);
                lat_n += 1;
                lat_max = lat_max.max(l);
            }
        }
        let d = &demand[f as usize];
        let mut missed = false;
        for id in d {
            refs += 1;
            if let Some(last) = resident.get_mut(id) {
                hits += 1;
                *last = f;
            } else {
                missed = true;
                first_miss.entry(*id).or_insert(f);
            }
        }
        if missed {
            missing_frames += 1;
        }
        wants.clear();
        for id in d {
            wants.push(Want {
                id: *id,
                priority: -1.0,
            });
        }
        if let Some(s) = selector.as_mut() {
            s.select(cam, &grid, &mut wants);
        }
        let keep: BTreeSet<TileId> = wants.iter().map(|w| w.id).collect();
        wants.sort_by(|a, b| a.priority.total_cmp(&b.priority).then(a.id.cmp(&b.id)));
        let mut issued = 0;
        for w in &wants {
            if issued >= cfg.loads_per_frame {
                break;
            }
            if resident.contains_key(&w.id) || in_flight.contains_key(&w.id) {
                continue;
            }
            if resident.len() + in_flight.len() >= cfg.capacity {
                let victim = resident
                    .iter()
                    .filter(|(id, _)| !keep.contains(id))
                    .map(|(&id, &last)| {
                        let key = if selector.is_some() {
                            -grid.eviction_score(cam.position, id)
                        } else {
                            f64::from(last)
                        };
                        (id, key)
                    })
                    .min_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
                match victim {
                    Some((v, _)) => {
                        resident.remove(&v);
                    }
                    None => break,
                }
            }
            in_flight.insert(w.id, f + cfg.latency_frames.max(1));
            loads += 1;
            issued += 1;
        }
    }
    SimResult {
        path,
        policy,
        hit_rate: if refs == 0 {
            1.0
        } else {
            hits as f64 / refs as f64
        },
        missing_frames,
        loads,
        bytes_moved: loads * cfg.tile_bytes,
        mean_latency: if lat_n == 0 {
            0.0
        } else {
            lat_sum as f64 / lat_n as f64
        },
        max_latency: lat_max,
    }
}

/// Belady's MIN over the demand trace (one frame's demands served together; zero latency).
fn belady(cfg: &SimConfig, path: CameraPath, demand: &[Vec<TileId>]) -> SimResult {
    // Next-use index: for each frame and tile, the next frame (> f) that demands it.
    let mut next_use: HashMap<TileId, Vec<u32>> = HashMap::new();
    for (f, d) in demand.iter().enumerate() {
        for id in d {
            next_use.entry(*id).or_default().push(f as u32);
        }
    }
    let next_after = |id: &TileId, f: u32| -> u32 {
        let uses = &next_use[id];
        let i = uses.partition_point(|&u| u <= f);
        uses.get(i).copied().unwrap_or(u32::MAX)
    };
    let mut resident: BTreeSet<TileId> = BTreeSet::new();
    let (mut hits, mut refs, mut missing_frames, mut loads) = (0u64, 0u64, 0u32, 0u64);
    for (f, d) in demand.iter().enumerate() {
        let f = f as u32;
        let mut missed = false;
        for id in d {
            refs += 1;
            if resident.contains(id) {
                hits += 1;
                continue;
            }
            missed = true;
            if resident.len() >= cfg.capacity {
                let victim = resident
                    .iter()
                    .filter(|r| !d.contains(r))
                    .max_by_key(|r| (next_after(r, f), **r))
                    .copied();
                if let Some(v) = victim {
                    resident.remove(&v);
                }
            }
            resident.insert(*id);
            loads += 1;
        }
        if missed {
            missing_frames += 1;
        }
    }
    SimResult {
        path,
        policy: SimPolicy::Belady,
        hit_rate: if refs == 0 {
            1.0
        } else {
            hits as f64 / refs as f64
        },
        missing_frames,
        loads,
        bytes_moved: loads * cfg.tile_bytes,
        mean_latency: 0.0,
        max_latency: 0,
    }
}

/// Every path with every default policy, as a Markdown table.
pub fn comparison_table(cfg: &SimConfig) -> (Vec<SimResult>, String) {
    let mut results = Vec::new();
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{} frames, {}x{} tiles of {} m, demand radius {} m, capacity {} tiles, latency {} frames, {} loads/frame, {} KiB/tile",
        cfg.frames,
        cfg.tiles.x,
        cfg.tiles.y,
        cfg.tile_m,
        cfg.demand_radius,
        cfg.capacity,
        cfg.latency_frames,
        cfg.loads_per_frame,
        cfg.tile_bytes / 1024
    );
    let _ = writeln!(s);
    let _ = writeln!(
        s,
        "| path | policy | hit rate | frames missing a tile | loads | MiB moved | mean latency (frames) | max latency |"
    );
    let _ = writeln!(s, "|---|---|---:|---:|---:|---:|---:|---:|");
    for path in CameraPath::ALL {
        for policy in SimPolicy::defaults() {
            let r = simulate(cfg, path, policy);
            let _ = writeln!(
                s,
                "| {} | {} | {:.2} % | {} | {} | {:.1} | {:.1} | {} |",
                path.name(),
                policy.name(),
                r.hit_rate * 100.0,
                r.missing_frames,
                r.loads,
                r.bytes_moved as f64 / (1024.0 * 1024.0),
                r.mean_latency,
                r.max_latency
            );
            results.push(r);
        }
    }
    (results, s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn deterministic_and_belady_bounds_demand_fetch() {
        let cfg = SimConfig {
            frames: 600,
            ..SimConfig::default()
        };
        let (a, table) = comparison_table(&cfg);
        let (b, _) = comparison_table(&cfg);
        assert_eq!(a, b, "deterministic");
        assert!(table.contains("Belady"));
        for path in CameraPath::ALL {
            let of = |p: &str| {
                a.iter()
                    .find(|r| r.path == path && r.policy.name().starts_with(p))
                    .unwrap()
            };
            let min = of("Belady");
            let lru = of("LRU");
            assert!(min.hit_rate >= lru.hit_rate, "{path:?}");
            assert!(min.loads <= lru.loads, "{path:?}");
            // Prefetching beats demand fetch on misses for moving cameras.
            if path != CameraPath::Walk {
                assert!(
                    of("spherical").missing_frames <= lru.missing_frames,
                    "{path:?}"
                );
            }
        }
    }
}
