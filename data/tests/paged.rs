//! The paged manifest's cut: a cell's page names what its stab list names, and a sparse header
//! grown from every page knows every instance a stab list names, exactly as the whole header.

mod common;

use portico_data::cells::CellGraph;
use portico_data::format::{CellPage, Header, InstanceRecord, UNKNOWN_ROW, take_rows};

fn tiny() -> portico_data::prefetch::Prefetcher {
    common::prefetcher_for(3, 2, true, &Default::default(), None)
}

#[test]
fn pages_grow_a_sparse_header_into_the_whole_one() {
    let p = tiny();
    let db = p.database();
    let full = db.header();
    let table = db.rows();
    let cells = full.cells.as_ref().expect("cells");
    let core = full.core();
    assert!(core.instances.is_empty());
    assert_eq!(core.objects, full.objects);
    let mut sparse = Header::sparse(core, full.instances.len() as u32);
    let mut known = vec![UNKNOWN_ROW; table.len()];
    for s in full.unowned_segments() {
        known[s as usize] = table[s as usize];
    }
    let graph = db.cell_graph().unwrap().unwrap();
    let frame = graph.core();
    let mut sparse_graph = CellGraph::sparse(&frame);
    let mut listed = std::collections::BTreeSet::new();
    let mut pages = 0;
    for (cell, &seg) in cells.stab_segments.iter().enumerate() {
        if seg == u32::MAX {
            continue;
        }
        let stab = db.stab_list(cell as u32).unwrap();
        let page = full.page(cell as u32, seg, &stab, &|s| table[s as usize], &graph);
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
        frame.check_part(&page.graph).unwrap();
        sparse_graph.take_part(&page.graph);
        let reached: Vec<u32> = page.graph.cells.iter().map(|(c, _)| *c).collect();
        let mut want_cells: Vec<u32> = stab.cells().collect();
        want_cells.sort_unstable();
        want_cells.dedup();
        assert_eq!(
            reached, want_cells,
            "cell {cell}: the page reaches what its list reaches"
        );
        let new = sparse.take_page(&page);
        assert!(new.iter().all(|i| !listed.contains(i)), "new means new");
        listed.extend(new);
        pages += 1;
    }
    assert!(pages > 1 && !listed.is_empty());
    // The graph grown from every page locates every live cell's centre as the whole graph
    // does, and holds its cells and portals as they are.
    for (c, cell) in graph.cells.iter().enumerate() {
        if !cell.live {
            continue;
        }
        assert_eq!(&sparse_graph.cells[c], cell, "cell {c}");
        for &p in &cell.portals {
            assert_eq!(sparse_graph.portals[p as usize], graph.portals[p as usize]);
        }
        let centre = cell.bounds.center();
        let found = sparse_graph.locate(centre).unwrap();
        assert!(graph.cells[found as usize].live && found == graph.locate(centre).unwrap());
    }
    assert!(sparse_graph.tree.is_empty());
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
type Spoil = Box<dyn Fn(&mut CellPage)>;

#[test]
fn a_hostile_page_is_refused_naming_what_is_wrong() {
    let p = tiny();
    let db = p.database();
    let full = db.header();
    let table = db.rows();
    let cells = full.cells.as_ref().unwrap();
    let (cell, seg) = cells
        .stab_segments
        .iter()
        .enumerate()
        .find(|(_, s)| **s != u32::MAX)
        .map(|(c, s)| (c as u32, *s))
        .unwrap();
    let stab = db.stab_list(cell).unwrap();
    let graph = db.cell_graph().unwrap().unwrap();
    let good = full.page(cell, seg, &stab, &|s| table[s as usize], &graph);
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
        ("the cell's is", Box::new(|p| p.stab.1.kind = 1)),
        ("not geometry", Box::new(|p| p.segments[0].1.kind = 6)),
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
    // Another cell's number on this cell's page.
    let mut other = good.clone();
    other.cell += 1;
    let e = sparse.check_page(n, table.len(), &other).unwrap_err();
    assert!(e.contains("the cell's is"), "{e}");
    // The graph's part: a cell or portal out of range, or a portal the page lacks.
    let frame = graph.core();
    frame.check_part(&good.graph).unwrap();
    let graph_cases: Vec<(&str, Spoil)> = vec![
        (
            "cell 4294967295 is malformed",
            Box::new(|p| p.graph.cells[0].0 = u32::MAX),
        ),
        (
            "is malformed",
            Box::new(|p| p.graph.portals[0].1.cells[1] = u32::MAX),
        ),
        (
            "which the page lacks",
            Box::new(|p| {
                p.graph.portals.remove(0);
            }),
        ),
        (
            "is malformed",
            Box::new(|p| p.graph.cells[0].1.bounds.max[1] = f32::INFINITY),
        ),
    ];
    for (want, spoil) in graph_cases {
        let mut bad = good.clone();
        spoil(&mut bad);
        let e = frame.check_part(&bad.graph).unwrap_err();
        assert!(e.contains(want), "{want}: {e}");
    }
    full.core().check_page(n, table.len(), &good).unwrap();
    let mut h = sparse.clone();
    assert_eq!(h.take_page(&good).len(), good.instances.len());
    assert!(h.take_page(&good).is_empty(), "taken twice: none new");
}

#[test]
fn a_core_manifest_is_checked_before_anything_is_sized_by_it() {
    use portico_data::format::{MAX_PAGED_COUNT, check_core};
    let p = tiny();
    let db = p.database();
    let h = db.header();
    let core = h.core();
    let frame = db.cell_graph().unwrap().unwrap().core();
    let (segments, instances) = (db.segments().len() as u32, h.instances.len() as u32);
    check_core(&core, segments, instances, Some(&frame)).unwrap();
    let huge = MAX_PAGED_COUNT + 1;
    let cases = [
        (
            check_core(&core, segments, huge, Some(&frame)),
            "instances, at most",
        ),
        (
            check_core(&core, huge, instances, Some(&frame)),
            "segments, at most",
        ),
        (
            check_core(
                &core,
                segments,
                instances,
                Some(&{
                    let mut f = frame;
                    f.cells += 1;
                    f
                }),
            ),
            "stab lists for",
        ),
        (
            check_core(&core, 1, instances, Some(&frame)),
            "stab list segment",
        ),
        (
            check_core(&core, segments, instances, None),
            "without a graph",
        ),
        (
            check_core(
                &core,
                segments,
                instances,
                Some(&{
                    let mut f = frame;
                    f.bounds.max[0] = f32::NAN;
                    f
                }),
            ),
            "not finite",
        ),
    ];
    for (got, want) in cases {
        let e = got.unwrap_err();
        assert!(e.contains(want), "{want}: {e}");
    }
}
