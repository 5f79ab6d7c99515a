//! Need lists and pushes of a stream session: an observer's need list (shared by place)
//! computed on a compute slot with the
//! stab lists' pages a paged client needs, and the pushes in need order, each when it cannot
//! wait for the next list (Funkhouser §5.2.3 with deadlines), paced to the session's rate.

use super::{Computing, PACING_BURST, Pending, Session, control, secs};
use crate::AppState;
use crate::error::Error;
use crate::inflight::Turn;
use axum::extract::ws::Message;
use axum::http::StatusCode;
use portico_data::deadline::{MARGIN_FRAMES, cannot_wait};
use portico_data::prefetch::NeedList;
use portico_data::prefetch::shared::{ShareKey, SharePlace};
use portico_protocol::{LookaheadCull, NeedKind, Observer, StreamServer, segment_frame};
use std::sync::Arc;
use std::sync::atomic::Ordering::Relaxed;
use std::time::Duration;
use tokio::time::Instant;

/// Most pages one computation makes (nearest stab lists first). A page of flattened `mega`
/// is about 31 KB of bincode at the median and 1.2 MB at most, so an update costs at most a
/// few milliseconds of page making however wide its policy.
pub const PAGES_PER_UPDATE: usize = 8;

impl Session {
    /// Starts computing the need list for `obs`: the shared list of its place, or (without
    /// cells) its own; with the time it held a compute slot.
    pub(super) fn compute(&self, obs: Observer, place: Option<SharePlace>) -> Computing {
        let state = self.state.clone();
        let policy = self.policy;
        let key = place.map(|p| ShareKey::new(p, self.policy_bytes.clone()));
        let paged = self.paged;
        Box::pin(async move {
            // One computation per place's list: a session whose place another is computing
            // waits for it without a compute slot (`crate::inflight`).
            let until = state.compute.deadline_from_now();
            let mut lead = None;
            if let Some(k) = &key {
                let cached = || state.prefetcher.shared_cached(k);
                match state.lists.turn(k, until, cached).await {
                    None => return (Err(state.compute.busy()), Duration::ZERO),
                    Some(Turn::Ready(list)) if !paged || pages_made(&state, &list) => {
                        return (Ok(list), Duration::ZERO);
                    }
                    // Cached, but its pages are made on a slot below.
                    Some(Turn::Ready(_)) => {}
                    Some(Turn::Lead(l)) => lead = Some(l),
                }
            }
            let s = state.clone();
            let done = state
                .compute
                .run_until(until, move |budget| {
                    // Let go when the computation ends (not when the session next looks).
                    let _lead = lead;
                    let on_slot = std::time::Instant::now();
                    let list = compute_on_slot(&s, key.as_ref(), &obs, &policy, paged, &budget);
                    Ok((list, on_slot.elapsed()))
                })
                .await;
            match done {
                Ok(d) => d,
                Err(e) => (Err(e), Duration::ZERO),
            }
        })
    }

    /// A new observer: nothing to do while it stays in its place; the cached list of a place
    /// another session computed; otherwise a computation (only the latest observer waits).
    /// The shared place of `obs` under the session's policy (`None`: its list is its own).
    pub(super) fn place_of(&self, obs: &Observer) -> Option<SharePlace> {
        self.state
            .sharing_now()
            .then(|| self.state.prefetcher.share_place(obs, &self.policy))
            .flatten()
    }

    pub(super) fn on_observer(&mut self, obs: Observer) -> Option<Message> {
        let arrived = Instant::now();
        let m = &self.state.metrics;
        m.stream_updates.fetch_add(1, Relaxed);
        let place = self.place_of(&obs);
        self.want = place;
        // A replaced observer's wait counts in the one that replaces it.
        let (arrived, updates) = match self.pending.take() {
            Some(p) => (p.arrived, p.updates + 1),
            None => (arrived, 1),
        };
        if place.is_some() && place == self.place {
            m.update(arrived.elapsed().as_secs_f64(), updates);
            // The list holds every observer of the place: its deadlines count from this one.
            self.observed = Instant::now();
            return None;
        }
        if let Some(p) = place {
            let key = ShareKey::new(p, self.policy_bytes.clone());
            // A paged session takes a cached list only once its stab lists' pages are made
            // (else the computation, on a compute slot, makes them).
            if let Some(list) = self.state.prefetcher.shared_cached(&key)
                && (!self.paged || pages_made(&self.state, &list))
            {
                m.update(arrived.elapsed().as_secs_f64(), updates);
                return self.take_list(list, place, arrived);
            }
        }
        self.pending = Some(Pending {
            obs,
            place,
            arrived,
            at: Instant::now(),
            updates,
            generation: self.generation,
        });
        None
    }

    /// A computation finished: its list is taken unless it is stale (another place is wanted
    /// now, or the policy changed); past its deadline the previous list stays.
    pub(super) fn on_computed(
        &mut self,
        (list, took): (Result<Arc<NeedList>, Error>, Duration),
        p: Pending,
    ) -> Option<Message> {
        self.state
            .metrics
            .update(p.arrived.elapsed().as_secs_f64(), p.updates);
        // A computation that held its compute slot half the deadline or more (a wide list,
        // pages made to the budget, or stopped past it) makes the session wait as long before
        // its next: one session takes at most about half a compute slot. Waiting for another
        // session's computation holds no slot and counts nothing.
        if took * 2 >= self.state.config.compute_deadline {
            self.compute_after = Instant::now() + took;
        }
        // A list for a place the observer has left is stale under the range lookahead (the
        // next one is a cache lookup away); with deadlines it is the freshest there is, and
        // is taken while the next place's list is computed (a turning observer changes place
        // faster than lists come).
        let moved = p.place.is_some() && p.place != self.want && !self.deadlines();
        let stale = p.generation != self.generation || moved;
        match list {
            Ok(_) if stale => None,
            Ok(l) => self.take_list(l, p.place, p.at),
            Err(e) if e.status() == StatusCode::SERVICE_UNAVAILABLE => {
                self.state.metrics.stream_overdue.fetch_add(1, Relaxed);
                None
            }
            Err(e) => Some(control(&StreamServer::Error(e.to_api()))),
        }
    }

    /// Puts a need list in place; reports queued items whose need vanished.
    fn take_list(
        &mut self,
        list: Arc<NeedList>,
        place: Option<SharePlace>,
        observed: Instant,
    ) -> Option<Message> {
        let m = &self.state.metrics;
        m.prefetch_answers.fetch_add(1, Relaxed);
        // With deadlines nothing past the push in flight is queued: nothing to report.
        let end = if self.deadlines() {
            0
        } else {
            self.list.fit.max(self.cursor).min(self.list.items.len())
        };
        let dropped: Vec<u32> = self.list.items[self.cursor.min(end)..end]
            .iter()
            .map(|i| i.segment)
            .filter(|s| !self.mirror.contains(s) && !list.segments.contains(s))
            .collect();
        self.list = list;
        self.cursor = 0;
        self.place = place;
        self.observed = observed;
        self.recheck = Instant::now();
        if dropped.is_empty() {
            return None;
        }
        m.stream_dropped.fetch_add(dropped.len() as u64, Relaxed);
        Some(control(&StreamServer::Dropped(dropped)))
    }

    /// The next segment of the list the client lacks, as a frame (or an error for a segment
    /// that cannot be read), and the pacing clock advanced by its size.
    /// A paged session gets a stab list's page first ([`crate::pages`]), then the stab list.
    pub(super) fn next_push(&mut self) -> Option<Message> {
        let segment = match self.after_page.take() {
            Some(s) => s,
            None => self.next_due(Instant::now())?,
        };
        if self.paged
            && let Some(&cell) = self.state.stab_cells.get(&segment)
            && !self.pages_sent.contains(&cell)
        {
            // Made on the compute slot with the need list; one that is not (an LRU eviction in
            // between, or it failed there) is left to the client, which reads it over HTTP.
            if let Some(frame) = self.state.page_frame(cell) {
                self.pages_sent.insert(cell);
                self.after_page = Some(segment);
                self.pace(frame.len());
                return Some(Message::Binary(frame));
            }
        }
        let bytes = match self.state.db().segment(segment) {
            Ok(b) => b,
            Err(e) => return Some(control(&StreamServer::Error(Error::from(e).to_api()))),
        };
        self.state.metrics.sent(bytes.len() as u64);
        self.mirror.insert(segment);
        self.pace(bytes.len());
        Some(Message::Binary(segment_frame(segment, &bytes).into()))
    }

    /// Advances the pacing clock by a frame of `len` bytes.
    fn pace(&mut self, len: usize) {
        let cost = secs(len as f64 / self.rate as f64);
        // A token bucket PACING_BURST deep: a timer that wakes late (they tick in whole
        // milliseconds, longer than a small segment takes at a few MB/s) lets the next pushes
        // go at once rather than losing the time, which halved the rate on small segments.
        let now = Instant::now();
        let floor = now.checked_sub(PACING_BURST).unwrap_or(now);
        self.next_free = self.next_free.max(floor) + cost;
    }

    /// Whether the session's pushes wait for their deadlines (the predicted lookahead).
    fn deadlines(&self) -> bool {
        self.policy.lookahead_cull == LookaheadCull::Predicted
    }

    /// The segment to push next: what the client's frame lacked and it does not hold, first;
    /// then the first item past the cursor that the client lacks, is wanted (past what the
    /// client's cache holds only the mandatory items are) and, with deadlines, cannot wait for
    /// the next list; the cursor moves past every item settled before it. `None`: nothing to
    /// push now (and `recheck` says when to look again).
    fn next_due(&mut self, now: Instant) -> Option<u32> {
        while let Some(&id) = self.lacking.get(self.lacking_at) {
            self.lacking_at += 1;
            if !self.mirror.contains(&id) {
                return Some(id);
            }
        }
        let dt = f64::from(self.policy.frame_time_s).max(1e-3);
        let lead = self.deadlines().then(|| {
            let age = now.saturating_duration_since(self.observed).as_secs_f64() + self.rtt_s / 2.0;
            age + dt + self.rtt_s + MARGIN_FRAMES * dt
        });
        let rate = self.rate as f64;
        let queued = self.next_free.saturating_duration_since(now).as_secs_f64() * rate;
        let mut settled = true;
        for i in self.cursor..self.list.items.len() {
            let item = self.list.items[i];
            let wanted = i < self.list.fit || self.list.must[i];
            // A paged client can check nothing before the stab lists' pages have come: they go
            // first, whatever their deadlines.
            let due = (self.paged && item.kind == NeedKind::Stab)
                || lead.is_none_or(|l| {
                    cannot_wait(item.frames, dt, l, queued, item.bytes as f64, rate)
                });
            if !wanted || self.mirror.contains(&item.segment) || due {
                if settled {
                    self.cursor = i + 1;
                }
                if wanted && due && !self.mirror.contains(&item.segment) {
                    return Some(item.segment);
                }
                continue;
            }
            settled = false;
        }
        self.recheck = now + secs(dt / 2.0);
        None
    }
}

/// Whether the pages of the first [`PAGES_PER_UPDATE`] stab lists in `list` are made
/// ([`AppState::page_frame`]): what a computation would make.
fn pages_made(state: &AppState, list: &NeedList) -> bool {
    list.items
        .iter()
        .filter(|i| i.kind == NeedKind::Stab)
        .filter_map(|i| state.stab_cells.get(&i.segment))
        .take(PAGES_PER_UPDATE)
        .all(|&c| state.page_frame(c).is_some())
}

/// The list a session's computation makes on its compute slot (its place's, or its own
/// without a place) and, for a paged client, the pages of its stab lists.
fn compute_on_slot(
    s: &AppState,
    key: Option<&ShareKey>,
    obs: &Observer,
    policy: &portico_protocol::Policy,
    paged: bool,
    budget: &portico_data::prefetch::Budget,
) -> Result<Arc<NeedList>, Error> {
    let p = &s.prefetcher;
    let list = match key {
        Some(k) => p.shared_list(k, obs, policy, budget),
        None => {
            s.metrics.stream_own_lists.fetch_add(1, Relaxed);
            let t0 = std::time::Instant::now();
            let own = p.need_list_within(obs, policy, budget).map(Arc::new);
            s.exact.charge(t0.elapsed().as_secs_f64());
            own
        }
    }
    .map_err(Error::from)?;
    // The pages of the list's stab lists, made here on the compute slot so that pushing them
    // costs the async worker nothing ([`crate::pages`]). Nearest first, at most
    // PAGES_PER_UPDATE new ones and none past the deadline: a list wider than the page cache
    // must not make every page on every update; the rest come with later lists, or the
    // client reads them.
    if paged {
        let mut made = 0;
        for item in list.items.iter().filter(|i| i.kind == NeedKind::Stab) {
            if made >= PAGES_PER_UPDATE || budget.spent() {
                break;
            }
            let Some(&cell) = s.stab_cells.get(&item.segment) else {
                continue;
            };
            if s.page_frame(cell).is_some() {
                continue;
            }
            made += 1;
            if let Err(e) = s.page(cell).map(|p| p.frame().len()) {
                tracing::warn!("page of cell {cell}: {}", e.to_api().message);
            }
        }
    }
    Ok(list)
}
