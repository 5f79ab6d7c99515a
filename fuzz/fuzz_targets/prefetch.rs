//! The `prefetch` fuzz target: `bodies/prefetch.rs` under libFuzzer. The same body replays the committed
//! seeds in the workspace's tests (`tests/fuzz_seeds.rs`).
#![no_main]

#[path = "../bodies/prefetch.rs"]
mod body;
#[path = "../bodies/tiny.rs"]
mod tiny;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    body::run(data);
});
