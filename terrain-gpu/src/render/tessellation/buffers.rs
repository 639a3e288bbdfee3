//! [`GpuTessellation`]: the persistent buffers of the tessellation.

use super::*;
use terrain_core::{HeightEncoding, Rect};
use terrain_lod::{CdlodTree, StreamedTessellation};

/// A [`TessHierarchy`] on the GPU, with room for `capacity` triangles of output and
/// `queue_capacity` triangles in each of the two level queues.
#[derive(Debug)]
pub struct GpuTessellation {
    pub(super) vertices: wgpu::Buffer,
    pub(super) patch_bounds: wgpu::Buffer,
    pub(super) output: wgpu::Buffer,
    pub(super) state: wgpu::Buffer,
    pub(super) queues: wgpu::Buffer,
    pub(super) dispatch: wgpu::Buffer,
    pub(super) capacity: u32,
    pub(super) queue_capacity: u32,
    pub(super) grid: UVec2,
    pub(super) patches: UVec2,
    pub(super) source: Source,
    /// A streamed world's tree: per LOD, nodes per axis and the first node's index.
    tree_lods: Vec<(UVec2, u64)>,
}

/// What a [`GpuTessellation`]'s splits are decided from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Source {
    /// A map's [`TessHierarchy`]: per-vertex bounds (binding 1) and patch bounds (2).
    Hierarchy,
    /// A streamed world's tree: node bounds (binding 1) and [`TreeInfo`] (2).
    Streamed,
}

/// The `TreeInfo` block of `tess_source_streamed.wgsl`, byte for byte.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct TreeInfo {
    lod: [[u32; 4]; 16],
    level: [[u32; 4]; 16],
    world: [u32; 4],
    height: [f32; 4],
}

/// The sizes [`GpuTessellation::allocate`] makes room for.
struct Sizes {
    /// Bytes of the decision data (binding 1) and its table (binding 2).
    decision: u64,
    table: u64,
    capacity: u32,
    queue_capacity: u32,
    patches: UVec2,
}

impl GpuTessellation {
    /// Uploads `hierarchy` and makes room for `capacity` triangles (at least 1), with level
    /// queues of as many triangles each (fewer where the device's storage buffer limit asks
    /// for it; 24 bytes a triangle, so the two add 48 bytes per triangle of capacity to the
    /// output's 36): a level queues only visible children of the triangles that split, each
    /// of which leads to at least one emitted triangle unless the frustum misses both of its
    /// own children. Fails when the buffers exceed the device's limits.
    pub fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        hierarchy: &TessHierarchy,
        capacity: u32,
    ) -> Result<Self, GpuError> {
        let limit = device.limits().max_storage_buffer_binding_size;
        let fit = u32::try_from(limit / (2 * QUEUED_BYTES)).unwrap_or(u32::MAX);
        Self::with_queues(device, queue, hierarchy, capacity, capacity.min(fit))
    }

    /// As [`GpuTessellation::new`], with room for `queue_capacity` triangles (at least 1) in
    /// each of the two level queues. A view whose refinement queues more triangles in one
    /// level emits those that find no room unsplit and reports an overflow, as a full output
    /// does. Fails when the buffers exceed the device's limits.
    pub fn with_queues(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        hierarchy: &TessHierarchy,
        capacity: u32,
        queue_capacity: u32,
    ) -> Result<Self, GpuError> {
        let grid = hierarchy.grid_size();
        let patches = hierarchy.patches();
        let limit = device.limits().max_storage_buffer_binding_size;
        let vertex_bytes = u64::from(grid.x) * u64::from(grid.y) * VERTEX_BYTES;
        if vertex_bytes > limit {
            return Err(GpuError::MapTooLarge {
                size: grid,
                bytes: vertex_bytes,
                limit,
            });
        }
        let sizes = Sizes {
            decision: vertex_bytes,
            table: u64::from(patches.x) * u64::from(patches.y) * 8,
            capacity,
            queue_capacity,
            patches,
        };
        let mut out = Self::allocate(device, &sizes, Source::Hierarchy)?;
        out.grid = grid;
        out.upload(queue, hierarchy, std::slice::from_ref(&(0..grid.y)))?;
        Ok(out)
    }

    /// The buffers of a streamed world's tessellation (`tess`, decided from `tree`, the world's
    /// streamed quadtree, whose heights are stored as `encoding` says), with room for
    /// `capacity` triangles as [`GpuTessellation::new`]. Keep the tree's bounds current with
    /// [`GpuTessellation::upload_tree`] after it changes.
    pub fn streamed(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        tess: &StreamedTessellation,
        tree: &CdlodTree,
        encoding: HeightEncoding,
        capacity: u32,
    ) -> Result<Self, GpuError> {
        // A tree of another world fails here as in every later upload.
        tess.lookup_lods()
            .iter()
            .all(|&l| l < tree.config().lod_count)
            .then_some(())
            .ok_or(GpuError::SizeMismatch {
                expected: tree.map_size(),
                actual: tree.map_size(),
            })?;
        let mut info = TreeInfo::zeroed();
        let mut first = 0u64;
        let mut lods = Vec::new();
        for lod in 0..tree.config().lod_count.min(16) {
            let Some((n, _)) = tree.lod_nodes(lod) else {
                break;
            };
            let side = u32::try_from(tree.node_size(lod)).unwrap_or(u32::MAX);
            info.lod[lod as usize] = [n.x, n.y, first as u32, side];
            lods.push((n, first));
            first += u64::from(n.x) * u64::from(n.y);
        }
        for (l, ((&reach, &lod), &radius)) in tess
            .reach()
            .iter()
            .zip(tess.lookup_lods())
            .zip(tess.radius())
            .enumerate()
            .take(16)
        {
            info.level[l] = [reach, lod, radius.to_bits(), 0];
        }
        let size = tree.map_size();
        info.world = [size.x, size.y, 0, 0];
        info.height = [encoding.offset, encoding.scale, 0.0, 0.0];
        let fit =
            u32::try_from(device.limits().max_storage_buffer_binding_size / (2 * QUEUED_BYTES))
                .unwrap_or(u32::MAX);
        let sizes = Sizes {
            decision: first * 8,
            table: std::mem::size_of::<TreeInfo>() as u64,
            capacity,
            queue_capacity: capacity.min(fit),
            patches: tess.patches(),
        };
        let mut out = Self::allocate(device, &sizes, Source::Streamed)?;
        out.grid = size;
        out.tree_lods = lods;
        queue.write_buffer(&out.patch_bounds, 0, bytemuck::bytes_of(&info));
        out.upload_tree(queue, tree, &[Rect::from_size(size)])?;
        Ok(out)
    }

    /// Copies the bounds of the tree's nodes that `dirty` (rects of texels the tree was
    /// updated over) touch, every LOD, to the GPU. Fails for a tree of another shape.
    pub fn upload_tree(
        &self,
        queue: &wgpu::Queue,
        tree: &CdlodTree,
        dirty: &[Rect],
    ) -> Result<(), GpuError> {
        let mismatch = GpuError::SizeMismatch {
            expected: self.grid,
            actual: tree.map_size(),
        };
        if self.source != Source::Streamed || tree.map_size() != self.grid {
            return Err(mismatch);
        }
        for (lod, &(n, first)) in self.tree_lods.iter().enumerate() {
            let Some((m, nodes)) = tree.lod_nodes(lod as u32) else {
                return Err(mismatch);
            };
            if m != n {
                return Err(mismatch);
            }
            let side = tree.node_size(lod as u32) as i64;
            for rect in dirty {
                // The rows of nodes whose texels (far edges included) meet the rect.
                let y0 = ((i64::from(rect.min.y) - 1).max(0) / side).min(i64::from(n.y));
                let y1 = ((i64::from(rect.min.y) + i64::from(rect.size.y)) / side + 1)
                    .clamp(y0, i64::from(n.y));
                let (a, b) = (y0 as usize * n.x as usize, y1 as usize * n.x as usize);
                let packed: Vec<[f32; 2]> = nodes[a..b].iter().map(|b| [b.min, b.max]).collect();
                queue.write_buffer(
                    &self.vertices,
                    (first + a as u64) * 8,
                    bytemuck::cast_slice(&packed),
                );
            }
        }
        Ok(())
    }

    /// The buffers, nothing uploaded.
    fn allocate(device: &wgpu::Device, sizes: &Sizes, source: Source) -> Result<Self, GpuError> {
        let patches = sizes.patches;
        let capacity = sizes.capacity.max(1);
        let queue_capacity = sizes.queue_capacity.max(1);
        let limit = device.limits().max_storage_buffer_binding_size;
        let output_bytes = u64::from(capacity) * TRIANGLE_BYTES;
        let queue_bytes = 2 * u64::from(queue_capacity) * QUEUED_BYTES;
        if sizes.decision > limit {
            return Err(GpuError::Unsupported {
                what: "GpuTessellation",
                reason: "the tree's node bounds exceed the device's storage buffer limit: use \
                         larger leaves",
            });
        }
        if output_bytes > limit {
            return Err(GpuError::Unsupported {
                what: "GpuTessellation",
                reason: "the output for this many triangles exceeds the device's storage buffer \
                         limit (36 bytes per triangle): ask for fewer",
            });
        }
        if u64::from(patches.x) * u64::from(patches.y) > MAX_PATCHES {
            return Err(GpuError::Unsupported {
                what: "GpuTessellation",
                reason: "more than 2^28 patches: use larger patches",
            });
        }
        if queue_bytes > limit {
            return Err(GpuError::Unsupported {
                what: "GpuTessellation",
                reason: "the level queues for this many triangles exceed the device's storage \
                         buffer limit (48 bytes per triangle): ask for fewer",
            });
        }
        let storage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
        let indirect = storage | wgpu::BufferUsages::INDIRECT;
        let buffers = scoped(device, "GpuTessellation", || {
            let buffer = |label, size: u64, usage| {
                device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size: size.max(16),
                    usage,
                    mapped_at_creation: false,
                })
            };
            (
                buffer("tessellation decisions", sizes.decision, storage),
                buffer("tessellation decision table", sizes.table, storage),
                buffer(
                    "tessellation output",
                    output_bytes,
                    wgpu::BufferUsages::STORAGE
                        | wgpu::BufferUsages::VERTEX
                        | wgpu::BufferUsages::COPY_SRC,
                ),
                buffer(
                    "tessellation state",
                    STATE_BYTES,
                    indirect | wgpu::BufferUsages::COPY_SRC,
                ),
                buffer("tessellation queues", queue_bytes, storage),
                buffer(
                    "tessellation dispatch",
                    u64::from(MAX_LEVELS + 1) * DISPATCH_BYTES,
                    indirect,
                ),
            )
        })?;
        let (vertices, patch_bounds, output, state, queues, dispatch) = buffers;
        let out = Self {
            vertices,
            patch_bounds,
            output,
            state,
            queues,
            dispatch,
            capacity,
            queue_capacity,
            grid: UVec2::ZERO,
            patches,
            source,
            tree_lods: Vec::new(),
        };
        Ok(out)
    }

    /// Copies the vertex rows `rows` (the ranges [`TessHierarchy::update_rect`] returns, of
    /// one or more updates) and all patch bounds of `hierarchy` to the GPU. Fails for a
    /// hierarchy of another size.
    pub fn upload(
        &self,
        queue: &wgpu::Queue,
        hierarchy: &TessHierarchy,
        rows: &[std::ops::Range<u32>],
    ) -> Result<(), GpuError> {
        if self.source != Source::Hierarchy
            || hierarchy.grid_size() != self.grid
            || hierarchy.patches() != self.patches
        {
            return Err(GpuError::SizeMismatch {
                expected: self.grid,
                actual: hierarchy.grid_size(),
            });
        }
        // Ranges of several updates overlap: each row is copied once. In pieces of at most
        // 256 rows, so the packed copy stays small.
        let pieces = merge_rows(rows, self.grid.y)
            .into_iter()
            .flat_map(|r| r.clone().step_by(256).map(move |y| y..(y + 256).min(r.end)));
        for rows in pieces {
            let w = self.grid.x as usize;
            let (a, b) = (rows.start as usize * w, rows.end as usize * w);
            let packed: Vec<[f32; 4]> = hierarchy.heights()[a..b]
                .iter()
                .zip(&hierarchy.bounds()[a..b])
                .map(|(&h, &[r, d, e])| [h, r, d, e])
                .collect();
            queue.write_buffer(
                &self.vertices,
                a as u64 * VERTEX_BYTES,
                bytemuck::cast_slice(&packed),
            );
        }
        queue.write_buffer(
            &self.patch_bounds,
            0,
            bytemuck::cast_slice(hierarchy.patch_bounds()),
        );
        Ok(())
    }

    /// Triangles the output holds.
    pub fn capacity(&self) -> u32 {
        self.capacity
    }

    /// Bytes of GPU memory the grid's vertices take (16 per vertex: height and bounds).
    pub fn vertex_bytes(&self) -> u64 {
        self.vertices.size()
    }

    /// Bytes of GPU memory of the output, the level queues and the small state buffers: what
    /// grows with the triangle capacity.
    pub fn triangle_bytes(&self) -> u64 {
        [
            &self.patch_bounds,
            &self.output,
            &self.state,
            &self.queues,
            &self.dispatch,
        ]
        .iter()
        .map(|b| b.size())
        .sum()
    }

    /// Triangles each of the two level queues holds.
    pub fn queue_capacity(&self) -> u32 {
        self.queue_capacity
    }

    /// Reads back what the last [`TessellationPass::encode`] wrote: its triangles (in no
    /// particular order) and whether more were generated than the output or a level queue
    /// holds. Blocking: for tests and tools.
    pub fn read_triangles(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> Result<(Vec<TessTriangle>, bool), GpuError> {
        let state = download_bytes(device, queue, &self.state, 0, STATE_BYTES)?;
        let words: &[u32] = bytemuck::cast_slice(&state);
        let count = words[0].min(self.capacity);
        let overflow = words[1] != 0;
        if count == 0 {
            return Ok((Vec::new(), overflow));
        }
        let bytes = download_bytes(
            device,
            queue,
            &self.output,
            0,
            u64::from(count) * TRIANGLE_BYTES,
        )?;
        let verts: &[TessVertex] = bytemuck::cast_slice(&bytes);
        let tris = verts.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
        Ok((tris, overflow))
    }
}

/// `rows` clipped to `0..grid_rows`, sorted and merged where they overlap or touch.
fn merge_rows(rows: &[std::ops::Range<u32>], grid_rows: u32) -> Vec<std::ops::Range<u32>> {
    let mut sorted: Vec<_> = rows
        .iter()
        .map(|r| r.start.min(grid_rows)..r.end.min(grid_rows))
        .filter(|r| !r.is_empty())
        .collect();
    sorted.sort_by_key(|r| r.start);
    let mut merged: Vec<std::ops::Range<u32>> = Vec::with_capacity(sorted.len());
    for r in sorted {
        match merged.last_mut() {
            Some(last) if r.start <= last.end => last.end = last.end.max(r.end),
            _ => merged.push(r),
        }
    }
    merged
}

#[cfg(test)]
mod tests {
    use super::merge_rows;

    #[test]
    fn overlapping_and_touching_rows_merge_and_rows_past_the_grid_are_dropped() {
        let rows = [5..9, 0..2, 8..12, 2..3, 40..50, 20..20, 14..15];
        assert_eq!(merge_rows(&rows, 45), vec![0..3, 5..12, 14..15, 40..45]);
        assert_eq!(
            merge_rows(&[50..60, 45..70], 45),
            Vec::<std::ops::Range<u32>>::new()
        );
    }
}
