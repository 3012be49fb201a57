//! `GET /api/jobs/{id}/records?frame=N&bbox=x0,y0,z0,x1,y1,z1[&limit=L][&sources=true]`:
//! the records alive at frame N inside a world-space box, read from the
//! store, each with its projected pixel position (`screen`) under the
//! scene's camera at that frame (the dashboard's overlay).
//!
//! A record's versions are keyed by the frame that wrote them
//! (`store::keys`); the record at frame N is its latest version written at
//! or before N, and it is alive there when `created_frame ≤ N ≤ last_frame`
//! (`store::schema::RecordValue`). A radiance record also shows how many
//! sources that frame stored with it (`store::schema::FrameSourcesValue`)
//! and, with `sources=true`, the sources themselves: up to 64 a record,
//! too many to send with every overlay the dashboard draws.

use super::{ApiError, AppState, Job};
use crate::decimal::parse_canonical_u64;
use crate::scene::Scene;
use crate::store::schema::{RecordValue, SourceValue};
use axum::body::Bytes;
use axum::extract::rejection::QueryRejection;
use axum::extract::{Path, Query, State};
use axum::http::header;
use axum::response::{IntoResponse, Response};
use serde_json::{json, Value};
use std::collections::hash_map::Entry;
use std::collections::HashMap;
use std::sync::atomic::Ordering;
use std::sync::Arc;

/// Records returned when no `limit` is given, and the most a `limit` may ask.
pub const DEFAULT_LIMIT: usize = 20_000;
pub const MAX_LIMIT: usize = 200_000;

/// An axis-aligned box, min and max corners.
type Bbox = ([f32; 3], [f32; 3]);

fn parse_bbox(s: &str) -> Result<Bbox, ApiError> {
    let bad = |why: &str| {
        ApiError::bad_request(format!(
            "bbox {s:?}: {why}; expected x0,y0,z0,x1,y1,z1 (six finite numbers, x0 ≤ x1, y0 ≤ y1, z0 ≤ z1)"
        ))
    };
    let v: Vec<f32> = s
        .split(',')
        .map(|p| p.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|_| bad("not a number"))?;
    if v.len() != 6 {
        return Err(bad("not six numbers"));
    }
    if v.iter().any(|x| !x.is_finite()) {
        return Err(bad("not finite"));
    }
    let (min, max) = ([v[0], v[1], v[2]], [v[3], v[4], v[5]]);
    if (0..3).any(|i| min[i] > max[i]) {
        return Err(bad("min corner above max corner"));
    }
    Ok((min, max))
}

fn inside(p: &[f32; 3], (min, max): &Bbox) -> bool {
    (0..3).all(|i| p[i] >= min[i] && p[i] <= max[i])
}

/// The job's scene, loaded once per scene source (the last one asked).
pub(super) fn scene(
    state: &AppState,
    key: &str,
    source: &crate::render::SceneSource,
) -> Result<Arc<Scene>, ApiError> {
    let mut cache = state.scene_cache.lock().expect("scene cache lock");
    if let Some((k, s)) = cache.as_ref() {
        if k == key {
            return Ok(s.clone());
        }
    }
    // A job of `radcache render` names its scene file by its absolute path
    // (one stored by an earlier build, relative to where it ran): the
    // server may not find it.
    let root = state.scene_root(source);
    let scene = Arc::new(source.load_confined(root.as_deref()).map_err(|e| {
        let relative = matches!(source, crate::render::SceneSource::File(p) if p.is_relative());
        ApiError::conflict(format!(
            "the records' screen positions need the job's scene, which the server \
             cannot load: {}{}",
            state.without_scenes_dir(&format!("{e:#}")),
            match relative {
                true => " (a relative path is taken from the server's working directory)",
                false => "",
            }
        ))
    })?);
    *cache = Some((key.to_string(), scene.clone()));
    Ok(scene)
}

/// The query of `GET /api/jobs/{id}/records`: `frame=N` (required),
/// `bbox=x0,y0,z0,x1,y1,z1` and `limit` (1..=[`MAX_LIMIT`]).
struct RecordsQuery {
    frame: u32,
    bbox: Option<Bbox>,
    limit: usize,
    /// List radiance records' sources (`sources=true`), not only count them.
    list_sources: bool,
}

/// A query's parameters by name, each given once (`frame=0&frame=1` is a
/// 400, not one of them quietly taken) and each one of the route's `known`
/// names or `token` (the API token, which [`super::layers::check_token`] reads):
/// a misspelt parameter (`limt=5`) is a 400 naming the route's
/// parameters, not a default quietly used.
pub(super) fn query_params(
    query: Result<Query<Vec<(String, String)>>, QueryRejection>,
    known: &[&str],
) -> Result<HashMap<String, String>, ApiError> {
    let Query(pairs) = query.map_err(|e| ApiError::bad_request(e.body_text()))?;
    let mut params = HashMap::with_capacity(pairs.len());
    for (key, value) in pairs {
        if key != "token" && !known.contains(&key.as_str()) {
            let takes = match known {
                [] => "none".to_string(),
                names => names.join(", "),
            };
            return Err(ApiError::bad_request(format!(
                "unknown query parameter {key:?}; this route takes {takes}"
            )));
        }
        if params.contains_key(&key) {
            return Err(ApiError::bad_request(format!("{key}= is given twice")));
        }
        params.insert(key, value);
    }
    Ok(params)
}

/// The `frame=N` of a query (required), in the one spelling a frame's
/// file name takes too (`frame=01` and `frame=+1` are refused as
/// `/frames/01.png` is): one frame, one URL.
pub(super) fn frame_param(q: &HashMap<String, String>) -> Result<u32, ApiError> {
    let text = q
        .get("frame")
        .ok_or_else(|| ApiError::bad_request("missing frame=N".into()))?;
    parse_canonical_u64(text)
        .and_then(|n| u32::try_from(n).ok())
        .ok_or_else(|| {
            ApiError::bad_request(format!(
                "frame {text:?} is not a frame number (decimal digits, no sign or leading zero)"
            ))
        })
}

/// Job `id`'s key in the store, where its frame `frame` is done (404
/// otherwise: no such job, or not that frame yet).
pub(super) fn stored_frame(state: &AppState, id: &str, frame: u32) -> Result<u64, ApiError> {
    let missing = || ApiError::not_found(format!("job {id} has no frame {frame} (yet)"));
    let sid = state.store_id(id)?.ok_or_else(missing)?;
    if !state
        .store
        .frame_done(sid, frame)
        .map_err(ApiError::internal)?
    {
        return Err(missing());
    }
    Ok(sid)
}

impl RecordsQuery {
    /// The parameters the route takes.
    const NAMES: &'static [&'static str] = &["frame", "bbox", "limit", "sources"];

    fn parse(q: &HashMap<String, String>) -> Result<Self, ApiError> {
        let frame = frame_param(q)?;
        let bbox = q.get("bbox").map(|b| parse_bbox(b)).transpose()?;
        let limit = match q.get("limit") {
            None => DEFAULT_LIMIT,
            Some(l) => parse_canonical_u64(l)
                .and_then(|l| usize::try_from(l).ok())
                .filter(|l| (1..=MAX_LIMIT).contains(l))
                .ok_or_else(|| {
                    ApiError::bad_request(format!("limit {l:?}: expected 1..={MAX_LIMIT}"))
                })?,
        };
        let list_sources = match q.get("sources").map(String::as_str) {
            None | Some("false") => false,
            Some("true") => true,
            Some(other) => {
                return Err(ApiError::bad_request(format!(
                    "sources {other:?}: expected true or false"
                )))
            }
        };
        Ok(RecordsQuery {
            frame,
            bbox,
            limit,
            list_sources,
        })
    }
}

/// Record `r` as the API shows it at `frame`, at `position` (the scene
/// file's coordinates), with where it lies on the
/// image (`screen`, pixels; `None` behind the camera) and, for a radiance
/// record, how many sources it has (`source_count`; `null` for an
/// irradiance record) and, when `list_sources`, the sources.
fn record_json(
    r: &RecordValue,
    position: [f32; 3],
    frame: u32,
    screen: Option<[f32; 2]>,
    sources: Option<&[SourceValue]>,
    list_sources: bool,
) -> Value {
    let mut row = json!({
        "id": r.id,
        "position": position,
        "normal": r.normal,
        "radius": r.radius,
        "irradiance": r.irradiance,
        "created": r.created_frame,
        "last_frame": r.last_frame,
        "lifespan": r.last_frame - r.created_frame + 1,
        "reused": frame - r.created_frame,
        "object": r.object,
        "screen": screen,
        "source_count": sources.map(<[SourceValue]>::len),
    });
    if list_sources {
        let list = sources.map(|list| {
            list.iter()
                .map(|s| {
                    json!({
                        "offset": s.offset,
                        "solid_angle": s.solid_angle,
                        "irradiance": s.irradiance,
                    })
                })
                .collect::<Vec<_>>()
        });
        row["sources"] = json!(list);
    }
    row
}

/// The sources of the radiance records that frames of job `sid` wrote,
/// read one frame at a time as records ask for them.
struct StoredSources<'a> {
    store: &'a crate::store::Store,
    sid: u64,
    by_frame: HashMap<u32, HashMap<u64, Vec<SourceValue>>>,
}

impl StoredSources<'_> {
    /// The sources of record `id` as frame `written` stored it (`None`: an
    /// irradiance record).
    fn of(&mut self, written: u32, id: u64) -> Result<Option<&[SourceValue]>, ApiError> {
        let frame = match self.by_frame.entry(written) {
            Entry::Occupied(e) => e.into_mut(),
            Entry::Vacant(e) => {
                let stored = self
                    .store
                    .frame_sources(self.sid, written)
                    .map_err(ApiError::internal)?;
                let records = stored.map_or_else(Vec::new, |v| v.records);
                e.insert(records.into_iter().map(|r| (r.id, r.sources)).collect())
            }
        };
        Ok(frame.get(&id).map(Vec::as_slice))
    }
}

pub async fn records(
    State(state): State<Arc<AppState>>,
    Path(id): Path<String>,
    query: Result<Query<Vec<(String, String)>>, QueryRejection>,
) -> Result<Response, ApiError> {
    // An unknown job is a 404 whatever its query.
    let job = state.job(&id)?;
    let q = query_params(query, RecordsQuery::NAMES)?;
    let query = RecordsQuery::parse(&q)?;
    let sid = stored_frame(&state, &id, query.frame)?;
    let key = RecordsKey::of(&id, sid, &query);
    let s = state.clone();
    // In one of the records slots: a query reads the record blocks of the
    // frames after the nearest kept set (`super::alive`), all of them up to
    // `frame` the first time. Asked again while it runs, it is not run
    // again: a frame's records never change once stored. Asked and left
    // (its clients gone before it had a slot), it is not run at all.
    let run = |wanted: super::flight::Wanted<_, _>| async move {
        let slots = s.records_slots.clone();
        super::blocking_in_slot(&slots, move || match wanted.still() {
            true => answer(&s, &job, &id, sid, &query),
            false => Err(ApiError::abandoned()),
        })
        .await
    };
    let body = state
        .records_queries
        .get(key, || None, run)
        .await
        .map_err(|_| ApiError::internal("the records query stopped"))??;
    Ok(([(header::CONTENT_TYPE, "application/json")], body).into_response())
}

/// What makes two `/records` queries the same: the job (its API id, which
/// the answer names, and its store id) and the query's values.
#[derive(Clone, PartialEq, Eq, Hash)]
pub struct RecordsKey {
    id: String,
    sid: u64,
    frame: u32,
    /// The box's corners' bits (two spellings of a number, one box).
    bbox: Option<[u32; 6]>,
    limit: usize,
    list_sources: bool,
}

impl RecordsKey {
    fn of(id: &str, sid: u64, q: &RecordsQuery) -> Self {
        RecordsKey {
            id: id.to_string(),
            sid,
            frame: q.frame,
            bbox: q.bbox.map(|(min, max)| {
                [min[0], min[1], min[2], max[0], max[1], max[2]].map(f32::to_bits)
            }),
            limit: q.limit,
            list_sources: q.list_sources,
        }
    }
}

/// The answer to query `q` on job `id` (store job `sid`), as JSON.
fn answer(
    state: &AppState,
    job: &Job,
    id: &str,
    sid: u64,
    q: &RecordsQuery,
) -> Result<Bytes, ApiError> {
    state.records_reads.fetch_add(1, Ordering::Relaxed);
    let frame = q.frame;
    let alive = super::alive::alive_at(&state.alive_sets, sid, frame, &mut |frames, f| {
        state.store.for_each_record_block(sid, frames, f)
    })
    .map_err(ApiError::internal)?;
    let mut sources = StoredSources {
        store: &state.store,
        sid,
        by_frame: HashMap::new(),
    };
    let scene = scene(state, &job.request.scene.to_string(), &job.request.scene)?;
    let settings = &job.request.settings;
    let camera = scene.camera_at(frame as f32 / settings.fps);
    let (w, h) = (settings.width as f32, settings.height as f32);
    let mut out = Vec::new();
    let mut count = 0usize;
    for (written, r) in alive.alive() {
        // Records are stored where the scene was rendered; the API speaks
        // the file's coordinates (`Scene::move_to_origin`).
        let position = (glam::Vec3::from_array(r.position) - scene.moved_by).to_array();
        if q.bbox.as_ref().is_some_and(|b| !inside(&position, b)) {
            continue;
        }
        count += 1;
        if out.len() >= q.limit {
            continue;
        }
        let screen = camera
            .project(glam::Vec3::from_array(r.position), w / h)
            .map(|(sx, sy)| [sx * w, sy * h]);
        let sources = sources.of(*written, r.id)?;
        out.push(record_json(
            r,
            position,
            frame,
            screen,
            sources,
            q.list_sources,
        ));
    }
    let body = json!({
        "id": id,
        "frame": frame,
        "bbox": q.bbox.map(|(a, b)| [a[0], a[1], a[2], b[0], b[1], b[2]]),
        "width": settings.width,
        "height": settings.height,
        "count": count,
        "truncated": count > out.len(),
        "records": out,
    });
    serde_json::to_vec(&body)
        .map(Bytes::from)
        .map_err(ApiError::internal)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params(pairs: &[(&str, &str)], known: &[&str]) -> Result<HashMap<String, String>, String> {
        let pairs = pairs
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect();
        query_params(Ok(Query(pairs)), known).map_err(|e| e.detail)
    }

    /// The dashboard adds `token=` to every request when the server has
    /// one; any other name a route does not take is refused by name.
    #[test]
    fn a_query_takes_the_routes_parameters_and_the_token_only() {
        let q = params(&[("frame", "3"), ("token", "t")], &["frame"]).unwrap();
        assert_eq!(frame_param(&q).unwrap(), 3);
        let err = params(&[("frame", "3"), ("limt", "5")], RecordsQuery::NAMES).unwrap_err();
        assert!(err.contains("\"limt\"") && err.contains("limit"), "{err}");
        assert!(params(&[("frame", "3"), ("frame", "4")], &["frame"]).is_err());
    }

    #[test]
    fn a_frame_has_one_spelling() {
        let frame = |text: &str| frame_param(&HashMap::from([("frame".into(), text.into())]));
        assert_eq!(frame("0").unwrap(), 0);
        assert_eq!(frame("4294967295").unwrap(), u32::MAX);
        for bad in ["01", "+1", "-1", " 1", "1.0", "", "4294967296"] {
            assert!(frame(bad).is_err(), "{bad:?}");
        }
    }

    /// Queries asked while the same query runs (here: while every records
    /// slot is taken, so that they meet) share its answer and read the
    /// store once; another query reads it for itself, and the same query
    /// asked later reads it again (nothing is cached).
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn the_same_query_asked_at_once_reads_the_store_once() {
        use crate::server::{testing, JobState};
        use futures_util::future::{join, join_all};
        let dir = tempfile::tempdir().unwrap();
        let state = testing::state(dir.path());
        testing::add_job(&state, "job-1", JobState::Done, &[0]);
        testing::store_frames(&state, "job-1", &[0]);
        let ask = |q: &[(&str, &str)]| {
            let q = q.iter().map(|(k, v)| (k.to_string(), v.to_string()));
            records(
                State(state.clone()),
                Path("job-1".to_string()),
                Ok(Query(q.collect())),
            )
        };
        let reads = || state.records_reads.load(Ordering::Relaxed);
        let body = |answer: Result<Response, ApiError>| async {
            let response = answer.map_err(|e| e.detail).unwrap();
            axum::body::to_bytes(response.into_body(), 1 << 20)
                .await
                .unwrap()
        };
        let slots = state.records_slots.available_permits() as u32;
        let held = state.records_slots.clone().acquire_many_owned(slots).await;
        let same = (0..8).map(|_| ask(&[("frame", "0")]));
        let other = ask(&[("frame", "0"), ("limit", "5")]);
        let asks = join_all(same.chain([other]));
        let (answers, ()) = join(asks, async move { drop(held) }).await;
        let mut bodies = Vec::new();
        for answer in answers {
            bodies.push(body(answer).await);
        }
        assert_eq!(reads(), 2, "eight queries alike and one other");
        assert!(bodies[..8].iter().all(|b| *b == bodies[0]));
        let json: Value = serde_json::from_slice(&bodies[0]).unwrap();
        assert_eq!(
            (json["id"].as_str(), json["frame"].as_u64()),
            (Some("job-1"), Some(0))
        );
        assert_eq!(body(ask(&[("frame", "0")]).await).await, bodies[0]);
        assert_eq!(reads(), 3);
        // Asked and left before a slot was free (the client gone): never
        // read.
        let held = state.records_slots.clone().acquire_many_owned(slots).await;
        let gone = tokio::spawn(ask(&[("frame", "0")]));
        while state.records_queries.in_progress() == 0 {
            tokio::task::yield_now().await;
        }
        gone.abort();
        assert!(gone.await.unwrap_err().is_cancelled());
        drop(held);
        while state.records_queries.in_progress() > 0 {
            tokio::task::yield_now().await;
        }
        assert_eq!(reads(), 3, "a query no one waits for was read");
    }
}
