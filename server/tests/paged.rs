//! The paged manifest over HTTP: the core is the manifest less its instance and segment
//! tables and the cell graph less its cells, each live cell's page is the part of them its
//! stab list names and reaches (gzip-coded,
//! immutable under the database id), and bad cells get one-line errors.

use portico_data::cells::paged::GraphCore;
use portico_data::format::{CellPage, Header};
use portico_protocol::{ApiError, BINCODE_MIME, CoreManifest, Manifest};
use portico_server::Config;

mod common;
use common::start;

async fn get(http: &reqwest::Client, url: &str) -> reqwest::Response {
    http.get(url)
        .header("accept", BINCODE_MIME)
        .send()
        .await
        .unwrap()
}

/// The whole manifest, bincode-coded.
async fn whole_manifest(http: &reqwest::Client, base: &str) -> Manifest<Header> {
    let bytes = get(http, &format!("{base}/v1/manifest"))
        .await
        .bytes()
        .await
        .unwrap();
    portico_protocol::manifest_from_bincode(&bytes).unwrap()
}

#[tokio::test]
async fn the_core_and_the_pages_make_up_the_whole_manifest() {
    let s = start(Config::default()).await;
    let http = reqwest::Client::new();
    let whole = whole_manifest(&http, &s.base).await;
    let r = get(&http, &format!("{}/v1/manifest/core", s.base)).await;
    assert_eq!(r.status(), 200);
    assert_eq!(r.headers()["cache-control"], "no-cache");
    let core_bytes = r.bytes().await.unwrap();
    let core: CoreManifest<Header, GraphCore> =
        portico_protocol::from_bincode(&core_bytes).unwrap();
    let graph = s.state.prefetcher.graph().unwrap();
    assert_eq!(core.graph, Some(graph.core()));
    assert_eq!(core.database_id, whole.database_id);
    assert_eq!(core.segment_count as usize, whole.segments.len());
    assert_eq!(core.instance_count as usize, whole.header.instances.len());
    assert_eq!(core.triangles, whole.header.finest_triangles());
    assert_eq!(core.header, whole.header.core());
    for (id, row) in &core.rows {
        assert_eq!(*row, whole.segments[*id as usize], "core row {id}");
    }
    let cells = whole.header.cells.as_ref().unwrap();
    assert!(core.rows.iter().any(|(id, _)| *id == cells.graph_segment));
    let db = s.state.db();
    let mut seen = std::collections::HashSet::new();
    for (cell, &seg) in cells.stab_segments.iter().enumerate() {
        if seg == u32::MAX {
            continue;
        }
        let url = format!("{}/v1/db/{}/pages/{cell}", s.base, whole.database_id);
        let r = get(&http, &url).await;
        assert_eq!(r.status(), 200, "cell {cell}");
        assert_eq!(r.headers()["cache-control"], portico_server::IMMUTABLE);
        let page: CellPage = portico_protocol::from_bincode(&r.bytes().await.unwrap()).unwrap();
        assert_eq!(page.graph, graph.part(&db.stab_list(cell as u32).unwrap()));
        assert!(page.graph.cells.iter().any(|(c, _)| *c == cell as u32));
        assert_eq!(page.cell, cell as u32);
        assert_eq!(page.stab, (seg, whole.segments[seg as usize]));
        let stab = db.stab_list(cell as u32).unwrap();
        for o in stab.objects() {
            assert!(
                page.instances.iter().any(|(i, _)| *i == o),
                "cell {cell}: {o} missing"
            );
        }
        for (i, inst) in &page.instances {
            assert_eq!(inst, &whole.header.instances[*i as usize]);
            for l in whole.header.lods_of(inst) {
                let row = page.segments.iter().find(|(s, _)| *s == l.segment);
                assert_eq!(row.map(|r| r.1), Some(whole.segments[l.segment as usize]));
            }
            seen.insert(*i);
        }
    }
    // The core is small beside the whole manifest, and the pages cover most of the model.
    let whole_bytes = portico_protocol::to_bincode(&whole).unwrap().len();
    assert!(
        core_bytes.len() * 2 < whole_bytes,
        "core {} of {whole_bytes}",
        core_bytes.len()
    );
    assert!(seen.len() * 2 > whole.header.instances.len());
}

#[tokio::test]
async fn pages_are_gzip_coded_and_bad_cells_get_one_line_errors() {
    let s = start(Config::default()).await;
    let http = reqwest::Client::builder().no_gzip().build().unwrap();
    let db = s.state.db();
    let cells = db.header().cells.as_ref().unwrap();
    let live = cells
        .stab_segments
        .iter()
        .position(|&s| s != u32::MAX)
        .unwrap();
    let id = &s.state.database_id;
    let url = |cell: &str| format!("{}/v1/db/{id}/pages/{cell}", s.base);
    let plain = get(&http, &url(&live.to_string())).await;
    let tag = plain.headers()["etag"].to_str().unwrap().to_string();
    let plain = plain.bytes().await.unwrap();
    let gz = http
        .get(url(&live.to_string()))
        .header("accept", BINCODE_MIME)
        .header("accept-encoding", "gzip")
        .send()
        .await
        .unwrap();
    assert_eq!(gz.headers()["content-encoding"], "gzip");
    assert_ne!(gz.headers()["etag"].to_str().unwrap(), tag);
    assert!(gz.bytes().await.unwrap().len() < plain.len());
    let revalidated = http
        .get(url(&live.to_string()))
        .header("accept", BINCODE_MIME)
        .header("if-none-match", &tag)
        .send()
        .await
        .unwrap();
    assert_eq!(revalidated.status(), 304);
    let dead = cells.stab_segments.iter().position(|&s| s == u32::MAX);
    let mut cases = vec![
        (url("x9"), 400, "\"x9\" is not a number".to_string()),
        (
            url("4000000000"),
            404,
            "cell 4000000000 has no page".to_string(),
        ),
        (
            format!("{}/v1/db/0000/pages/{live}", s.base),
            410,
            "database 0000 is no longer served".to_string(),
        ),
    ];
    if let Some(d) = dead {
        cases.push((url(&d.to_string()), 404, format!("cell {d} has no page")));
    }
    for (u, status, want) in cases {
        let r = get(&http, &u).await;
        assert_eq!(r.status(), status, "{u}");
        let e: ApiError = r.json().await.unwrap();
        assert!(
            e.message.contains(&want) && !e.message.contains('\n'),
            "{u}: {}",
            e.message
        );
    }
    // JSON clients read the whole manifest: the paged documents are bincode only.
    let r = http
        .get(format!("{}/v1/manifest/core", s.base))
        .header("accept", "application/json")
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 406);
    // The server still serves.
    assert_eq!(get(&http, &url(&live.to_string())).await.status(), 200);
}

/// Pages are cut along the stab lists: a database without cells has none, and a client that
/// started from its core would never learn an instance (its walk drew nothing). The core is
/// refused, so clients read the whole manifest, which holds every instance.
#[tokio::test]
async fn a_database_without_cells_has_no_core_and_its_whole_manifest_lists_everything() {
    let dir = tempfile::tempdir().unwrap();
    let tiny = portico_data::Database::open(common::db_path()).unwrap();
    let instances = tiny.header().instances.len();
    let glb = common::db_path().with_file_name("tiny.glb");
    let out = dir.path().join("no-cells.portico");
    let opts = portico_data::build::BuildOptions {
        no_cells: true,
        no_hierarchy: true,
        ..Default::default()
    };
    let model = portico_data::import::import_file(&glb).unwrap();
    portico_data::build::build(model, &out, &opts, &portico_data::build::Quiet).unwrap();
    let s = common::start_on(&out, Config::default()).await;
    let http = reqwest::Client::new();
    let r = get(&http, &format!("{}/v1/manifest/core", s.base)).await;
    assert_eq!(r.status(), 404);
    let e: ApiError = r.json().await.unwrap();
    assert!(e.message.contains("no cells"), "{}", e.message);
    let whole = whole_manifest(&http, &s.base).await;
    assert_eq!(whole.header.instances.len(), instances);
    assert!(whole.header.cells.is_none());
}

/// A paged client has no whole cell graph to make a tour from: the server gives the standard
/// one, the same the whole model makes, under the database's URL.
#[tokio::test]
async fn the_standard_tour_is_served_under_the_database() {
    let s = start(Config::default()).await;
    let http = reqwest::Client::new();
    let id = &s.state.database_id;
    let r = get(&http, &format!("{}/v1/db/{id}/tour", s.base)).await;
    assert_eq!(r.status(), 200);
    assert_eq!(r.headers()["cache-control"], portico_server::IMMUTABLE);
    let tour: portico_data::path::CameraPath = r.json().await.unwrap();
    let db = s.state.db();
    let h = db.header();
    let bounds: Vec<_> = h.instances.iter().map(|i| i.bounds).collect();
    let want = portico_data::path::standard(
        s.state.prefetcher.graph(),
        &h.bounds,
        &bounds,
        portico_data::path::PathKind::Tour,
        6,
        1,
        portico_data::person::WALK_SPEED,
        portico_data::person::TURN_DEGREES.to_radians(),
    )
    .unwrap();
    assert_eq!(tour, want);
    assert!(tour.duration() > 1.0);
    let r = get(&http, &format!("{}/v1/db/0123abcd/tour", s.base)).await;
    assert_eq!(r.status(), 410, "another database's tour");
    let r = get(&http, &format!("{}/v1/tour", s.base)).await;
    assert_eq!(r.headers()["cache-control"], "no-cache");
    let tag = r.headers()["etag"].clone();
    let again = http
        .get(format!("{}/v1/tour", s.base))
        .header("if-none-match", tag)
        .send()
        .await
        .unwrap();
    assert_eq!(again.status(), 304, "revalidated, not sent again");
    assert_eq!(again.headers()["cache-control"], "no-cache");
    // Under the database's URL a 304 keeps the copy immutable (its headers update the cached
    // ones).
    let url = format!("{}/v1/db/{id}/tour", s.base);
    let first = get(&http, &url).await;
    let kept = http
        .get(&url)
        .header("if-none-match", first.headers()["etag"].clone())
        .send()
        .await
        .unwrap();
    assert_eq!(kept.status(), 304);
    assert_eq!(kept.headers()["cache-control"], portico_server::IMMUTABLE);
    assert_eq!(kept.headers()["vary"], first.headers()["vary"]);
    assert_eq!(
        r.json::<portico_data::path::CameraPath>().await.unwrap(),
        want
    );
    // Gzip-coded for a client that takes it (a page reads the tour before its first frame),
    // under its own ETag.
    let raw = reqwest::Client::builder().no_gzip().build().unwrap();
    let zipped = raw
        .get(format!("{}/v1/tour", s.base))
        .header("accept-encoding", "gzip")
        .send()
        .await
        .unwrap();
    assert_eq!(zipped.headers()["content-encoding"], "gzip");
    let plain = raw.get(format!("{}/v1/tour", s.base)).send().await.unwrap();
    assert!(plain.headers().get("content-encoding").is_none());
    assert_ne!(zipped.headers()["etag"], plain.headers()["etag"]);
    let body = zipped.bytes().await.unwrap();
    let mut json = Vec::new();
    std::io::Read::read_to_end(&mut flate2::read::GzDecoder::new(&body[..]), &mut json).unwrap();
    let unzipped: portico_data::path::CameraPath = serde_json::from_slice(&json).unwrap();
    assert_eq!(unzipped, want);
    assert!(
        body.len() * 2 < json.len(),
        "{} bytes gzip-coded of {}",
        body.len(),
        json.len()
    );
}
