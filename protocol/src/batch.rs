//! The body of a batched segment read (`GET /v1/db/{id}/batch?ids=…`): for each segment asked
//! for, in order, its id (`u32` LE), its length (`u64` LE) and its bytes. A segment the server
//! could not read (damaged on disk) has the length [`MISSING`] and no bytes: it fails alone and
//! the client asks for it again later; the rest of the batch arrives.

use std::ops::Range;

/// The length written for a segment the server could not read.
pub const MISSING: u64 = u64::MAX;

/// Bytes of one entry's head (id + length).
pub const HEAD_BYTES: usize = 12;

/// The head of one entry: `len` = [`MISSING`] for a segment that could not be read.
pub fn entry_head(id: u32, len: u64) -> [u8; HEAD_BYTES] {
    let mut h = [0u8; HEAD_BYTES];
    h[..4].copy_from_slice(&id.to_le_bytes());
    h[4..].copy_from_slice(&len.to_le_bytes());
    h
}

/// One parsed entry: the segment id and where its bytes are in the body (`None`: missing).
pub type Entry = (u32, Option<Range<usize>>);

/// Splits a batch body into its entries; an error says where it is truncated.
pub fn parse(body: &[u8]) -> Result<Vec<Entry>, String> {
    let mut out = Vec::new();
    let mut at = 0usize;
    while at < body.len() {
        let head = body
            .get(at..at + HEAD_BYTES)
            .ok_or("batch body truncated in a segment header")?;
        let id = u32::from_le_bytes([head[0], head[1], head[2], head[3]]);
        let len = u64::from_le_bytes(std::array::from_fn(|i| head[4 + i]));
        let start = at + HEAD_BYTES;
        if len == MISSING {
            out.push((id, None));
            at = start;
            continue;
        }
        let end = usize::try_from(len)
            .ok()
            .and_then(|l| start.checked_add(l))
            .filter(|&e| e <= body.len())
            .ok_or_else(|| format!("batch body truncated in segment {id}"))?;
        out.push((id, Some(start..end)));
        at = end;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn entries_split_missing_ones_have_no_bytes_and_truncation_is_an_error() {
        let mut b = Vec::new();
        b.extend(entry_head(7, 3));
        b.extend(b"abc");
        b.extend(entry_head(2, MISSING));
        b.extend(entry_head(9, 2));
        b.extend(b"xy");
        let parts = parse(&b).unwrap();
        assert_eq!(parts, vec![(7, Some(12..15)), (2, None), (9, Some(39..41))]);
        assert_eq!(&b[parts[2].1.clone().unwrap()], b"xy");
        assert!(parse(&b[..b.len() - 1]).is_err());
        assert!(parse(&b[..5]).is_err());
        assert!(parse(&[]).unwrap().is_empty());
    }
}
