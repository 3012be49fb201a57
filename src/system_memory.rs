//! The memory this process may still take, read from Linux's /proc and
//! cgroup files: what `render`, `bench`, `serve` and the EXR reader
//! measure a demand against before they allocate
//! ([`render::memory`](crate::render::memory) estimates a render's).

use std::path::{Path, PathBuf};

/// `21.3 GiB`, `512 MiB`, `1.3 TiB`.
pub fn bytes_text(bytes: u64) -> String {
    const GIB: f64 = (1u64 << 30) as f64;
    const TIB: f64 = (1u64 << 40) as f64;
    if bytes >= 1 << 40 {
        // A frame no machine holds: TiB reads better than a million GiB.
        format!("{:.1} TiB", bytes as f64 / TIB)
    } else if bytes >= 1 << 30 {
        format!("{:.1} GiB", bytes as f64 / GIB)
    } else {
        format!("{} MiB", bytes.div_ceil(1 << 20))
    }
}

/// Bytes this process may still take: the least of the memory the kernel
/// can give without swapping (`MemAvailable`, which counts the caches it
/// can reclaim), the room under its cgroup's memory limit (and its
/// parents'), and the room under its address-space limit (`ulimit -v`).
/// `None` where none of them can be read (not Linux): then nothing is
/// checked.
pub fn available_bytes() -> Option<u64> {
    let read = |path: &Path| std::fs::read_to_string(path).ok();
    let kernel = read(Path::new("/proc/meminfo")).and_then(|t| meminfo_available(&t));
    let cgroups = read(Path::new("/proc/self/cgroup")).map_or_else(Vec::new, |t| cgroup_limits(&t));
    let cgroup = cgroups
        .iter()
        .filter_map(|(limit, usage)| cgroup_room(&read(limit)?, &read(usage)?))
        .min();
    let address_space = read(Path::new("/proc/self/limits"))
        .zip(read(Path::new("/proc/self/status")))
        .and_then(|(limits, status)| address_space_room(&limits, &status));
    [kernel, cgroup, address_space].into_iter().flatten().min()
}

/// This process's resident memory in bytes (`VmRSS`); `None` where it
/// cannot be read.
pub fn resident_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    kib_field(&status, "VmRSS:").map(|kib| kib * 1024)
}

/// `MemAvailable` of /proc/meminfo, in bytes.
fn meminfo_available(meminfo: &str) -> Option<u64> {
    kib_field(meminfo, "MemAvailable:").map(|kib| kib * 1024)
}

/// The number of a `Field:   123 kB` line.
fn kib_field(text: &str, field: &str) -> Option<u64> {
    let line = text.lines().find_map(|l| l.strip_prefix(field))?;
    line.split_whitespace().next()?.parse().ok()
}

/// Room under `ulimit -v`: the soft `Max address space` of
/// /proc/self/limits less the `VmSize` of /proc/self/status; `None` when
/// unlimited.
fn address_space_room(limits: &str, status: &str) -> Option<u64> {
    let soft = limits
        .lines()
        .find_map(|l| l.strip_prefix("Max address space"))?
        .split_whitespace()
        .next()?;
    let limit: u64 = soft.parse().ok()?; // "unlimited" is not a number.
    let size = kib_field(status, "VmSize:")? * 1024;
    Some(limit.saturating_sub(size))
}

/// Room under a cgroup's memory limit: its limit (`memory.max`, or v1's
/// `memory.limit_in_bytes`) less its usage; `None` when unlimited (`max`).
fn cgroup_room(limit: &str, usage: &str) -> Option<u64> {
    let limit: u64 = limit.trim().parse().ok()?;
    let usage: u64 = usage.trim().parse().ok()?;
    Some(limit.saturating_sub(usage))
}

/// The (limit, usage) files of the memory limits this process lives
/// under, from /proc/self/cgroup: its cgroup's and every one above it, in
/// the unified (v2) hierarchy, mounted at /sys/fs/cgroup or, beside v1's,
/// at /sys/fs/cgroup/unified, and in v1's memory hierarchy. A container
/// whose cgroups are mounted at its own shows its limit at the mount's
/// root, which the walk up reaches.
fn cgroup_limits(proc_cgroup: &str) -> Vec<(PathBuf, PathBuf)> {
    let mut files = Vec::new();
    for line in proc_cgroup.lines() {
        let mut parts = line.splitn(3, ':');
        let (Some(_), Some(controllers), Some(path)) = (parts.next(), parts.next(), parts.next())
        else {
            continue;
        };
        let (mounts, limit, usage): (&[&str], _, _) = if controllers.is_empty() {
            (
                &["/sys/fs/cgroup", "/sys/fs/cgroup/unified"],
                "memory.max",
                "memory.current",
            )
        } else if controllers.split(',').any(|c| c == "memory") {
            (
                &["/sys/fs/cgroup/memory"],
                "memory.limit_in_bytes",
                "memory.usage_in_bytes",
            )
        } else {
            continue;
        };
        let relative = Path::new(path.trim_start_matches('/'));
        for mount in mounts {
            for dir in relative.ancestors() {
                let dir = Path::new(mount).join(dir);
                files.push((dir.join(limit), dir.join(usage)));
            }
        }
    }
    files
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn byte_counts_read_in_mib_or_gib() {
        assert_eq!(bytes_text(0), "0 MiB");
        assert_eq!(bytes_text(1), "1 MiB");
        assert_eq!(bytes_text(512 << 20), "512 MiB");
        assert_eq!(bytes_text((1 << 30) - 1), "1024 MiB");
        assert_eq!(bytes_text(1 << 30), "1.0 GiB");
        assert_eq!(bytes_text(190 << 30), "190.0 GiB");
        assert_eq!(bytes_text((1 << 40) - (1 << 20)), "1024.0 GiB");
        assert_eq!(bytes_text(1 << 40), "1.0 TiB");
        assert_eq!(bytes_text(u64::MAX), "16777216.0 TiB");
    }

    const MEMINFO: &str = "MemTotal:       24523716 kB\nMemFree:        22103416 kB\n\
                           MemAvailable:   22342288 kB\nBuffers:          113452 kB\n";

    const STATUS: &str = "Name:\tradcache\nVmPeak:\t  220000 kB\nVmSize:\t  204800 kB\n\
                          VmHWM:\t   70000 kB\nVmRSS:\t   65536 kB\n";

    #[test]
    fn meminfo_gives_the_available_memory() {
        assert_eq!(meminfo_available(MEMINFO), Some(22_342_288 * 1024));
        assert_eq!(meminfo_available("MemTotal: 1 kB\n"), None);
        assert_eq!(meminfo_available("MemAvailable: lots kB\n"), None);
        assert_eq!(kib_field(STATUS, "VmRSS:"), Some(65536));
    }

    #[test]
    fn the_address_space_limit_leaves_the_limit_less_the_mapped_size() {
        let limits = |soft: &str| {
            format!(
                "Limit                     Soft Limit           Hard Limit           Units\n\
                 Max stack size            8388608              unlimited            bytes\n\
                 Max address space         {soft:<20} unlimited            bytes\n"
            )
        };
        assert_eq!(address_space_room(&limits("unlimited"), STATUS), None);
        assert_eq!(
            address_space_room(&limits("1073741824"), STATUS),
            Some((1 << 30) - 204_800 * 1024)
        );
        assert_eq!(address_space_room(&limits("1000"), STATUS), Some(0));
        assert_eq!(
            address_space_room(&limits("1073741824"), "VmRSS: 1 kB\n"),
            None
        );
    }

    #[test]
    fn a_cgroup_limit_leaves_the_limit_less_the_usage() {
        assert_eq!(cgroup_room("max\n", "123\n"), None);
        assert_eq!(cgroup_room("4294967296\n", "1073741824\n"), Some(3 << 30));
        assert_eq!(cgroup_room("100\n", "200\n"), Some(0));
        assert_eq!(cgroup_room("", "1"), None);
    }

    /// v2's limits are looked for in the process's cgroup and each above
    /// it under both of v2's mount points; v1's in its memory hierarchy;
    /// other v1 controllers are not memory limits.
    #[test]
    fn the_cgroup_limits_are_the_process_cgroup_and_its_parents() {
        let v2 = cgroup_limits("0::/user.slice/job\n");
        let limits: Vec<&Path> = v2.iter().map(|(l, _)| l.as_path()).collect();
        assert_eq!(
            limits,
            [
                "/sys/fs/cgroup/user.slice/job/memory.max",
                "/sys/fs/cgroup/user.slice/memory.max",
                "/sys/fs/cgroup/memory.max",
                "/sys/fs/cgroup/unified/user.slice/job/memory.max",
                "/sys/fs/cgroup/unified/user.slice/memory.max",
                "/sys/fs/cgroup/unified/memory.max",
            ]
            .map(Path::new)
        );
        assert_eq!(
            v2[0].1,
            Path::new("/sys/fs/cgroup/user.slice/job/memory.current")
        );
        let v1 = cgroup_limits("5:cpu,cpuacct:/a\n4:memory:/docker/abc\n0::/\n");
        let limits: Vec<&Path> = v1.iter().map(|(l, _)| l.as_path()).collect();
        assert_eq!(
            limits,
            [
                "/sys/fs/cgroup/memory/docker/abc/memory.limit_in_bytes",
                "/sys/fs/cgroup/memory/docker/memory.limit_in_bytes",
                "/sys/fs/cgroup/memory/memory.limit_in_bytes",
                "/sys/fs/cgroup/memory.max",
                "/sys/fs/cgroup/unified/memory.max",
            ]
            .map(Path::new)
        );
        assert!(cgroup_limits("").is_empty());
        assert!(cgroup_limits("garbage\n").is_empty());
    }

    /// On Linux something is always known (MemAvailable at least), and
    /// it is less than all of the machine.
    #[cfg(target_os = "linux")]
    #[test]
    fn this_machine_has_some_memory_available() {
        let available = available_bytes().expect("Linux reports MemAvailable");
        assert!(available > 0);
        assert!(resident_bytes().is_some_and(|r| r > 0));
    }
}
