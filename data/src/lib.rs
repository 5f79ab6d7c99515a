//! The Portico display database (DESIGN §2): the `.portico` file format (writer and validating
//! memory-mapped reader), the in-memory model, OBJ and glTF importers, automatic LODs, and the
//! build pipeline. Pure and synchronous: no async runtime, no network.
//!
//! The flow of `portico build` is [`import::import_file`] → [`build::build`] (which calls
//! [`lod::complete_lods`] and, for `--flatten`, [`bake::bake`]) → [`format::writer::DbWriter`];
//! servers and tools open the result with [`Database::open`].

pub mod bake;
pub mod build;
pub mod bulk;
pub mod cells;
pub mod error;
pub mod format;
pub mod geometry;
pub mod hierarchy;
pub mod import;
pub mod lod;
pub mod model;
pub mod path;
pub mod prefetch;
pub mod stats;

pub use error::{DataError, Result};
pub use format::reader::Database;
