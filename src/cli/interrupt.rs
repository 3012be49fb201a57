//! Ctrl-C in the verbs that stop cleanly (`render`, `bench`): the first
//! sets a flag the verb watches, a second stops the process at once; a
//! verb that stopped early ends with [`Interrupted`] (status 130).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// A verb stopped by Ctrl-C once it had put what it finished in order: the
/// process exits with status 130 (128 + SIGINT), as a shell reports a
/// command that SIGINT stopped, so a script running it stops too. The
/// message says what was done and is printed without "error:".
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct Interrupted(pub(super) String);

/// What a verb says at each Ctrl-C: what the first one stops, and what a
/// second one, which stops the process at once, loses.
pub(super) struct CtrlCWords {
    pub first: &'static str,
    pub second: &'static str,
}

/// Sets the returned flag at the first Ctrl-C, saying `words.first` (the
/// verb stops where it can, so a long run ends with a message saying where
/// it stopped); a second Ctrl-C says `words.second` and stops the process
/// at once (status 130).
pub(super) fn stop_on_ctrl_c(words: CtrlCWords) -> Arc<AtomicBool> {
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    let (ready, wait_ready) = std::sync::mpsc::channel();
    let watch = move || {
        let Ok(runtime) = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
        else {
            let _ = ready.send(());
            return; // Ctrl-C keeps its default: the process stops at once.
        };
        let registered = {
            let _runtime = runtime.enter();
            #[cfg(unix)]
            let signal = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::interrupt());
            #[cfg(windows)]
            let signal = tokio::signal::windows::ctrl_c();
            signal
        };
        let _ = ready.send(());
        let Ok(mut ctrl_c) = registered else {
            return;
        };
        runtime.block_on(async {
            ctrl_c.recv().await;
            flag.store(true, Ordering::Relaxed);
            eprintln!("\n{} (Ctrl-C again to stop now)", words.first);
            ctrl_c.recv().await;
            eprintln!("stopped at once: {}", words.second);
            std::process::exit(130);
        })
    };
    // The verb starts once the watcher listens, so that no Ctrl-C falls
    // between the two; without a watcher Ctrl-C keeps its default.
    if std::thread::Builder::new()
        .name("ctrl-c".into())
        .spawn(watch)
        .is_ok()
    {
        let _ = wait_ready.recv();
    }
    stop
}
