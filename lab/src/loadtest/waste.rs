//! Where the bytes never drawn went: each fetched segment that no frame drew is put down to one
//! reason, so a report says what a policy reads in vain instead of one total (Funkhouser §5.3.1
//! measured the lookahead's overestimate the same way, by what the frames then drew).
//!
//! Geometry segments belong to a LOD chain (an object's LODs, finest first); a chain no frame
//! drew at any level is an object read for nothing, a level finer than every level drawn is
//! detail the frames never got close enough for, and a level coarser than the finest drawn is a
//! stand-in the frames did not need (it arrived with or after the finer one).

use portico_data::format::{Header, SegmentKind};
use serde::Serialize;
use std::collections::HashMap;

/// Never-drawn bytes by reason (wire bytes).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct Waste {
    /// Geometry of objects no frame drew at any LOD.
    pub object_never_drawn: u64,
    /// Geometry finer than every LOD of its object that a frame drew.
    pub finer_than_drawn: u64,
    /// Geometry coarser than the finest LOD of its object that a frame drew, never drawn.
    pub coarser_than_drawn: u64,
    /// Texture mips and impostor atlases.
    pub textures: u64,
    /// Stab lists.
    pub stab_lists: u64,
    /// Segments that arrived while already resident.
    pub twice: u64,
}

impl Waste {
    /// Every reason together.
    pub fn total(&self) -> u64 {
        self.object_never_drawn
            + self.finer_than_drawn
            + self.coarser_than_drawn
            + self.textures
            + self.stab_lists
            + self.twice
    }

    /// `self + o`.
    pub fn add(&mut self, o: &Waste) {
        self.object_never_drawn += o.object_never_drawn;
        self.finer_than_drawn += o.finer_than_drawn;
        self.coarser_than_drawn += o.coarser_than_drawn;
        self.textures += o.textures;
        self.stab_lists += o.stab_lists;
        self.twice += o.twice;
    }

    /// Each reason divided by `n` (per client).
    pub fn per(&self, n: u64) -> Waste {
        let n = n.max(1);
        Waste {
            object_never_drawn: self.object_never_drawn / n,
            finer_than_drawn: self.finer_than_drawn / n,
            coarser_than_drawn: self.coarser_than_drawn / n,
            textures: self.textures / n,
            stab_lists: self.stab_lists / n,
            twice: self.twice / n,
        }
    }
}

/// Which LOD chain and level each geometry segment is, and each segment's kind.
#[derive(Debug, Clone, Default)]
pub struct Chains {
    /// Geometry segment → (chain: its finest LOD's segment, level: 0 = finest).
    level: HashMap<u32, (u32, u8)>,
    /// Segment kinds by id (the manifest's).
    kinds: Vec<u16>,
}

impl Chains {
    /// From the model header and the manifest's segment kinds.
    pub fn new(header: &Header, kinds: Vec<u16>) -> Chains {
        let mut level = HashMap::new();
        let chains = header
            .objects
            .iter()
            .map(|o| o.lods.as_slice())
            .chain(header.instances.iter().filter_map(|i| i.lods.as_deref()));
        for lods in chains {
            let Some(first) = lods.first() else { continue };
            for (l, r) in lods.iter().enumerate() {
                level.insert(r.segment, (first.segment, l.min(255) as u8));
            }
        }
        Chains { level, kinds }
    }

    /// The chain and level of a geometry segment.
    pub fn of(&self, segment: u32) -> Option<(u32, u8)> {
        self.level.get(&segment).copied()
    }

    fn kind(&self, segment: u32) -> Option<SegmentKind> {
        SegmentKind::from_u16(*self.kinds.get(segment as usize)?)
    }
}

/// One client's record: the levels drawn per chain, and what arrived and was never drawn.
#[derive(Debug, Clone, Default)]
pub struct Ledger {
    /// Per chain, the finest and coarsest level a frame drew.
    drawn: HashMap<u32, (u8, u8)>,
    /// Never-drawn arrivals (segment, wire bytes), classified at the end.
    unused: Vec<(u32, u64)>,
    twice: u64,
}

impl Ledger {
    /// A frame drew `segment`.
    pub fn drew(&mut self, chains: &Chains, segment: u32) {
        if let Some((chain, l)) = chains.of(segment) {
            let e = self.drawn.entry(chain).or_insert((l, l));
            e.0 = e.0.min(l);
            e.1 = e.1.max(l);
        }
    }

    /// `segment` left the cache (or the run ended) without being drawn.
    pub fn unused(&mut self, segment: u32, bytes: u64) {
        self.unused.push((segment, bytes));
    }

    /// `bytes` arrived for a segment already resident.
    pub fn twice(&mut self, bytes: u64) {
        self.twice += bytes;
    }

    /// The breakdown, once the run is over.
    pub fn waste(&self, chains: &Chains) -> Waste {
        let mut w = Waste {
            twice: self.twice,
            ..Waste::default()
        };
        for &(s, b) in &self.unused {
            match chains.of(s) {
                Some((chain, l)) => match self.drawn.get(&chain) {
                    None => w.object_never_drawn += b,
                    Some(&(finest, _)) if l < finest => w.finer_than_drawn += b,
                    Some(_) => w.coarser_than_drawn += b,
                },
                None => match chains.kind(s) {
                    Some(SegmentKind::StabList) => w.stab_lists += b,
                    _ => w.textures += b,
                },
            }
        }
        w
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chains() -> Chains {
        // One chain: segments 10 (finest), 11, 12 (coarsest); 20 a stab list, 21 a texture.
        let mut level = HashMap::new();
        for (l, s) in [10u32, 11, 12].into_iter().enumerate() {
            level.insert(s, (10, l as u8));
        }
        level.insert(30, (30, 0));
        let mut kinds = vec![0u16; 32];
        kinds[20] = SegmentKind::StabList as u16;
        kinds[21] = SegmentKind::Texture as u16;
        Chains { level, kinds }
    }

    #[test]
    fn each_unused_segment_gets_its_reason() {
        let c = chains();
        let mut l = Ledger::default();
        l.drew(&c, 11);
        for (s, b) in [(10, 1), (12, 10), (30, 100), (20, 1000), (21, 10_000)] {
            l.unused(s, b);
        }
        l.twice(100_000);
        let w = l.waste(&c);
        assert_eq!(
            w,
            Waste {
                finer_than_drawn: 1,
                coarser_than_drawn: 10,
                object_never_drawn: 100,
                stab_lists: 1000,
                textures: 10_000,
                twice: 100_000,
            }
        );
        assert_eq!(w.total(), 111_111);
    }
}
