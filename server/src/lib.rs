//! The Portico server (DESIGN §4): axum + tokio over a memory-mapped `portico_data::Database`.
//!
//! Not written yet — issue 5. The crate exists so the workspace has its final shape.
