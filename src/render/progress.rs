//! How long work shows it goes on, on stderr: a bar on a terminal; a line
//! per finished frame elsewhere (a log, `nohup`, CI), where a bar would
//! leave nothing; and, there, a line now and then while one frame (or one
//! bench run) takes long, so that a log never stays silent for an hour.

use std::io::Write;
use std::sync::mpsc::{self, RecvTimeoutError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// How often [`Heartbeat`] says that work it was told of still runs.
pub(crate) const HEARTBEAT_PERIOD: Duration = Duration::from_secs(30);

/// How often a bar on a terminal is redrawn while nothing advances it, so
/// that its spinner and elapsed time move during a long frame.
const BAR_TICK: Duration = Duration::from_millis(250);

/// The progress of [`super::render_job_to_dir_with`] on stderr: a bar on a
/// terminal; elsewhere one line per finished frame and a [`Heartbeat`]
/// during a long one; nothing when `quiet`.
pub(super) enum FrameProgress {
    Bar(indicatif::ProgressBar),
    Lines {
        len: u64,
        position: u64,
        /// Frames finished by this run, and the time since it started
        /// rendering: the ETA is their mean time per frame.
        finished: u64,
        start: Instant,
        heartbeat: Heartbeat,
    },
    Quiet,
}

impl FrameProgress {
    /// Over `len` frames of which `done` are already finished.
    pub(super) fn new(len: u64, done: u64, quiet: bool) -> Self {
        use std::io::IsTerminal;
        if quiet {
            return Self::Quiet;
        }
        if !std::io::stderr().is_terminal() {
            return Self::Lines {
                len,
                position: done,
                finished: 0,
                start: Instant::now(),
                heartbeat: Heartbeat::to_stderr(HEARTBEAT_PERIOD),
            };
        }
        let bar = progress_bar(len, false);
        bar.set_position(done);
        bar.reset_eta();
        Self::Bar(bar)
    }

    /// Frame `frame` starts rendering.
    pub(super) fn start_frame(&mut self, frame: u32) {
        match self {
            Self::Bar(bar) => bar.set_message(format!("frame {frame}")),
            Self::Lines { heartbeat, .. } => {
                heartbeat.begin(format!("frame {frame} still rendering"));
            }
            Self::Quiet => {}
        }
    }

    /// The frame started last is rendered (or failed): the writer has it.
    pub(super) fn end_render(&mut self) {
        if let Self::Lines { heartbeat, .. } = self {
            heartbeat.end();
        }
    }

    /// Frame `frame`, whose render began at `started`, is stored and
    /// written (the next one may be rendering by then).
    pub(super) fn finish_frame(&mut self, frame: u32, started: Instant) {
        match self {
            Self::Bar(bar) => bar.inc(1),
            Self::Lines {
                len,
                position,
                finished,
                start,
                ..
            } => {
                *position += 1;
                *finished += 1;
                let mut line = format!(
                    "frame {frame} done ({position}/{len}) in {:.2} s",
                    started.elapsed().as_secs_f64()
                );
                let left = len.saturating_sub(*position);
                if left > 0 {
                    let per_frame = start.elapsed().as_secs_f64() / *finished as f64;
                    line.push_str(&format!(", eta {}", eta_words(per_frame * left as f64)));
                }
                say(&mut std::io::stderr(), &line);
            }
            Self::Quiet => {}
        }
    }

    /// Prints a warning, also when quiet, above the bar where there is one.
    pub(super) fn warn(&self, line: &str) {
        match self {
            Self::Bar(bar) => bar.suspend(|| say(&mut std::io::stderr(), line)),
            Self::Lines { .. } | Self::Quiet => say(&mut std::io::stderr(), line),
        }
    }

    /// Leaves the bar where it stopped (a frame failed).
    pub(super) fn abandon(&self) {
        match self {
            Self::Bar(bar) => bar.abandon(),
            Self::Lines { heartbeat, .. } => heartbeat.end(),
            Self::Quiet => {}
        }
    }

    pub(super) fn finish_and_clear(&self) {
        match self {
            Self::Bar(bar) => bar.finish_and_clear(),
            Self::Lines { heartbeat, .. } => heartbeat.end(),
            Self::Quiet => {}
        }
    }
}

/// Writes a progress line. Progress is not worth failing (or panicking)
/// over a closed stderr.
fn say(out: &mut dyn Write, line: &str) {
    let _ = writeln!(out, "{line}");
}

/// `seconds` rounded for an ETA: `8 s`, `3 min 20 s`, `2 h 05 min`.
pub(crate) fn eta_words(seconds: f64) -> String {
    let s = seconds.round() as u64;
    match s {
        0..60 => format!("{s} s"),
        60..3600 => format!("{} min {} s", s / 60, s % 60),
        _ => format!("{} h {:02} min", s / 3600, s % 3600 / 60),
    }
}

/// A progress bar over `len` frames (hidden when `quiet`).
pub(crate) fn progress_bar(len: u64, quiet: bool) -> indicatif::ProgressBar {
    if quiet {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(len);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {bar:40} {pos}/{len} frames, eta {eta} {msg}",
        )
        .expect("static progress template is valid"),
    );
    if !bar.is_hidden() {
        bar.enable_steady_tick(BAR_TICK);
    }
    bar
}

/// Says, every `period` that one piece of work runs, that it still does:
/// `frame 7 still rendering after 1 min 0 s`. The work is told of with
/// [`Heartbeat::begin`] and [`Heartbeat::end`]; a thread of its own keeps
/// the time, so the work is not interrupted and nothing is said of work
/// shorter than `period`.
pub(crate) struct Heartbeat {
    beats: Option<mpsc::Sender<Beat>>,
    thread: Option<JoinHandle<()>>,
}

enum Beat {
    /// Work begun now, said as this phrase.
    Begin(String, Instant),
    End,
}

impl Heartbeat {
    /// Lines on stderr.
    pub(crate) fn to_stderr(period: Duration) -> Self {
        Self::to(period, Box::new(std::io::stderr()))
    }

    /// Lines on stderr every [`HEARTBEAT_PERIOD`] where it is not a
    /// terminal (a bar shows the work there); none when `quiet`.
    pub(crate) fn for_logs(quiet: bool) -> Self {
        use std::io::IsTerminal;
        if quiet || std::io::stderr().is_terminal() {
            return Self {
                beats: None,
                thread: None,
            };
        }
        Self::to_stderr(HEARTBEAT_PERIOD)
    }

    /// Lines on `out`.
    fn to(period: Duration, mut out: Box<dyn Write + Send>) -> Self {
        let (beats, heard) = mpsc::channel();
        let thread = std::thread::Builder::new()
            .name("heartbeat".into())
            .spawn(move || keep_time(&heard, period, &mut *out))
            // Without a thread the work goes on, only unannounced.
            .ok();
        Self {
            beats: thread.is_some().then_some(beats),
            thread,
        }
    }

    /// Work said as `phrase` (`frame 7 still rendering`) begins now.
    pub(crate) fn begin(&self, phrase: String) {
        self.send(Beat::Begin(phrase, Instant::now()));
    }

    /// The work begun last has ended (or failed).
    pub(crate) fn end(&self) {
        self.send(Beat::End);
    }

    fn send(&self, beat: Beat) {
        if let Some(beats) = &self.beats {
            let _ = beats.send(beat);
        }
    }
}

impl Drop for Heartbeat {
    fn drop(&mut self) {
        self.beats = None; // The thread hears the channel close and ends.
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

/// The heartbeat thread: waits for work, then says every `period` of it
/// that it runs, until it ends or the channel closes.
fn keep_time(heard: &mpsc::Receiver<Beat>, period: Duration, out: &mut dyn Write) {
    let mut work: Option<(String, Instant)> = None;
    let mut next = Instant::now();
    loop {
        let beat = match &work {
            None => heard.recv().map_err(|_| RecvTimeoutError::Disconnected),
            Some(_) => heard.recv_timeout(next.saturating_duration_since(Instant::now())),
        };
        match beat {
            Ok(Beat::Begin(phrase, since)) => {
                next = since + period;
                work = Some((phrase, since));
            }
            Ok(Beat::End) => work = None,
            Err(RecvTimeoutError::Timeout) => {
                if let Some((phrase, since)) = &work {
                    let so_far = since.elapsed().as_secs_f64();
                    say(out, &format!("{phrase} after {}", eta_words(so_far)));
                    next += period;
                }
            }
            Err(RecvTimeoutError::Disconnected) => return,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::{Arc, Mutex};

    #[test]
    fn etas_are_rounded_to_what_matters() {
        assert_eq!(eta_words(0.4), "0 s");
        assert_eq!(eta_words(59.4), "59 s");
        assert_eq!(eta_words(200.0), "3 min 20 s");
        assert_eq!(eta_words(7500.0), "2 h 05 min");
    }

    /// What a [`Heartbeat`] writes, readable while it runs.
    #[derive(Clone, Default)]
    struct Said(Arc<Mutex<Vec<u8>>>);

    impl Write for Said {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            self.0.lock().unwrap().extend_from_slice(buf);
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    impl Said {
        fn lines(&self) -> Vec<String> {
            let bytes = self.0.lock().unwrap().clone();
            String::from_utf8(bytes)
                .unwrap()
                .lines()
                .map(str::to_owned)
                .collect()
        }
    }

    #[test]
    fn long_work_is_said_to_go_on_every_period_and_short_work_never() {
        let period = Duration::from_millis(20);
        let said = Said::default();
        let heartbeat = Heartbeat::to(period, Box::new(said.clone()));

        heartbeat.begin("frame 1 still rendering".into());
        heartbeat.end(); // Shorter than a period: nothing.
        let start = Instant::now();
        heartbeat.begin("frame 2 still rendering".into());
        let deadline = start + Duration::from_secs(20);
        while said.lines().len() < 3 && Instant::now() < deadline {
            std::thread::sleep(period / 4);
        }
        heartbeat.end();
        let elapsed = start.elapsed();
        std::thread::sleep(period * 4); // Between frames: nothing more.
        drop(heartbeat); // Joins the thread: every line is written.

        let lines = said.lines();
        assert!(lines.len() >= 3, "{lines:?}");
        // A line a whole period of work, never sooner, and none once it
        // has ended.
        let periods = elapsed.as_secs_f64() / period.as_secs_f64();
        assert!(
            lines.len() as f64 <= periods,
            "{lines:?} in {periods} periods"
        );
        for line in &lines {
            assert!(
                line.starts_with("frame 2 still rendering after ") && line.ends_with(" s"),
                "{line}"
            );
        }
    }

    #[test]
    fn a_dropped_heartbeat_ends_its_thread_in_the_middle_of_work() {
        let said = Said::default();
        let heartbeat = Heartbeat::to(Duration::from_secs(3600), Box::new(said.clone()));
        heartbeat.begin("frame 0 still rendering".into());
        let start = Instant::now();
        drop(heartbeat);
        assert!(start.elapsed() < Duration::from_secs(60));
        assert!(said.lines().is_empty());
    }
}
