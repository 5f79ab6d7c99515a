//! 64-bit checksums as JSON strings. JavaScript reads every JSON number as a double, so an xxh3
//! above 2^53 would arrive changed; JSON (and any human-readable format) carries it as 16 hex
//! digits, the form the server's ETags use, while bincode keeps the compact `u64`.
//!
//! Use with `#[serde(with = "crate::hex")]` on a `u64` field. Reading JSON also accepts a plain
//! number, for clients written before the change.

use serde::de::{self, Visitor};
use serde::{Deserializer, Serializer};
use std::fmt;

/// Writes `v` as `"00ff…"` (16 lower-case hex digits) in human-readable formats, else as `u64`.
pub fn serialize<S: Serializer>(v: &u64, s: S) -> Result<S::Ok, S::Error> {
    if s.is_human_readable() {
        s.serialize_str(&format!("{v:016x}"))
    } else {
        s.serialize_u64(*v)
    }
}

/// Reads what [`serialize`] writes; human-readable formats may also give a number.
pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<u64, D::Error> {
    struct Hex;
    impl Visitor<'_> for Hex {
        type Value = u64;
        fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
            f.write_str("a 64-bit checksum as up to 16 hex digits")
        }
        fn visit_u64<E: de::Error>(self, v: u64) -> Result<u64, E> {
            Ok(v)
        }
        fn visit_str<E: de::Error>(self, v: &str) -> Result<u64, E> {
            if v.is_empty() || v.len() > 16 {
                return Err(E::invalid_length(v.len(), &self));
            }
            u64::from_str_radix(v, 16).map_err(|_| E::invalid_value(de::Unexpected::Str(v), &self))
        }
    }
    if d.is_human_readable() {
        d.deserialize_any(Hex)
    } else {
        d.deserialize_u64(Hex)
    }
}

#[cfg(test)]
mod tests {
    use serde::{Deserialize, Serialize};

    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    struct Row {
        #[serde(with = "crate::hex")]
        checksum: u64,
    }

    #[test]
    fn json_carries_checksums_above_2_pow_53_as_hex_strings() {
        let row = Row {
            checksum: 0xfedc_ba98_7654_3210,
        };
        let json = serde_json::to_string(&row).unwrap();
        assert_eq!(json, r#"{"checksum":"fedcba9876543210"}"#);
        assert_eq!(serde_json::from_str::<Row>(&json).unwrap(), row);
        // A double cannot hold it: the reason for the string.
        assert_ne!(row.checksum as f64 as u64, row.checksum);
    }

    #[test]
    fn json_numbers_are_still_read_and_bad_strings_refused() {
        let row: Row = serde_json::from_str(r#"{"checksum":42}"#).unwrap();
        assert_eq!(row.checksum, 42);
        assert!(serde_json::from_str::<Row>(r#"{"checksum":"xyz"}"#).is_err());
        assert!(serde_json::from_str::<Row>(r#"{"checksum":"00000000000000000"}"#).is_err());
    }

    #[test]
    fn bincode_keeps_the_compact_integer() {
        let row = Row { checksum: u64::MAX };
        let bytes = crate::to_bincode(&row).unwrap();
        assert_eq!(bytes.len(), 9, "varint u64::MAX: 1 tag + 8 bytes");
        assert_eq!(crate::from_bincode::<Row>(&bytes).unwrap(), row);
    }
}
