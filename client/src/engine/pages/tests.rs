//! A paged start grown page by page knows what the whole manifest says of everything a stab
//! list names; segments wait for their pages, and a page that does not fit is refused whole.

use super::*;
use crate::engine::catalogue::{Kind, Start};
use portico_data::Database;
use portico_data::texture::TexelFormat;
use portico_protocol::{CoreManifest, PROTOCOL_VERSION};
use std::sync::OnceLock;

/// The tiny generated building (seed 3, two storeys), built once with cells.
fn tiny() -> &'static (tempfile::TempDir, Database) {
    static DB: OnceLock<(tempfile::TempDir, Database)> = OnceLock::new();
    DB.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let params = portico_generator::Params {
            preset: portico_generator::Preset::Tiny,
            seed: 3,
            floors: Some(2),
        };
        let b = portico_generator::generate(&params, &mut |_| {}).expect("generate");
        let glb = dir.path().join("tiny.glb");
        std::fs::write(&glb, &b.glb).unwrap();
        let out = dir.path().join("tiny.portico");
        let model = portico_data::import::import_file(&glb).unwrap();
        let opts = portico_data::build::BuildOptions::default();
        portico_data::build::build_with(model, &out, &opts, &portico_data::build::Quiet, None)
            .unwrap();
        let db = Database::open(&out).unwrap();
        (dir, db)
    })
}

/// What the server's `/v1/manifest/core` says of `db`.
fn core_of(db: &Database) -> CoreManifest<Header, GraphCore> {
    let h = db.header();
    let table = db.rows();
    CoreManifest {
        protocol_version: PROTOCOL_VERSION,
        database_id: "tiny".into(),
        file_bytes: db.file_len(),
        segment_count: table.len() as u32,
        instance_count: h.instances.len() as u32,
        triangles: h.finest_triangles(),
        rows: h
            .unowned_segments()
            .into_iter()
            .map(|s| (s, table[s as usize]))
            .collect(),
        header: h.core(),
        graph: db.cell_graph().unwrap().map(|g| g.core()),
    }
}

/// Cell `cell`'s page as the server makes it.
fn page_of(db: &Database, cell: u32) -> CellPage {
    let h = db.header();
    let seg = h.cells.as_ref().unwrap().stab_segment(cell).unwrap();
    let table = db.rows();
    let graph = db.cell_graph().unwrap().unwrap();
    let stab = db.stab_list(cell).unwrap();
    h.page(cell, seg, &stab, &|s| table[s as usize], &graph)
}

#[test]
fn pages_grow_the_start_into_what_the_whole_manifest_says() {
    let (_, db) = tiny();
    let full = db.header();
    let table = db.rows();
    let mut start = Start::paged(core_of(db), TexelFormat::Rgba8).unwrap();
    let mut pages = start.pages.take().unwrap();
    let live: Vec<(u32, u32)> = full.cells.as_ref().unwrap().stab_lists().collect();
    assert!(live.len() > 4, "{} live cells", live.len());
    let mut named = std::collections::BTreeSet::new();
    for &(seg, cell) in &live {
        assert_eq!(pages.claim(seg), Some(cell));
        assert_eq!(pages.claim(seg), None, "asked once");
        let page = page_of(db, cell);
        pages.take(&mut start.catalogue, page, Some(cell)).unwrap();
        let page = pages.handed(seg).expect("the page waits for its stab list");
        assert!(pages.handed(seg).is_none(), "handed once");
        let m = &mut start;
        let new = Start::learn(&mut m.header, m.graph.as_mut(), &mut m.bounds, &page);
        named.extend(page.instances.iter().map(|(i, _)| *i));
        assert!(new.iter().all(|i| named.contains(i)));
    }
    assert!(!named.is_empty());
    for &i in &named {
        let (got, want) = (
            &start.header.instances[i as usize],
            &full.instances[i as usize],
        );
        assert_eq!(got, want, "instance {i}");
        assert_eq!(start.bounds[i as usize], want.bounds);
        for l in full.lods_of(want) {
            let s = l.segment;
            assert_eq!(start.catalogue.segments[s as usize], table[s as usize]);
            let decoded = start.catalogue.decoded.get(&s).copied();
            assert!(decoded.is_some(), "segment {s}'s decoded size");
            assert_eq!(start.catalogue.kind(s), Kind::Geometry(decoded));
        }
    }
}

#[test]
fn a_segment_waits_while_its_page_is_on_its_way_and_a_stab_list_for_its_page() {
    let (_, db) = tiny();
    let mut start = Start::paged(core_of(db), TexelFormat::Rgba8).unwrap();
    let mut pages = start.pages.take().unwrap();
    let cells = db.header().cells.as_ref().unwrap();
    let (seg, cell) = cells.stab_lists().next().unwrap();
    let page = page_of(db, cell);
    let lod = page.segments.first().expect("a page names segments").0;
    let cat = &mut start.catalogue;
    assert_eq!(pages.readiness(cat, lod), Readiness::Never, "nothing asked");
    assert_eq!(pages.readiness(cat, seg), Readiness::Never);
    pages.claim(seg);
    assert_eq!(pages.readiness(cat, lod), Readiness::Waiting);
    assert_eq!(pages.readiness(cat, seg), Readiness::Waiting);
    pages.take(cat, page, Some(cell)).unwrap();
    assert_eq!(pages.readiness(cat, lod), Readiness::Ready);
    assert_eq!(pages.readiness(cat, seg), Readiness::Ready);
    // A failed request releases its cell: nothing on its way any more.
    let (seg2, cell2) = cells.stab_lists().nth(1).unwrap();
    assert_eq!(pages.claim(seg2), Some(cell2));
    pages.release(cell2);
    assert_eq!(pages.readiness(cat, seg2), Readiness::Never);
    assert_eq!(pages.claim(seg2), Some(cell2), "asked again");
}

#[test]
fn a_page_that_is_not_the_one_asked_for_or_does_not_fit_is_refused_whole() {
    let (_, db) = tiny();
    let mut start = Start::paged(core_of(db), TexelFormat::Rgba8).unwrap();
    let mut pages = start.pages.take().unwrap();
    let mut lists = db.header().cells.as_ref().unwrap().stab_lists();
    let ((seg, cell), (_, other)) = (lists.next().unwrap(), lists.next().unwrap());
    let cat = &mut start.catalogue;
    let before = cat.segments.clone();
    let e = pages.take(cat, page_of(db, other), Some(cell)).unwrap_err();
    assert!(e.contains(&format!("page of cell {cell}")), "{e}");
    let mut bad = page_of(db, cell);
    bad.instances[0].0 = u32::MAX - 1;
    assert!(pages.take(cat, bad, Some(cell)).is_err());
    assert_eq!(cat.segments, before, "nothing taken");
    assert!(pages.handed(seg).is_none());
    assert!(pages.take_frame(cat, b"not deflate").is_err());
}
