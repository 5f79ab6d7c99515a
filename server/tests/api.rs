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

mod common;
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

/// A token with characters a query string must escape (as base64 tokens have).
const TOKEN: &str = "s3c+r/t=";
/// [`TOKEN`] percent-encoded (`encodeURIComponent`).
const TOKEN_IN_QUERY: &str = "s3c%2Br%2Ft%3D";

#[tokio::test]
async fn a_token_guards_every_api_route_but_not_health() {
    let s = start(Config {
        token: Some(TOKEN.into()),
        ..Config::default()
    })
    .await;
    let http = reqwest::Client::new();
    let id = s.state.database_id.clone();
    let routes = [
        "/v1/manifest".to_string(),
        "/v1/cells".to_string(),
        "/v1/segments/0".to_string(),
        "/v1/batch?ids=0".to_string(),
        format!("/v1/db/{id}/segments/0"),
        format!("/v1/db/{id}/batch?ids=0"),
    ];
    for r in &routes {
        let url = format!("{}{r}", s.base);
        error_of(http.get(&url).send().await.unwrap(), 401).await;
        error_of(
            http.get(&url).bearer_auth("wrong").send().await.unwrap(),
            401,
        )
        .await;
        // A query token is refused on plain HTTP routes: query strings end up in access logs.
        let q = if r.contains('?') { "&" } else { "?" };
        error_of(
            http.get(format!("{url}{q}token={TOKEN}"))
                .send()
                .await
                .unwrap(),
            401,
        )
        .await;
        assert_eq!(
            http.get(&url)
                .bearer_auth(TOKEN)
                .send()
                .await
                .unwrap()
                .status(),
            200,
            "{r}"
        );
    }
    for r in ["/v1/prefetch".to_string(), format!("/v1/db/{id}/prefetch")] {
        let url = format!("{}{r}", s.base);
        error_of(http.post(&url).body("{}").send().await.unwrap(), 401).await;
        let wrong = http.post(&url).bearer_auth("wrong").body("{}");
        error_of(wrong.send().await.unwrap(), 401).await;
        // With the token the request gets past auth (and fails as the empty body it is).
        let right = http.post(&url).bearer_auth(TOKEN).body("{}");
        let status = right.send().await.unwrap().status();
        assert_ne!(status, 401, "{r} refused the right token");
    }
    // The WebSocket upgrade: refused (401) without a token and with a wrong one; accepted with
    // `?token=` (browsers cannot set headers on it).
    let ws = s.base.replace("http://", "ws://");
    for url in [
        format!("{ws}/v1/stream"),
        format!("{ws}/v1/stream?token=wrong"),
    ] {
        match tokio_tungstenite::connect_async(&url).await {
            Ok(_) => panic!("{url}: a stream without the right token was accepted"),
            Err(tokio_tungstenite::tungstenite::Error::Http(r)) => {
                assert_eq!(r.status(), 401, "{url}")
            }
            Err(e) => panic!("{url}: refused, but not with 401: {e}"),
        }
    }
    // The query token is percent-encoded, as the browser page sends it.
    let (mut sock, _) =
        tokio_tungstenite::connect_async(format!("{ws}/v1/stream?token={TOKEN_IN_QUERY}"))
            .await
            .expect("a stream with the query token");
    let _ = sock.close(None).await;
    assert_eq!(
        http.get(format!("{}/healthz", s.base))
            .send()
            .await
            .unwrap()
            .status(),
        200
    );
}

fn binary(msg: &StreamClient) -> Message {
    Message::Binary(portico_protocol::to_bincode(msg).unwrap().into())
}

#[tokio::test]
async fn the_stream_pushes_needed_segments_and_survives_vanishing_clients() {
    let s = start(Config {
        max_sessions: 1,
        ..Config::default()
    })
    .await;
    let ws_url = s.base.replace("http://", "ws://") + "/v1/stream";
    let (mut ws, _) = tokio_tungstenite::connect_async(&ws_url).await.unwrap();
    // A second session is refused while the first is open, with a 503 that says when to retry.
    match tokio_tungstenite::connect_async(&ws_url).await {
        Err(tokio_tungstenite::tungstenite::Error::Http(r)) => {
            assert_eq!(r.status(), 503);
            assert_eq!(r.headers()["retry-after"], "1");
        }
        other => panic!("max_sessions = 1, yet a second session: {other:?}"),
    }
    let db = s.state.db();
    let mut req = request(db);
    // Under the range lookahead (the predicted one is each observer's own, pushed by deadline:
    // tests/stream.rs) the session pushes its place's shared need list (the eye cell and
    // direction bucket's).
    req.policy.lookahead_cull = portico_protocol::LookaheadCull::Any;
    let p = &s.state.prefetcher;
    let key = p.share_key(&req.observer, &req.policy).expect("cells");
    let expected = p
        .shared_list(&key, &req.observer, &req.policy, &Budget::unlimited())
        .unwrap();
    ws.send(binary(&StreamClient::Hello {
        version: PROTOCOL_VERSION,
        policy: req.policy,
        rate_bytes_per_s: 100 << 20,
        rtt_ms: 0,
    }))
    .await
    .unwrap();
    ws.send(binary(&StreamClient::Observer(req.observer)))
        .await
        .unwrap();
    // Garbage is answered with an error, not a closed session.
    ws.send(Message::Binary(vec![0xff, 0xff, 0xff].into()))
        .await
        .unwrap();
    let mut got = Vec::new();
    let mut saw_error = false;
    let patience = std::time::Duration::from_secs(10);
    while got.len() < expected.items.len() || !saw_error {
        let next = tokio::time::timeout(patience, ws.next()).await;
        let Message::Binary(frame) = next.expect("a frame within 10 s").unwrap().unwrap() else {
            continue;
        };
        match portico_protocol::parse_server_frame(&frame).unwrap() {
            ServerFrame::Segment(id, bytes) => {
                assert_eq!(bytes, &db.segment(id).unwrap()[..]);
                got.push(id);
            }
            ServerFrame::Control(StreamServer::Error(_)) => saw_error = true,
            ServerFrame::Control(StreamServer::Dropped(d)) => {
                panic!("one observer, nothing to drop: {d:?}")
            }
            ServerFrame::Page(_) => panic!("a page for a session that asked for none"),
        }
    }
    let want: Vec<u32> = expected.items.iter().map(|i| i.segment).collect();
    assert_eq!(got, want, "pushed in need order");
    // Vanish mid-session: the slot frees up and the server keeps serving.
    drop(ws);
    let mut reconnected = None;
    for _ in 0..200 {
        if let Ok((c, _)) = tokio_tungstenite::connect_async(&ws_url).await {
            reconnected = Some(c);
            break;
        }
        tokio::task::yield_now().await;
        tokio::time::sleep(std::time::Duration::from_millis(5)).await;
    }
    let mut ws = reconnected.expect("the session slot is released when a client vanishes");
    // Graceful shutdown closes open sessions.
    s.stop.unwrap().send(()).unwrap();
    s.task.await.unwrap().unwrap();
    let closed = tokio::time::timeout(patience, async {
        while let Some(Ok(m)) = ws.next().await {
            if matches!(m, Message::Close(_)) {
                return true;
            }
        }
        false
    });
    assert!(
        closed.await.expect("closed within 10 s"),
        "the session ended without a Close frame"
    );
}

/// A damaged segment on disk fails alone: a batch that holds it still brings the others (it is
/// marked missing), and its own error says what is damaged without the server's file path.
#[tokio::test]
async fn a_damaged_segment_fails_alone_and_no_error_names_a_file() {
    let db = common::db_path();
    let copy = tempfile::tempdir().unwrap();
    let path = copy.path().join("damaged.portico");
    let mut bytes = std::fs::read(db).unwrap();
    let d = portico_data::Database::open(db).unwrap();
    let lod = d.header().lods_of(&d.header().instances[0])[0];
    let entry = d.segments()[lod.segment as usize];
    bytes[entry.offset as usize + entry.length as usize / 2] ^= 0xff;
    std::fs::write(&path, &bytes).unwrap();
    let s = common::start_on(&path, Config::default()).await;
    let http = reqwest::Client::new();
    let good = (0..d.segments().len() as u32)
        .find(|&i| i != lod.segment)
        .unwrap();
    let r = http
        .get(format!(
            "{}/v1/db/{}/batch?ids={good},{},{good}",
            s.base, s.state.database_id, lod.segment
        ))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    let body = r.bytes().await.unwrap();
    let parts = portico_protocol::batch::parse(&body).unwrap();
    assert_eq!(parts.len(), 3);
    assert!(
        parts[0].1.is_some() && parts[1].1.is_none() && parts[2].1.is_some(),
        "{parts:?}"
    );
    assert_eq!(
        &body[parts[0].1.clone().unwrap()],
        &d.segment(good).unwrap()[..]
    );
    let e = error_of(
        http.get(format!("{}/v1/segments/{}", s.base, lod.segment))
            .send()
            .await
            .unwrap(),
        500,
    )
    .await;
    assert!(
        e.message.contains(&format!("segment {}", lod.segment)),
        "{}",
        e.message
    );
    assert!(
        !e.message.contains(".portico") && !e.message.contains('/'),
        "a path in {}",
        e.message
    );
}
