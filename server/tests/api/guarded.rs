//! The bearer token, the push stream through the API, and a damaged segment on disk.

use super::*;

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
        // Shared answers whatever the load (a few clients get their own by default).
        exact_share: 0.0,
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
    // Under the range lookahead (the predicted one pushes by deadline: tests/stream/) the
    // session pushes its place's shared need list (the eye cell and direction bucket's).
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
