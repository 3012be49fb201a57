//! The wgpu plumbing both GPU passes share (the ray queries here and the
//! cache splat, [`cache_splat`](super::cache_splat)): bind group layout entries,
//! one compute pass with the copies of its results to a staging buffer,
//! the workgroup grid of a dispatch, and the readback of that buffer.

use super::ErrorSlot;
use std::time::{Duration, Instant};

/// The workgroups of a dispatch over `items` invocations, `size` a
/// workgroup, as an `(x, y)` grid at most `max_per_dim` wide (devices cap
/// each dimension, often at 65,535): the shaders number an invocation
/// `y · row_width + x` with `row_width = x · size`, and skip those past
/// the last item.
pub(crate) fn workgroup_grid(items: u32, size: u32, max_per_dim: u32) -> (u32, u32) {
    let groups = items.div_ceil(size);
    let x = groups.min(max_per_dim).max(1);
    (x, groups.div_ceil(x))
}

/// How long a readback waits for its submission before the GPU counts as
/// hung (each readback's own limit starts at this value). No dispatch of this backend comes near it:
/// a chunk of 4 Mi rays takes milliseconds on a GPU and seconds on
/// lavapipe, even behind the other threads' submissions queued before it.
/// It turns a device or driver that never answers into the backend's
/// error, so that a render stops and its job can resume, where it would
/// otherwise wait for ever.
pub const WAIT_LIMIT: Duration = Duration::from_secs(300);

/// A submission whose results are to be read back, and how long to wait
/// for it.
pub(crate) struct Submitted {
    pub index: wgpu::SubmissionIndex,
    pub limit: Duration,
}

/// Waits for `submitted` (and the queue's work before it, not the later
/// submissions of other threads), maps the first `bytes` of `staging`,
/// hands them to `read` and unmaps: the readback of a dispatch whose
/// results were copied to `staging`. `what` names them in errors; an error
/// the device reported meanwhile (`errors`) fails it too, and so does a
/// wait past `submitted.limit`. Returns the time spent waiting for the GPU
/// and the time spent mapping and reading.
pub(crate) fn read_back(
    device: &wgpu::Device,
    submitted: Submitted,
    staging: &wgpu::Buffer,
    bytes: u64,
    what: &str,
    errors: &ErrorSlot,
    read: impl FnOnce(&[u8]),
) -> Result<(Duration, Duration), String> {
    let start = Instant::now();
    let (tx, rx) = std::sync::mpsc::channel();
    staging.map_async(wgpu::MapMode::Read, 0..bytes, move |r| {
        let _ = tx.send(r);
    });
    let limit = submitted.limit;
    device
        .poll(wgpu::PollType::Wait {
            submission_index: Some(submitted.index),
            timeout: Some(limit),
        })
        .map_err(|e| match e {
            wgpu::PollError::Timeout => format!(
                "the GPU did not finish the work of the {what} within {:.3} s: \
                 the device or its driver hangs",
                limit.as_secs_f64()
            ),
            e => format!("waiting for the GPU failed: {e}"),
        })?;
    let waited = start.elapsed();
    let start = Instant::now();
    match mapped(device, &rx, limit) {
        Some(Ok(())) => {}
        Some(Err(e)) => return Err(format!("cannot map the {what}: {e}")),
        None => {
            return Err(format!(
                "the {what} were not mapped within {:.3} s of the GPU finishing them: \
                 the device or its driver hangs",
                limit.as_secs_f64()
            ))
        }
    }
    if let Some(e) = errors.lock().ok().and_then(|s| s.clone()) {
        staging.unmap();
        return Err(e);
    }
    {
        let view = staging
            .get_mapped_range(0..bytes)
            .map_err(|e| format!("cannot read the {what}: {e}"))?;
        read(&view);
    }
    staging.unmap();
    Ok((waited, start.elapsed()))
}

/// The answer of a `map_async` whose submission is done: wgpu runs the
/// callback in whichever thread's poll finds the buffer ready, which is
/// normally the wait just made or another thread's poll at the same time.
/// Should neither take it up (a driver that signals the submission before
/// the buffer is free), this thread polls again, without blocking, until
/// it comes or `limit` has passed (`None`: the backend then fails rather
/// than wait for ever, as `WAIT_LIMIT` is for). A dropped sender (the
/// buffer destroyed) is an error too.
fn mapped(
    device: &wgpu::Device,
    rx: &std::sync::mpsc::Receiver<Result<(), wgpu::BufferAsyncError>>,
    limit: Duration,
) -> Option<Result<(), String>> {
    use std::sync::mpsc::RecvTimeoutError;
    const RETRY: Duration = Duration::from_millis(1);
    let start = Instant::now();
    loop {
        match rx.recv_timeout(RETRY) {
            Ok(answer) => return Some(answer.map_err(|e| e.to_string())),
            Err(RecvTimeoutError::Disconnected) => {
                return Some(Err("the mapping was cancelled".into()))
            }
            Err(RecvTimeoutError::Timeout) if start.elapsed() >= limit => return None,
            Err(RecvTimeoutError::Timeout) => {
                let _ = device.poll(wgpu::PollType::Poll);
            }
        }
    }
}

pub(crate) fn layout_entry(
    binding: u32,
    ty: wgpu::BufferBindingType,
) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

pub(crate) fn storage_entry(binding: u32, read_only: bool) -> wgpu::BindGroupLayoutEntry {
    layout_entry(binding, wgpu::BufferBindingType::Storage { read_only })
}

/// One compute pass: `pipeline` over a `groups` grid of workgroups with
/// the buffers `entries` bound as group 0 of `layout`, then each of
/// `copies` (a buffer, a byte count) copied from its start into `staging`,
/// one after the other; submitted. `prepare` encodes what must run before
/// the pass (clearing a buffer).
pub(crate) struct ComputePass<'a> {
    pub label: &'a str,
    pub pipeline: &'a wgpu::ComputePipeline,
    pub layout: &'a wgpu::BindGroupLayout,
    pub entries: &'a [wgpu::BindGroupEntry<'a>],
    pub groups: (u32, u32),
}

impl ComputePass<'_> {
    pub(crate) fn submit(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        prepare: impl FnOnce(&mut wgpu::CommandEncoder),
        copies: &[(&wgpu::Buffer, u64)],
        staging: &wgpu::Buffer,
    ) -> wgpu::SubmissionIndex {
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some(self.label),
        });
        prepare(&mut encoder);
        self.encode(device, &mut encoder, copies, staging);
        queue.submit([encoder.finish()])
    }

    /// The pass and its copies encoded into `encoder`, for the caller to
    /// submit (with other passes).
    pub(crate) fn encode(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        copies: &[(&wgpu::Buffer, u64)],
        staging: &wgpu::Buffer,
    ) {
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(self.label),
            layout: self.layout,
            entries: self.entries,
        });
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some(self.label),
                timestamp_writes: None,
            });
            pass.set_pipeline(self.pipeline);
            pass.set_bind_group(0, &bind_group, &[]);
            pass.dispatch_workgroups(self.groups.0, self.groups.1, 1);
        }
        let mut offset = 0;
        for &(source, bytes) in copies {
            encoder.copy_buffer_to_buffer(source, 0, staging, offset, bytes);
            offset += bytes;
        }
    }
}

pub(crate) fn bind(binding: u32, buffer: &wgpu::Buffer) -> wgpu::BindGroupEntry<'_> {
    wgpu::BindGroupEntry {
        binding,
        resource: buffer.as_entire_binding(),
    }
}

#[cfg(test)]
mod tests {
    use super::workgroup_grid;

    /// The grid covers every item, stays within the per-dimension cap and
    /// adds no whole row of workgroups past the last item.
    #[test]
    fn workgroup_grid_covers_items_within_the_cap() {
        let (size, cap) = (64, 65_535);
        for items in [0, 1, 63, 64, 65, 64 * 65_535, 64 * 65_535 + 1, 50_000_000] {
            let (x, y) = workgroup_grid(items, size, cap);
            assert!((1..=cap).contains(&x), "{items}: x = {x}");
            let covered = u64::from(x) * u64::from(y) * u64::from(size);
            assert!(covered >= u64::from(items), "{items}: {x}×{y}");
            let one_row_less = u64::from(x) * u64::from(y.saturating_sub(1)) * u64::from(size);
            assert!(
                items == 0 || one_row_less < u64::from(items),
                "{items}: {x}×{y}"
            );
        }
    }
}
