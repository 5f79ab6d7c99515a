//! How fast a client decodes texture segments and re-codes them as BC blocks, and what picture
//! the GPU then samples (docs/performance.md's figures). Measurements, not timed tests: run them by
//! hand in release,
//! `PORTICO_DB=soda.tex.portico cargo test --release -p portico-data --test texture_decode_speed -- --ignored --nocapture`
//! (add `PORTICO_MODEL=soda.tex.glb`, the model it was built from, for the PSNR of what the GPU
//! samples against the model's own texels).

use portico_data::Database;
use portico_data::texture::{
    BlockFormat, compress, decode_segment, decompress_finest, is_opaque, mip_chain, psnr,
};

#[test]
#[ignore = "a measurement: needs PORTICO_DB and a release build"]
fn decode_every_texture_segment() {
    let path = std::env::var("PORTICO_DB").expect("PORTICO_DB names a textured database");
    let db = Database::open(std::path::Path::new(&path)).unwrap();
    let records: Vec<_> = db
        .header()
        .textures
        .iter()
        .flat_map(|t| &t.segments)
        .copied()
        .collect();
    let segments: Vec<(u32, u64)> = records
        .iter()
        .map(|s| (s.segment, s.texel_bytes()))
        .collect();
    assert!(!segments.is_empty(), "{path} has no textures");
    // Each joined from its parts, as a client joins them.
    let bytes: Vec<_> = records
        .iter()
        .map(|s| db.texture_segment(s).unwrap())
        .collect();
    let (mut coded, mut decoded) = (0u64, 0u64);
    let t0 = std::time::Instant::now();
    let mut chains = Vec::new();
    for ((_, want), b) in segments.iter().zip(&bytes) {
        let c = decode_segment(b).unwrap();
        assert_eq!(c.texels.len() as u64, *want);
        coded += b.len() as u64;
        decoded += c.texels.len() as u64;
        chains.push(c);
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
    // Then into BC blocks, as a client whose GPU takes them does on its IO stage.
    let t0 = std::time::Instant::now();
    let (mut held, mut worst) = (0u64, f64::INFINITY);
    let mut compressed = Vec::new();
    for c in &chains {
        let format = if is_opaque(&c.texels) {
            BlockFormat::Bc1
        } else {
            BlockFormat::Bc3
        };
        if let Some(b) = compress(c, format) {
            held += b.bytes.len() as u64;
            compressed.push((c, b));
        }
    }
    let s = t0.elapsed().as_secs_f64();
    for (c, b) in &compressed {
        worst = worst.min(psnr(c.level(0).2, &decompress_finest(b).unwrap()));
    }
    println!(
        "{} chains into BC blocks in {:.3} s: {:.1} ms per decoded MB; {:.2} MB held ({:.2} bytes per texel against 4), PSNR at least {worst:.1} dB against the decoded texels",
        compressed.len(),
        s,
        1e3 * s / (decoded as f64 / 1e6),
        held as f64 / 1e6,
        4.0 * held as f64 / decoded as f64,
    );
    if let Ok(model) = std::env::var("PORTICO_MODEL") {
        end_to_end(&model);
    }
}

/// Each texture of `model` coded as the build codes it, decoded and block-compressed as a
/// client does: the finest level's PSNR against the model's own texels, per step.
fn end_to_end(model: &str) {
    let m = portico_data::import::import_file(std::path::Path::new(model)).unwrap();
    for t in &m.textures {
        let chain = mip_chain(t.width, t.height, &t.rgba);
        let coded = portico_data::texture::code_segments(t.width, t.height, &chain);
        let finest = decode_segment(&coded.last().unwrap().bytes).unwrap();
        let format = if is_opaque(&t.rgba) {
            BlockFormat::Bc1
        } else {
            BlockFormat::Bc3
        };
        let wire = psnr(&t.rgba, finest.level(0).2);
        let gpu = compress(&finest, format).map(|b| psnr(&t.rgba, &decompress_finest(&b).unwrap()));
        let direct = compress(&finest_of(&chain, t.width, t.height), format)
            .map(|b| psnr(&t.rgba, &decompress_finest(&b).unwrap()));
        println!(
            "{:<24} {}x{} {:?}: wire {wire:.1} dB, GPU {} dB (BC of the original: {} dB)",
            t.name,
            t.width,
            t.height,
            format,
            gpu.map_or("-".into(), |p| format!("{p:.1}")),
            direct.map_or("-".into(), |p| format!("{p:.1}")),
        );
    }
}

fn finest_of(chain: &[Vec<u8>], w: u32, h: u32) -> portico_data::texture::TextureChain {
    portico_data::texture::TextureChain {
        width: w,
        height: h,
        levels: chain.len() as u32,
        texels: chain.concat(),
    }
}
