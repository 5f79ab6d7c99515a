//! One texture budget per model, on the OBJ path (which had none): a dozen 4096² maps, three
//! times the budget, all kept and shrunk by one factor, and the import's peak memory bounded by
//! the budget rather than the sum of the images. Alone in its binary so the process's peak
//! memory is this import's.

use portico_data::import::image::{MODEL_TEXELS, fit};
use portico_data::import::import_file;

/// The process's peak resident memory (bytes), from `/proc/self/status`.
fn peak_rss() -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap();
    let line = status.lines().find(|l| l.starts_with("VmHWM:")).unwrap();
    let kb: u64 = line.split_whitespace().nth(1).unwrap().parse().unwrap();
    kb * 1024
}

#[test]
fn many_large_maps_shrink_evenly_within_the_budget() {
    const N: usize = 12;
    const SIDE: u32 = 4096;
    let dir = tempfile::tempdir().unwrap();
    let img = image::RgbaImage::from_fn(SIDE, SIDE, |x, y| {
        image::Rgba([(x / 16) as u8, (y / 16) as u8, ((x ^ y) / 64) as u8, 255])
    });
    img.save(dir.path().join("map_0.png")).unwrap();
    drop(img);
    let mut mtl = String::new();
    let mut obj = String::from("mtllib house.mtl\n");
    for i in 0..N {
        if i > 0 {
            std::fs::copy(
                dir.path().join("map_0.png"),
                dir.path().join(format!("map_{i}.png")),
            )
            .unwrap();
        }
        mtl += &format!("newmtl m{i}\nKd 1 1 1\nmap_Kd map_{i}.png\n");
        let x = i as f32 * 2.0;
        obj += &format!(
            "o quad{i}\nusemtl m{i}\nv {x} 0 0\nv {} 0 0\nv {} 1 0\nv {x} 1 0\n\
             vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf -4/-4 -3/-3 -2/-2 -1/-1\n",
            x + 1.0,
            x + 1.0
        );
    }
    std::fs::write(dir.path().join("house.mtl"), mtl).unwrap();
    std::fs::write(dir.path().join("house.obj"), obj).unwrap();
    let before = peak_rss();
    let m = import_file(&dir.path().join("house.obj")).unwrap();
    let peak = peak_rss();
    // Every map kept, each the same size, together within the budget.
    assert_eq!(m.textures.len(), N, "{:?}", m.warnings);
    let (s, _) = fit(&[(SIDE, SIDE); N], MODEL_TEXELS);
    let side = (SIDE as f64 * s).round() as u32;
    for t in &m.textures {
        assert_eq!((t.width, t.height), (side, side), "{}", t.name);
    }
    let texels: u64 = m
        .textures
        .iter()
        .map(|t| t.width as u64 * t.height as u64)
        .sum();
    assert!(
        texels <= MODEL_TEXELS && texels > MODEL_TEXELS * 9 / 10,
        "{texels}"
    );
    assert!(
        m.warnings
            .iter()
            .any(|w| w.contains("12 textures") && w.contains("budget")),
        "{:?}",
        m.warnings
    );
    // The maps decode to 12 × 64 MiB; the import holds the budget (256 MiB) and about one
    // image at a time.
    let sum = N as u64 * SIDE as u64 * SIDE as u64 * 4;
    let budget = MODEL_TEXELS * 4;
    assert!(
        peak.saturating_sub(before.min(peak)) < budget + 3 * (SIDE as u64 * SIDE as u64 * 4),
        "peak {} MiB from {} MiB (images {} MiB)",
        peak >> 20,
        before >> 20,
        sum >> 20
    );
    assert!(peak < sum, "peak {} MiB", peak >> 20);
}
