//! The Portico display database: the `.portico` file format (writer and validating
//! memory-mapped reader), the in-memory model, OBJ and glTF importers, automatic LODs, and the
//! build pipeline. Pure and synchronous: no async runtime, no network.
//!
//! The feature `native` (on by default) holds everything that builds or reads files; without it
//! the crate is the model types and the pure algorithms a client needs (cells, real-time
//! visibility, geometry, the hierarchy, paths) and compiles for `wasm32-unknown-unknown`.
//!
//! The flow of `portico build` is [`import::import_file`] → [`build::build`] (which calls
//! [`lod::complete_lods`] and, for `--flatten`, [`bake::bake`]) → [`format::writer::DbWriter`];
//! servers and tools open the result with [`Database::open`].

// Unsafe code only where each use is allowed by name, with its SAFETY note (memory maps,
// C decoders and libc calls).
#![deny(unsafe_code)]

#[cfg(feature = "native")]
pub mod bake;
#[cfg(feature = "native")]
pub mod build;
pub mod bulk;
pub mod cells;
pub mod codec;
pub mod deadline;
pub mod error;
#[cfg(feature = "native")]
pub mod export;
pub mod format;
pub mod frame;
pub mod geometry;
pub mod hierarchy;
#[cfg(feature = "native")]
pub mod import;
#[cfg(feature = "native")]
pub mod lod;
pub mod model;
pub mod path;
pub mod person;
#[cfg(feature = "native")]
pub mod prefetch;
#[cfg(feature = "native")]
pub mod stats;
pub mod texture;
#[cfg(feature = "native")]
pub mod tileset;

pub use error::{DataError, Result};
#[cfg(feature = "native")]
pub use format::reader::Database;
