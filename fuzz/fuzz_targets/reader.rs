//! The `reader` fuzz target: `bodies/reader.rs` under libFuzzer. The same body replays the committed
//! seeds in the workspace's tests (`tests/fuzz_seeds.rs`).
#![no_main]

#[path = "../bodies/reader.rs"]
mod body;

libfuzzer_sys::fuzz_target!(|data: &[u8]| body::run(data));
