//! How fast a client decodes texture segments (the README's figure): every mip segment of the
//! database `PORTICO_DB` names decoded and its chain built, timed. A measurement, not a timed
//! test: run it by hand in release,
//! `PORTICO_DB=soda.tex.portico cargo test --release -p portico-data --test texture_decode_speed -- --ignored --nocapture`.

use portico_data::Database;
use portico_data::texture::decode_segment;

#[test]
#[ignore = "a measurement: needs PORTICO_DB and a release build"]
fn decode_every_texture_segment() {
    let path = std::env::var("PORTICO_DB").expect("PORTICO_DB names a textured database");
    let db = Database::open(std::path::Path::new(&path)).unwrap();
    let segments: Vec<(u32, u64)> = db
        .header()
        .textures
        .iter()
        .flat_map(|t| &t.segments)
        .map(|s| (s.segment, s.texel_bytes()))
        .collect();
    assert!(!segments.is_empty(), "{path} has no textures");
    let bytes: Vec<_> = segments
        .iter()
        .map(|(s, _)| db.segment(*s).unwrap())
        .collect();
    let (mut coded, mut decoded) = (0u64, 0u64);
    let t0 = std::time::Instant::now();
    for ((_, want), b) in segments.iter().zip(&bytes) {
        let c = decode_segment(b).unwrap();
        assert_eq!(c.texels.len() as u64, *want);
        coded += b.len() as u64;
        decoded += c.texels.len() as u64;
    }
    let s = t0.elapsed().as_secs_f64();
    println!(
        "{} segments, {:.2} MB coded -> {:.2} MB of texels in {:.3} s: {:.1} ms per coded MB, {:.1} ms per decoded MB",
        segments.len(),
        coded as f64 / 1e6,
        decoded as f64 / 1e6,
        s,
        1e3 * s / (coded as f64 / 1e6),
        1e3 * s / (decoded as f64 / 1e6)
    );
}
