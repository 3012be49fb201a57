//! Which adapter the GPU backend runs on ([`AdapterPolicy`], [`adapters`]),
//! and where the device's own errors go: wgpu reports validation errors
//! outside an error scope, and a lost device, through callbacks, which
//! these slots keep for the next dispatch to report.

use super::GpuError;
use std::sync::{Arc, Mutex};

/// Which adapters [`GpuBackend::new`](super::GpuBackend::new) may pick.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AdapterPolicy {
    /// Only a real GPU (device type other than `Cpu`): `--backend auto`.
    HardwareOnly,
    /// Any adapter, a software one (lavapipe) included: `--backend gpu`.
    AllowSoftware,
}

/// Errors reported by wgpu outside an error scope, or the device being lost.
pub(crate) type ErrorSlot = Arc<Mutex<Option<String>>>;

/// The first error that failed the backend ([`RayBackend::failure`](crate::backend::RayBackend::failure)).
pub(crate) type FailureSlot = Arc<Mutex<Option<String>>>;

/// The adapters wgpu sees (backends from `WGPU_BACKEND` when set, else
/// Vulkan, Metal and DX12), with their information.
pub fn adapters() -> Vec<wgpu::AdapterInfo> {
    let instance = instance();
    pollster::block_on(instance.enumerate_adapters(backends()))
        .iter()
        .map(|a| a.get_info())
        .collect()
}

fn backends() -> wgpu::Backends {
    wgpu::Backends::PRIMARY.with_env()
}

fn instance() -> wgpu::Instance {
    let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
    desc.backends = backends();
    wgpu::Instance::new(desc.with_env())
}

/// The first adapter by [`rank`] that `policy` allows.
pub(super) fn pick_adapter(policy: AdapterPolicy) -> Result<wgpu::Adapter, GpuError> {
    let instance = instance();
    let mut candidates: Vec<wgpu::Adapter> =
        pollster::block_on(instance.enumerate_adapters(backends()))
            .into_iter()
            .filter(|a| {
                policy == AdapterPolicy::AllowSoftware
                    || a.get_info().device_type != wgpu::DeviceType::Cpu
            })
            .collect();
    candidates.sort_by_key(|a| rank(a.get_info().device_type));
    candidates.into_iter().next().ok_or(GpuError::NoAdapter)
}

/// A slot that keeps the first uncaptured error or device loss of
/// `device`, which later dispatches report.
pub(super) fn record_device_errors(device: &wgpu::Device) -> ErrorSlot {
    let errors: ErrorSlot = Arc::default();
    let slot = errors.clone();
    device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
        if let Ok(mut s) = slot.lock() {
            s.get_or_insert_with(|| e.to_string());
        }
    }));
    let slot = errors.clone();
    device.set_device_lost_callback(move |reason, message| {
        if let Ok(mut s) = slot.lock() {
            s.get_or_insert_with(|| format!("device lost ({reason:?}): {message}"));
        }
    });
    errors
}

/// Preference among device types: discrete, integrated, virtual, other,
/// then software.
fn rank(t: wgpu::DeviceType) -> u8 {
    match t {
        wgpu::DeviceType::DiscreteGpu => 0,
        wgpu::DeviceType::IntegratedGpu => 1,
        wgpu::DeviceType::VirtualGpu => 2,
        wgpu::DeviceType::Other => 3,
        wgpu::DeviceType::Cpu => 4,
    }
}
