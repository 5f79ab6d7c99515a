//! The platform-free core of the Portico client: everything a walkthrough client decides, with
//! no IO, no threads and no GPU, so the native walker, the measuring lab and a browser client
//! share it (it compiles for `wasm32-unknown-unknown`).
//!
//! - [`frame`]: the one frame decision — visibility, candidates, detail elision or the
//!   cluster traversal over resident LODs, and what the cache must hear.
//! - [`view`]: the viewpoint of a frame, visibility through the cells (Funkhouser §4.1.2) and
//!   the candidates' screen sizes.
//! - [`elision`]: detail elision (Funkhouser §4.2: static, feedback, cost/benefit optimisation).
//! - [`cluster`]: Maciel's best-first traversal of the model hierarchy (§6.4).
//! - [`cost`]: the cost model (§4.2.3) and its online correction.
//! - [`cache`]: the LRU object cache under a hard byte budget (§5.2.3).
//! - [`demand`]: what a frame lacked, most urgent first (§5.2.4): demand fetch's need list and
//!   the head of every other.
//! - [`schedule`]: the read schedule of the IO stage (§5.2.3, Ch. 6); [`pacing`]: what it
//!   keeps in flight on the measured link; [`deadline`]: which of the server's items to read
//!   now and which a later answer can still bring in time.
//! - [`engine`]: the IO stage without IO — state machines every front end drives (pull, …).
//! - [`navigate`]: Funkhouser's mouse-and-keyboard navigation (§3.3.1); [`walk`]: walk mode
//!   (walls, floors, stairs and holes from the cells and portals); [`pick`]: the object under
//!   a pixel.
//! - [`defaults`]: the view, pace and IO defaults every front end shares.
//! - [`policy`], [`stats`]: prefetch policy specs, per-frame statistics.

#![forbid(unsafe_code)]

pub mod cache;
pub mod cluster;
pub mod cost;
pub mod deadline;
pub mod defaults;
pub mod demand;
pub mod elision;
pub mod engine;
pub mod frame;
pub mod navigate;
pub mod pacing;
pub mod parts;
pub mod pick;
pub mod policy;
pub mod schedule;
pub mod stats;
pub mod view;
pub mod walk;
