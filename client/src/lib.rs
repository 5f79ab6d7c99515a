//! The Portico client (DESIGN §5): wgpu renderer, LRU cache, detail elision, prefetch.

pub mod cost;
pub mod elision;
pub mod render;
