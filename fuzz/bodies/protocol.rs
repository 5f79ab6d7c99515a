//! Fuzzes the protocol decoders the server exposes: any bytes give a message or an error, never
//! a panic (the prefetch body, stream messages in both encodings, server frames, held sets).
use portico_protocol::{PrefetchRequest, StreamClient};

/// One input.
pub fn run(data: &[u8]) {
    if let Ok(req) = portico_protocol::from_bincode::<PrefetchRequest>(data) {
        let _ = portico_protocol::decode_held(&req.held);
    }
    let _ = portico_protocol::from_json::<PrefetchRequest>(data);
    let _ = portico_protocol::from_bincode::<StreamClient>(data);
    let _ = portico_protocol::from_json::<StreamClient>(data);
    let _ = portico_protocol::parse_server_frame(data);
}
