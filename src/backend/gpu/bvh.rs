//! The BVH layouts the GPU backend traverses, and building one part
//! (static or dynamic) of the geometry in either for upload.
//!
//! - [`GpuLayout::Bvh2`]: obvhs's BVH2 (`build_bvh2_from_tris`), nodes
//!   repacked as [`GpuNode`], traversed by `shaders/bvh2_traverse.wgsl`.
//! - [`GpuLayout::Cwbvh`]: obvhs's compressed wide BVH8
//!   (`build_cwbvh_from_tris`), the very tree the CPU backend traverses
//!   (`src/accel`), its 80-byte nodes uploaded as they are, traversed by
//!   `shaders/cwbvh_traverse.wgsl`.
//!
//! Both lay triangles out in the BVH's `primitive_indices` order, so that
//! leaves index the triangle buffer directly.

use super::{GpuError, GpuTriangle};
use crate::accel::BvhLife;
use crate::scene::Snapshot;
use bytemuck::{Pod, Zeroable};
use obvhs::bvh2::builder::build_bvh2_from_tris;
use obvhs::bvh2::Bvh2;
use obvhs::cwbvh::builder::build_cwbvh_from_tris;
use obvhs::cwbvh::node::CwBvhNode;
use obvhs::cwbvh::CwBvh;
use obvhs::triangle::Triangle as ObTriangle;
use std::time::Duration;

/// Entries of the BVH2 traversal stack. Must match `STACK_SIZE` in
/// `shaders/bvh2_traverse.wgsl`; deeper BVHs are refused.
pub const STACK_SIZE: usize = 64;

/// Node groups the CWBVH traversal can keep pending. Must match
/// `STACK_SIZE` in `shaders/cwbvh_traverse.wgsl`; deeper BVHs are refused.
pub const CWBVH_STACK_SIZE: usize = 32;

/// Environment variable that picks the layout of [`GpuLayout::from_env`]:
/// `cwbvh` (default) or `bvh2`.
pub const LAYOUT_ENV: &str = "RADCACHE_GPU_BVH";

/// Which BVH the GPU traverses. Chosen when the backend is created.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum GpuLayout {
    /// Binary BVH, 48-byte nodes, one box per node visit.
    Bvh2,
    /// Compressed wide BVH8, 80-byte nodes, 8 quantised child boxes per
    /// node visit; the CPU backend's tree. The default: it traced about
    /// twice as many rays per second as BVH2 on lavapipe (README,
    /// `--backend`) and returns the CPU's hits bit for bit there.
    #[default]
    Cwbvh,
}

impl GpuLayout {
    pub const ALL: [GpuLayout; 2] = [GpuLayout::Bvh2, GpuLayout::Cwbvh];

    /// The layout named by `RADCACHE_GPU_BVH` (unset or empty: the default).
    /// A developer's switch for comparing the two; the CLI has no flag.
    pub fn from_env() -> Result<Self, GpuError> {
        Self::parse(&std::env::var(LAYOUT_ENV).unwrap_or_default())
    }

    /// `bvh2`, `cwbvh`, or empty for the default.
    pub fn parse(name: &str) -> Result<Self, GpuError> {
        match name {
            "" => Ok(GpuLayout::default()),
            "bvh2" => Ok(GpuLayout::Bvh2),
            "cwbvh" => Ok(GpuLayout::Cwbvh),
            other => Err(GpuError::Config(format!(
                "{LAYOUT_ENV}={other}: expected bvh2 or cwbvh"
            ))),
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            GpuLayout::Bvh2 => "BVH2",
            GpuLayout::Cwbvh => "CWBVH",
        }
    }

    /// Bytes of one node in the node buffer.
    pub fn node_bytes(self) -> u64 {
        match self {
            GpuLayout::Bvh2 => std::mem::size_of::<GpuNode>() as u64,
            GpuLayout::Cwbvh => std::mem::size_of::<CwBvhNode>() as u64,
        }
    }

    /// The traversal shader, declaring the node binding, `trace_ray` and
    /// `traverse`.
    pub(super) fn traversal_source(self) -> &'static str {
        match self {
            GpuLayout::Bvh2 => include_str!("../../../shaders/bvh2_traverse.wgsl"),
            GpuLayout::Cwbvh => include_str!("../../../shaders/cwbvh_traverse.wgsl"),
        }
    }
}

/// A BVH2 node as the shaders read it: obvhs `Bvh2Node` with its bounds as
/// vec4-sized fields. Field order must match `Node` in
/// `shaders/bvh2_traverse.wgsl`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct GpuNode {
    pub aabb_min: [f32; 3],
    pub _pad0: u32,
    pub aabb_max: [f32; 3],
    pub _pad1: u32,
    /// 0 for an inner node, else the number of triangles of the leaf.
    pub prim_count: u32,
    /// Inner node: index of the first child (the second follows it). Leaf:
    /// index of its first triangle in the triangle buffer.
    pub first_index: u32,
    pub _pad2: u32,
    pub _pad3: u32,
}

const _: () = assert!(std::mem::size_of::<GpuNode>() == 48);
const _: () = assert!(std::mem::size_of::<obvhs::bvh2::node::Bvh2Node>() == 48);
// `Node` in `shaders/cwbvh_traverse.wgsl` reads it as 80 bytes, stride 80.
const _: () = assert!(std::mem::size_of::<CwBvhNode>() == 80);

/// The nodes of a part, in its layout's format.
enum Nodes {
    Bvh2(Vec<GpuNode>),
    Cwbvh(Vec<CwBvhNode>),
}

/// One part (static or dynamic) of the geometry, ready for upload.
pub(super) struct Part {
    nodes: Nodes,
    pub triangles: Vec<GpuTriangle>,
}

impl Part {
    /// A BVH in `layout` over snapshot triangles `range`, built with the
    /// preset the CPU's takes for `life`, triangles in leaf order. Refuses
    /// a BVH deeper than its traversal's stack.
    pub fn build(
        layout: GpuLayout,
        snapshot: &Snapshot,
        range: std::ops::Range<usize>,
        life: BvhLife,
    ) -> Result<Self, GpuError> {
        let source: Vec<ObTriangle> = (snapshot.triangles.range(range.clone()))
            .map(|t| ObTriangle {
                v0: t.p[0].into(),
                v1: t.p[1].into(),
                v2: t.p[2].into(),
            })
            .collect();
        // obvhs builds nothing useful from no triangles: an empty part has
        // no nodes (its root is NONE in the shaders).
        let (nodes, order) = match layout {
            GpuLayout::Bvh2 if range.is_empty() => (Nodes::Bvh2(Vec::new()), Vec::new()),
            GpuLayout::Cwbvh if range.is_empty() => (Nodes::Cwbvh(Vec::new()), Vec::new()),
            GpuLayout::Bvh2 => bvh2_nodes(&source, life)?,
            GpuLayout::Cwbvh => cwbvh_nodes(&source, life)?,
        };
        let triangles = order
            .iter()
            .map(|&i| {
                let id = range.start + i as usize;
                let t = &snapshot.triangles[id];
                GpuTriangle {
                    v0: t.p[0].to_array(),
                    id: id as u32,
                    v1: t.p[1].to_array(),
                    object: snapshot.tri_object[id],
                    v2: t.p[2].to_array(),
                    _pad: 0,
                }
            })
            .collect();
        Ok(Part { nodes, triangles })
    }

    pub fn node_count(&self) -> usize {
        match &self.nodes {
            Nodes::Bvh2(n) => n.len(),
            Nodes::Cwbvh(n) => n.len(),
        }
    }

    pub fn node_bytes(&self) -> &[u8] {
        match &self.nodes {
            Nodes::Bvh2(n) => bytemuck::cast_slice(n),
            Nodes::Cwbvh(n) => bytemuck::cast_slice(n),
        }
    }

    /// Moves the part behind `nodes` nodes and `triangles` triangles in the
    /// shared buffers.
    pub fn offset(&mut self, nodes: u32, triangles: u32) {
        match &mut self.nodes {
            Nodes::Bvh2(all) => {
                for n in all {
                    n.first_index += if n.prim_count == 0 { nodes } else { triangles };
                }
            }
            Nodes::Cwbvh(all) => {
                for n in all {
                    n.child_base_idx += nodes;
                    n.primitive_base_idx += triangles;
                }
            }
        }
    }
}

fn too_deep(depth: usize, stack: usize) -> Result<(), GpuError> {
    if depth > stack {
        return Err(GpuError::Geometry(format!(
            "BVH depth {depth} exceeds the traversal stack of {stack} entries"
        )));
    }
    Ok(())
}

/// BVH2 nodes and the triangle order of their leaves.
fn bvh2_nodes(source: &[ObTriangle], life: BvhLife) -> Result<(Nodes, Vec<u32>), GpuError> {
    let params = life.params(source.len());
    let bvh = build_bvh2_from_tris(source, params, &mut Duration::default());
    too_deep(bvh2_depth(&bvh), STACK_SIZE)?;
    let nodes = bvh
        .nodes
        .iter()
        .map(|n| GpuNode {
            aabb_min: n.aabb.min.to_array(),
            aabb_max: n.aabb.max.to_array(),
            prim_count: n.prim_count,
            first_index: n.first_index,
            ..GpuNode::default()
        })
        .collect();
    Ok((Nodes::Bvh2(nodes), bvh.primitive_indices))
}

/// CWBVH nodes (built exactly as `src/accel` builds the CPU's) and the
/// triangle order of their leaves.
fn cwbvh_nodes(source: &[ObTriangle], life: BvhLife) -> Result<(Nodes, Vec<u32>), GpuError> {
    let params = life.params(source.len());
    let bvh = build_cwbvh_from_tris(source, params, &mut Duration::default());
    too_deep(cwbvh_depth(&bvh), CWBVH_STACK_SIZE)?;
    Ok((Nodes::Cwbvh(bvh.nodes), bvh.primitive_indices))
}

/// Depth of a BVH2 (a lone root leaf has depth 1): the traversal stack
/// holds at most depth − 1 entries.
fn bvh2_depth(bvh: &Bvh2) -> usize {
    tree_depth(bvh.nodes.len(), |i| {
        let n = &bvh.nodes[i];
        let c = n.first_index as usize;
        (n.prim_count == 0)
            .then_some([c, c + 1])
            .into_iter()
            .flatten()
    })
}

/// Depth in nodes of a CWBVH (a lone root has depth 1): the traversal
/// keeps at most one pending group per level above the current node.
fn cwbvh_depth(bvh: &CwBvh) -> usize {
    tree_depth(bvh.nodes.len(), |i| {
        let n = &bvh.nodes[i];
        (0..8)
            .filter(|&slot| !n.is_leaf(slot))
            .map(|slot| n.child_node_index(slot) as usize)
    })
}

/// Depth in nodes of a tree of `len` nodes rooted at node 0, given each
/// node's child nodes (0 for an empty tree).
fn tree_depth<I: Iterator<Item = usize>>(len: usize, children: impl Fn(usize) -> I) -> usize {
    if len == 0 {
        return 0;
    }
    let mut max = 0;
    let mut stack = vec![(0usize, 1usize)];
    while let Some((i, d)) = stack.pop() {
        max = max.max(d);
        stack.extend(children(i).map(|c| (c, d + 1)));
    }
    max
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout_names_parse_and_cwbvh_is_the_default() {
        assert_eq!(GpuLayout::parse("").unwrap(), GpuLayout::Cwbvh);
        assert_eq!(GpuLayout::parse("bvh2").unwrap(), GpuLayout::Bvh2);
        assert_eq!(GpuLayout::parse("cwbvh").unwrap(), GpuLayout::Cwbvh);
        let e = GpuLayout::parse("bvh4").unwrap_err().to_string();
        assert!(e.contains("RADCACHE_GPU_BVH=bvh4"), "{e}");
    }

    #[test]
    fn node_sizes_match_the_shaders() {
        assert_eq!(GpuLayout::Bvh2.node_bytes(), 48);
        assert_eq!(GpuLayout::Cwbvh.node_bytes(), 80);
    }
}
