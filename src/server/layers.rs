//! The layers every request passes through before and after its handler:
//! errors as the API's JSON, query parameters refused where a route takes
//! none, the API token, and bodies read whole within their limit and time.

use super::{records, ApiError, AppState, MAX_BODY_BYTES};
use axum::extract::{Request, State};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use std::sync::Arc;

/// The errors axum answers by itself (a wrong method: 405 with no body; a
/// body over the limit: 413 in plain text) as the API's JSON
/// `{error, detail}`, like every other error.
pub(super) async fn json_errors(response: Response) -> Response {
    use axum::http::header::{ALLOW, CONTENT_TYPE};
    let status = response.status();
    let json = response
        .headers()
        .get(CONTENT_TYPE)
        .is_some_and(|v| v.as_bytes().starts_with(b"application/json"));
    if json || !(status.is_client_error() || status.is_server_error()) {
        return response;
    }
    let (parts, body) = response.into_parts();
    let text = axum::body::to_bytes(body, 64 * 1024)
        .await
        .unwrap_or_default();
    let allow = parts.headers.get(ALLOW).cloned();
    let detail = match (String::from_utf8_lossy(&text).trim(), &allow) {
        ("", Some(allow)) => format!(
            "this route takes {}",
            allow.to_str().unwrap_or("other methods")
        ),
        ("", None) => status.canonical_reason().unwrap_or("error").to_string(),
        (text, _) => text.to_string(),
    };
    let error = match status {
        axum::http::StatusCode::METHOD_NOT_ALLOWED => "method not allowed",
        axum::http::StatusCode::PAYLOAD_TOO_LARGE => "payload too large",
        s if s.is_server_error() => "internal error",
        _ => "bad request",
    };
    let mut response = ApiError::new(status, error, detail).into_response();
    if let Some(allow) = allow {
        response.headers_mut().insert(ALLOW, allow);
    }
    response
}

/// A 400 for a request to a route that takes no query parameters that
/// carries one other than `token`.
pub(super) async fn refuse_query_params(req: Request, next: Next) -> Response {
    only_query_params(&[], req, next).await
}

/// A 400 for a request to `/stream` with a query parameter other than `n`
/// (ignored) and `token`.
pub(super) async fn stream_query_params(req: Request, next: Next) -> Response {
    only_query_params(&["n"], req, next).await
}

/// Runs `req` if its query parameters are among `known` (and `token`),
/// each given once ([`records::query_params`]); a 400 otherwise.
async fn only_query_params(known: &[&str], req: Request, next: Next) -> Response {
    let query = axum::extract::Query::try_from_uri(req.uri());
    match records::query_params(query, known) {
        Ok(_) => next.run(req).await,
        Err(e) => e.into_response(),
    }
}

/// With a token configured, every request must carry it as
/// `Authorization: Bearer TOKEN` (the scheme in any case, RFC 7235 §2.1)
/// or `?token=TOKEN`.
pub(super) async fn check_token(
    State(state): State<Arc<AppState>>,
    req: Request,
    next: Next,
) -> Response {
    if let Some(token) = &state.options.token {
        let bearer = req
            .headers()
            .get(axum::http::header::AUTHORIZATION)
            .and_then(|v| bearer_token(v.as_bytes()));
        // One `token=` only: of several, none is taken.
        let mut tokens = req
            .uri()
            .query()
            .into_iter()
            .flat_map(|q| q.split('&'))
            .filter_map(|kv| kv.strip_prefix("token="));
        let query = match (tokens.next(), tokens.next()) {
            (Some(t), None) => crate::uri::query_decode(t),
            _ => None,
        };
        let given = |t: Option<&[u8]>| t.is_some_and(|t| same_secret(t, token));
        // Both compared, with no short cut from one to the other.
        let (by_header, by_query) = (given(bearer), given(query.as_deref().map(str::as_bytes)));
        if !(by_header | by_query) {
            let mut response = ApiError::new(
                axum::http::StatusCode::UNAUTHORIZED,
                "unauthorized",
                "missing or wrong token".into(),
            )
            .into_response();
            response.headers_mut().insert(
                axum::http::header::WWW_AUTHENTICATE,
                axum::http::HeaderValue::from_static("Bearer realm=\"radcache\""),
            );
            return response;
        }
    }
    next.run(req).await
}

/// The token of an `Authorization: Bearer TOKEN` header's value (the
/// scheme in any case, RFC 7235), as bytes: a header carries a token of
/// non-ASCII characters as their UTF-8 bytes, which a `str` view of the
/// value refuses.
fn bearer_token(value: &[u8]) -> Option<&[u8]> {
    let space = value.iter().position(|&b| b == b' ')?;
    let (scheme, token) = value.split_at(space);
    scheme
        .eq_ignore_ascii_case(b"bearer")
        .then(|| token.trim_ascii())
}

/// Whether `given` is the secret `token`, in a time that depends on their
/// lengths only, not on where they first differ (`==` stops at the first
/// byte that differs, which a client timing many guesses could measure to
/// find the token a byte at a time). The length is no secret worth the
/// trouble.
fn same_secret(given: impl AsRef<[u8]>, token: impl AsRef<[u8]>) -> bool {
    let (given, token) = (given.as_ref(), token.as_ref());
    if given.len() != token.len() {
        return false;
    }
    // Each step kept opaque, so that the optimiser does not turn the loop
    // back into one that stops at a difference.
    let differ = given
        .iter()
        .zip(token)
        .fold(0u8, |acc, (a, b)| std::hint::black_box(acc | (a ^ b)));
    differ == 0
}

/// A request's body, read whole before the handler runs: one announced
/// (`Content-Length`) over [`MAX_BODY_BYTES`] is refused at once with 413,
/// before it is read (the limit on the body alone would wait for bytes the
/// client may never send), and one not sent within
/// [`ServeOptions::client_timeout`](super::ServeOptions::client_timeout) gets 408.
pub(super) async fn read_bodies(
    State(state): State<Arc<AppState>>,
    req: Request,
    next: Next,
) -> Response {
    let announced = req
        .headers()
        .get(axum::http::header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse::<u64>().ok());
    if let Some(n) = announced.filter(|&n| n > MAX_BODY_BYTES as u64) {
        return ApiError::new(
            axum::http::StatusCode::PAYLOAD_TOO_LARGE,
            "payload too large",
            format!("the body has {n} bytes; at most {MAX_BODY_BYTES}"),
        )
        .into_response();
    }
    let (parts, body) = req.into_parts();
    let limit = state.options.client_timeout;
    let body = match tokio::time::timeout(limit, read_body(body)).await {
        Ok(Ok(bytes)) => bytes,
        Ok(Err(e)) => return e.into_response(),
        Err(_) => {
            return ApiError::new(
                axum::http::StatusCode::REQUEST_TIMEOUT,
                "request timeout",
                format!("the body was not sent within {} s", limit.as_secs_f64()),
            )
            .into_response()
        }
    };
    next.run(Request::from_parts(parts, axum::body::Body::from(body)))
        .await
}

/// A request's body, at most [`MAX_BODY_BYTES`] of it (413 past them); a
/// body that breaks off or is malformed (a bad chunk size) is a 400.
async fn read_body(body: axum::body::Body) -> Result<Vec<u8>, ApiError> {
    use futures_util::StreamExt;
    let mut stream = body.into_data_stream();
    let mut bytes = Vec::new();
    while let Some(chunk) = stream.next().await {
        let chunk =
            chunk.map_err(|e| ApiError::bad_request(format!("the body could not be read: {e}")))?;
        if bytes.len() + chunk.len() > MAX_BODY_BYTES {
            return Err(ApiError::new(
                axum::http::StatusCode::PAYLOAD_TOO_LARGE,
                "payload too large",
                format!("the body has more than {MAX_BODY_BYTES} bytes"),
            ));
        }
        bytes.extend_from_slice(&chunk);
    }
    Ok(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Tokens compare equal when they are, byte for byte, and only then.
    #[test]
    fn tokens_compare_equal_only_when_equal() {
        assert!(same_secret("s3cret", "s3cret"));
        assert!(same_secret("", ""));
        assert!(!same_secret("s3cret", "s3creT"));
        assert!(!same_secret("X3cret", "s3cret"));
        assert!(!same_secret("s3cre", "s3cret"));
        assert!(!same_secret("s3cret", "s3cre"));
        assert!(!same_secret("s3cret\0", "s3cret"));
        assert!(!same_secret("", "s3cret"));
        assert!(same_secret("é", "é"));
        assert!(!same_secret("é", "e\u{301}"));
    }
}
