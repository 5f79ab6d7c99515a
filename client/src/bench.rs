//! `portico bench` (issue 7): frame rate and image fidelity of the elision algorithms. Being written.
