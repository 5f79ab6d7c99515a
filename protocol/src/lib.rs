//! Portico's wire types and their encodings. No I/O: the server and the client both
//! depend on this crate and agree on bytes through it.
//!
//! Every message is serde-serialisable, so it travels as bincode 2 (the compact default) or JSON
//! (for people and curl), chosen by `Content-Type`. [`PROTOCOL_VERSION`] is bumped on any
//! incompatible change; the server answers clients of another version with a clear error.

#![forbid(unsafe_code)]

pub mod batch;
pub mod hex;
mod messages;
mod paged;

pub use messages::*;
pub use paged::*;
use serde::{Serialize, de::DeserializeOwned};

/// Version of the wire types in this crate.
pub const PROTOCOL_VERSION: u32 = 5;

/// `Content-Type` of bincode bodies.
pub const BINCODE_MIME: &str = "application/x-portico-bincode";
/// `Content-Type` of JSON bodies.
pub const JSON_MIME: &str = "application/json";

/// Largest message we agree to decode (16 MiB): bounds memory on hostile input.
pub const MAX_MESSAGE_BYTES: usize = 16 << 20;
/// Largest manifest a client agrees to decode (1 GiB: a `mega` header is tens of MB).
pub const MAX_MANIFEST_BYTES: usize = 1 << 30;

/// Failure to encode or decode a message.
#[derive(Debug, thiserror::Error)]
pub enum CodecError {
    /// bincode refused the bytes.
    #[error("bincode: {0}")]
    Bincode(String),
    /// JSON refused the bytes.
    #[error("json: {0}")]
    Json(#[from] serde_json::Error),
    /// The body is larger than [`MAX_MESSAGE_BYTES`].
    #[error("message of {0} bytes exceeds the {MAX_MESSAGE_BYTES}-byte limit")]
    TooLarge(usize),
    /// The body has bytes after the message.
    #[error("{0} trailing bytes after the message")]
    Trailing(usize),
}

fn config() -> impl bincode::config::Config {
    bincode::config::standard().with_limit::<MAX_MESSAGE_BYTES>()
}

/// Encodes a message as bincode 2.
pub fn to_bincode<T: Serialize>(msg: &T) -> Result<Vec<u8>, CodecError> {
    bincode::serde::encode_to_vec(msg, config()).map_err(|e| CodecError::Bincode(e.to_string()))
}

/// Decodes a bincode 2 message, rejecting oversized bodies and trailing bytes.
pub fn from_bincode<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, CodecError> {
    if bytes.len() > MAX_MESSAGE_BYTES {
        return Err(CodecError::TooLarge(bytes.len()));
    }
    let (msg, used) = bincode::serde::decode_from_slice(bytes, config())
        .map_err(|e| CodecError::Bincode(e.to_string()))?;
    if used != bytes.len() {
        return Err(CodecError::Trailing(bytes.len() - used));
    }
    Ok(msg)
}

/// Decodes a bincode 2 manifest (or any large trusted-size message) with the
/// [`MAX_MANIFEST_BYTES`] limit instead of [`MAX_MESSAGE_BYTES`].
pub fn manifest_from_bincode<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, CodecError> {
    let cfg = bincode::config::standard().with_limit::<MAX_MANIFEST_BYTES>();
    let (msg, used) = bincode::serde::decode_from_slice(bytes, cfg)
        .map_err(|e| CodecError::Bincode(e.to_string()))?;
    if used != bytes.len() {
        return Err(CodecError::Trailing(bytes.len() - used));
    }
    Ok(msg)
}

/// Decodes a JSON message with the same size limit.
pub fn from_json<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, CodecError> {
    if bytes.len() > MAX_MESSAGE_BYTES {
        return Err(CodecError::TooLarge(bytes.len()));
    }
    Ok(serde_json::from_slice(bytes)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, PartialEq, serde::Serialize, serde::Deserialize)]
    struct Probe {
        id: u32,
        name: String,
        values: Vec<f32>,
    }

    fn probe() -> Probe {
        Probe {
            id: 7,
            name: "cell".into(),
            values: vec![1.5, -2.0],
        }
    }

    #[test]
    fn bincode_round_trip_and_trailing_bytes() {
        let mut bytes = to_bincode(&probe()).unwrap();
        assert_eq!(from_bincode::<Probe>(&bytes).unwrap(), probe());
        bytes.push(0);
        assert!(matches!(
            from_bincode::<Probe>(&bytes),
            Err(CodecError::Trailing(1))
        ));
    }

    #[test]
    fn held_sets_round_trip_and_reject_overflow() {
        let ids = [40u32, 3, 3, 7, u32::MAX];
        let enc = encode_held(ids);
        assert_eq!(decode_held(&enc).unwrap(), vec![3, 7, 40, u32::MAX]);
        assert_eq!(decode_held(&[u32::MAX, 1]), None);
        assert_eq!(decode_held(&[1, 0]), None);
    }

    #[test]
    fn prefetch_request_round_trips_in_both_encodings() {
        let req = PrefetchRequest {
            version: PROTOCOL_VERSION,
            observer: Observer {
                eye: [1.0, 1.6, 2.0],
                dir: [0.0, 0.0, -1.0],
                up: [0.0, 1.0, 0.0],
                velocity: [0.5, 0.0, 0.0],
                half_fov_x: 0.6,
                half_fov_y: 0.45,
                max_speed: 2.0,
                max_turn: 1.5,
                turn: [0.0; 3],
            },
            policy: Policy::default(),
            held: encode_held([5, 9]),
        };
        let b = to_bincode(&req).unwrap();
        assert_eq!(from_bincode::<PrefetchRequest>(&b).unwrap(), req);
        let j = serde_json::to_vec(&req).unwrap();
        assert_eq!(from_json::<PrefetchRequest>(&j).unwrap(), req);
        assert!(String::from_utf8(j).unwrap().contains("\"direction\""));
    }

    #[test]
    fn segment_frames_round_trip() {
        let f = segment_frame(77, b"abc");
        assert_eq!(
            parse_server_frame(&f).unwrap(),
            ServerFrame::Segment(77, b"abc")
        );
        let mut c = vec![FRAME_CONTROL];
        c.extend(to_bincode(&StreamServer::Dropped(vec![1, 2])).unwrap());
        assert_eq!(
            parse_server_frame(&c).unwrap(),
            ServerFrame::Control(StreamServer::Dropped(vec![1, 2]))
        );
        assert!(parse_server_frame(&[1, 0]).is_err());
        assert!(parse_server_frame(&[]).is_err());
        assert!(parse_server_frame(&[9]).is_err());
    }

    #[test]
    fn garbage_is_an_error_not_a_panic() {
        for bytes in [
            &b""[..],
            b"\xff\xff\xff\xff\xff\xff\xff\xff\xff",
            b"{\"id\":1}",
        ] {
            assert!(from_bincode::<Probe>(bytes).is_err());
        }
        assert!(from_json::<Probe>(b"{\"id\":1}").is_err());
        assert_eq!(
            from_json::<Probe>(br#"{"id":7,"name":"cell","values":[1.5,-2.0]}"#).unwrap(),
            probe()
        );
    }
}
