//! The dashboard's files (`web/`), embedded in the binary so that
//! `radcache serve` needs nothing beside it: `/` (index.html), `/web/{file}`
//! (script, style sheet), `/web/charts/{file}` and `/api/charts` (the charts
//! of the latest `radcache bench` run kept in `web/charts/`) and
//! `/api/openapi.json`.

use super::ApiError;
use axum::extract::Path;
use axum::http::header;
use axum::response::IntoResponse;
use axum::Json;
use serde_json::{json, Value};

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

/// The bench charts in `web/charts/` (README "Benchmarking").
const CHARTS: [(&str, &str, &str); 3] = [
    (
        "cube-in-box_error_vs_time.svg",
        "image/svg+xml",
        include_str!("../../web/charts/cube-in-box_error_vs_time.svg"),
    ),
    (
        "cube-in-box_flicker_vs_time.svg",
        "image/svg+xml",
        include_str!("../../web/charts/cube-in-box_flicker_vs_time.svg"),
    ),
    (
        "cube-in-box_bench.csv",
        "text/csv; charset=utf-8",
        include_str!("../../web/charts/cube-in-box_bench.csv"),
    ),
];

pub async fn index() -> impl IntoResponse {
    (
        [(header::CACHE_CONTROL, "no-cache")],
        axum::response::Html(include_str!("../../web/index.html")),
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

pub async fn chart(Path(file): Path<String>) -> Result<impl IntoResponse, ApiError> {
    find(&CHARTS, &file)
}

pub async fn charts() -> Json<Value> {
    Json(Value::Array(
        CHARTS
            .iter()
            .map(|(name, mime, _)| {
                json!({ "name": name, "type": mime, "url": format!("/web/charts/{name}") })
            })
            .collect(),
    ))
}

pub async fn openapi() -> impl IntoResponse {
    ([(header::CONTENT_TYPE, "application/json")], OPENAPI)
}
