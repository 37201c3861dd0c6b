//! The machine model of `docs/machine-model.md` as validated Rust values.
//!
//! Built once per profile; everything IK can precompute is precomputed here (`chain`), so the
//! per-pose path (FK, IK) does no allocation and no validation.

use super::angle_error::AngleError;
use super::{Error, Vec3};
use arrayvec::ArrayVec;

mod chain;
pub(crate) use chain::{Chain, Form, Shape, TERMS, controlled_point_cs};

/// Length units of a profile. Every length of a profile, and its NC output, is in these units.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Units {
    Mm,
    Inch,
}

impl Units {
    pub fn mm_per_unit(self) -> f64 {
        match self {
            Units::Mm => 1.0,
            Units::Inch => 25.4,
        }
    }

    /// Factor that converts a length in `self` into `to`. Explicit, so that no caller guesses.
    pub fn factor_to(self, to: Units) -> f64 {
        self.mm_per_unit() / to.mm_per_unit()
    }

    pub fn as_str(self) -> &'static str {
        match self {
            Units::Mm => "mm",
            Units::Inch => "inch",
        }
    }
}

/// Which body a rotary turns.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mount {
    /// Turns the workpiece (the frame W turns with it).
    Table,
    /// Turns the spindle.
    Head,
}

/// One of X, Y, Z: it translates the head along M's x, y or z. Limits in profile units.
#[derive(Clone, Debug, PartialEq)]
pub struct Linear {
    pub min: f64,
    pub max: f64,
    /// Units per minute.
    pub max_feed: Option<f64>,
    /// Units per second squared.
    pub max_accel: Option<f64>,
}

/// A rotary joint: turns its body by +angle about `axis` through `pivot` (right-hand rule).
#[derive(Clone, Debug, PartialEq)]
pub struct Rotary {
    /// The NC word: 'A', 'B' or 'C'.
    pub name: char,
    pub mount: Mount,
    /// Unit vector.
    pub axis: Vec3,
    /// Table: a point in M. Head: relative to the gauge point at home.
    pub pivot: Vec3,
    /// Commanded-word travel in radians; `None` for an unbounded axis.
    pub limits: Option<(f64, f64)>,
    /// Radians per minute.
    pub max_feed: Option<f64>,
    /// Radians per second squared.
    pub max_accel: Option<f64>,
    pub angle_error: Option<AngleError>,
}

impl Rotary {
    /// Where its word sits among X Y Z A B C (3, 4 or 5).
    #[inline]
    pub fn slot(&self) -> usize {
        3 + (self.name as u8 - b'A') as usize
    }

    /// The angle the axis really stands at when the NC word commands `word` (radians).
    #[inline]
    pub fn actual(&self, word: f64) -> f64 {
        match &self.angle_error {
            Some(e) => word + e.delta(word),
            None => word,
        }
    }

    /// The NC word that makes the axis stand at `actual` (inverse of [`Rotary::actual`]).
    #[inline]
    pub fn word(&self, actual: f64) -> f64 {
        match &self.angle_error {
            Some(e) => e.word_for(actual),
            None => actual,
        }
    }

    pub fn within(&self, word: f64, eps: f64) -> bool {
        match self.limits {
            Some((lo, hi)) => word >= lo - eps && word <= hi + eps,
            None => true,
        }
    }

    /// [`Rotary::windings`] where it has at most one word, known without a search: less than a
    /// turn of travel without angle error (most tilting axes), and an angle within a turn of it.
    /// `Some(None)`: no word in travel; `None`: not that case (ask `windings`). The planner's hot
    /// path, without floor/ceil (libm calls on baseline x86-64) or a list.
    #[inline]
    pub fn one_winding(&self, actual: f64) -> Option<Option<f64>> {
        use std::f64::consts::TAU;
        let (lo, hi) = self.limits?;
        if self.angle_error.is_some() || hi - lo >= TAU - 1e-6 || !(actual >= lo - TAU && actual <= hi + TAU) {
            return None;
        }
        Some(
            [actual, actual - TAU, actual + TAU]
                .into_iter()
                .find(|&w| self.within(w, 1e-9))
                .map(|w| w.clamp(lo, hi)),
        )
    }

    /// The commanded words within travel that make the axis stand at `actual` modulo a full
    /// turn, in increasing order: every one for travel up to [`WINDINGS`] turns, else the
    /// [`WINDINGS`] nearest `near` (the word the axis stands at), so that a long-travel table
    /// winds on from where it is instead of from its lower limit. Unbounded axes get the one
    /// nearest `near`.
    pub fn windings(&self, actual: f64, near: f64) -> ArrayVec<f64, WINDINGS> {
        use std::f64::consts::TAU;
        let mut out = ArrayVec::new();
        if let Some(one) = self.one_winding(actual) {
            out.extend(one);
            return out;
        }
        let Some((lo, hi)) = self.limits else {
            let k = ((near - actual) / TAU).round();
            out.push(self.word(actual + k * TAU));
            return out;
        };
        if !actual.is_finite() {
            return out;
        }
        let near = if near.is_finite() { near } else { actual };
        // Turns k from a turn below the first word in range to a turn past the last (angle
        // error is bounded, so a turn of margin catches every word); truncation, not floor/ceil
        // (libm calls on baseline x86-64).
        let k_lo = ((lo - actual) / TAU) as i64 - 2;
        let k_hi = ((hi - actual) / TAU) as i64 + 2;
        let x = (near - actual) / TAU;
        let k_near = if x >= 0.0 { (x + 0.5) as i64 } else { (x - 0.5) as i64 };
        let span = WINDINGS as i64 + 4;
        let first = (k_near - span / 2).min(k_hi - span).max(k_lo);
        for k in first..=first.saturating_add(span).min(k_hi) {
            let w = self.word(actual + k as f64 * TAU);
            if self.within(w, 1e-9) {
                out.push(w.clamp(lo, hi));
                if out.is_full() {
                    break;
                }
            }
        }
        out
    }
}

/// The largest rotary travel a profile may state (degrees): the largest word a control carries.
pub const MAX_ROTARY_WORD: f64 = 99_999.999;

/// Words [`Rotary::windings`] lists at most: a table with more turns of travel than this gets
/// the ones nearest where it stands.
pub const WINDINGS: usize = 8;

/// A validated machine. Construct with [`Machine::new`].
#[derive(Clone, Debug)]
pub struct Machine {
    pub id: String,
    pub name: String,
    pub units: Units,
    /// Default dialect.
    pub controller: String,
    pub description: String,
    /// X, Y, Z; `None` where the machine lacks that linear (its value is then always 0).
    pub linears: [Option<Linear>; 3],
    /// In chain order (file order): tables from the bed outward, heads from the ram outward.
    pub rotaries: ArrayVec<Rotary, 3>,
    pub default_tool_length: f64,
    /// What IK reads of the chain, derived from the rotaries and linears above.
    pub(crate) chain: Chain,
}

/// What a caller supplies to build a [`Machine`]; plain values, no file format attached.
#[derive(Clone, Debug)]
pub struct MachineSpec {
    pub id: String,
    pub name: String,
    pub units: Units,
    pub controller: String,
    pub description: String,
    pub linears: [Option<Linear>; 3],
    pub rotaries: Vec<Rotary>,
    pub default_tool_length: f64,
}

pub const LINEAR_NAMES: [char; 3] = ['X', 'Y', 'Z'];

impl Machine {
    /// Validates the spec and derives the chain IK reads. Errors name the key that is wrong.
    pub fn new(spec: MachineSpec) -> Result<Machine, Error> {
        let bad = |key: String, problem: String| Err(Error::Profile { key, problem });
        if spec.id.is_empty()
            || spec.id.len() > 64
            || !spec
                .id
                .bytes()
                .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'-')
        {
            return bad(
                "id".into(),
                format!(
                    "{:?} must match [a-z0-9-]{{1,64}}",
                    spec.id.chars().take(80).collect::<String>()
                ),
            );
        }
        for (i, l) in spec.linears.iter().enumerate() {
            let Some(l) = l else { continue };
            let key = format!("linear.{}", LINEAR_NAMES[i]);
            if !l.min.is_finite() || !l.max.is_finite() {
                return bad(key, "min and max must be finite".into());
            }
            if l.min >= l.max {
                return bad(key, format!("min ({}) must be less than max ({})", l.min, l.max));
            }
            for (what, v) in [("max_feed", l.max_feed), ("max_accel", l.max_accel)] {
                if let Some(f) = v
                    && !(f.is_finite() && f > 0.0)
                {
                    return bad(format!("{key}.{what}"), "must be a positive number".into());
                }
            }
        }
        if spec.rotaries.len() > 3 {
            return bad("rotary".into(), format!("at most 3 rotaries, found {}", spec.rotaries.len()));
        }
        let mut rotaries = ArrayVec::<Rotary, 3>::new();
        for (i, r) in spec.rotaries.into_iter().enumerate() {
            let key = format!("rotary[{i}] ({})", r.name);
            if !matches!(r.name, 'A' | 'B' | 'C') {
                return bad(format!("rotary[{i}].name"), format!("{:?} must be A, B or C", r.name));
            }
            if rotaries.iter().any(|o| o.name == r.name) {
                return bad(format!("rotary[{i}].name"), format!("duplicate rotary name {}", r.name));
            }
            let n = r.axis.norm();
            if !n.is_finite() || n < 1e-9 {
                return bad(format!("{key}.axis"), "must be a finite, non-zero vector".into());
            }
            if !r.pivot.iter().all(|v| v.is_finite()) {
                return bad(format!("{key}.pivot"), "must be finite".into());
            }
            if let Some((lo, hi)) = r.limits {
                if !lo.is_finite() || !hi.is_finite() {
                    return bad(format!("{key}.min/max"), "must be finite".into());
                }
                if lo >= hi {
                    return bad(
                        format!("{key}.min/max"),
                        format!("min ({}) must be less than max ({})", lo.to_degrees(), hi.to_degrees()),
                    );
                }
                if lo.abs().max(hi.abs()) > MAX_ROTARY_WORD.to_radians() {
                    return bad(
                        format!("{key}.min/max"),
                        format!(
                            "beyond ±{MAX_ROTARY_WORD}°, the largest word a control carries: an axis that turns without end has neither"
                        ),
                    );
                }
            }
            for (what, v) in [("max_feed", r.max_feed), ("max_accel", r.max_accel)] {
                if let Some(f) = v
                    && !(f.is_finite() && f > 0.0)
                {
                    return bad(format!("{key}.{what}"), "must be a positive number".into());
                }
            }
            if let Some(e) = &r.angle_error {
                e.validate().map_err(|p| Error::Profile {
                    key: format!("{key}.angle_error"),
                    problem: p,
                })?;
            }
            rotaries.push(Rotary { axis: r.axis / n, ..r });
        }
        if !(spec.default_tool_length.is_finite() && spec.default_tool_length >= 0.0) {
            return bad("tool.default_length".into(), "must be a finite, non-negative length".into());
        }
        let chain = Chain::new(&spec.linears, &rotaries).map_err(|problem| Error::Profile {
            key: "rotary".into(),
            problem,
        })?;
        Ok(Machine {
            id: spec.id,
            name: spec.name,
            units: spec.units,
            controller: spec.controller,
            description: spec.description,
            linears: spec.linears,
            rotaries,
            default_tool_length: spec.default_tool_length,
            chain,
        })
    }

    /// The same machine with other rotaries (calibrated pivots, say), validated again.
    pub fn with_rotaries(&self, rotaries: Vec<Rotary>) -> Result<Machine, Error> {
        Machine::new(MachineSpec {
            id: self.id.clone(),
            name: self.name.clone(),
            units: self.units,
            controller: self.controller.clone(),
            description: self.description.clone(),
            linears: self.linears.clone(),
            rotaries,
            default_tool_length: self.default_tool_length,
        })
    }

    /// Actual rotary angles for commanded words (angle-error compensation applied).
    #[inline]
    pub fn actual_angles(&self, words: &[f64; 3]) -> [f64; 3] {
        let mut a = [0.0; 3];
        for (i, r) in self.rotaries.iter().enumerate() {
            a[i] = r.actual(words[i]);
        }
        a
    }

    /// Whether any rotary has angle-error compensation: its actual angle is then not linear in
    /// the word, which rules out bounds that assume it is (linearization, the fold memo).
    pub fn has_angle_error(&self) -> bool {
        self.rotaries.iter().any(|r| r.angle_error.is_some())
    }

    pub fn rotary_index(&self, name: char) -> Option<usize> {
        self.rotaries.iter().position(|r| r.name == name)
    }

    /// "table-table", "head-head", "head-table", "3-axis", … for listings.
    pub fn kinematics_kind(&self) -> String {
        let tables = self.rotaries.iter().filter(|r| r.mount == Mount::Table).count();
        let heads = self.rotaries.len() - tables;
        let lin = self.linears.iter().filter(|l| l.is_some()).count();
        match (tables, heads) {
            (0, 0) => "3-axis".into(),
            (1, 0) | (0, 1) => "4-axis".into(),
            (2, 0) => "table-table".into(),
            (0, 2) => "head-head".into(),
            (1, 1) => "head-table".into(),
            _ => format!("{}-rotary/{lin}-linear", tables + heads),
        }
    }

    /// Names of the axes in NC word order (linears X Y Z present, then rotaries in chain order).
    pub fn axis_names(&self) -> Vec<char> {
        let mut v: Vec<char> = (0..3)
            .filter(|&i| self.linears[i].is_some())
            .map(|i| LINEAR_NAMES[i])
            .collect();
        v.extend(self.rotaries.iter().map(|r| r.name));
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::f64::consts::TAU;

    proptest! {
        /// The short cuts (travel under a turn, and longer travel without angle error) give what
        /// trying every winding gives.
        #[test]
        fn windings_are_every_word_in_travel(lo in -7.0f64..7.0, span in 0.0f64..12.0, actual in -14.0f64..14.0) {
            let r = Rotary {
                name: 'B',
                mount: Mount::Table,
                axis: Vec3::y(),
                pivot: Vec3::zeros(),
                limits: Some((lo, lo + span)),
                max_feed: None,
                max_accel: None,
                angle_error: None,
            };
            let want: Vec<f64> = (-6..=6)
                .map(|k| actual + k as f64 * TAU)
                .filter(|w| r.within(*w, 1e-9))
                .map(|w| w.clamp(lo, lo + span))
                .collect();
            prop_assert_eq!(&r.windings(actual, 0.0).to_vec(), &want);
            // The planner asks for the single word first, and takes it as the whole answer.
            if let Some(one) = r.one_winding(actual) {
                prop_assert_eq!(one.into_iter().collect::<Vec<_>>(), want);
            }
        }
    }

    proptest! {
        /// On a table with hundreds of turns of travel, the words listed are consecutive turns
        /// around the one nearest `near`.
        #[test]
        fn long_travel_lists_the_windings_around_near(near in -1700.0f64..1700.0, actual in -3.2f64..3.2) {
            let span = 1745.0; // ±99 999°, in radians
            let r = Rotary {
                name: 'C',
                mount: Mount::Table,
                axis: Vec3::z(),
                pivot: Vec3::zeros(),
                limits: Some((-span, span)),
                max_feed: None,
                max_accel: None,
                angle_error: None,
            };
            let ws = r.windings(actual, near);
            prop_assert_eq!(ws.len(), WINDINGS);
            let nearest = actual + ((near - actual) / TAU).round() * TAU;
            prop_assert!(ws.iter().any(|w| (w - nearest).abs() < 1e-6), "{ws:?} lacks {nearest}");
            prop_assert!(ws.iter().any(|w| *w < nearest - 1.0) && ws.iter().any(|w| *w > nearest + 1.0));
            for p in ws.windows(2) {
                prop_assert!((p[1] - p[0] - TAU).abs() < 1e-6);
            }
        }
    }

    #[test]
    fn windings_of_no_angle_are_none() {
        for limits in [(-1.0, 1.0), (-2.0 * TAU, 2.0 * TAU)] {
            let r = Rotary {
                name: 'C',
                mount: Mount::Table,
                axis: Vec3::z(),
                pivot: Vec3::zeros(),
                limits: Some(limits),
                max_feed: None,
                max_accel: None,
                angle_error: None,
            };
            assert!(r.windings(f64::NAN, 0.0).is_empty());
            assert!(r.windings(f64::INFINITY, 0.0).is_empty());
        }
    }
}
