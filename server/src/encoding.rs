//! Content coding for the large documents every client fetches before its first frame (the
//! manifest and the cell graph): each is gzip-compressed once (bincode when the file is
//! opened, JSON on first use), as nginx's `gzip_static` serves a `.gz` beside a file, and sent
//! so to clients whose `Accept-Encoding` allows it (RFC 9110 §12.5.3). Compressing per request
//! would hand every client seconds of server CPU on a large model.

use axum::http::{HeaderMap, header};
use bytes::Bytes;
use std::io::Write;

/// A document and its gzip coding, made once.
#[derive(Debug, Clone)]
pub struct Precompressed {
    /// The bytes as they are.
    pub identity: Bytes,
    /// The same bytes gzip-compressed (RFC 1952).
    pub gzip: Bytes,
}

impl Precompressed {
    /// Compresses `identity` (flate2, default level: the manifest of flattened `mega`, 39 MB,
    /// in about a second, once).
    pub fn new(identity: Bytes) -> Precompressed {
        let mut z = flate2::write::GzEncoder::new(
            Vec::with_capacity(identity.len() / 4),
            flate2::Compression::default(),
        );
        // Writing into a Vec cannot fail.
        let gzip = z
            .write_all(&identity)
            .and_then(|()| z.finish())
            .map(Bytes::from)
            .unwrap_or_default();
        Precompressed { identity, gzip }
    }

    /// The coding to send for these request headers: `(bytes, Some("gzip"))` when the client
    /// accepts gzip and it is smaller, else `(identity, None)`.
    pub fn pick(&self, headers: &HeaderMap) -> (Bytes, Option<&'static str>) {
        if !self.gzip.is_empty() && self.gzip.len() < self.identity.len() && accepts_gzip(headers) {
            (self.gzip.clone(), Some("gzip"))
        } else {
            (self.identity.clone(), None)
        }
    }
}

/// Whether `Accept-Encoding` allows gzip: `gzip` (or `x-gzip`, or `*`) listed without `q=0`.
/// Without the header only the identity coding is assumed (RFC 9110 allows any, but a client
/// that sends nothing may not decode).
pub fn accepts_gzip(headers: &HeaderMap) -> bool {
    let mut gzip: Option<bool> = None;
    let mut any = None;
    // Every Accept-Encoding line, each a comma-separated list (RFC 9110 §5.3).
    let lines = headers
        .get_all(header::ACCEPT_ENCODING)
        .iter()
        .filter_map(|v| v.to_str().ok());
    for item in lines.flat_map(|v| v.split(',')) {
        let mut parts = item.split(';');
        let coding = parts.next().unwrap_or("").trim().to_ascii_lowercase();
        let q = parts
            .filter_map(|p| {
                let (k, v) = p.split_once('=')?;
                k.trim().eq_ignore_ascii_case("q").then_some(v)
            })
            .find_map(|q| q.trim().parse::<f32>().ok())
            .unwrap_or(1.0);
        match coding.as_str() {
            // `x-gzip` is gzip: either listed with a weight above zero allows it.
            "gzip" | "x-gzip" => gzip = Some(gzip.unwrap_or(false) || q > 0.0),
            "*" => any = Some(q > 0.0),
            _ => {}
        }
    }
    gzip.or(any).unwrap_or(false)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn with(v: &str) -> HeaderMap {
        let mut h = HeaderMap::new();
        h.insert(header::ACCEPT_ENCODING, v.parse().unwrap());
        h
    }

    #[test]
    fn gzip_is_sent_only_where_accept_encoding_allows_it() {
        assert!(accepts_gzip(&with("gzip")));
        assert!(accepts_gzip(&with("br, gzip;q=0.5, deflate")));
        assert!(accepts_gzip(&with("GZIP")));
        assert!(accepts_gzip(&with("*")));
        assert!(!accepts_gzip(&with("gzip;q=0")));
        assert!(!accepts_gzip(&with("gzip; q=0.0, *")));
        assert!(!accepts_gzip(&with("*;q=0")));
        assert!(!accepts_gzip(&with("br, deflate")));
        assert!(!accepts_gzip(&with("identity")));
        assert!(!accepts_gzip(&HeaderMap::new()));
        // The weight's name is case-insensitive.
        assert!(!accepts_gzip(&with("gzip;Q=0")));
        assert!(accepts_gzip(&with("x-gzip;q=0, gzip")));
        // Several header lines are one list.
        let mut h = with("br");
        h.append(header::ACCEPT_ENCODING, "gzip".parse().unwrap());
        assert!(accepts_gzip(&h));
    }

    #[test]
    fn the_gzip_coding_decodes_to_the_same_bytes() {
        use std::io::Read;
        let doc = Bytes::from(b"cell ".repeat(1000));
        let p = Precompressed::new(doc.clone());
        assert!(p.gzip.len() < doc.len() / 10, "{} bytes", p.gzip.len());
        let mut back = Vec::new();
        flate2::read::GzDecoder::new(&p.gzip[..])
            .read_to_end(&mut back)
            .unwrap();
        assert_eq!(back, doc);
        let (sent, coding) = p.pick(&with("gzip"));
        assert_eq!((sent, coding), (p.gzip.clone(), Some("gzip")));
        assert_eq!(p.pick(&HeaderMap::new()), (doc.clone(), None));
        // A document gzip cannot shrink goes out as it is.
        let tiny = Precompressed::new(Bytes::from_static(b"x"));
        assert_eq!(tiny.pick(&with("gzip")).1, None);
    }
}
