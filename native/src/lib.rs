//! The native Portico client around the platform-free core (`portico_client`): the HTTP side of
//! the protocol ([`net`]), the IO thread that reads, checks, decodes and uploads segments
//! ([`io`], learning the model page by page when it started from the core manifest ([`pages`]), over server push ([`stream`]) or driving the core's read schedule with [`drive`]),
//! the headless walk ([`walk`]) and
//! the interactive window (`window`, feature `window`).

#![forbid(unsafe_code)]

pub mod drive;
pub mod io;
pub mod net;
pub mod pages;
pub mod stream;
pub mod walk;
#[cfg(feature = "window")]
pub mod window;
