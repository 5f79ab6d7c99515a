//! Portico's measuring lab, kept apart from the client it measures (as ripgrep keeps its
//! benchmark harness apart): the detail-elision benchmark ([`bench`](mod@bench): Regular against each
//! elision algorithm on the same frames, frame times, Es/Et and PSNR after the RRB thesis) and the
//! prefetch load tester ([`loadtest`]: simulated clients through emulated links, with demand-fetch
//! and oracle baselines, after Funkhouser Ch. 5).

pub mod bench;
pub mod loadtest;
pub mod style;
