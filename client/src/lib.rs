//! The Portico client (DESIGN §5): wgpu renderer, LRU cache, detail elision, prefetch.

pub mod bench;
pub mod cache;
pub mod cluster;
pub mod cost;
pub mod elision;
pub mod frame;
pub mod impostor;
pub mod io;
pub mod loadtest;
pub mod navigate;
pub mod net;
pub mod policy;
pub mod render;
pub mod schedule;
pub mod sheet;
pub mod stats;
pub mod view;
pub mod walk;
#[cfg(feature = "window")]
pub mod window;
