//! The Portico client (DESIGN §5): wgpu renderer, LRU cache, detail elision, prefetch.
//!
//! Not written yet — issue 6. The crate exists so the workspace has its final shape.
