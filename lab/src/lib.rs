//! Portico's measuring lab, kept apart from the client it measures (as ripgrep keeps its
//! benchmark harness apart): the detail-elision benchmark ([`bench`](mod@bench): Regular against each
//! elision algorithm on the same frames, frame times, Es/Et and PSNR after the RRB thesis) and the
//! prefetch load tester ([`loadtest`]: simulated clients through emulated links, with demand-fetch
//! and oracle baselines, after Funkhouser Ch. 5), joined by [`drawn`] (the frames a load test's
//! client drew, scored by the benchmark against the full-detail frames); each judged against its targets in words
//! ([`verdict`]), with the plots' shared style ([`style`]) and captioned pictures ([`picture`]).

#![forbid(unsafe_code)]

pub mod bench;
pub mod drawn;
pub mod loadtest;
pub mod picture;
pub mod style;
pub mod verdict;
