//! Fuzzes the display database reader: any bytes must give a database or an error, never a
//! panic, and whatever opens must survive reading every segment and every cell structure.
#![no_main]

use libfuzzer_sys::fuzz_target;
use portico_data::Database;
use portico_data::geometry::GeometryView;

fuzz_target!(|data: &[u8]| {
    let Ok(db) = Database::from_bytes(std::path::Path::new("fuzz.portico"), bytes::Bytes::copy_from_slice(data)) else {
        return;
    };
    let _ = db.verify_all();
    for e in db.segments() {
        if let Ok(b) = db.segment(e.id) {
            let _ = GeometryView::parse(&b).map(|v| v.to_mesh());
        }
    }
    if let Ok(Some(g)) = db.cell_graph() {
        for c in 0..g.cells.len() as u32 {
            let _ = db.stab_list(c);
        }
        let _ = g.locate(glam_free_point(&g.bounds));
    }
    let _ = db.occluders();
    let _ = portico_data::stats::stats(&db);
});

fn glam_free_point(b: &portico_data::geometry::Aabb) -> glam::Vec3 {
    glam::Vec3::from(b.center())
}
