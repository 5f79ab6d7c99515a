//! The Portico browser viewer: open a URL, walk the building.
//!
//! The same client core as the native walker ([`portico_client`]: the LRU cache under a byte
//! budget, visibility through the cells, detail elision over resident LODs, the read schedule)
//! and the same renderer (`portico_render`, wgpu on WebGPU where the browser has an adapter,
//! else WebGL2), compiled to wasm32 and fetching from a Portico server: segments pushed in need
//! order over the `/v1/stream` WebSocket, or pulled over HTTP (prefetch answers, Funkhouser
//! §5.2, and segment batches) when the stream is unavailable. `portico serve` serves the page
//! at `/`; `web/build.sh` builds it.
//!
//! Query parameters of the page: `server` (another origin's server, which must then allow the
//! page's origin by CORS — Portico's own server does not; default the page's own), `token`
//! (the server's `--token`),
//! `cache_mb` (the byte budget, default 64), `budget_ms` (the frame budget, default 50),
//! `backend` (`webgl`, `webgpu` or `auto`, the default), `transport` (`stream`, the default, or
//! `pull`), `manifest` (`paged`, the default: the core manifest, then each cell's page with its
//! stab list; or `whole`), `elision` (`optimize`, the default, or `impostors`: Maciel's cluster
//! traversal, far clusters drawn as their textured boxes). The fragment holds the viewpoint
//! (`#eye=x,y,z&dir=x,y,z`), kept up to date so the address shares what one sees.
//!
//! Natively only [`input`] is compiled (and tested); everything else is for `wasm32`.

#![forbid(unsafe_code)]

pub mod input;
#[cfg(target_arch = "wasm32")]
mod io;
#[cfg(target_arch = "wasm32")]
mod minimap;
#[cfg(target_arch = "wasm32")]
mod net;
#[cfg(target_arch = "wasm32")]
mod page;
#[cfg(target_arch = "wasm32")]
mod paged;
#[cfg(target_arch = "wasm32")]
mod stream;
#[cfg(target_arch = "wasm32")]
mod viewer;

#[cfg(target_arch = "wasm32")]
pub use page::{Handle, start};
