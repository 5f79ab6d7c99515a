//! Every answer's shape, as a tower layer around the whole router: requests with an oversized
//! URI (414) or header block (431) are refused before routing, and every error answer that is
//! not already JSON — axum's 405, the extractors' text rejections, the timeout layer's empty
//! 408 — gets the JSON `{"status","code","message"}` body the API promises. A plain future
//! wrapper, no boxing: it runs on every segment read.

use axum::body::Body;
use axum::extract::Request;
use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use pin_project_lite::pin_project;
use std::future::Future;
use std::pin::Pin;
use std::task::{Context, Poll, ready};
use tower::{Layer, Service};

/// Longest request target (path and query) accepted, bytes.
pub const MAX_URI_BYTES: usize = 8 << 10;
/// Largest header block accepted, bytes (names and values).
pub const MAX_HEADER_BYTES: usize = 16 << 10;

/// Wraps the router in a [`Guard`].
#[derive(Clone, Copy, Default)]
pub struct GuardLayer;

impl<S> Layer<S> for GuardLayer {
    type Service = Guard<S>;

    fn layer(&self, inner: S) -> Guard<S> {
        Guard { inner }
    }
}

/// See the module documentation.
#[derive(Clone)]
pub struct Guard<S> {
    inner: S,
}

impl<S> Service<Request> for Guard<S>
where
    S: Service<Request, Response = Response>,
{
    type Response = Response;
    type Error = S::Error;
    type Future = GuardFuture<S::Future>;

    fn poll_ready(&mut self, cx: &mut Context<'_>) -> Poll<Result<(), S::Error>> {
        self.inner.poll_ready(cx)
    }

    fn call(&mut self, req: Request) -> Self::Future {
        let uri = req.uri().path_and_query().map_or(0, |p| p.as_str().len());
        let headers: usize = req
            .headers()
            .iter()
            .map(|(k, v)| k.as_str().len() + v.len())
            .sum();
        let refused = if uri > MAX_URI_BYTES {
            Some(crate::error::Error::new(
                StatusCode::URI_TOO_LONG,
                "uri_too_long",
                format!("the request target is {uri} bytes; at most {MAX_URI_BYTES}"),
            ))
        } else if headers > MAX_HEADER_BYTES {
            Some(crate::error::Error::new(
                StatusCode::REQUEST_HEADER_FIELDS_TOO_LARGE,
                "headers_too_large",
                format!("the headers are {headers} bytes; at most {MAX_HEADER_BYTES}"),
            ))
        } else {
            None
        };
        match refused {
            Some(e) => GuardFuture::Refused {
                response: Some(e.into_response()),
            },
            None => GuardFuture::Inner {
                inner: self.inner.call(req),
            },
        }
    }
}

pin_project! {
    /// The response future of [`Guard`].
    #[project = GuardProj]
    pub enum GuardFuture<F> {
        /// Refused before routing.
        Refused { response: Option<Response> },
        /// Routed; its answer is checked on the way out.
        Inner { #[pin] inner: F },
    }
}

impl<F, E> Future for GuardFuture<F>
where
    F: Future<Output = Result<Response, E>>,
{
    type Output = Result<Response, E>;

    fn poll(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Self::Output> {
        match self.project() {
            GuardProj::Refused { response } => Poll::Ready(Ok(response.take().unwrap_or_default())),
            GuardProj::Inner { inner } => {
                let out = ready!(inner.poll(cx));
                Poll::Ready(out.map(as_json))
            }
        }
    }
}

/// An error answer with any other body becomes a JSON one (its text, if any, as the message).
fn as_json(resp: Response) -> Response {
    let status = resp.status();
    let is_json = resp
        .headers()
        .get(header::CONTENT_TYPE)
        .is_some_and(|v| v.as_bytes().starts_with(b"application/json"));
    if !(status.is_client_error() || status.is_server_error()) || is_json {
        return resp;
    }
    let (mut parts, body) = resp.into_parts();
    // Error bodies from axum and tower-http are short texts; anything else is not shown.
    let text = match body.size_hint_exact() {
        Some(n) if n <= 4096 => {
            futures_util::FutureExt::now_or_never(axum::body::to_bytes(body, 4096))
                .and_then(Result::ok)
                .map(|b| String::from_utf8_lossy(&b).trim().to_string())
                .unwrap_or_default()
        }
        _ => String::new(),
    };
    let message = if text.is_empty() {
        status.canonical_reason().unwrap_or("error").to_string()
    } else {
        text
    };
    let code = match status {
        StatusCode::METHOD_NOT_ALLOWED => "method_not_allowed",
        StatusCode::REQUEST_TIMEOUT => "timeout",
        StatusCode::PAYLOAD_TOO_LARGE => "too_large",
        s if s.is_server_error() => "internal",
        _ => "bad_request",
    };
    let api = portico_protocol::ApiError {
        status: status.as_u16(),
        code: code.into(),
        message,
    };
    let bytes = serde_json::to_vec(&api).unwrap_or_default();
    parts.headers.insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("application/json"),
    );
    // The body is ours now: nothing said about the one it replaces (its coding, its
    // validators) is true of it.
    for h in [
        header::CONTENT_LENGTH,
        header::CONTENT_ENCODING,
        header::ETAG,
        header::LAST_MODIFIED,
    ] {
        parts.headers.remove(h);
    }
    Response::from_parts(parts, Body::from(bytes))
}

/// The exact size of a body, when it is known.
trait SizeHintExact {
    fn size_hint_exact(&self) -> Option<u64>;
}

impl SizeHintExact for Body {
    fn size_hint_exact(&self) -> Option<u64> {
        http_body::Body::size_hint(self).exact()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Fault 6 of the second hardening round: an error answer from a file service kept the
    /// file's `Content-Encoding: gzip` (and its validators) over the JSON body put in its place.
    #[test]
    fn an_error_body_replaced_by_json_carries_nothing_of_the_file() {
        let file_error = Response::builder()
            .status(StatusCode::RANGE_NOT_SATISFIABLE)
            .header(header::CONTENT_ENCODING, "gzip")
            .header(header::ETAG, "\"abc\"")
            .header(header::LAST_MODIFIED, "Wed, 21 Oct 2015 07:28:00 GMT")
            .header(header::CONTENT_RANGE, "bytes */100")
            .body(Body::from("range not satisfiable"))
            .unwrap();
        let r = as_json(file_error);
        let h = r.headers();
        assert_eq!(h[header::CONTENT_TYPE], "application/json");
        for gone in [
            header::CONTENT_ENCODING,
            header::ETAG,
            header::LAST_MODIFIED,
        ] {
            assert!(h.get(&gone).is_none(), "{gone} kept");
        }
        assert_eq!(h[header::CONTENT_RANGE], "bytes */100");
        let body = futures_util::FutureExt::now_or_never(axum::body::to_bytes(r.into_body(), 4096))
            .unwrap()
            .unwrap();
        let e: portico_protocol::ApiError = serde_json::from_slice(&body).unwrap();
        assert_eq!(
            (e.status, e.message.as_str()),
            (416, "range not satisfiable")
        );
    }
}
