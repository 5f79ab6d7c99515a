//! Texture segments cut into parts for the wire ([`portico_data::texture::PART_BYTES`]):
//! which ids travel together, and their bytes joined back as they arrive.
//!
//! A texture segment longer than a part is stored as its *head* (the first part, the id every
//! header record, need list and cache entry names) and further part segments whose bytes
//! follow it. Each part is fetched, pushed and checked like any segment, so a long finest
//! level never holds a slow link for long and what the frame lacks is read between its parts;
//! the client keeps the parts that came until the last one joins them, then decodes the whole
//! and holds it under the head's id. Parts that came are reported held, so that no one sends
//! them again, and asking for a head asks for its parts ([`Parts::expand`]).
//!
//! IO-free: every front end (the native client, the browser, the load tester's clients) joins
//! its arrivals here.

use portico_data::texture::{MIN_PART_BYTES, TEXTURE_HEADER, TextureRecord};
use std::collections::{HashMap, HashSet};

/// What [`Parts::join`] made of an arrival.
#[derive(Debug, PartialEq, Eq)]
pub enum Joined {
    /// A segment of its own (no parts): use it as it came.
    Whole(u32, Vec<u8>),
    /// A head or part whose others have not all come: kept.
    Waiting,
    /// The last of a head's parts: the head's id and the whole segment's bytes.
    Complete(u32, Vec<u8>),
}

/// Most groups of pieces kept waiting at once: past it the longest waiting is dropped (asked
/// for again when it is needed), so that pieces whose need passed cannot pile up.
pub const MAX_WAITING: usize = 64;

/// The pieces of one segment that came (index 0 its head), `None` for those still to come.
type Pieces = Vec<Option<Vec<u8>>>;

/// The parts of every texture segment of a model, and those that came.
#[derive(Debug, Clone, Default)]
pub struct Parts {
    /// Head → number of further parts (ids `head + 1 ..= head + n`).
    heads: HashMap<u32, u32>,
    /// Part → its head.
    head_of: HashMap<u32, u32>,
    /// Head → when its first piece came (a count) and the pieces that came (index 0 the head),
    /// until all have.
    pending: HashMap<u32, (u64, Pieces)>,
    /// Heads whose pieces all came and that are being decoded: still reported held (as a
    /// whole) until [`Parts::settle`], so that nothing is sent again meanwhile.
    joined: HashSet<u32>,
    /// Pieces taken so far (orders `pending`).
    taken: u64,
}

impl Parts {
    /// The parts of the texture segments of `textures` (a header's). A record whose parts are
    /// more than its texels could need, whose ids overflow, or that claims an id another
    /// record has is left whole (a hostile header cannot make this allocate or panic).
    pub fn new(textures: &[TextureRecord]) -> Parts {
        let mut p = Parts::default();
        for s in textures.iter().flat_map(|t| &t.segments) {
            let most = (TEXTURE_HEADER as u64 + s.texel_bytes()) / MIN_PART_BYTES as u64 + 1;
            let Some(last) = s.segment.checked_add(s.parts) else {
                continue;
            };
            if s.parts == 0 || u64::from(s.parts) > most {
                continue;
            }
            let taken = (s.segment..=last)
                .any(|id| p.heads.contains_key(&id) || p.head_of.contains_key(&id));
            if taken {
                continue;
            }
            p.heads.insert(s.segment, s.parts);
            for id in s.segment + 1..=last {
                p.head_of.insert(id, s.segment);
            }
        }
        p
    }

    /// Whether the model has any segment cut into parts.
    pub fn is_empty(&self) -> bool {
        self.heads.is_empty()
    }

    /// The head `id` belongs to: itself for a head or any other segment, its head for a part.
    pub fn head(&self, id: u32) -> u32 {
        self.head_of.get(&id).copied().unwrap_or(id)
    }

    /// The ids of `head` and its parts (just `head` for a segment of its own).
    pub fn group(&self, head: u32) -> std::ops::RangeInclusive<u32> {
        head..=head + self.heads.get(&head).copied().unwrap_or(0)
    }

    /// Whether `id` is a head with parts or one of its parts.
    pub fn is_piece(&self, id: u32) -> bool {
        self.heads.contains_key(&id) || self.head_of.contains_key(&id)
    }

    /// Takes an arrival (after its checksum): a segment of its own comes back whole; a piece is
    /// kept until the last of its head's pieces completes the segment, which stays reported
    /// held until [`Parts::settle`]. A piece that came twice is kept once; one whose segment
    /// is being joined is dropped. Past [`MAX_WAITING`] groups the longest waiting is dropped.
    pub fn join(&mut self, id: u32, bytes: Vec<u8>) -> Joined {
        let head = self.head(id);
        let Some(&n) = self.heads.get(&head) else {
            return Joined::Whole(id, bytes);
        };
        if self.joined.contains(&head) {
            return Joined::Waiting;
        }
        if !self.pending.contains_key(&head) && self.pending.len() >= MAX_WAITING {
            let oldest = self
                .pending
                .iter()
                .min_by_key(|(_, (at, _))| *at)
                .map(|(&h, _)| h);
            if let Some(h) = oldest {
                self.pending.remove(&h);
            }
        }
        self.taken += 1;
        let at = self.taken;
        let (_, slots) = self
            .pending
            .entry(head)
            .or_insert_with(|| (at, vec![None; n as usize + 1]));
        if let Some(slot) = slots.get_mut((id - head) as usize) {
            *slot = Some(bytes);
        }
        if slots.iter().any(Option::is_none) {
            return Joined::Waiting;
        }
        let (_, slots) = self.pending.remove(&head).unwrap_or_default();
        self.joined.insert(head);
        Joined::Complete(head, slots.into_iter().flatten().flatten().collect())
    }

    /// The segment of `head` was taken (held, found unusable, or given up): it is no longer
    /// reported held for its pieces.
    pub fn settle(&mut self, head: u32) {
        self.joined.remove(&head);
    }

    /// The pieces that came and wait for the rest of their segment, and the whole groups of
    /// segments joined and not yet settled: what a client reports held besides its cache.
    pub fn waiting(&self) -> impl Iterator<Item = u32> + '_ {
        let pieces = self.pending.iter().flat_map(|(&head, (_, slots))| {
            slots
                .iter()
                .enumerate()
                .filter(|(_, s)| s.is_some())
                .map(move |(i, _)| head + i as u32)
        });
        pieces.chain(self.joined.iter().flat_map(|&h| self.group(h)))
    }

    /// Bytes kept waiting.
    pub fn waiting_bytes(&self) -> u64 {
        self.pending
            .values()
            .flat_map(|(_, slots)| slots)
            .flatten()
            .map(|b| b.len() as u64)
            .sum()
    }

    /// `ids` with each head followed by its parts, leaving out the pieces that came and the
    /// segments being joined.
    pub fn expand(&self, ids: impl IntoIterator<Item = u32>) -> Vec<u32> {
        let mut out = Vec::new();
        for id in ids {
            let Some(&n) = self.heads.get(&id) else {
                out.push(id);
                continue;
            };
            if self.joined.contains(&id) {
                continue;
            }
            let came = self.pending.get(&id).map(|(_, s)| s);
            let missing = |i: u32| came.is_none_or(|s| s[i as usize].is_none());
            out.extend((0..=n).filter(|&i| missing(i)).map(|i| id + i));
        }
        out
    }

    /// `ids` with each head's parts after it: what a client evicting `ids` evicts.
    pub fn with_parts(&self, ids: impl IntoIterator<Item = u32>) -> Vec<u32> {
        ids.into_iter().flat_map(|id| self.group(id)).collect()
    }

    /// What a client holding `ids` (its cache) reports held: each head with all its parts (so
    /// that neither is sent again, and an evicted head's parts are evicted with it), and the
    /// pieces waiting for the rest of their segment.
    pub fn holding(&self, ids: impl IntoIterator<Item = u32>) -> Vec<u32> {
        let mut out = self.with_parts(ids);
        out.extend(self.waiting());
        out
    }

    /// Forgets the pieces that came of the segment `id` belongs to (it is held already, or was
    /// given up).
    pub fn forget(&mut self, id: u32) {
        self.pending.remove(&self.head(id));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use portico_data::texture::{MipSegment, Wrap};

    /// One texture: segment 3 alone, segment 4 with parts 5 and 6.
    fn textures() -> Vec<TextureRecord> {
        let seg = |segment, parts| MipSegment {
            segment,
            width: 64,
            height: 64,
            levels: 7,
            opaque: true,
            parts,
        };
        vec![TextureRecord {
            name: "t".into(),
            width: 64,
            height: 64,
            segments: vec![seg(3, 0), seg(4, 2)],
            average: [0.5; 4],
            wrap: [Wrap::Repeat; 2],
            psnr: None,
        }]
    }

    #[test]
    fn parts_join_in_order_whatever_order_they_come_in() {
        let mut p = Parts::new(&textures());
        assert_eq!(p.join(3, vec![1]), Joined::Whole(3, vec![1]));
        assert_eq!(p.join(9, vec![2]), Joined::Whole(9, vec![2]));
        assert_eq!(p.expand([2, 4, 3]), vec![2, 4, 5, 6, 3]);
        assert_eq!(p.join(6, vec![60, 61]), Joined::Waiting);
        assert_eq!(p.join(4, vec![40]), Joined::Waiting);
        // Twice: kept once.
        assert_eq!(p.join(4, vec![40]), Joined::Waiting);
        let mut waiting: Vec<u32> = p.waiting().collect();
        waiting.sort();
        assert_eq!(waiting, vec![4, 6]);
        assert_eq!(p.waiting_bytes(), 3);
        // Asking for the head again asks only for what did not come.
        assert_eq!(p.expand([4]), vec![5]);
        assert_eq!(p.head(5), 4);
        assert_eq!(
            p.join(5, vec![50]),
            Joined::Complete(4, vec![40, 50, 60, 61])
        );
        // Being decoded: reported held as a whole, asked for not at all, a piece again dropped.
        let mut waiting: Vec<u32> = p.waiting().collect();
        waiting.sort();
        assert_eq!(waiting, vec![4, 5, 6]);
        assert_eq!(p.expand([4]), Vec::<u32>::new());
        assert_eq!(p.join(6, vec![60]), Joined::Waiting);
        p.settle(4);
        assert_eq!(p.waiting().count(), 0);
        assert_eq!(p.expand([4]), vec![4, 5, 6]);
        // Held: the head with its parts, and what waits.
        assert_eq!(p.join(6, vec![60]), Joined::Waiting);
        assert_eq!(p.holding([4, 3]), vec![4, 5, 6, 3, 6]);
        assert_eq!(p.with_parts([3, 4]), vec![3, 4, 5, 6]);
        p.forget(4);
        // Given up: forgotten.
        assert_eq!(p.join(5, vec![50]), Joined::Waiting);
        p.forget(5);
        assert_eq!(p.waiting().count(), 0);
    }

    #[test]
    fn hostile_records_are_left_whole_and_waiting_is_bounded() {
        let mut t = textures();
        // Parts past what its texels could need; then a record claiming another's part.
        t[0].segments[0].parts = u32::MAX - 3;
        let claimer = MipSegment {
            segment: 5,
            parts: 1,
            ..t[0].segments[1]
        };
        t[0].segments.push(claimer);
        let mut p = Parts::new(&t);
        assert!(!p.is_piece(3) && p.is_piece(4) && p.is_piece(6));
        assert_eq!(p.head(6), 4);
        // Many big textures begun, none finished: the oldest are dropped.
        let many: Vec<TextureRecord> = (0..200u32)
            .map(|i| TextureRecord {
                segments: vec![MipSegment {
                    segment: 100 + 2 * i,
                    parts: 1,
                    ..t[0].segments[1]
                }],
                ..t[0].clone()
            })
            .collect();
        p = Parts::new(&many);
        for i in 0..200u32 {
            assert_eq!(p.join(100 + 2 * i, vec![1]), Joined::Waiting);
        }
        assert_eq!(p.waiting().count(), MAX_WAITING);
        assert!(
            p.waiting()
                .all(|id| id >= 100 + 2 * (200 - MAX_WAITING as u32))
        );
    }
}
