//! The server over a real socket on 127.0.0.1:0 with the generated tiny building: every
//! endpoint, the error answers, auth, metrics, the WebSocket stream and graceful shutdown.

use futures_util::{SinkExt, StreamExt};
use portico_data::format::Header;
use portico_data::prefetch::Budget;
use portico_protocol::{
    ApiError, BINCODE_MIME, Manifest, PROTOCOL_VERSION, PrefetchResponse, ServerFrame,
    StreamClient, StreamServer,
};
use portico_server::Config;
use tokio_tungstenite::tungstenite::Message;

#[path = "../common/mod.rs"]
mod common;
mod guarded;
use common::{request, start};

/// The documents every client fetches first go out gzip-coded to clients that accept it (made
/// once at start-up), decode to the same bytes, and carry their own ETag and `Vary`.
#[tokio::test]
async fn manifest_and_cells_are_gzip_coded_for_clients_that_accept_it() {
    use std::io::Read;
    let s = start(Config::default()).await;
    // No automatic decoding: the test sees the bytes on the wire.
    let http = reqwest::Client::builder().no_gzip().build().unwrap();
    for path in ["/v1/manifest", "/v1/cells"] {
        let get = |coding: Option<&'static str>| {
            let mut r = http
                .get(format!("{}{path}", s.base))
                .header("accept", BINCODE_MIME);
            if let Some(c) = coding {
                r = r.header("accept-encoding", c);
            }
            r.send()
        };
        let plain = get(None).await.unwrap();
        assert_eq!(plain.headers().get("content-encoding"), None, "{path}");
        let plain_tag = plain.headers()["etag"].to_str().unwrap().to_string();
        let plain = plain.bytes().await.unwrap();
        let gz = get(Some("br;q=1, gzip;q=0.8")).await.unwrap();
        assert_eq!(gz.headers()["content-encoding"], "gzip", "{path}");
        assert_eq!(gz.headers()["vary"], "accept, accept-encoding", "{path}");
        let gz_tag = gz.headers()["etag"].to_str().unwrap().to_string();
        assert_ne!(gz_tag, plain_tag, "{path}: two codings share an ETag");
        let wire = gz.bytes().await.unwrap();
        let mut back = Vec::new();
        flate2::read::GzDecoder::new(&wire[..])
            .read_to_end(&mut back)
            .unwrap();
        assert_eq!(back, plain, "{path}");
        assert!(
            wire.len() * 2 < plain.len(),
            "{path}: {} bytes gzip-coded of {}",
            wire.len(),
            plain.len()
        );
        // A client that refuses gzip gets the plain bytes.
        let no = get(Some("gzip;q=0")).await.unwrap();
        assert_eq!(no.headers().get("content-encoding"), None, "{path}");
        // Conditional requests revalidate per coding.
        let r = http
            .get(format!("{}{path}", s.base))
            .header("accept", BINCODE_MIME)
            .header("accept-encoding", "gzip")
            .header("if-none-match", &gz_tag)
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 304, "{path}");
        assert_eq!(r.headers()["etag"], gz_tag.as_str(), "{path}");
        assert_eq!(r.headers()["vary"], "accept, accept-encoding", "{path}");
        // The plain tag revalidates the plain coding, and not the gzip one.
        for (coding, status) in [(None, 304), (Some("gzip"), 200)] {
            let mut r = http
                .get(format!("{}{path}", s.base))
                .header("accept", BINCODE_MIME)
                .header("if-none-match", &plain_tag);
            if let Some(c) = coding {
                r = r.header("accept-encoding", c);
            }
            assert_eq!(
                r.send().await.unwrap().status(),
                status,
                "{path} {coding:?}"
            );
        }
    }
}

#[tokio::test]
async fn manifest_cells_and_segments_are_served_from_the_map() {
    let s = start(Config::default()).await;
    let http = reqwest::Client::new();
    let db = s.state.db();
    // Manifest, bincode.
    let r = http
        .get(format!("{}/v1/manifest", s.base))
        .header("accept", BINCODE_MIME)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    let etag = r.headers()["etag"].to_str().unwrap().to_string();
    let m: Manifest<Header> =
        portico_protocol::manifest_from_bincode(&r.bytes().await.unwrap()).unwrap();
    assert_eq!(m.header, *db.header());
    assert_eq!(m.segments.len(), db.segments().len());
    // Manifest, JSON, and conditional: revalidated (a rebuild changes it), one ETag per
    // encoding, weak comparison.
    assert!(
        r_cache_control(&http, &format!("{}/v1/manifest", s.base))
            .await
            .contains("no-cache")
    );
    let r = http
        .get(format!("{}/v1/manifest", s.base))
        .send()
        .await
        .unwrap();
    assert_ne!(
        r.headers()["etag"].to_str().unwrap(),
        etag,
        "JSON and bincode share an ETag"
    );
    let j: serde_json::Value = r.json().await.unwrap();
    assert_eq!(j["database_id"], m.database_id);
    for tag in [etag.clone(), format!("W/{etag}")] {
        let r = http
            .get(format!("{}/v1/manifest", s.base))
            .header("accept", BINCODE_MIME)
            .header("if-none-match", &tag)
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 304, "{tag}");
    }
    // Cells: bincode is the stored graph; conditional too.
    let r = http
        .get(format!("{}/v1/cells", s.base))
        .header("accept", BINCODE_MIME)
        .send()
        .await
        .unwrap();
    let cells_tag = r.headers()["etag"].to_str().unwrap().to_string();
    let g: portico_data::cells::CellGraph =
        portico_data::format::decode_segment(&r.bytes().await.unwrap()).unwrap();
    assert_eq!(Some(g), db.cell_graph().unwrap());
    let r = http
        .get(format!("{}/v1/cells", s.base))
        .header("accept", BINCODE_MIME)
        .header("if-none-match", &cells_tag)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 304);
    // A segment under its content-named URL, whole and ranged: immutable.
    let lod = db.header().lods_of(&db.header().instances[0])[0];
    let want = db.segment(lod.segment).unwrap();
    let url = format!(
        "{}/v1/db/{}/segments/{}",
        s.base, m.database_id, lod.segment
    );
    let r = http.get(&url).send().await.unwrap();
    assert_eq!(r.status(), 200);
    assert!(
        r.headers()["cache-control"]
            .to_str()
            .unwrap()
            .contains("immutable")
    );
    let tag = r.headers()["etag"].to_str().unwrap().to_string();
    assert_eq!(r.bytes().await.unwrap(), want);
    let r = http
        .get(&url)
        .header("range", "bytes=4-19")
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 206);
    assert_eq!(
        r.headers()["content-range"],
        format!("bytes 4-19/{}", want.len()).as_str()
    );
    assert_eq!(r.bytes().await.unwrap(), want.slice(4..20));
    assert_eq!(
        http.get(&url)
            .header("if-none-match", &tag)
            .send()
            .await
            .unwrap()
            .status(),
        304
    );
    assert_eq!(
        http.get(&url)
            .header("range", "bytes=999999999-")
            .send()
            .await
            .unwrap()
            .status(),
        416
    );
    // The URL a rebuild reuses is revalidated, never immutable; another database's URL is gone.
    let plain = format!("{}/v1/segments/{}", s.base, lod.segment);
    assert_eq!(r_cache_control(&http, &plain).await, "no-cache");
    let stale = format!(
        "{}/v1/db/0000000000000000ffffffffffffffff/segments/{}",
        s.base, lod.segment
    );
    let e = error_of(http.get(&stale).send().await.unwrap(), 410).await;
    assert_eq!(e.code, "stale");
    // Batched, framed as the protocol says.
    let ids = [lod.segment, 0, lod.segment];
    let r = http
        .get(format!(
            "{}/v1/db/{}/batch?ids={},{},{}",
            s.base, m.database_id, ids[0], ids[1], ids[2]
        ))
        .send()
        .await
        .unwrap();
    assert!(
        r.headers()["cache-control"]
            .to_str()
            .unwrap()
            .contains("immutable")
    );
    let body = r.bytes().await.unwrap();
    let parts = portico_protocol::batch::parse(&body).unwrap();
    assert_eq!(parts.len(), 3);
    for ((got, range), id) in parts.into_iter().zip(ids) {
        assert_eq!(got, id);
        assert_eq!(&body[range.unwrap()], &db.segment(id).unwrap()[..]);
    }
    s.stop.unwrap().send(()).unwrap();
    s.task.await.unwrap().unwrap();
}

async fn r_cache_control(http: &reqwest::Client, url: &str) -> String {
    let r = http.get(url).send().await.unwrap();
    r.headers()["cache-control"].to_str().unwrap().to_string()
}

async fn error_of(r: reqwest::Response, status: u16) -> ApiError {
    assert_eq!(r.status(), status);
    r.json::<ApiError>().await.expect("a JSON error body")
}

#[tokio::test]
async fn bad_requests_get_json_errors_and_the_server_keeps_serving() {
    let s = start(Config {
        max_body_bytes: 64 << 10,
        max_batch: 4,
        ..Config::default()
    })
    .await;
    let http = reqwest::Client::new();
    let get = |p: &str| http.get(format!("{}{p}", s.base)).send();
    assert_eq!(
        error_of(get("/v1/segments/abc").await.unwrap(), 400)
            .await
            .code,
        "bad_request"
    );
    assert_eq!(
        error_of(get("/v1/segments/4000000000").await.unwrap(), 404)
            .await
            .code,
        "not_found"
    );
    error_of(get("/v1/batch?ids=1,2,3,4,5").await.unwrap(), 400).await;
    error_of(get("/v1/batch?ids=").await.unwrap(), 400).await;
    error_of(get("/no/such/thing").await.unwrap(), 404).await;
    // Every error is JSON: axum's 405, the query extractor's rejection, an oversized target or
    // header block (the guard layer).
    let e = error_of(
        http.delete(format!("{}/v1/manifest", s.base))
            .send()
            .await
            .unwrap(),
        405,
    )
    .await;
    assert_eq!(e.code, "method_not_allowed");
    error_of(get("/v1/batch").await.unwrap(), 400).await;
    let long = format!("/v1/batch?ids={}", "1,".repeat(5000));
    assert_eq!(
        error_of(get(&long).await.unwrap(), 414).await.code,
        "uri_too_long"
    );
    let big = http
        .get(format!("{}/healthz", s.base))
        .header("x-junk", "j".repeat(20 << 10))
        .send()
        .await
        .unwrap();
    assert_eq!(error_of(big, 431).await.code, "headers_too_large");
    let post = |body: Vec<u8>, ct: &'static str| {
        http.post(format!("{}/v1/prefetch", s.base))
            .header("content-type", ct)
            .body(body)
            .send()
    };
    let good = portico_protocol::to_bincode(&request(s.state.db())).unwrap();
    for cut in [0, 1, good.len() / 2, good.len() - 1] {
        error_of(post(good[..cut].to_vec(), BINCODE_MIME).await.unwrap(), 400).await;
    }
    error_of(
        post(b"{\"version\":1}".to_vec(), "application/json")
            .await
            .unwrap(),
        400,
    )
    .await;
    error_of(post(good.clone(), "text/plain").await.unwrap(), 415).await;
    error_of(post(vec![0u8; 100 << 10], BINCODE_MIME).await.unwrap(), 413).await;
    let mut nan = request(s.state.db());
    nan.observer.eye[0] = f32::NAN;
    error_of(
        post(serde_json::to_vec(&nan).unwrap(), "application/json")
            .await
            .unwrap(),
        400,
    )
    .await;
    let mut old = request(s.state.db());
    old.version = 999;
    let e = error_of(
        post(portico_protocol::to_bincode(&old).unwrap(), BINCODE_MIME)
            .await
            .unwrap(),
        400,
    )
    .await;
    assert!(e.message.contains("version"), "{}", e.message);
    let mut huge = request(s.state.db());
    huge.policy.depth_frames = u32::MAX;
    error_of(
        post(portico_protocol::to_bincode(&huge).unwrap(), BINCODE_MIME)
            .await
            .unwrap(),
        400,
    )
    .await;
    // After all that, a good request still works, in both encodings.
    let r = post(good, BINCODE_MIME).await.unwrap();
    assert_eq!(r.status(), 200);
    let a: PrefetchResponse = portico_protocol::from_bincode(&r.bytes().await.unwrap()).unwrap();
    assert!(!a.items.is_empty());
    let j = serde_json::to_vec(&request(s.state.db())).unwrap();
    let b: PrefetchResponse = post(j, "application/json")
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(a.items, b.items);
    // Metrics saw it all.
    let text = get("/metrics").await.unwrap().text().await.unwrap();
    assert!(
        text.contains("portico_requests_total{route=\"prefetch\"} 12"),
        "{text}"
    );
    assert!(
        text.contains("portico_errors_total{route=\"prefetch\",class=\"4xx\"} 10"),
        "{text}"
    );
}
