//! Frames (PNG, EXR), per-frame statistics and `/metrics`, all read from
//! the store.

use super::{ApiError, AppState, JobState};
use crate::decimal::{parse_canonical_u64, parse_padded_u64};
use axum::body::Bytes;
use axum::extract::{Path, State};
use axum::http::header;
use axum::response::IntoResponse;
use axum::Json;
use serde_json::{json, Value};
use std::fmt::Write;
use std::sync::atomic::Ordering;
use std::sync::Arc;

/// The frame and extension a frame file name asks for: `N.png` or `N.exr`,
/// or `frame_NNNN.png` as `radcache render` names its files; exactly those
/// spellings (not `+1.png` or `01.png`), so that one frame has one URL.
fn frame_of_file(file: &str) -> Option<(u32, &str)> {
    let (stem, ext) = file.split_once('.')?;
    if ext != "png" && ext != "exr" {
        return None;
    }
    let n = match stem.strip_prefix("frame_") {
        Some(digits) => parse_padded_u64(digits, 4)?,
        None => parse_canonical_u64(stem)?,
    };
    Some((u32::try_from(n).ok()?, ext))
}

pub async fn frame(
    State(state): State<Arc<AppState>>,
    Path((id, file)): Path<(String, String)>,
) -> Result<impl IntoResponse, ApiError> {
    let (n, ext) = frame_of_file(&file).ok_or_else(|| {
        ApiError::not_found(format!(
            "no frame file {file:?}; use N.png or N.exr (or frame_NNNN.png, as render names them)"
        ))
    })?;
    let missing = || ApiError::not_found(format!("job {id} has no frame {n} (yet)"));
    let sid = state.store_id(&id)?.ok_or_else(missing)?;
    if ext == "exr" {
        // Read (and decompressed) in a decode slot, as frames are encoded.
        let s = state.clone();
        let exr = state
            .decoding(move || s.store.frame_exr(sid, n).map_err(ApiError::internal))
            .await?
            .ok_or_else(missing)?;
        return Ok(([(header::CONTENT_TYPE, "image/x-exr")], Bytes::from(exr)));
    }
    let png = state.frame_png(sid, n).await?.ok_or_else(missing)?;
    Ok(([(header::CONTENT_TYPE, "image/png")], png))
}

pub async fn stats(
    State(state): State<Arc<AppState>>,
    Path(id): Path<String>,
) -> Result<Json<Value>, ApiError> {
    // Store reads, one a frame: on the blocking pool, not an async worker,
    // and in a stats slot, held until the reads end even if the client
    // has gone: many requests, or clients that ask and hang up, cannot
    // pile up reads past the slots.
    let s = state.clone();
    state
        .reading_stats(move || {
            let Some(sid) = s.store_id(&id)? else {
                return Ok(json!({ "id": id, "frames": [] }));
            };
            let mut frames = Vec::new();
            for frame in s.store.frames_done(sid).map_err(ApiError::internal)? {
                if let Some(row) = frame_stats_json(&s, sid, frame)? {
                    frames.push(row);
                }
            }
            Ok(json!({ "id": id, "frames": frames }))
        })
        .await
        .map(Json)
}

/// One frame's statistics row (`/stats`, and the `frame` event).
pub fn frame_stats_json(state: &AppState, sid: u64, frame: u32) -> Result<Option<Value>, ApiError> {
    let Some(s) = state
        .store
        .frame_stats(sid, frame)
        .map_err(ApiError::internal)?
    else {
        return Ok(None);
    };
    let exr_bytes = state
        .store
        .frame(sid, frame)
        .map_err(ApiError::internal)?
        .map_or(0, |f| u64::from(f.exr_stored_len));
    let phases: serde_json::Map<String, Value> = s
        .phase_seconds
        .iter()
        .map(|(k, v)| (k.clone(), json!(v)))
        .collect();
    Ok(Some(json!({
        "frame": s.frame,
        "records_alive": s.records_alive,
        "records_created": s.records_created,
        "records_reused": s.records_reused,
        "records_replaced": s.records_replaced,
        "records_dropped": s.records_dropped,
        // `null` where the frame computed no record whose life is set, as
        // `inspect --json` says it.
        "mean_lifespan": (s.mean_lifespan > 0.0).then_some(s.mean_lifespan),
        "samples_reshot": s.samples_reshot,
        "cache_bytes": s.cache_bytes,
        "lookups": s.lookups,
        "rays": s.rays,
        "phase_seconds": phases,
        // Folded from 0, not summed: an empty f64 sum is -0 (a `path` frame
        // stored before `path` timed its frames has no phases).
        "seconds": s.phase_seconds.iter().fold(0.0, |sum, p| sum + p.1),
        "exr_bytes": exr_bytes,
        "samples_raw_bytes": s.samples_raw_bytes,
        "stored_bytes": s.stored_bytes,
    })))
}

/// Prometheus text format.
pub async fn metrics(State(state): State<Arc<AppState>>) -> Result<impl IntoResponse, ApiError> {
    // The store's size on disk (sled's files) and its sample log's length
    // (whose lock a frame being stored holds): off the async workers, in
    // a stats slot, so that a scraper gone wild cannot pile up reads.
    let s = state.clone();
    let (database, log) = state
        .reading_stats(move || {
            Ok((
                s.store.size_on_disk().unwrap_or(0),
                s.store.sample_log_bytes(),
            ))
        })
        .await?;
    let mut out = String::new();
    let counts = {
        let jobs = state.jobs.lock().expect("job table lock");
        [
            JobState::Queued,
            JobState::Running,
            JobState::Done,
            JobState::Failed,
            JobState::Cancelled,
            JobState::Stopped,
        ]
        .map(|s| (s, jobs.values().filter(|j| j.state == s).count()))
    };
    out.push_str("# HELP radcache_jobs Jobs by state.\n# TYPE radcache_jobs gauge\n");
    for (s, n) in counts {
        let _ = writeln!(out, "radcache_jobs{{state=\"{}\"}} {n}", s.as_str());
    }
    let count = |c: &std::sync::atomic::AtomicU64| c.load(Ordering::Relaxed);
    let mut metric = |name: &str, kind: &str, help: &str, value: &dyn std::fmt::Display| {
        let _ = writeln!(
            out,
            "# HELP {name} {help}\n# TYPE {name} {kind}\n{name} {value}"
        );
    };
    metric(
        "radcache_frames_rendered_total",
        "counter",
        "Frames rendered by this server.",
        &count(&state.frames_rendered),
    );
    metric(
        "radcache_render_seconds_total",
        "counter",
        "Seconds spent rendering frames.",
        &(count(&state.render_micros) as f64 / 1e6),
    );
    metric(
        "radcache_http_connections",
        "gauge",
        "Client connections being served (this one among them).",
        &count(&state.open_connections),
    );
    metric(
        "radcache_http_connections_refused_total",
        "counter",
        "Connections closed as soon as accepted, their client's address having as many open as one address may.",
        &count(&state.refused_connections),
    );
    metric(
        "radcache_frame_encodes_total",
        "counter",
        "Frames decoded from the store and encoded as PNG (once a frame, however many clients ask, until evicted from the PNG cache).",
        &count(&state.frame_encodes),
    );
    metric(
        "radcache_records_queries_total",
        "counter",
        "Record queries answered from the store (a query asked again while it runs shares its answer).",
        &count(&state.records_reads),
    );
    metric(
        "radcache_store_bytes",
        "gauge",
        "Bytes of the store on disk: its database and its sample log.",
        &(database + log),
    );
    metric(
        "radcache_store_sample_log_bytes",
        "gauge",
        "Committed bytes of the store's sample log (of radcache_store_bytes).",
        &log,
    );
    Ok(([(header::CONTENT_TYPE, "text/plain; version=0.0.4")], out))
}

#[cfg(test)]
mod tests {
    use crate::server::{testing, JobState};
    use axum::extract::{Path, State};

    /// `/stats` reads the store in one of the stats slots (so that many
    /// requests, or clients that ask and hang up, cannot pile up reads
    /// past them; a slot is held until its work ends, however the request
    /// ends: `blocking_in_slot`): with no slot to be had, it reads nothing
    /// and answers 500, and with one, it answers.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn stats_are_read_in_a_stats_slot() {
        let dir = tempfile::tempdir().unwrap();
        let state = testing::state(dir.path());
        testing::add_job(&state, "job-1", JobState::Done, &[]);
        let ask = || super::stats(State(state.clone()), Path("job-1".to_string()));
        let answer = ask().await.unwrap();
        assert_eq!(answer.0["frames"], serde_json::json!([]));
        state.stats_slots.close();
        let e = ask().await.unwrap_err();
        assert_eq!(e.status, axum::http::StatusCode::INTERNAL_SERVER_ERROR);
    }
}
