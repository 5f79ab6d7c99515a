//! `GET /v1/db/{database_id}/pages/{cell}`: one cell's page, made on a compute slot and kept in
//! the page cache ([`crate::pages`]).

use super::Shared;
use crate::conditional::not_modified;
use crate::encoding::accepts_gzip;
use crate::error::Error;
use crate::respond::{IMMUTABLE, current, document, revalidated, wants_bincode};
use axum::extract::{Path, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};

/// `GET /v1/db/{database_id}/pages/{cell}`: the cell's [`portico_protocol::Page`] (bincode,
/// gzip-coded where accepted). The URL names the database, so the answer is immutable.
pub async fn page(
    State(s): Shared,
    Path((db, raw)): Path<(String, String)>,
    headers: HeaderMap,
) -> Result<Response, Error> {
    current(&s, &db)?;
    let cell: u32 = raw
        .parse()
        .map_err(|_| Error::bad_request(format!("cell {raw:?} is not a number")))?;
    if !wants_bincode(&headers) {
        return Err(Error::new(
            axum::http::StatusCode::NOT_ACCEPTABLE,
            "not_acceptable",
            format!(
                "pages are bincode only (Accept: {})",
                portico_protocol::BINCODE_MIME
            ),
        ));
    }
    if s.prefetcher.stab_segment(cell).is_none() {
        return Err(Error::not_found(format!(
            "cell {cell} has no page: it is not a live cell of this database"
        )));
    }
    // The URL names the database: a client that holds the coding its Accept-Encoding picks
    // (a page's gzip is always the smaller) has the page, which is not made to say so.
    let name = format!("p-{cell}");
    let held = format!(
        "\"{name}-b{}\"",
        if accepts_gzip(&headers) { "-gzip" } else { "" }
    );
    if not_modified(&headers, &held) {
        let mut r = revalidated(StatusCode::NOT_MODIFIED.into_response(), &held);
        r.headers_mut()
            .insert(header::CACHE_CONTROL, HeaderValue::from_static(IMMUTABLE));
        return Ok(r);
    }
    let state = s.clone();
    let p = s
        .compute
        .run(move |_| {
            let p = state.page(cell)?;
            p.coded();
            Ok(p)
        })
        .await?;
    let mut r = document(&headers, true, p.coded(), &name);
    r.headers_mut()
        .insert(header::CACHE_CONTROL, HeaderValue::from_static(IMMUTABLE));
    Ok(r)
}
