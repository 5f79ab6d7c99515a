//! The server over a real socket on 127.0.0.1:0 with the generated tiny building: every
//! endpoint, the error answers, auth, metrics, the WebSocket stream and graceful shutdown.

use futures_util::{SinkExt, StreamExt};
use portico_data::Database;
use portico_data::build::{BuildOptions, Quiet, build};
use portico_data::format::Header;
use portico_data::import::import_file;
use portico_protocol::{
    ApiError, BINCODE_MIME, Manifest, Observer, PROTOCOL_VERSION, Policy, PrefetchRequest,
    PrefetchResponse, ServerFrame, StreamClient, StreamServer,
};
use portico_server::{AppState, Config};
use std::path::PathBuf;
use std::sync::{Arc, OnceLock};
use tokio_tungstenite::tungstenite::Message;

/// The tiny building's database, built once per test binary.
fn db_path() -> &'static PathBuf {
    static PATH: OnceLock<PathBuf> = OnceLock::new();
    PATH.get_or_init(|| {
        let params = portico_generator::Params {
            preset: portico_generator::Preset::Tiny,
            seed: 1,
            floors: Some(1),
        };
        let b = portico_generator::generate(&params, &mut |_| {}).expect("generate");
        let dir = tempfile::tempdir().unwrap().keep();
        let glb = dir.join("tiny.glb");
        std::fs::write(&glb, &b.glb).unwrap();
        let out = dir.join("tiny.portico");
        build(
            import_file(&glb).unwrap(),
            &out,
            &BuildOptions::default(),
            &Quiet,
        )
        .unwrap();
        out
    })
}

struct Running {
    base: String,
    state: Arc<AppState>,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    task: tokio::task::JoinHandle<std::io::Result<()>>,
}

async fn start(config: Config) -> Running {
    let state = AppState::open(db_path(), config).unwrap();
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let base = format!("http://{}", listener.local_addr().unwrap());
    let (tx, rx) = tokio::sync::oneshot::channel::<()>();
    let task = tokio::spawn(portico_server::serve(state.clone(), listener, async move {
        let _ = rx.await;
    }));
    Running {
        base,
        state,
        stop: Some(tx),
        task,
    }
}

fn observer(db: &Database) -> Observer {
    let g = db.cell_graph().unwrap().unwrap();
    let c = g.cells.iter().find(|c| c.live).unwrap();
    let mid = |k: usize| (c.bounds.min[k] + c.bounds.max[k]) * 0.5;
    Observer {
        eye: [mid(0), mid(1), mid(2)],
        dir: [1.0, 0.0, 0.0],
        up: [0.0, 1.0, 0.0],
        velocity: [0.0; 3],
        half_fov_x: 0.6,
        half_fov_y: 0.45,
        max_speed: 1.5,
        max_turn: 1.0,
    }
}

fn request(db: &Database) -> PrefetchRequest {
    PrefetchRequest {
        version: PROTOCOL_VERSION,
        observer: observer(db),
        policy: Policy::default(),
        held: Vec::new(),
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
    // Manifest, JSON, and conditional.
    let j: serde_json::Value = http
        .get(format!("{}/v1/manifest", s.base))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(j["database_id"], m.database_id);
    let r = http
        .get(format!("{}/v1/manifest", s.base))
        .header("if-none-match", &etag)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 304);
    // Cells: bincode is the stored graph.
    let r = http
        .get(format!("{}/v1/cells", s.base))
        .header("accept", BINCODE_MIME)
        .send()
        .await
        .unwrap();
    let g: portico_data::cells::CellGraph =
        portico_data::format::decode_segment(&r.bytes().await.unwrap()).unwrap();
    assert_eq!(Some(g), db.cell_graph().unwrap());
    // A segment, whole and ranged, with caching headers.
    let lod = db.header().lods_of(&db.header().instances[0])[0];
    let want = db.segment(lod.segment).unwrap();
    let url = format!("{}/v1/segments/{}", s.base, lod.segment);
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
    // Batched.
    let ids = [lod.segment, 0, lod.segment];
    let r = http
        .get(format!(
            "{}/v1/batch?ids={},{},{}",
            s.base, ids[0], ids[1], ids[2]
        ))
        .send()
        .await
        .unwrap();
    let body = r.bytes().await.unwrap();
    let mut at = 0;
    for id in ids {
        let got = u32::from_le_bytes(body[at..at + 4].try_into().unwrap());
        let len = u64::from_le_bytes(body[at + 4..at + 12].try_into().unwrap()) as usize;
        assert_eq!(got, id);
        assert_eq!(&body[at + 12..at + 12 + len], &db.segment(id).unwrap()[..]);
        at += 12 + len;
    }
    assert_eq!(at, body.len());
    s.stop.unwrap().send(()).unwrap();
    s.task.await.unwrap().unwrap();
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

#[tokio::test]
async fn a_token_guards_the_api_but_not_health() {
    let s = start(Config {
        token: Some("s3cret".into()),
        ..Config::default()
    })
    .await;
    let http = reqwest::Client::new();
    let url = format!("{}/v1/manifest", s.base);
    error_of(http.get(&url).send().await.unwrap(), 401).await;
    error_of(
        http.get(&url).bearer_auth("wrong").send().await.unwrap(),
        401,
    )
    .await;
    assert_eq!(
        http.get(&url)
            .bearer_auth("s3cret")
            .send()
            .await
            .unwrap()
            .status(),
        200
    );
    assert_eq!(
        http.get(format!("{url}?token=s3cret"))
            .send()
            .await
            .unwrap()
            .status(),
        200
    );
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
    // A second session is refused while the first is open.
    let second = tokio_tungstenite::connect_async(&ws_url).await;
    assert!(second.is_err(), "max_sessions = 1");
    let db = s.state.db();
    let req = request(db);
    let expected = s
        .state
        .prefetcher
        .answer(&req.observer, &req.policy, &Default::default())
        .unwrap();
    ws.send(binary(&StreamClient::Hello {
        version: PROTOCOL_VERSION,
        policy: req.policy,
        rate_bytes_per_s: 100 << 20,
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
    while got.len() < expected.items.len() || !saw_error {
        let Message::Binary(frame) = ws.next().await.unwrap().unwrap() else {
            continue;
        };
        match portico_protocol::parse_server_frame(&frame).unwrap() {
            ServerFrame::Segment(id, bytes) => {
                assert_eq!(bytes, &db.segment(id).unwrap()[..]);
                got.push(id);
            }
            ServerFrame::Control(StreamServer::Error(_)) => saw_error = true,
            ServerFrame::Control(StreamServer::Dropped(_)) => {}
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
    while let Some(Ok(m)) = ws.next().await {
        if matches!(m, Message::Close(_)) {
            break;
        }
    }
}
