//! A proxy that damages segments on their way: the client must check every segment against the
//! manifest's checksum, reject and count a damaged one, never cache or draw it, and fetch it
//! again — and the walk goes on.

use axum::body::{Body, Bytes};
use axum::extract::Request;
use axum::response::Response;
use portico_client::elision::Algorithm;
use portico_data::path::{CameraPath, PathKind, generate};
use portico_native::walk::{WalkConfig, walk};
use portico_protocol::Policy;
use std::collections::HashMap;
use std::sync::{Arc, Mutex};

mod common;

/// Per segment id: how many times the proxy delivered it, and how many of those it damaged.
#[derive(Default)]
struct Ledger {
    delivered: HashMap<u32, u32>,
    damaged: HashMap<u32, u32>,
}

/// The first `victims` distinct segments the proxy passes get one byte flipped on their first
/// delivery, in single reads and in batches alike; everything else passes unchanged.
fn damaging_proxy(upstream: String, victims: usize) -> (String, Arc<Mutex<Ledger>>) {
    let ledger = Arc::new(Mutex::new(Ledger::default()));
    let l2 = ledger.clone();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let rt = tokio::runtime::Runtime::new().unwrap();
        rt.block_on(async move {
            let http = reqwest::Client::new();
            let app = axum::Router::new().fallback(move |req: Request| {
                let (http, up, ledger) = (http.clone(), upstream.clone(), l2.clone());
                async move { forward(&http, &up, req, &ledger, victims).await }
            });
            let l = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
            tx.send(format!("http://{}", l.local_addr().unwrap()))
                .unwrap();
            axum::serve(l, app).await.unwrap();
        });
    });
    (rx.recv().unwrap(), ledger)
}

async fn forward(
    http: &reqwest::Client,
    upstream: &str,
    req: Request,
    ledger: &Mutex<Ledger>,
    victims: usize,
) -> Response {
    let (parts, body) = req.into_parts();
    let body = axum::body::to_bytes(body, 64 << 20)
        .await
        .unwrap_or_default();
    let uri = parts.uri.to_string();
    let mut out = http.request(parts.method.clone(), format!("{upstream}{uri}"));
    for (k, v) in &parts.headers {
        if k != "host" {
            out = out.header(k, v);
        }
    }
    let r = out.body(body).send().await.expect("upstream");
    let (status, headers) = (r.status(), r.headers().clone());
    let mut bytes = r.bytes().await.expect("upstream body").to_vec();
    if status == 200 {
        // (segment id, where its bytes are) for every segment in the answer.
        let ranges: Vec<(u32, std::ops::Range<usize>)> = if uri.contains("/batch?") {
            portico_protocol::batch::parse(&bytes)
                .unwrap_or_default()
                .into_iter()
                .filter_map(|(id, r)| Some((id, r?)))
                .collect()
        } else if let Some(id) = uri
            .rsplit("/segments/")
            .next()
            .filter(|_| uri.contains("/segments/"))
        {
            id.parse()
                .ok()
                .map(|id| vec![(id, 0..bytes.len())])
                .unwrap_or_default()
        } else {
            Vec::new()
        };
        let mut l = ledger.lock().unwrap();
        for (id, range) in ranges {
            let first = !l.delivered.contains_key(&id);
            *l.delivered.entry(id).or_default() += 1;
            if first && l.damaged.len() < victims && !range.is_empty() {
                bytes[range.start + range.len() / 2] ^= 0x5a;
                l.damaged.insert(id, 1);
            }
        }
    }
    let mut resp = Response::builder().status(status);
    for (k, v) in &headers {
        if k != "content-length" && k != "transfer-encoding" {
            resp = resp.header(k, v);
        }
    }
    resp.body(Body::from(Bytes::from(bytes))).unwrap()
}

/// The tour's first view held for a minute. A walking observer under the predicted lookahead
/// may stop needing a segment it read ahead, and a rejected segment is asked for again only
/// while a list still wants it (`client/src/schedule.rs`): standing, every segment read stays
/// wanted, so each damaged one must come again.
fn standing(mut path: CameraPath) -> CameraPath {
    let first = path.keyframes[0];
    let mut later = first;
    later.t = 60.0;
    path.keyframes = vec![first, later];
    path
}

#[test]
fn damaged_segments_are_rejected_counted_and_fetched_again() {
    let dir = tempfile::tempdir().unwrap();
    let (server, _, db) = common::serve_tiny(dir.path());
    let (proxy, ledger) = damaging_proxy(server, 5);
    let graph = portico_data::Database::open(&db)
        .unwrap()
        .cell_graph()
        .unwrap()
        .unwrap();
    let cfg = WalkConfig {
        server: proxy,
        token: None,
        path: standing(generate(&graph, PathKind::Tour, 2, 1, 1.5, 1.5).unwrap()),
        budget_s: 0.02,
        cache_bytes: 64 << 20,
        size: (96, 72),
        elision: Algorithm::Optimize,
        policy: Policy::default(),
        out: None,
        png_every: 0,
        max_frames: Some(150),
        pace: true,
        fovy: 1.0,
        max_speed: 2.0,
        max_turn: 2.0,
        transport: portico_native::stream::Transport::Pull,
        paged: true,
    };
    let s = walk(&cfg, &mut |_, _| {}).unwrap();
    let l = ledger.lock().unwrap();
    assert_eq!(l.damaged.len(), 5, "the walk read fewer than 5 segments");
    // Each damaged delivery was rejected and counted ...
    assert_eq!(s.io_failures, 5, "damaged deliveries rejected and counted");
    // ... and, not being cached, asked for again and delivered intact.
    for id in l.damaged.keys() {
        assert!(
            l.delivered[id] >= 2,
            "segment {id} was damaged and never fetched again (cached as it was?)"
        );
    }
    assert!(!s.database_changed);
    assert!(s.drawn_triangles.max > 0.0, "the walk went on drawing");
}
