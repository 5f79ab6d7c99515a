//! What a walkthrough client holds between frames, without IO or GPU: the LRU cache under its
//! byte budget (Funkhouser §5.2.3), the segments held outside it (larger than the whole cache, or
//! unusable here: reported held so that no list names them again), and what the last frame
//! lacked (§5.2.4). Every front end's frame loop runs the same steps on it:
//! arrivals → [`Holdings::hold`] (texture pieces: [`Holdings::piece_waits`]) → the frame decision
//! → [`Holdings::decided`] → [`Holdings::held`] for the next request.

use crate::cache::ObjectCache;
use crate::demand::lacking;
use crate::frame::{Decision, Scene};
use crate::parts::Parts;
use std::collections::HashSet;

/// The cache, what is held beside it, and the last frame's needs.
#[derive(Debug)]
pub struct Holdings<V> {
    /// The LRU cache of resident segments.
    pub cache: ObjectCache<V>,
    /// Segments larger than the whole cache, or unusable here.
    pub too_big: HashSet<u32>,
    /// What the last frame lacked, most urgent first, a texture's missing parts included.
    pub lacking: Vec<u32>,
    /// Whether the last frame skipped objects (something in view had nothing to draw).
    pub incomplete: bool,
}

impl<V> Holdings<V> {
    /// Holdings with a cache of `budget` bytes.
    pub fn new(budget: u64) -> Holdings<V> {
        Holdings {
            cache: ObjectCache::new(budget),
            too_big: HashSet::new(),
            lacking: Vec::new(),
            incomplete: false,
        }
    }

    /// Whether segment `id` is held (resident, or held beside the cache).
    pub fn has(&self, id: u32) -> bool {
        self.cache.contains(id) || self.too_big.contains(&id)
    }

    /// A piece of a texture segment came and waits for the rest: if its segment is held
    /// already, nothing waits for it and the pieces are forgotten.
    pub fn piece_waits(&self, parts: &mut Parts, id: u32) {
        let head = parts.head(id);
        if self.has(head) {
            parts.forget(head);
        }
    }

    /// Holds `value` under segment `id`, charged `charge` bytes; one larger than the whole cache
    /// is held beside it. A joined texture needs no more reporting of its pieces. Returns what
    /// the cache released.
    pub fn hold(&mut self, parts: &mut Parts, id: u32, value: V, charge: u64) -> Vec<u32> {
        let released = match self.cache.insert(id, value, charge) {
            Ok(released) => released,
            Err(_) => {
                self.too_big.insert(id);
                Vec::new()
            }
        };
        parts.settle(id);
        released
    }

    /// Segment `id` came but cannot be used here (it does not decode, or is over the device's
    /// limits): held beside the cache, so that it is not sent again and again.
    pub fn unusable(&mut self, parts: &mut Parts, id: u32) {
        self.too_big.insert(id);
        parts.settle(id);
    }

    /// After a frame's decision `d` over `scene`: what it lacked (with the missing parts of
    /// textures), whether it skipped objects, and the entries it used moved to the cache's head.
    pub fn decided(&mut self, parts: &Parts, d: &Decision, scene: &Scene<'_>) {
        let lacked = lacking(d, scene, &|s| self.has(s));
        self.lacking = parts.expand(lacked);
        self.incomplete = d.frame.objects_skipped > 0;
        for &s in &d.touched {
            self.cache.touch(s);
        }
    }

    /// What to report held to the server: the cache, what is held beside it, and texture
    /// segments' parts (those of held segments, and pieces waiting for the rest).
    pub fn held(&self, parts: &Parts) -> Vec<u32> {
        parts.holding(self.cache.ids().chain(self.too_big.iter().copied()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use portico_data::texture::{MipSegment, TextureRecord, Wrap};

    /// One texture: segment 4 with parts 5 and 6.
    fn parts() -> Parts {
        let seg = MipSegment {
            segment: 4,
            width: 64,
            height: 64,
            levels: 7,
            opaque: true,
            parts: 2,
        };
        Parts::new(&[TextureRecord {
            name: "t".into(),
            width: 64,
            height: 64,
            segments: vec![seg],
            average: [0.5; 4],
            wrap: [Wrap::Repeat; 2],
            psnr: None,
        }])
    }

    #[test]
    fn what_the_cache_cannot_hold_is_held_beside_it_and_reported() {
        let mut p = parts();
        let mut h: Holdings<()> = Holdings::new(100);
        assert!(h.hold(&mut p, 1, (), 60).is_empty());
        assert_eq!(h.hold(&mut p, 2, (), 60), vec![1], "the budget holds");
        assert!(h.hold(&mut p, 3, (), 1000).is_empty());
        assert!(h.has(3) && !h.cache.contains(3), "too big for the cache");
        h.unusable(&mut p, 9);
        let mut held = h.held(&p);
        held.sort_unstable();
        assert_eq!(held, vec![2, 3, 9]);
    }

    #[test]
    fn a_held_texture_reports_its_parts_and_forgets_late_pieces() {
        let mut p = parts();
        let mut h: Holdings<()> = Holdings::new(1 << 20);
        h.hold(&mut p, 4, (), 100);
        let mut held = h.held(&p);
        held.sort_unstable();
        assert_eq!(held, vec![4, 5, 6], "the head with its parts");
        // A piece of the held texture came late: nothing waits for it.
        let _ = p.join(5, vec![1, 2, 3]);
        h.piece_waits(&mut p, 5);
        assert_eq!(p.waiting().count(), 0);
    }
}
