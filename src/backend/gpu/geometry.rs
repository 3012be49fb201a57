//! The frame's BVHs on the device: one node buffer and one triangle
//! buffer, the static part at their front (uploaded once per scene) and
//! the dynamic part after it (written every frame). The buffers only grow,
//! by a quarter more than needed, within one storage binding.

use super::bvh::Part;
use super::{GpuError, NONE, TRIANGLE_BYTES};

/// The node and triangle buffers: static part first, dynamic part after.
pub(super) struct GeometryBuffers {
    pub(super) nodes: wgpu::Buffer,
    pub(super) triangles: wgpu::Buffer,
    /// Bytes of one node of the layout the shaders traverse.
    node_bytes: u64,
    node_capacity: u64,
    triangle_capacity: u64,
    /// Nodes and triangles of the static part at the front of the buffers.
    pub(super) static_nodes: u64,
    pub(super) static_triangles: u64,
    pub(super) static_fingerprint: Option<u64>,
    pub(super) static_root: u32,
    pub(super) dynamic_root: u32,
}

impl GeometryBuffers {
    /// Empty buffers for nodes of `node_bytes` bytes: no part uploaded.
    pub(super) fn new(device: &wgpu::Device, node_bytes: u64) -> Self {
        GeometryBuffers {
            nodes: storage_buffer(device, "nodes", node_bytes),
            triangles: storage_buffer(device, "triangles", TRIANGLE_BYTES),
            node_bytes,
            node_capacity: 1,
            triangle_capacity: 1,
            static_nodes: 0,
            static_triangles: 0,
            static_fingerprint: None,
            static_root: NONE,
            dynamic_root: NONE,
        }
    }

    /// Grows (never shrinks) the geometry buffers to hold a static part of
    /// `(nodes, triangles)` followed by `dynamic`. With `keep_static`, the
    /// static part already in the buffers is copied over on the GPU by
    /// `encoder`, not uploaded again. An error where they would exceed a
    /// storage binding.
    pub(super) fn reserve(
        &mut self,
        grow: &Growth,
        encoder: &mut wgpu::CommandEncoder,
        (static_nodes, static_triangles): (u64, u64),
        dynamic: &Part,
        keep_static: bool,
    ) -> Result<(), GpuError> {
        let nodes_needed = (static_nodes + dynamic.node_count() as u64).max(1);
        let triangles_needed = (static_triangles + dynamic.triangles.len() as u64).max(1);
        let node_bytes = self.node_bytes;
        check_binding_size("BVH nodes", nodes_needed, node_bytes, grow.max_binding)?;
        check_binding_size(
            "triangles",
            triangles_needed,
            TRIANGLE_BYTES,
            grow.max_binding,
        )?;
        let kept = |count: u64| if keep_static { count } else { 0 };
        grow.reserve(
            encoder,
            ("nodes", node_bytes),
            (&mut self.nodes, &mut self.node_capacity),
            nodes_needed,
            kept(static_nodes),
        );
        grow.reserve(
            encoder,
            ("triangles", TRIANGLE_BYTES),
            (&mut self.triangles, &mut self.triangle_capacity),
            triangles_needed,
            kept(static_triangles),
        );
        Ok(())
    }

    /// Writes a new static part (of fingerprint `fp`) at the front of the
    /// geometry buffers.
    pub(super) fn upload_static(&mut self, queue: &wgpu::Queue, part: &Part, fp: Option<u64>) {
        queue.write_buffer(&self.nodes, 0, part.node_bytes());
        queue.write_buffer(&self.triangles, 0, bytemuck::cast_slice(&part.triangles));
        self.static_nodes = part.node_count() as u64;
        self.static_triangles = part.triangles.len() as u64;
        self.static_root = if part.node_count() == 0 { NONE } else { 0 };
        self.static_fingerprint = fp;
    }

    /// Writes the dynamic part after a static part of `(nodes, triangles)`,
    /// its node and triangle indices offset past it.
    pub(super) fn upload_dynamic(
        &mut self,
        queue: &wgpu::Queue,
        mut dynamic: Part,
        (static_nodes, static_triangles): (u64, u64),
    ) {
        dynamic.offset(static_nodes as u32, static_triangles as u32);
        if dynamic.node_count() > 0 {
            queue.write_buffer(
                &self.nodes,
                static_nodes * self.node_bytes,
                dynamic.node_bytes(),
            );
            queue.write_buffer(
                &self.triangles,
                static_triangles * TRIANGLE_BYTES,
                bytemuck::cast_slice(&dynamic.triangles),
            );
            self.dynamic_root = static_nodes as u32;
        } else {
            self.dynamic_root = NONE;
        }
    }
}

/// An error unless `count` elements of `size` bytes (`what`) fit in one
/// storage binding of `max_binding` bytes.
fn check_binding_size(what: &str, count: u64, size: u64, max_binding: u64) -> Result<(), GpuError> {
    if count * size > max_binding {
        return Err(GpuError::Geometry(format!(
            "{count} {what} ({} MiB) exceed the device's storage binding size of {} MiB",
            (count * size) >> 20,
            max_binding >> 20
        )));
    }
    Ok(())
}

/// How the geometry buffers grow: by a quarter more than needed, within
/// one storage binding.
pub(super) struct Growth<'a> {
    pub(super) device: &'a wgpu::Device,
    pub(super) max_binding: u64,
}

impl Growth<'_> {
    /// Replaces `buffer` (`label`, elements of `size` bytes, `capacity` of
    /// them) by a larger one when `needed` elements exceed its capacity,
    /// with its first `kept` elements copied over by `encoder`.
    fn reserve(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        (label, size): (&str, u64),
        (buffer, capacity): (&mut wgpu::Buffer, &mut u64),
        needed: u64,
        kept: u64,
    ) {
        if needed <= *capacity {
            return;
        }
        let cap = (needed + needed / 4)
            .min(self.max_binding / size)
            .max(needed);
        let grown = storage_buffer(self.device, label, cap * size);
        if kept > 0 {
            encoder.copy_buffer_to_buffer(buffer, 0, &grown, 0, kept * size);
        }
        *buffer = grown;
        *capacity = cap;
    }
}

/// A geometry buffer; COPY_SRC so that it can be copied into its grown
/// successor.
fn storage_buffer(device: &wgpu::Device, label: &str, size: u64) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size,
        usage: wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_DST
            | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    })
}
