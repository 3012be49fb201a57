//! A loose octree over spheres of influence, for finding every record whose
//! sphere contains a query point (Ward et al. 1988 store records in an
//! octree for the same purpose).
//!
//! A sphere is stored in the deepest node whose cell contains its centre and
//! whose half-size is at least its radius; the sphere then lies inside the
//! node's *loose* bounds (the cell grown by its half-size on every side).
//! Each node also keeps the exact box around every sphere of its subtree,
//! which is much tighter than the loose cell where records lie on surfaces
//! (a wall's records fill a thin slab, not the cube around it): a query
//! descends only into children whose box contains the point. This test
//! runs once per shading point and dominates the render pass's lookups.

use glam::Vec3;

/// Depth limit: cells 2⁻¹⁶ of the root are far below any record radius.
const MAX_DEPTH: u32 = 16;

struct Node {
    center: Vec3,
    half: f32,
    /// `(item, centre, radius)` of the spheres stored here.
    items: Vec<(u32, Vec3, f32)>,
    /// Box around every sphere stored in this node or below (empty:
    /// `min > max`). Shrinking a sphere leaves it conservative.
    bounds_min: Vec3,
    bounds_max: Vec3,
    children: Option<Box<[Node; 8]>>,
}

impl Node {
    fn new(center: Vec3, half: f32) -> Self {
        Node {
            center,
            half,
            items: Vec::new(),
            bounds_min: Vec3::INFINITY,
            bounds_max: Vec3::NEG_INFINITY,
            children: None,
        }
    }

    fn grow_bounds(&mut self, center: Vec3, radius: f32) {
        self.bounds_min = self.bounds_min.min(center - radius);
        self.bounds_max = self.bounds_max.max(center + radius);
    }

    fn bounds_contain(&self, p: Vec3) -> bool {
        p.cmpge(self.bounds_min).all() && p.cmple(self.bounds_max).all()
    }

    fn split(&mut self) {
        let h = self.half * 0.5;
        let c = self.center;
        self.children = Some(Box::new(std::array::from_fn(|i| {
            let offset = Vec3::new(
                if i & 1 != 0 { h } else { -h },
                if i & 2 != 0 { h } else { -h },
                if i & 4 != 0 { h } else { -h },
            );
            Node::new(c + offset, h)
        })));
    }
}

/// Spheres (id, centre, radius) indexed for point queries.
pub struct SphereOctree {
    root: Node,
    len: usize,
}

impl SphereOctree {
    /// An empty tree covering the box `[min, max]` (points outside still
    /// work, they are kept at the root).
    pub fn new(min: Vec3, max: Vec3) -> Self {
        let center = 0.5 * (min + max);
        let half = (0.5 * (max - min)).max_element().max(1e-3) * 1.01;
        SphereOctree {
            root: Node::new(center, half),
            len: 0,
        }
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    pub fn insert(&mut self, id: u32, center: Vec3, radius: f32) {
        self.len += 1;
        let mut node = &mut self.root;
        let mut depth = 0;
        let inside_root = (center - node.center).abs().max_element() <= node.half;
        node.grow_bounds(center, radius);
        while inside_root && depth < MAX_DEPTH && node.half * 0.5 >= radius {
            if node.children.is_none() {
                node.split();
            }
            let i = child_for(node.center, center);
            node = &mut node.children.as_mut().expect("split above")[i];
            node.grow_bounds(center, radius);
            depth += 1;
        }
        node.items.push((id, center, radius));
    }

    /// Bytes the tree holds: its nodes and their item lists.
    pub fn memory_bytes(&self) -> usize {
        let mut bytes = 0;
        let mut stack = vec![&self.root];
        while let Some(node) = stack.pop() {
            bytes += std::mem::size_of::<Node>()
                + node.items.capacity() * std::mem::size_of::<(u32, Vec3, f32)>();
            stack.extend(node.children.iter().flat_map(|c| c.iter()));
        }
        bytes
    }

    /// Calls `visit(id)` for every sphere that contains `p`.
    pub fn query(&self, p: Vec3, mut visit: impl FnMut(u32)) {
        self.find(p, |id| {
            visit(id);
            false
        });
    }

    /// Whether `test(id)` holds for some sphere that contains `p`: the
    /// spheres are visited as by [`Self::query`] until one passes.
    pub fn any(&self, p: Vec3, test: impl FnMut(u32) -> bool) -> bool {
        self.find(p, test)
    }

    /// Visits the spheres that contain `p` until `stop(id)` is true;
    /// returns whether it was.
    fn find(&self, p: Vec3, mut stop: impl FnMut(u32) -> bool) -> bool {
        // A fixed stack: at most 8 children are pushed per level (this runs
        // once per shading point, so it must not allocate).
        let mut stack: [Option<&Node>; 8 * MAX_DEPTH as usize + 1] =
            [None; 8 * MAX_DEPTH as usize + 1];
        stack[0] = Some(&self.root);
        let mut len = 1;
        while len > 0 {
            len -= 1;
            let node = stack[len].take().expect("entries below len are set");
            for &(id, c, r) in &node.items {
                if (p - c).length_squared() <= r * r && stop(id) {
                    return true;
                }
            }
            if let Some(children) = &node.children {
                for child in children.iter().filter(|c| c.bounds_contain(p)) {
                    stack[len] = Some(child);
                    len += 1;
                }
            }
        }
        false
    }

    /// Shrinks the stored radius of `id` (the sphere stays where it is
    /// stored: a smaller sphere still fits its node's loose bounds).
    pub fn shrink(&mut self, id: u32, center: Vec3, radius: f32) {
        let mut stack: Vec<&mut Node> = vec![&mut self.root];
        while let Some(node) = stack.pop() {
            if let Some(item) = node.items.iter_mut().find(|it| it.0 == id) {
                item.2 = item.2.min(radius);
                return;
            }
            if let Some(children) = node.children.as_deref_mut() {
                let i = child_for(node.center, center);
                stack.push(&mut children[i]);
            }
        }
    }
}

/// Index of the child cell of a node centred at `node_center` holding `p`.
fn child_for(node_center: Vec3, p: Vec3) -> usize {
    (usize::from(p.x >= node_center.x))
        | (usize::from(p.y >= node_center.y) << 1)
        | (usize::from(p.z >= node_center.z) << 2)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::{Rng, SampleKey};

    #[test]
    fn query_finds_exactly_the_containing_spheres() {
        let mut rng = Rng::new(SampleKey {
            seed: 1,
            frame: None,
            item: 0,
            sample: 0,
        });
        let mut tree = SphereOctree::new(Vec3::splat(-1.0), Vec3::splat(1.0));
        let mut spheres = Vec::new();
        for id in 0..2000u32 {
            let c = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.4 - 1.2;
            let r = 0.002 + 0.3 * rng.next_f32().powi(3);
            tree.insert(id, c, r);
            spheres.push((c, r));
        }
        for (id, (c, r)) in spheres.iter_mut().enumerate().step_by(7) {
            *r *= 0.5;
            tree.shrink(id as u32, *c, *r);
        }
        for _ in 0..2000 {
            let p = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.6 - 1.3;
            let mut found = Vec::new();
            tree.query(p, |id| found.push(id));
            found.sort_unstable();
            let brute: Vec<u32> = spheres
                .iter()
                .enumerate()
                .filter(|(_, (c, r))| (p - *c).length_squared() <= r * r)
                .map(|(i, _)| i as u32)
                .collect();
            assert_eq!(found, brute, "at {p}");
        }
    }

    #[test]
    fn memory_grows_with_the_spheres_held() {
        let mut tree = SphereOctree::new(Vec3::splat(-1.0), Vec3::splat(1.0));
        let empty = tree.memory_bytes();
        assert!(empty >= std::mem::size_of::<Node>());
        // Small spheres split the root: eight children at least.
        tree.insert(0, Vec3::splat(0.5), 0.01);
        let one = tree.memory_bytes();
        assert!(one >= empty + 8 * std::mem::size_of::<Node>() + 20, "{one}");
        for id in 1..100 {
            tree.insert(id, Vec3::splat(0.5) - 0.004 * id as f32, 0.01);
        }
        assert!(tree.memory_bytes() >= one + 99 * 20);
    }
}
