//! A job request (`POST /api/jobs` body) checked and turned into the
//! library's render settings: the same types `radcache render` builds.

use super::ApiError;
use crate::method::settings::{limits, method_settings};
use crate::render::{self, memory, FrameSettings, MethodSettings, SceneSource};
use crate::store::schema::JobValue;
use crate::system_memory;
use serde::Deserialize;
use std::ops::Range;
use std::path::{Component, Path};

/// Most frames one job may render.
pub const MAX_FRAMES: u32 = 10_000;
/// Largest image side.
pub const MAX_SIDE: u32 = 4096;
/// Most samples per pixel.
pub const MAX_SPP: u32 = 65_536;
/// Most gather rays per record (`strata` M × N): the limit of the
/// setting itself ([`limits::MAX_GATHER_RAYS`]), which `radcache render`
/// and `bench` hold it to as well.
pub const MAX_GATHER_RAYS: usize = limits::MAX_GATHER_RAYS as usize;
/// Most pixel samples per frame (pixels × spp): 4096² at 16 spp, 1024² at
/// 256. Methods keep per-sample buffers for a frame (`trc` and `tcg` keep
/// the last frame's camera samples too), so beyond this one frame's memory
/// grows past what a shared server should give one job; `radcache render`
/// has no such limit.
pub const MAX_FRAME_SAMPLES: u64 = 1 << 28;
/// Most gather cells a frame may ask for (pixels × a record's strata):
/// a cached method may make a record at every pixel (a small `accuracy`
/// nearly does), each gathering and keeping a sample of 8 bytes a cell
/// (`tcg` holds them in memory across frames), so this bounds one frame's
/// gather at 16 GiB of samples and 2^31 rays: 1920×1080 at the default
/// 16×48 cells, 2048² at 16×32, 4096² at 8×16. Without it 4096² at the
/// largest hemisphere asked for 8 TiB.
pub const MAX_FRAME_GATHER_CELLS: u64 = 1 << 31;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Body {
    scene: String,
    method: String,
    frames: String,
    size: String,
    spp: Option<u32>,
    seed: Option<u64>,
    /// Frames per second (`radcache render --fps`).
    fps: Option<f32>,
    /// Every frame draws the same pixel streams (`--same-pattern`).
    same_pattern: Option<bool>,
    /// The method's settings by the names `radcache bench --methods`
    /// takes (`{"max_life": 5, "at": 0.02}`); the rest keep their defaults.
    settings: Option<SettingsObject>,
}

/// A JSON object of settings, in the order given, each name once: a name
/// given twice is refused rather than one of its values quietly kept.
struct SettingsObject(Vec<(String, serde_json::Value)>);

impl<'de> Deserialize<'de> for SettingsObject {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Visitor;
        impl<'de> serde::de::Visitor<'de> for Visitor {
            type Value = SettingsObject;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("an object of settings")
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(
                self,
                mut map: A,
            ) -> Result<Self::Value, A::Error> {
                let mut pairs: Vec<(String, serde_json::Value)> = Vec::new();
                while let Some((key, value)) = map.next_entry::<String, serde_json::Value>()? {
                    if pairs.iter().any(|(k, _)| *k == key) {
                        return Err(serde::de::Error::custom(format!(
                            "setting `{key}` given twice"
                        )));
                    }
                    pairs.push((key, value));
                }
                Ok(SettingsObject(pairs))
            }
        }
        d.deserialize_map(Visitor)
    }
}

/// What a job renders.
#[derive(Clone, Debug)]
pub struct JobRequest {
    pub scene: SceneSource,
    pub method: MethodSettings,
    pub settings: FrameSettings,
    pub frames: Range<u32>,
}

impl JobRequest {
    /// Parses and checks a request body; scene files must lie under
    /// `scenes`. Its frames' memory is checked once its scene is loaded
    /// ([`Self::check_memory`]), as its triangles count.
    pub fn parse(body: &[u8], scenes: Option<&Path>) -> Result<JobRequest, ApiError> {
        let malformed = |e: String| ApiError::bad_request(format!("malformed job request: {e}"));
        let value: serde_json::Value =
            serde_json::from_slice(body).map_err(|e| malformed(e.to_string()))?;
        if !value.is_object() {
            return Err(malformed(
                "expected a JSON object with scene, method, frames and size".into(),
            ));
        }
        // From the text, not the value: a `Value` keeps only the last of
        // a field given twice, where the text is refused.
        let b: Body = serde_json::from_slice(body).map_err(|e| malformed(e.to_string()))?;
        let scene = parse_scene(&b.scene, scenes)?;
        let frames = parse_frames(&b.frames)?;
        let (width, height) = parse_size(&b.size)?;
        let method = parse_method(&b.method, b.settings.as_ref(), b.spp)?;
        check_frame_samples(width, height, method.spp())?;
        check_frame_gather(width, height, &method)?;
        let settings = FrameSettings {
            width,
            height,
            fps: parse_fps(b.fps)?,
            seed: b.seed.unwrap_or(0),
            same_pattern: b.same_pattern.unwrap_or(false),
            ..FrameSettings::default()
        };
        Ok(JobRequest {
            scene,
            method,
            settings,
            frames,
        })
    }

    /// The request of a job found in the store (a restart resumes it);
    /// none for one whose method or frame range no request could give.
    pub fn from_stored(job: &JobValue) -> Option<JobRequest> {
        if job.frame_start >= job.frame_end {
            return None;
        }
        let scene = match job.scene.strip_prefix("builtin:") {
            Some(name) => SceneSource::Builtin(name.to_string()),
            None => SceneSource::File(job.scene.clone().into()),
        };
        Some(JobRequest {
            scene,
            method: stored_method(job)?,
            settings: FrameSettings {
                width: job.width,
                height: job.height,
                fps: job.fps,
                seed: job.seed,
                same_pattern: job.same_pattern,
                ..FrameSettings::default()
            },
            frames: job.frame_start..job.frame_end,
        })
    }

    pub fn frames_total(&self) -> u32 {
        self.frames.len() as u32
    }

    /// Refuses a job whose frame, on its scene of `triangles` triangles,
    /// needs more memory than the server's next job may take
    /// (`memory_for_the_next_job`, read now: after the scene's load,
    /// which the job's render loads again).
    pub fn check_memory(&self, triangles: u64) -> Result<(), ApiError> {
        self.check_memory_within(triangles, memory_for_the_next_job())
    }

    /// [`Self::check_memory`] with `available` bytes of memory for the job
    /// (`None`: unknown, not checked).
    pub fn check_memory_within(
        &self,
        triangles: u64,
        available: Option<u64>,
    ) -> Result<(), ApiError> {
        let (width, height) = (self.settings.width, self.settings.height);
        check_frame_memory(width, height, &self.method, triangles, available)
    }
}

/// A request's `fps` within [`crate::render::FPS_RANGE`], or the default.
fn parse_fps(fps: Option<f32>) -> Result<f32, ApiError> {
    let Some(fps) = fps else {
        return Ok(crate::scene::DEFAULT_FPS);
    };
    let range = crate::render::FPS_RANGE;
    if !range.contains(&fps) {
        return Err(ApiError::bad_request(format!(
            "fps {fps} is out of range ({}..={})",
            range.start(),
            range.end()
        )));
    }
    Ok(fps)
}

/// The method named `name` with `settings` (name-value pairs, as the
/// bench's `--methods`) and `spp` applied to its defaults.
fn parse_method(
    name: &str,
    settings: Option<&SettingsObject>,
    spp: Option<u32>,
) -> Result<MethodSettings, ApiError> {
    let mut changes = Vec::new();
    for (key, value) in settings.into_iter().flat_map(|s| &s.0) {
        changes.push((key.as_str(), setting_text(key, value)?));
    }
    if let Some(n) = spp.filter(|n| !(1..=MAX_SPP).contains(n)) {
        return Err(ApiError::bad_request(format!(
            "spp {n} is out of range (1..={MAX_SPP})"
        )));
    }
    let spp = spp.map(|n| n.to_string());
    if let Some(spp) = &spp {
        // A job as the API shows it has spp in both places, the same: it
        // may be posted again as it is. Two values are refused.
        match changes.iter().find(|(key, _)| *key == "spp") {
            Some((_, other)) if other != spp => {
                return Err(ApiError::bad_request(format!(
                    "spp is given twice with two values: {spp} on its own and {other} in settings"
                )));
            }
            Some(_) => {}
            None => changes.push(("spp", spp.clone())),
        }
    }
    let method = method_settings(name, changes.iter().map(|(k, v)| (*k, v.as_str())))
        .map_err(|e| ApiError::bad_request(e.to_string()))?;
    check_work_limits(&method)?;
    Ok(method)
}

/// A job's samples per pixel within the server's limit (the setting's
/// range, [`limits::SPP`], allows far more). Its gather rays a record need
/// no check here: [`MAX_GATHER_RAYS`] is the setting's own limit, which
/// the names hold it to.
fn check_work_limits(method: &MethodSettings) -> Result<(), ApiError> {
    let spp = method.spp();
    if spp > MAX_SPP {
        return Err(ApiError::bad_request(format!(
            "spp {spp} is out of range (1..={MAX_SPP})"
        )));
    }
    Ok(())
}

/// A frame's pixel samples within [`MAX_FRAME_SAMPLES`].
fn check_frame_samples(width: u32, height: u32, spp: u32) -> Result<(), ApiError> {
    let samples = u64::from(width) * u64::from(height) * u64::from(spp);
    if samples > MAX_FRAME_SAMPLES {
        return Err(ApiError::bad_request(format!(
            "size {width}x{height} at {spp} spp is {samples} pixel samples a frame; \
             at most {MAX_FRAME_SAMPLES} (e.g. 4096x4096 at 16 spp, 1024x1024 at 256)"
        )));
    }
    Ok(())
}

/// A frame's gather cells, were every pixel a record, within
/// [`MAX_FRAME_GATHER_CELLS`].
fn check_frame_gather(width: u32, height: u32, method: &MethodSettings) -> Result<(), ApiError> {
    let Some(strata) = gather_strata(method) else {
        return Ok(());
    };
    let cells = u64::from(width) * u64::from(height) * strata.count() as u64;
    if cells > MAX_FRAME_GATHER_CELLS {
        return Err(ApiError::bad_request(format!(
            "size {width}x{height} with {}x{} strata is {cells} gather cells a frame, \
             were every pixel a record; at most {MAX_FRAME_GATHER_CELLS} \
             (e.g. 1920x1080 at 16x48, 4096x4096 at 8x16)",
            strata.theta, strata.phi
        )));
    }
    Ok(())
}

/// A frame's estimated peak memory ([`memory::peak_bytes`], on a scene of
/// `triangles` triangles) within `available` bytes: beyond them the render
/// would end in an abort or the OOM killer, and take the server, and every
/// job it serves, down with it.
fn check_frame_memory(
    width: u32,
    height: u32,
    method: &MethodSettings,
    triangles: u64,
    available: Option<u64>,
) -> Result<(), ApiError> {
    memory::check_fits(method, (width, height), triangles, available).map_err(|too_large| {
        // Checked before the scene is read with 0 triangles: too large
        // whatever its scene, which is then not named.
        let scene = match triangles {
            0 => "(whatever its scene); ask for a smaller size or fewer spp".to_string(),
            n => format!(
                "(its scene has {n} triangles); ask for a smaller size, fewer spp or a \
                 smaller scene"
            ),
        };
        ApiError::bad_request(format!("{too_large} to this server {scene}"))
    })
}

/// The memory a job submitted now may take when it renders: what this
/// process may still take ([`system_memory::available_bytes`]) and what it holds
/// now, as jobs render one at a time and the one rendering now, most of
/// what it holds, lets go of it before the next starts.
fn memory_for_the_next_job() -> Option<u64> {
    let held = system_memory::resident_bytes().unwrap_or(0);
    system_memory::available_bytes().map(|available| available.saturating_add(held))
}

/// The gather hemisphere of a method's records (`None` for `path`).
fn gather_strata(method: &MethodSettings) -> Option<crate::cache::gather::Strata> {
    match method {
        MethodSettings::Path(_) => None,
        MethodSettings::Ic(s) => Some(s.strata),
        MethodSettings::Trc(s) => Some(s.ic.strata),
        MethodSettings::Tcg(s) => Some(s.ic.strata),
        MethodSettings::Movies(_) => None,
    }
}

/// A setting's JSON value as the text the bench's `KEY=VALUE` would give:
/// numbers and strings as written, booleans as `true`/`false`, which only
/// on/off settings take (as `1`/`0` a boolean passed for a number: `"max_life":
/// true` ran with a life of 1 frame).
fn setting_text(key: &str, value: &serde_json::Value) -> Result<String, ApiError> {
    match value {
        serde_json::Value::String(s) => Ok(s.clone()),
        serde_json::Value::Number(n) => Ok(n.to_string()),
        serde_json::Value::Bool(b) => Ok(b.to_string()),
        other => Err(ApiError::bad_request(format!(
            "setting {key:?}: expected a number, a string or a boolean, not {other}"
        ))),
    }
}

/// A stored job's method settings: its settings identity (serde JSON)
/// read back; where that cannot be read, or names a gather no job could
/// have been started with (an empty hemisphere, or more rays a record than
/// `render` and `serve` allow: a damaged store), the method's defaults at
/// the job's spp, which the store's settings check refuses clearly should
/// they differ from the stored ones.
fn stored_method(job: &JobValue) -> Option<MethodSettings> {
    let gathers = |m: &MethodSettings| {
        gather_strata(m).is_none_or(|s| (1..=MAX_GATHER_RAYS).contains(&s.count()))
    };
    let stored = serde_json::from_str(&job.settings).ok().filter(gathers);
    stored.or_else(|| {
        let spp = job.spp.to_string();
        method_settings(&job.method, [("spp", spp.as_str())]).ok()
    })
}

/// `builtin:NAME`, or a relative path inside the scenes directory (no `..`,
/// no absolute path).
fn parse_scene(s: &str, scenes: Option<&Path>) -> Result<SceneSource, ApiError> {
    if let Some(name) = s.strip_prefix("builtin:") {
        // By name: the scene is built once, with the job's memory check
        // (`jobs::check_scene_loads`).
        if !crate::scene::builtin::NAMES.contains(&name) {
            let unknown = crate::scene::SceneError::UnknownBuiltin(name.to_string());
            return Err(ApiError::bad_request(format!("scene {s:?}: {unknown}")));
        }
        return Ok(SceneSource::Builtin(name.to_string()));
    }
    let rel = Path::new(s);
    if s.is_empty() || !rel.components().all(|c| matches!(c, Component::Normal(_))) {
        return Err(ApiError::bad_request(format!(
            "scene path {s:?} must name a file by its names in the scenes directory \
             (e.g. \"sub/room.glb\"): no leading '/', and no '.' or '..' part"
        )));
    }
    let dir = scenes.ok_or_else(|| {
        ApiError::bad_request("this server has no --scenes directory; use builtin:NAME".into())
    })?;
    let path = dir.join(rel);
    // Symbolic links must not lead out of the directory either.
    let real = path
        .canonicalize()
        .map_err(|_| ApiError::bad_request(format!("no scene {s:?} in the scenes directory")))?;
    let root = dir
        .canonicalize()
        .map_err(|e| ApiError::internal(format!("scenes directory: {e}")))?;
    if !real.starts_with(&root) || !real.is_file() {
        return Err(ApiError::bad_request(format!(
            "scene {s:?} is not a file in the scenes directory"
        )));
    }
    Ok(SceneSource::File(real))
}

fn parse_frames(s: &str) -> Result<Range<u32>, ApiError> {
    let frames = render::parse_frame_range(s).map_err(ApiError::bad_request)?;
    if frames.len() > MAX_FRAMES as usize {
        return Err(ApiError::bad_request(format!(
            "frame range '{s}' has {} frames; at most {MAX_FRAMES}",
            frames.len()
        )));
    }
    Ok(frames)
}

fn parse_size(s: &str) -> Result<(u32, u32), ApiError> {
    render::parse_image_size(s, MAX_SIDE).map_err(ApiError::bad_request)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stored(method: &str, settings: String) -> JobValue {
        JobValue::for_test(method, settings)
    }

    fn ic_with_strata(theta: u32, phi: u32) -> String {
        let ic = crate::method::ic::IcSettings {
            strata: crate::cache::gather::Strata { theta, phi },
            accuracy: 0.3,
            ..Default::default()
        };
        serde_json::to_string(&MethodSettings::Ic(ic)).unwrap()
    }

    /// A cached method's frame is refused where every pixel a record would
    /// gather more than [`MAX_FRAME_GATHER_CELLS`] cells, whatever the
    /// pixel samples; `path` at that size has no gather to bound.
    #[test]
    fn a_frame_whose_records_could_gather_too_much_is_refused() {
        let parse = |method: &str, size: &str, strata: Option<&str>| {
            let settings = strata.map_or(String::new(), |s| {
                format!(r#","settings":{{"strata":"{s}"}}"#)
            });
            let body = format!(
                r#"{{"scene":"builtin:cube-in-box","method":"{method}","frames":"0..1","size":"{size}"{settings}}}"#
            );
            JobRequest::parse(body.as_bytes(), None).map_err(|e| e.detail)
        };
        for method in ["ic", "trc", "tcg"] {
            assert!(parse(method, "1920x1080", None).is_ok(), "{method}");
            assert!(parse(method, "4096x4096", Some("8x16")).is_ok(), "{method}");
            assert!(
                parse(method, "2048x2048", Some("16x32")).is_ok(),
                "{method}"
            );
            let err = parse(method, "4096x4096", None).unwrap_err();
            assert!(err.contains("gather cells a frame"), "{method}: {err}");
            let err = parse(method, "1024x1024", Some("256x256")).unwrap_err();
            assert!(
                err.contains("1024x1024 with 256x256 strata"),
                "{method}: {err}"
            );
            assert!(
                parse(method, "2048x2049", Some("16x32")).is_err(),
                "{method}"
            );
        }
        assert!(parse("path", "4096x4096", None).is_ok());
    }

    /// A job whose frame would need more memory than the server has for
    /// it is refused as a bad request that says how much each, and its
    /// scene's triangles; one that fits, or where the memory is unknown, is
    /// taken.
    #[test]
    fn a_job_over_the_memory_available_is_refused() {
        let check = |method: &str, size: &str, triangles: u64, available: Option<u64>| {
            let body = format!(
                r#"{{"scene":"builtin:cube-in-box","method":"{method}","frames":"0..1","size":"{size}"}}"#
            );
            let request = JobRequest::parse(body.as_bytes(), None).unwrap();
            request.check_memory_within(triangles, available)
        };
        let gib = 1u64 << 30;
        let small = 128u64 << 20;
        let err = check("trc", "1920x1080", 12, Some(small)).unwrap_err();
        assert_eq!(err.status, axum::http::StatusCode::BAD_REQUEST);
        let trc = JobRequest::parse(
            br#"{"scene":"builtin:cube-in-box","method":"trc","frames":"0..1","size":"8x8"}"#,
            None,
        )
        .unwrap()
        .method;
        let need = memory::peak_bytes(&trc, 1920, 1080, 12);
        assert_eq!(
            err.detail,
            format!(
                "a 1920x1080 trc render at 16 spp needs at least {} of memory at its peak \
                 (estimated), and 128 MiB is available to this server (its scene has 12 \
                 triangles); ask for a smaller size, fewer spp or a smaller scene",
                system_memory::bytes_text(need)
            )
        );
        for method in ["ic", "tcg", "movies"] {
            let err = check(method, "1920x1080", 0, Some(small)).unwrap_err();
            // Refused before its scene is read: no triangles named.
            assert!(
                err.detail.ends_with(
                    "to this server (whatever its scene); ask for a smaller size or fewer spp"
                ),
                "{method}: {}",
                err.detail
            );
        }
        assert!(check("trc", "1920x1080", 12, Some(64 * gib)).is_ok());
        assert!(check("trc", "1920x1080", u64::MAX, None).is_ok());
        assert!(check("path", "1920x1080", 0, Some(small)).is_ok());
        assert!(check("trc", "64x64", 0, Some(small)).is_ok());
    }

    /// A job posted again as the API shows it, with spp on its own and in
    /// its settings alike, is taken; two values are refused.
    #[test]
    fn spp_given_twice_alike_is_taken_and_unlike_refused() {
        let parse = |body: &str| JobRequest::parse(body.as_bytes(), None);
        let body = |settings_spp: u32| {
            format!(
                r#"{{"scene":"builtin:cube-in-box","method":"trc","frames":"0..1","size":"8x8",
                    "spp":16,"settings":{{"spp":{settings_spp},"at":0.05}}}}"#
            )
        };
        assert_eq!(parse(&body(16)).unwrap().method.spp(), 16);
        let err = parse(&body(8)).unwrap_err();
        assert_eq!(err.status, axum::http::StatusCode::BAD_REQUEST);
        assert_eq!(
            err.detail,
            "spp is given twice with two values: 16 on its own and 8 in settings"
        );
    }

    /// The scene's triangles count: a job that fits on an empty scene is
    /// refused on one of a million triangles (152 bytes each by the
    /// estimate), and taken again with their memory added.
    #[test]
    fn a_job_is_refused_on_its_scene_triangles() {
        let request = JobRequest::parse(
            br#"{"scene":"builtin:cube-in-box","method":"path","frames":"0..1","size":"64x64"}"#,
            None,
        )
        .unwrap();
        let empty = memory::peak_bytes(&request.method, 64, 64, 0);
        let million = memory::peak_bytes(&request.method, 64, 64, 1_000_000);
        assert!(million > empty + (100 << 20), "{empty} {million}");
        assert!(request.check_memory_within(0, Some(empty)).is_ok());
        let err = request
            .check_memory_within(1_000_000, Some(empty))
            .unwrap_err();
        assert_eq!(err.status, axum::http::StatusCode::BAD_REQUEST);
        assert!(
            err.detail.contains("(its scene has 1000000 triangles)"),
            "{}",
            err.detail
        );
        assert!(request
            .check_memory_within(1_000_000, Some(million))
            .is_ok());
    }

    /// Stored settings come back as they were; a gather no job can have
    /// (empty, or past the rays a record may have, even past `u32` when
    /// multiplied out) reads as the method's defaults at the job's spp, for
    /// the store's settings check to refuse by name.
    #[test]
    fn stored_settings_with_an_impossible_gather_read_as_defaults() {
        let method = |settings| {
            JobRequest::from_stored(&stored("ic", settings))
                .unwrap()
                .method
        };
        let MethodSettings::Ic(kept) = method(ic_with_strata(8, 24)) else {
            panic!("not ic")
        };
        assert_eq!((kept.strata.count(), kept.accuracy), (192, 0.3));
        for (theta, phi) in [(0, 48), (16, 0), (512, 512), (u32::MAX, u32::MAX)] {
            let MethodSettings::Ic(read) = method(ic_with_strata(theta, phi)) else {
                panic!("not ic")
            };
            let defaults = crate::method::ic::IcSettings::default();
            assert_eq!(read.strata, defaults.strata, "{theta}x{phi}");
            assert_eq!((read.spp, read.accuracy), (4, defaults.accuracy));
        }
    }
}
