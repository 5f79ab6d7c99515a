//! The deadline test of deadline-ordered prefetch: whether an item of a need list must travel
//! now, or can be left to a later list.
//!
//! Every item of a need list says when it can first be needed (`frames` until visible, counted
//! from the observer the list was made for). A later list, made for a newer observer, takes
//! effect some `lead` after that observer (the list's age, the wait for the next one, the
//! round trips, a margin), and whatever it sends queues behind what is on the wire already. An
//! item is sent now when leaving it to that later list would make it late:
//!
//! `lead + (queued + bytes) / rate ≥ frames · Δt`
//!
//! Items needed now (`frames` 0) always go. The pull client's read plan
//! (`portico_client::deadline`) and the server's push sessions (`/v1/stream`) both apply it;
//! they differ only in what makes up the lead.

/// Frames of slack in the deadline test.
pub const MARGIN_FRAMES: f64 = 2.0;
/// How many frames ahead items go before the link's rate and round trip are known.
pub const UNMEASURED_FRAMES: u32 = 4;

/// Whether an item needed `frames` frames of `frame_s` seconds after its list's observer,
/// `bytes` long, with `queued` bytes ahead of it on a link of `rate` bytes per second, would be
/// late if left to a list that takes effect `lead_s` seconds after that observer (see the
/// module). `rate` ≤ 0 or NaN counts as an idle, unlimited link.
pub fn cannot_wait(
    frames: u32,
    frame_s: f64,
    lead_s: f64,
    queued: f64,
    bytes: f64,
    rate: f64,
) -> bool {
    let wire = if rate > 0.0 {
        (queued + bytes) / rate
    } else {
        0.0
    };
    frames == 0 || lead_s + wire >= f64::from(frames) * frame_s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_item_goes_once_waiting_would_make_it_late() {
        // 50 ms frames, a lead of 200 ms, 1 MB/s: 10 kB (10 ms) items go up to 4 frames ahead.
        assert!(cannot_wait(4, 0.05, 0.2, 0.0, 1e4, 1e6));
        assert!(!cannot_wait(5, 0.05, 0.2, 0.0, 1e4, 1e6));
        // 100 kB queued ahead of it bring the fifth frame's item forward.
        assert!(cannot_wait(5, 0.05, 0.2, 1e5, 1e4, 1e6));
        // Needed now: always, whatever the link.
        assert!(cannot_wait(0, 0.05, 0.0, 0.0, 1e9, 1.0));
        // No rate: only the lead counts.
        assert!(!cannot_wait(5, 0.05, 0.2, 1e9, 1e9, 0.0));
    }
}
