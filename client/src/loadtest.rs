//! `portico loadtest` (issue 7): simulated clients against a real server. Being written.
