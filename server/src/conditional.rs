//! HTTP's conditional requests and ranges (RFC 9110 §13, §14), shared by the segment routes
//! and the viewer's files: `If-None-Match` with the weak comparison, `If-Range`, and single
//! byte ranges.

use axum::http::{HeaderMap, header};

/// `If-None-Match` with the weak comparison RFC 9110 §13.1.2 prescribes for it: `W/"x"` matches
/// `"x"`.
pub fn not_modified(headers: &HeaderMap, etag: &str) -> bool {
    let strip = |t: &str| t.trim().trim_start_matches("W/").to_string();
    let etag = strip(etag);
    headers
        .get(header::IF_NONE_MATCH)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| v.split(',').any(|t| strip(t) == etag || t.trim() == "*"))
}

/// Whether a `Range` may be served under the request's `If-Range` (RFC 9110 §13.1.5): no
/// `If-Range`; an entity tag that is strong and equals `etag`; or a date that equals
/// `last_modified` exactly. Anything else asks for the whole representation (200).
pub fn if_range_holds(
    headers: &HeaderMap,
    etag: &str,
    last_modified: Option<std::time::SystemTime>,
) -> bool {
    let Some(v) = headers.get(header::IF_RANGE) else {
        return true;
    };
    let Ok(v) = v.to_str() else { return false };
    let v = v.trim();
    if v.starts_with('"') {
        return v == etag;
    }
    if v.starts_with("W/") {
        return false;
    }
    match (httpdate::parse_http_date(v), last_modified) {
        (Ok(date), Some(modified)) => httpdate::HttpDate::from(date) == modified.into(),
        _ => false,
    }
}

/// A `Range` header that cannot be served (answered with 416).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Unsatisfiable;

/// A single byte range `bytes=a-b`, `bytes=a-` or `bytes=-n` resolved against `len`.
/// `Ok(None)` = serve everything (no header, or several ranges, which we may ignore);
/// `Err` = unsatisfiable (416).
pub fn parse_range(value: &str, len: u64) -> Result<Option<(u64, u64)>, Unsatisfiable> {
    let Some(spec) = value.trim().strip_prefix("bytes=") else {
        return Ok(None);
    };
    if spec.contains(',') {
        return Ok(None);
    }
    let (a, b) = spec.split_once('-').ok_or(Unsatisfiable)?;
    let (a, b) = (a.trim(), b.trim());
    let range = match (a.is_empty(), b.is_empty()) {
        (true, false) => {
            let n: u64 = b.parse().map_err(|_| Unsatisfiable)?;
            if n == 0 {
                return Err(Unsatisfiable);
            }
            (len.saturating_sub(n), len.saturating_sub(1))
        }
        (false, _) => {
            let start: u64 = a.parse().map_err(|_| Unsatisfiable)?;
            let end = if b.is_empty() {
                len.saturating_sub(1)
            } else {
                b.parse().map_err(|_| Unsatisfiable)?
            };
            (start, end.min(len.saturating_sub(1)))
        }
        (true, true) => return Err(Unsatisfiable),
    };
    if range.0 >= len || range.0 > range.1 {
        return Err(Unsatisfiable);
    }
    Ok(Some(range))
}

#[cfg(test)]
mod tests {
    use super::{Unsatisfiable, not_modified, parse_range};
    use axum::http::{HeaderMap, HeaderValue, header};

    /// `If-None-Match` (RFC 9110 §13.1.2): weak comparison, a list of tags, `*`; anything
    /// else — another tag, no header — is not a match.
    #[test]
    fn if_none_match_compares_weakly_over_lists() {
        let with = |v: &str| {
            let mut h = HeaderMap::new();
            h.insert(header::IF_NONE_MATCH, HeaderValue::from_str(v).unwrap());
            h
        };
        let tag = "\"abc-json\"";
        for v in [
            "\"abc-json\"",
            "W/\"abc-json\"",
            "\"x\", \"abc-json\"",
            "W/\"x\",W/\"abc-json\"",
            "*",
        ] {
            assert!(not_modified(&with(v), tag), "{v} should match");
            assert!(
                not_modified(&with(v), "W/\"abc-json\""),
                "{v} vs a weak tag"
            );
        }
        for v in ["\"abc-bincode\"", "\"abc\"", "\"x\", \"y\"", ""] {
            assert!(!not_modified(&with(v), tag), "{v} should not match");
        }
        assert!(!not_modified(&HeaderMap::new(), tag));
    }

    #[test]
    fn byte_ranges() {
        assert_eq!(parse_range("bytes=0-9", 100), Ok(Some((0, 9))));
        assert_eq!(parse_range("bytes=90-", 100), Ok(Some((90, 99))));
        assert_eq!(parse_range("bytes=-10", 100), Ok(Some((90, 99))));
        assert_eq!(parse_range("bytes=50-500", 100), Ok(Some((50, 99))));
        assert_eq!(parse_range("bytes=0-1,5-6", 100), Ok(None));
        assert_eq!(parse_range("items=1-2", 100), Ok(None));
        assert_eq!(parse_range("bytes=100-", 100), Err(Unsatisfiable));
        assert_eq!(parse_range("bytes=9-3", 100), Err(Unsatisfiable));
        assert_eq!(parse_range("bytes=-0", 100), Err(Unsatisfiable));
        assert_eq!(parse_range("bytes=x-3", 100), Err(Unsatisfiable));
        assert_eq!(parse_range("bytes=-", 100), Err(Unsatisfiable));
    }
}
