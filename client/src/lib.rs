//! The Portico client (DESIGN §5): wgpu renderer, LRU cache, detail elision, prefetch.

pub mod cache;
pub mod cost;
pub mod elision;
pub mod io;
pub mod net;
pub mod policy;
pub mod render;
pub mod stats;
pub mod view;
pub mod walk;
pub mod bench;
pub mod loadtest;
