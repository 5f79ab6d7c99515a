//! The bulk of a model and its stray objects.
//!
//! Real exports carry objects far from the building: a chair left 3 km away, a survey marker, a
//! camera target. Anything sized from the model's bounds (the cell subdivision's root, a grid,
//! an orbit) would then be sized by the stray, and the building itself would get a few huge
//! cells. The bulk is the box where most objects are: the box spanning the 10th to the 90th
//! percentile of object centres on each axis, widened by twice its diagonal (at least
//! [`MIN_REACH`]); an object whose box does not reach it is a stray. The same test runs at import
//! (to warn, and to pick a local origin for survey coordinates) and in the cell builder (to
//! subdivide the bulk and give the strays cells of their own), so both agree.

use glam::DVec3;

/// The bulk reaches at least this far (metres) beyond its core: a model smaller than this is
/// never split into bulk and strays.
pub const MIN_REACH: f64 = 100.0;

/// Coordinates larger than this (metres, any axis) are not a building's, even in survey
/// coordinates (a UTM northing is below 1e7 m): importers refuse them.
pub const MAX_COORDINATE: f64 = 1.0e8;

/// A box in double precision (`min > max` when empty).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DBox {
    /// Lower corner.
    pub min: DVec3,
    /// Upper corner.
    pub max: DVec3,
}

impl DBox {
    /// The empty box.
    pub const EMPTY: DBox = DBox {
        min: DVec3::splat(f64::INFINITY),
        max: DVec3::splat(f64::NEG_INFINITY),
    };

    /// Grows the box to hold `p`.
    pub fn include(&mut self, p: DVec3) {
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }

    /// The smallest box holding both.
    pub fn union(&self, o: &DBox) -> DBox {
        DBox {
            min: self.min.min(o.min),
            max: self.max.max(o.max),
        }
    }

    /// Whether the box holds nothing.
    pub fn is_empty(&self) -> bool {
        self.min.cmpgt(self.max).any()
    }

    /// Centre point.
    pub fn center(&self) -> DVec3 {
        (self.min + self.max) * 0.5
    }

    /// Whether the boxes overlap (touching counts).
    pub fn touches(&self, o: &DBox) -> bool {
        self.min.cmple(o.max).all() && o.min.cmple(self.max).all()
    }

    /// Distance between the boxes (0 when they touch).
    pub fn distance(&self, o: &DBox) -> f64 {
        let gap = (o.min - self.max).max(self.min - o.max).max(DVec3::ZERO);
        gap.length()
    }
}

/// The bulk of a set of object boxes and the indices of the strays.
#[derive(Debug, Clone, PartialEq)]
pub struct Bulk {
    /// Union of the boxes of every object that is not a stray.
    pub bounds: DBox,
    /// Indices (into the input) of the objects outside the bulk, in input order.
    pub strays: Vec<usize>,
}

/// Splits object boxes into the bulk and the strays (see the module documentation).
pub fn bulk(boxes: &[DBox]) -> Bulk {
    let live: Vec<usize> = (0..boxes.len()).filter(|&i| !boxes[i].is_empty()).collect();
    if live.is_empty() {
        return Bulk {
            bounds: DBox::EMPTY,
            strays: Vec::new(),
        };
    }
    let mut core = DBox::EMPTY;
    for axis in 0..3 {
        let mut c: Vec<f64> = live.iter().map(|&i| boxes[i].center()[axis]).collect();
        c.sort_by(f64::total_cmp);
        let last = c.len() - 1;
        core.min[axis] = c[(last as f64 * 0.1).floor() as usize];
        core.max[axis] = c[(last as f64 * 0.9).ceil() as usize];
    }
    let reach = (2.0 * (core.max - core.min).length()).max(MIN_REACH);
    let region = DBox {
        min: core.min - DVec3::splat(reach),
        max: core.max + DVec3::splat(reach),
    };
    let mut bounds = DBox::EMPTY;
    let mut strays = Vec::new();
    for &i in &live {
        if boxes[i].touches(&region) {
            bounds = bounds.union(&boxes[i]);
        } else {
            strays.push(i);
        }
    }
    Bulk { bounds, strays }
}

/// The local origin for a model whose bulk is `bounds`: 0 on each axis where the bulk's centre
/// is within 1 km of it, else the centre rounded to a whole kilometre. Survey coordinates
/// (millions of metres) lose centimetres in single precision; relative to this origin they keep
/// tenths of a millimetre, and models already near the origin keep their coordinates exactly.
pub fn local_origin(bounds: &DBox) -> DVec3 {
    if bounds.is_empty() {
        return DVec3::ZERO;
    }
    let c = bounds.center();
    DVec3::from_array(c.to_array().map(|x| {
        if x.abs() < 1000.0 {
            0.0
        } else {
            (x / 1000.0).round() * 1000.0
        }
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cube(at: [f64; 3], size: f64) -> DBox {
        let min = DVec3::from(at);
        DBox {
            min,
            max: min + DVec3::splat(size),
        }
    }

    #[test]
    fn a_chair_3_km_away_is_a_stray_and_the_house_is_the_bulk() {
        let mut boxes: Vec<DBox> = (0..11).map(|i| cube([i as f64, 0.0, 0.0], 1.0)).collect();
        boxes.push(cube([3000.0, 3000.0, 3000.0], 1.0));
        let b = bulk(&boxes);
        assert_eq!(b.strays, vec![11]);
        assert_eq!(b.bounds.max, DVec3::new(11.0, 1.0, 1.0));
    }

    #[test]
    fn a_spread_out_campus_has_no_strays() {
        let boxes: Vec<DBox> = (0..20)
            .map(|i| cube([(i % 5) as f64 * 400.0, 0.0, (i / 5) as f64 * 400.0], 50.0))
            .collect();
        assert!(bulk(&boxes).strays.is_empty());
    }

    #[test]
    fn survey_coordinates_get_a_kilometre_origin_and_local_models_keep_theirs() {
        let far = cube([600_123.0, 50.0, -5_000_456.0], 10.0);
        assert_eq!(local_origin(&far), DVec3::new(600_000.0, 0.0, -5_000_000.0));
        assert_eq!(local_origin(&cube([-40.0, 0.0, 300.0], 10.0)), DVec3::ZERO);
    }
}
