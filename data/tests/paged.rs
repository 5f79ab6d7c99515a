//! The paged manifest's cut: a cell's page names what its stab list names, and a sparse header
//! grown from every page knows every instance a stab list names, exactly as the whole header.

mod common;

use portico_data::format::{Header, InstanceRecord, UNKNOWN_ROW, take_rows};
use portico_protocol::SegmentInfo;

fn tiny() -> portico_data::prefetch::Prefetcher {
    common::prefetcher_for(3, 2, true, &Default::default(), None)
}

fn rows(db: &portico_data::Database) -> Vec<SegmentInfo> {
    db.segments()
        .iter()
        .map(|e| SegmentInfo {
            kind: e.kind,
            bytes: e.length,
            checksum: e.checksum,
        })
        .collect()
}

#[test]
fn pages_grow_a_sparse_header_into_the_whole_one() {
    let p = tiny();
    let db = p.database();
    let full = db.header();
    let table = rows(db);
    let cells = full.cells.as_ref().expect("cells");
    let core = full.core();
    assert!(core.instances.is_empty());
    assert_eq!(core.objects, full.objects);
    let mut sparse = Header::sparse(core, full.instances.len() as u32);
    let mut known = vec![UNKNOWN_ROW; table.len()];
    for s in full.unowned_segments() {
        known[s as usize] = table[s as usize];
    }
    let mut listed = std::collections::BTreeSet::new();
    let mut pages = 0;
    for (cell, &seg) in cells.stab_segments.iter().enumerate() {
        if seg == u32::MAX {
            continue;
        }
        let stab = db.stab_list(cell as u32).unwrap();
        let page = full.page(cell as u32, seg, &stab, &|s| table[s as usize]);
        let ids: Vec<u32> = page.instances.iter().map(|(i, _)| *i).collect();
        let mut want: Vec<u32> = stab.objects();
        want.extend(stab.inside.iter().chain(&stab.partial));
        want.sort_unstable();
        want.dedup();
        assert_eq!(
            ids, want,
            "cell {cell}: the page names what its stab list names"
        );
        assert_eq!(page.stab, (seg, table[seg as usize]));
        sparse
            .check_page(full.instances.len() as u32, table.len(), &page)
            .unwrap();
        take_rows(&mut known, &page);
        let new = sparse.take_page(&page);
        assert!(new.iter().all(|i| !listed.contains(i)), "new means new");
        listed.extend(new);
        pages += 1;
    }
    assert!(pages > 1 && !listed.is_empty());
    for (i, inst) in sparse.instances.iter().enumerate() {
        if listed.contains(&(i as u32)) {
            assert_eq!(inst, &full.instances[i], "instance {i}");
            for l in sparse.lods_of(inst) {
                assert_eq!(known[l.segment as usize], table[l.segment as usize]);
            }
        } else {
            assert!(inst.is_placeholder(), "instance {i} no page names");
            assert!(sparse.lods_of(inst).is_empty());
        }
    }
    // Every segment a texture or the cells need is in the core's rows.
    for t in &full.textures {
        for s in &t.segments {
            assert_eq!(known[s.segment as usize], table[s.segment as usize]);
        }
    }
    assert_eq!(
        known[cells.graph_segment as usize],
        table[cells.graph_segment as usize]
    );
    assert_eq!(sparse.finest_triangles(), {
        let mut only = full.clone();
        for (i, inst) in only.instances.iter_mut().enumerate() {
            if !listed.contains(&(i as u32)) {
                *inst = InstanceRecord::placeholder();
            }
        }
        only.finest_triangles()
    });
}

/// A way to damage a page.
type Spoil = Box<dyn Fn(&mut portico_protocol::Page<InstanceRecord>)>;

#[test]
fn a_hostile_page_is_refused_naming_what_is_wrong() {
    let p = tiny();
    let db = p.database();
    let full = db.header();
    let table = rows(db);
    let cells = full.cells.as_ref().unwrap();
    let (cell, seg) = cells
        .stab_segments
        .iter()
        .enumerate()
        .find(|(_, s)| **s != u32::MAX)
        .map(|(c, s)| (c as u32, *s))
        .unwrap();
    let stab = db.stab_list(cell).unwrap();
    let good = full.page(cell, seg, &stab, &|s| table[s as usize]);
    assert!(good.instances.len() >= 2);
    let n = full.instances.len() as u32;
    let sparse = Header::sparse(full.core(), n);
    let cases: Vec<(&str, Spoil)> = vec![
        ("of ", Box::new(|p| p.instances[1].0 = u32::MAX)),
        (
            "missing object",
            Box::new(|p| p.instances[1].1.object = 1 << 30),
        ),
        (
            "non-finite",
            Box::new(|p| p.instances[1].1.transform[3] = f32::NAN),
        ),
        (
            "without a geometry row",
            Box::new(|p| {
                let s = p.segments.remove(p.segments.len() - 1);
                assert!(s.0 != p.stab.0);
            }),
        ),
        ("segment", Box::new(|p| p.stab.0 = u32::MAX)),
    ];
    for (want, spoil) in cases {
        let mut bad = good.clone();
        spoil(&mut bad);
        let e = sparse.check_page(n, table.len(), &bad).unwrap_err();
        assert!(
            e.starts_with(&format!("page of cell {cell}: ")) && e.contains(want),
            "{e}"
        );
    }
    sparse.check_page(n, table.len(), &good).unwrap();
    full.core().check_page(n, table.len(), &good).unwrap();
    let mut h = sparse.clone();
    assert_eq!(h.take_page(&good).len(), good.instances.len());
    assert!(h.take_page(&good).is_empty(), "taken twice: none new");
}
