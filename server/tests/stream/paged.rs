//! Stream sessions that started from the core manifest: each stab list's page goes right
//! before the list, and no segment before a page with its row.

use super::common;
use super::*;

/// A session that started from the core manifest gets each stab list's page right before the
/// list, once: the page names the list's segment, and every segment pushed after it has its
/// row in a page that came before it (so the client can check it).
#[tokio::test]
async fn a_paged_session_gets_each_page_before_its_stab_list_once() {
    let s = start(shared()).await;
    let db = s.state.db();
    let req = request(db);
    let list = need_list(&s.state, &req.observer, &req.policy);
    let stabs: HashSet<u32> = db
        .header()
        .cells
        .as_ref()
        .unwrap()
        .stab_segments
        .iter()
        .copied()
        .collect();
    let listed_stabs = list
        .items
        .iter()
        .filter(|i| stabs.contains(&i.segment))
        .count();
    assert!(listed_stabs >= 2, "the list has {listed_stabs} stab lists");
    let mut ws = connect(&s.base).await;
    hello(&mut ws, req.policy, 1 << 30).await;
    ws.send(binary(&StreamClient::Pages)).await.unwrap();
    let observe = binary(&StreamClient::Observer(req.observer));
    ws.send(observe.clone()).await.unwrap();
    let (segments_got, pages) = paged_frames(&mut ws, db, &stabs, list.items.len()).await;
    assert_eq!(segments_got, list.items.len());
    assert_eq!(pages, listed_stabs, "one page per stab list pushed");
    // Evicted and pushed again, a stab list comes without its page: the client has it.
    let stab = list
        .items
        .iter()
        .find(|i| stabs.contains(&i.segment))
        .unwrap()
        .segment;
    ws.send(binary(&StreamClient::Evicted(vec![stab])))
        .await
        .unwrap();
    ws.send(observe).await.unwrap();
    match next(&mut ws, Duration::from_secs(10)).await {
        Some(Got::Segment(id, _)) => assert_eq!(id, stab),
        other => panic!("{other:?} instead of stab list {stab} alone"),
    }
}

/// Reads a paged session's frames until `want` segments came (or 3 s of silence), checking that
/// each stab list comes right after its page and every segment after a page with its row;
/// returns the segments and the pages that came.
async fn paged_frames(
    ws: &mut Ws,
    db: &portico_data::Database,
    stabs: &HashSet<u32>,
    want: usize,
) -> (usize, usize) {
    use portico_data::format::CellPage;
    let mut rows = std::collections::HashMap::new();
    let mut page_for: Option<u32> = None;
    let (mut segments_got, mut pages) = (0, 0);
    while segments_got < want {
        match next(ws, Duration::from_secs(3)).await {
            Some(Got::Page(deflated)) => {
                assert!(page_for.is_none(), "two pages in a row");
                let page: CellPage = portico_protocol::inflate_page(&deflated).unwrap();
                rows.extend(page.segments.iter().copied());
                rows.insert(page.stab.0, page.stab.1);
                page_for = Some(page.stab.0);
                pages += 1;
            }
            Some(Got::Segment(id, n)) => {
                segments_got += 1;
                if stabs.contains(&id) {
                    assert_eq!(
                        page_for.take(),
                        Some(id),
                        "stab list {id} without its page first"
                    );
                } else {
                    assert!(
                        page_for.is_none(),
                        "a page, then segment {id}, no stab list"
                    );
                }
                let row = rows
                    .get(&id)
                    .unwrap_or_else(|| panic!("segment {id} came before any page with its row"));
                let e = db.segments()[id as usize];
                assert_eq!(
                    (row.bytes, row.checksum, n as u64),
                    (e.length, e.checksum, e.length)
                );
            }
            None => break,
            other => panic!("{other:?} after {segments_got} segments"),
        }
    }
    (segments_got, pages)
}

/// Under the default policy at a real link's rate, where deadlines would push a large LOD
/// before the small stab list that names it, a paged session still sends every stab list (with
/// its page) first: no segment reaches the client before a row it can be checked against.
#[tokio::test]
async fn a_paged_session_at_a_slow_rate_sends_no_segment_before_its_row() {
    let s = start(shared()).await;
    let db = s.state.db();
    let req = common::request(db); // the default policy: the predicted lookahead
    assert_eq!(req.policy.lookahead_cull, LookaheadCull::Predicted);
    let stabs: HashSet<u32> = db
        .header()
        .cells
        .as_ref()
        .unwrap()
        .stab_segments
        .iter()
        .copied()
        .collect();
    let mut ws = connect(&s.base).await;
    hello(&mut ws, req.policy, 20_000).await;
    ws.send(binary(&StreamClient::Pages)).await.unwrap();
    ws.send(binary(&StreamClient::Observer(req.observer)))
        .await
        .unwrap();
    let (segments, pages) = paged_frames(&mut ws, db, &stabs, 40).await;
    assert!(
        segments >= 5 && pages >= 1,
        "{segments} segments, {pages} pages"
    );
}
