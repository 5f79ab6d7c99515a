//! Fuzzes the protocol decoders: any bytes give a message or an error, never a panic.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = portico_protocol::from_bincode::<(u32, String, Vec<f32>)>(data);
    let _ = portico_protocol::from_json::<serde_json::Value>(data);
});
