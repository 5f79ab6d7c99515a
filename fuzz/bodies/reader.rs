//! Fuzzes the display database reader: any bytes must give a database or an error, never a
//! panic, and whatever opens must survive reading every segment and every cell structure.
//!
//! Checksums stop random mutations at the prologue, so each input is tried twice: as it is, and
//! "resealed" — version, length and every checksum (prologue, header, index, segments) made to
//! match the mutated bytes — so the fuzzer reaches the header, index, geometry, cell-graph and
//! stab-list decoders behind them. Seed the corpus with a real file (fuzz/README.md).
use portico_data::Database;
use portico_data::format::{FORMAT_VERSION, MAGIC, PROLOGUE_SIZE, Prologue, SegmentEntry};
use portico_data::geometry::GeometryView;
use xxhash_rust::xxh3::xxh3_64;

/// One input: opened as it is and resealed.
pub fn run(data: &[u8]) {
    open_and_read(data.to_vec());
    if let Some(sealed) = reseal(data) {
        open_and_read(sealed);
    }
}

fn open_and_read(data: Vec<u8>) {
    let Ok(db) = Database::from_bytes(
        std::path::Path::new("fuzz.portico"),
        bytes::Bytes::from(data),
    ) else {
        return;
    };
    let _ = db.verify_all();
    for e in db.segments() {
        if let Ok(b) = db.segment(e.id) {
            let _ = GeometryView::parse(&b).map(|v| v.to_mesh());
            // Texture segments: whatever decodes yields every level in bounds.
            if let Ok(t) = portico_data::texture::decode_segment(&b) {
                (0..t.levels).for_each(|i| {
                    t.level(i);
                });
            }
            // Compressed segments: whatever decodes must parse.
            if let Ok(plain) = portico_data::codec::decode(&b) {
                GeometryView::parse(&plain).expect("a decoded segment parses");
            }
        }
    }
    if let Ok(Some(g)) = db.cell_graph() {
        for c in 0..g.cells.len() as u32 {
            let _ = db.stab_list(c);
        }
        let _ = g.locate(g.bounds.center());
    }
    let _ = db.occluders();
    let _ = portico_data::stats::stats(&db);
}

/// The input with its prologue made self-consistent and every checksum recomputed; `None` when
/// it has no room for a prologue.
fn reseal(data: &[u8]) -> Option<Vec<u8>> {
    let mut out = data.to_vec();
    let head = out.get(..PROLOGUE_SIZE)?;
    let mut p: Prologue = bytemuck::pod_read_unaligned(head);
    p.magic = MAGIC;
    p.version = FORMAT_VERSION;
    p.file_len = out.len() as u64;
    let range = |off: u64, len: u64| {
        let end = off.checked_add(len)?;
        (end <= out.len() as u64).then_some(off as usize..end as usize)
    };
    if let Some(r) = range(p.header_offset, p.header_len) {
        p.header_checksum = xxh3_64(&out[r]);
    }
    let entry = std::mem::size_of::<SegmentEntry>() as u64;
    if let Some(r) = p
        .index_count
        .checked_mul(entry)
        .and_then(|len| range(p.index_offset, len))
    {
        let mut index: Vec<SegmentEntry> = bytemuck::pod_collect_to_vec(&out[r.clone()]);
        for e in &mut index {
            if let Some(s) = range(e.offset, e.length) {
                e.checksum = xxh3_64(&out[s]);
            }
        }
        out[r.clone()].copy_from_slice(bytemuck::cast_slice(&index));
        p.index_checksum = xxh3_64(&out[r]);
    }
    p.prologue_checksum = p.compute_checksum();
    out[..PROLOGUE_SIZE].copy_from_slice(bytemuck::bytes_of(&p));
    Some(out)
}
