//! Fuzzes the HTTP layer: the input is read as a request (a method and a target on the first
//! line, `Name: value` header lines, a blank line, a body) and handed to the router over the
//! tiny building. Whatever it is, the answer is a response with a JSON body when it is an
//! error, never a panic.
use axum::body::Body;
use std::sync::OnceLock;
use tower::ServiceExt;

fn router() -> &'static axum::Router {
    static R: OnceLock<axum::Router> = OnceLock::new();
    R.get_or_init(|| {
        let state =
            portico_server::AppState::open(crate::tiny::tiny_db(), Default::default()).unwrap();
        portico_server::router(state)
    })
}

fn runtime() -> &'static tokio::runtime::Runtime {
    static RT: OnceLock<tokio::runtime::Runtime> = OnceLock::new();
    RT.get_or_init(|| {
        tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap()
    })
}

/// Splits the input into a request, if its first line has a method and a target.
fn request(data: &[u8]) -> Option<axum::http::Request<Body>> {
    let split = data.windows(4).position(|w| w == b"\r\n\r\n");
    let (head, body) = match split {
        Some(i) => (&data[..i], &data[i + 4..]),
        None => (data, &[][..]),
    };
    let head = std::str::from_utf8(head).ok()?;
    let mut lines = head.split("\r\n");
    let mut first = lines.next()?.split(' ');
    let (method, target) = (first.next()?, first.next()?);
    let mut b = axum::http::Request::builder().method(method).uri(target);
    for l in lines {
        let (k, v) = l.split_once(':')?;
        b = b.header(k.trim(), v.trim());
    }
    b.body(Body::from(body.to_vec())).ok()
}

/// One input.
pub fn run(data: &[u8]) {
    let Some(req) = request(data) else { return };
    let resp = runtime().block_on(router().clone().oneshot(req)).unwrap();
    let status = resp.status();
    if status.is_client_error() || status.is_server_error() {
        let ct = resp
            .headers()
            .get("content-type")
            .map(|v| v.as_bytes().to_vec());
        assert_eq!(
            ct.as_deref(),
            Some(&b"application/json"[..]),
            "{status} without a JSON body"
        );
    }
}
