//! The dashboard's files (`web/`), embedded in the binary so that
//! `radcache serve` needs nothing beside it: `/` (index.html), `/web/{file}`
//! (script, style sheet), `/web/charts/{file}` and `/api/charts` (the charts
//! of the latest `radcache bench` run kept in `web/charts/`, or those of a
//! bench directory given with `--bench`) and `/api/openapi.json`.

use super::{ApiError, AppState};
use axum::extract::{Path, State};
use axum::http::header;
use axum::response::{IntoResponse, Response};
use axum::Json;
use serde_json::{json, Value};
use std::sync::Arc;

/// The OpenAPI 3 document of every route (`web/openapi.json`).
pub const OPENAPI: &str = include_str!("../../web/openapi.json");

const FILES: [(&str, &str, &str); 2] = [
    (
        "app.js",
        "text/javascript; charset=utf-8",
        include_str!("../../web/app.js"),
    ),
    (
        "app.css",
        "text/css; charset=utf-8",
        include_str!("../../web/app.css"),
    ),
];

/// A file of `web/charts/`, embedded: its name, MIME type and text.
macro_rules! chart {
    ($name:literal, $mime:expr) => {
        (
            $name,
            $mime,
            include_str!(concat!("../../web/charts/", $name)),
        )
    };
}

const SVG: &str = "image/svg+xml";
const CSV: &str = "text/csv; charset=utf-8";

/// The bench charts in `web/charts/` (README "Benchmarking"): methods
/// against `path` on cube-in-box (128×128, 24 frames, `spp` sweeps), `trc`
/// against `ic` over 400 frames (64×64, sweeps of `a_t` and `δt_max`),
/// every method at the bench's default sweeps under a moving light and
/// among moving balls (64×64, 24 frames), and every method where
/// everything moves: 400 cubes under a sliding light (64×64, 24 frames),
/// where the temporal methods cost more than `ic`.
const CHARTS: [(&str, &str, &str); 19] = [
    chart!("cube-in-box_error_vs_time.svg", SVG),
    chart!("cube-in-box_surface_error_vs_time.svg", SVG),
    chart!("cube-in-box_flicker_vs_time.svg", SVG),
    chart!("cube-in-box_surface_flicker_vs_time.svg", SVG),
    chart!("cube-in-box_bench.csv", CSV),
    chart!("cube-in-box-400-frames_error_vs_time.svg", SVG),
    chart!("cube-in-box-400-frames_surface_error_vs_time.svg", SVG),
    chart!("cube-in-box-400-frames_flicker_vs_time.svg", SVG),
    chart!("cube-in-box-400-frames_surface_flicker_vs_time.svg", SVG),
    chart!("cube-in-box-400-frames_bench.csv", CSV),
    chart!("moving-light_error_vs_time.svg", SVG),
    chart!("moving-light_flicker_vs_time.svg", SVG),
    chart!("moving-light_bench.csv", CSV),
    chart!("spheres_error_vs_time.svg", SVG),
    chart!("spheres_flicker_vs_time.svg", SVG),
    chart!("spheres_bench.csv", CSV),
    chart!("many-cubes_error_vs_time.svg", SVG),
    chart!("many-cubes_flicker_vs_time.svg", SVG),
    chart!("many-cubes_bench.csv", CSV),
];

/// The page. With a token, the request that got here carried it (the
/// middleware checked it), and the page's own script and style sheet links
/// carry it on (`/?token=…`; the script adds it to every API request).
pub async fn index(State(state): State<Arc<AppState>>) -> impl IntoResponse {
    let html = include_str!("../../web/index.html");
    let html = match &state.options.token {
        None => html.to_string(),
        Some(token) => {
            let q = format!("?token={}", crate::uri::percent_encode(token));
            html.replace("/web/app.js", &format!("/web/app.js{q}"))
                .replace("/web/app.css", &format!("/web/app.css{q}"))
        }
    };
    (
        [(header::CACHE_CONTROL, "no-cache")],
        axum::response::Html(html),
    )
}

fn find(
    table: &'static [(&'static str, &'static str, &'static str)],
    file: &str,
) -> Result<impl IntoResponse, ApiError> {
    let (_, mime, body) = table
        .iter()
        .find(|(name, _, _)| *name == file)
        .ok_or_else(|| ApiError::not_found(format!("no file {file:?}")))?;
    Ok((
        [
            (header::CONTENT_TYPE, *mime),
            (header::CACHE_CONTROL, "no-cache"),
        ],
        *body,
    ))
}

pub async fn file(Path(file): Path<String>) -> Result<impl IntoResponse, ApiError> {
    find(&FILES, &file)
}

/// A chart file name from a bench directory: a plain `*.svg` or `*.csv`
/// name, nothing that could leave the directory.
fn chart_mime(name: &str) -> Option<&'static str> {
    if name.starts_with('.') || name.contains(['/', '\\']) {
        return None;
    }
    if name.ends_with(".svg") {
        Some(SVG)
    } else if name.ends_with(".csv") {
        Some(CSV)
    } else {
        None
    }
}

pub async fn chart(
    State(state): State<Arc<AppState>>,
    Path(file): Path<String>,
) -> Result<Response, ApiError> {
    let Some(dir) = &state.options.bench else {
        return Ok(find(&CHARTS, &file)?.into_response());
    };
    let missing = || ApiError::not_found(format!("no chart {file:?}"));
    let mime = chart_mime(&file).ok_or_else(missing)?;
    let path = dir.join(&file);
    // As `/api/charts` lists them: files of the directory itself, not
    // links that may lead out of it.
    let read = move || match std::fs::symlink_metadata(&path) {
        Ok(m) if m.file_type().is_file() => std::fs::read(&path).ok(),
        _ => None,
    };
    // In a decode slot: a chart is a file of any size the bench wrote.
    let body = state
        .decoding(move || Ok(read()))
        .await?
        .ok_or_else(missing)?;
    Ok((
        [
            (header::CONTENT_TYPE, mime),
            (header::CACHE_CONTROL, "no-cache"),
        ],
        body,
    )
        .into_response())
}

/// The charts the dashboard shows: the bench directory's (`--bench`),
/// sorted by name, or the embedded ones.
pub async fn charts(State(state): State<Arc<AppState>>) -> Result<Json<Value>, ApiError> {
    let entry = |name: &str, mime: &str| json!({ "name": name, "type": mime, "url": format!("/web/charts/{name}") });
    let Some(dir) = &state.options.bench else {
        return Ok(Json(Value::Array(
            CHARTS
                .iter()
                .map(|(name, mime, _)| entry(name, mime))
                .collect(),
        )));
    };
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .map_err(|e| ApiError::internal(format!("bench directory {}: {e}", dir.display())))?
        .filter_map(|e| e.ok())
        .filter(|e| e.file_type().is_ok_and(|t| t.is_file()))
        .filter_map(|e| e.file_name().into_string().ok())
        .filter(|n| chart_mime(n).is_some())
        .collect();
    names.sort();
    Ok(Json(Value::Array(
        names
            .iter()
            .map(|n| entry(n, chart_mime(n).expect("filtered")))
            .collect(),
    )))
}

pub async fn openapi() -> impl IntoResponse {
    ([(header::CONTENT_TYPE, "application/json")], OPENAPI)
}
