//! The second stage of [`super::render_job_to_dir_with`]: a thread that
//! stores and writes each rendered frame while the render thread goes on
//! with the next. A frame's commit to a store job (its records' samples,
//! the method's state changes, the frame's EXR, compressed and flushed)
//! and its files (EXR, tone-mapped PNG) run mostly on one core; written on
//! the render thread they left the other cores idle between frames.
//!
//! Order and durability are as they were on one thread: frames are stored
//! and written in the order they render, each in one atomic batch before
//! its files; `after_frame` is told of each once its files are written;
//! and the render stops after the first frame that fails to be stored or
//! written or that `after_frame` stops at. The frame then in progress is
//! abandoned ([`FrameContext::render_stopped`]), never stored or written,
//! as a frame interrupted by a crash is.
//!
//! [`FrameContext::render_stopped`]: crate::method::FrameContext::render_stopped

use super::job::{store_frame, StoreJob};
use super::progress::FrameProgress;
use crate::film::{self, Film};
use crate::method::{FrameRecords, FrameStats};
use anyhow::{Context, Result};
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::Receiver;
use std::sync::{Mutex, MutexGuard};
use std::time::Instant;

/// A frame the render thread finished, handed to the writer.
pub(super) struct RenderedFrame {
    pub frame: u32,
    pub film: Film,
    pub stats: FrameStats,
    /// The records and state changes the method kept for the store.
    pub kept: Option<FrameRecords>,
    /// When its render began: its progress line counts from there.
    pub started: Instant,
}

/// Stores and writes the frames of one render, in order.
pub(super) struct FrameWriter<'a, 'j> {
    pub out_dir: &'a Path,
    pub job: Option<&'a mut StoreJob<'j>>,
    /// The first frame of the render's chain and, for a method that looks
    /// ahead, its end ([`store_frame`]).
    pub chain: (u32, Option<u32>),
    /// The method's name if it carries state from frame to frame: each of
    /// its frames must then come with state changes to store.
    pub stateful_method: Option<&'static str>,
    pub progress: &'a Mutex<FrameProgress>,
    pub after_frame: &'a mut (dyn FnMut(u32) -> bool + Send),
    /// Set when the writer stops, so that the render thread abandons the
    /// frame it is on ([`crate::method::FrameContext::render_stopped`]).
    pub stopped: &'a AtomicBool,
}

impl FrameWriter<'_, '_> {
    /// Writes the frames `rendered` hands over until the render thread
    /// closes it, a frame fails, or `after_frame` says stop; the statistics
    /// of the frames written. The first error names the first frame not
    /// kept and what running the job again does.
    pub fn write_all(mut self, rendered: Receiver<RenderedFrame>) -> Result<Vec<FrameStats>> {
        let written = self.write_until_stopped(rendered);
        // Rendering on would be thrown away: the frame in progress is
        // abandoned, and the channel closes as `rendered` drops.
        self.stopped.store(true, Ordering::Relaxed);
        written
    }

    fn write_until_stopped(
        &mut self,
        rendered: Receiver<RenderedFrame>,
    ) -> Result<Vec<FrameStats>> {
        let mut written = Vec::new();
        for frame in rendered.iter() {
            let (number, started) = (frame.frame, frame.started);
            written.push(self.write(frame)?);
            lock(self.progress).finish_frame(number, started);
            if !(self.after_frame)(number) {
                break;
            }
        }
        Ok(written)
    }

    /// Stores `frame` in the job, if any, then writes its files.
    fn write(&mut self, frame: RenderedFrame) -> Result<FrameStats> {
        let RenderedFrame {
            frame: number,
            film,
            stats,
            kept,
            ..
        } = frame;
        // Encoded once: the store keeps the bytes the file holds.
        let exr = film::encode_exr(&film)
            .map_err(|e| anyhow::anyhow!("cannot encode frame {number} as EXR: {e}"))?;
        if let Some(j) = self.job.as_deref_mut() {
            remove_frame_files(self.out_dir, number)?;
            let (chain, stateful) = (self.chain, self.stateful_method);
            store_frame(j, (&film, &exr), number, &stats, kept, chain, stateful).map_err(|e| {
                anyhow::anyhow!(
                    "{e:#}\nframe {number} was not saved, the frames finished before it were: \
                     running the job again (once the cause is fixed, e.g. space freed) \
                     resumes at frame {number}"
                )
            })?;
        }
        film::write_encoded_frame(&film, &exr, self.out_dir, number).map_err(|e| {
            match self.job {
                Some(_) => anyhow::anyhow!(
                    "{e:#}\nframe {number} is saved in the store: running the job again \
                     writes its files from there and resumes after it"
                ),
                None => anyhow::Error::new(e),
            }
        })?;
        Ok(stats)
    }
}

/// The progress, shared by the render and the writer thread. A panic on
/// the other thread while it held the lock left nothing half-made that
/// matters here (lines on stderr), so a poisoned lock is used as it is.
pub(super) fn lock(progress: &Mutex<FrameProgress>) -> MutexGuard<'_, FrameProgress> {
    progress
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// Removes the files of an earlier render of `frame`, EXR first, before
/// the store takes the new one: an EXR in `out_dir` says the frame's files
/// are complete, so a crash between the two leaves them missing (written
/// back from the store on resume), not stale.
fn remove_frame_files(out_dir: &Path, frame: u32) -> Result<()> {
    for ext in ["exr", "png"] {
        let old = film::frame_path(out_dir, frame, ext);
        match std::fs::remove_file(&old) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                return Err(e).with_context(|| format!("cannot replace {}", old.display()));
            }
            _ => {}
        }
    }
    Ok(())
}
