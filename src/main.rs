//! The `radcache` binary: a thin shell over [`radcache::cli`].

fn main() -> std::process::ExitCode {
    give_mesa_a_runtime_dir();
    radcache::cli::main()
}

/// Mesa's Vulkan drivers (lavapipe on machines without a GPU, which the
/// automatic backend probes) print "XDG_RUNTIME_DIR is invalid or not set"
/// twice when that variable is missing, as it is under `sudo`, in
/// containers and in CI. Where it is missing, point it at a private
/// directory of our own before any thread starts, so a plain
/// `radcache render` prints only its own messages.
fn give_mesa_a_runtime_dir() {
    if std::env::var_os("XDG_RUNTIME_DIR").is_some() {
        return;
    }
    let dir = std::env::temp_dir().join(format!("radcache-runtime-{}", uid()));
    if std::fs::create_dir_all(&dir).is_err() || !private(&dir) {
        return;
    }
    // Single-threaded here: nothing else reads the environment yet.
    std::env::set_var("XDG_RUNTIME_DIR", &dir);
}

/// The user id from /proc (no libc dependency for one number); 0 if unknown.
fn uid() -> u32 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find_map(|l| l.strip_prefix("Uid:"))
                .and_then(|v| v.split_whitespace().next()?.parse().ok())
        })
        .unwrap_or(0)
}

/// Restricts `dir` to its owner, as the XDG spec requires (0700); false
/// when it cannot be made so (then the variable stays unset).
fn private(dir: &std::path::Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(dir, std::fs::Permissions::from_mode(0o700)).is_ok()
    }
    #[cfg(not(unix))]
    {
        let _ = dir;
        false
    }
}
