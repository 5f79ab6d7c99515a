//! Prints the statistics, GLB size and generation time of each preset (or of those named on the
//! command line): `cargo run --release -p portico-generator --example measure -- soda mega`.

use std::time::Instant;

use portico_generator::{Params, Preset, generate};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let names: Vec<String> = std::env::args().skip(1).collect();
    let presets: Vec<Preset> = if names.is_empty() {
        Preset::ALL.to_vec()
    } else {
        names.iter().map(|n| n.parse()).collect::<Result<_, _>>()?
    };
    for preset in presets {
        let params = Params {
            preset,
            seed: 1,
            floors: None,
        };
        let start = Instant::now();
        let building = generate(&params, &mut |_| {})?;
        let secs = start.elapsed().as_secs_f64();
        let s = &building.stats;
        println!(
            "{preset}: storeys {} rooms {} instances {} definitions {} (furniture {}) \
             triangles_highest {} triangles_all_lods {} glb_bytes {} doors {} time {secs:.2}s",
            s.storeys,
            s.rooms,
            s.instances,
            s.definitions,
            s.furniture_definitions,
            s.triangles_highest,
            s.triangles_all_lods,
            building.glb.len(),
            building.doors.len(),
        );
    }
    Ok(())
}
