//! The cheap bounds that spare parry's queries: how far body points can move between two sets
//! of joints, counted per set of joints that moves a pair ([`Class`]), and how far each class's
//! pairs may move before one of them must be asked again.
//!
//! A pair keeps a lower bound on its bodies' distance ([`super::pairs::Pair`]); the world lowers
//! it by the motion of the pair's class since it was measured. While every class has moved less
//! than its [`Limit`], no pair can have come within what is told, and nothing is queried.

use super::geometry::Link;
use super::pairs::PairKind;
use crate::kinematics::{Machine, Mount};

/// Bit 3 of a set of joints: the linears (bits 0–2: the rotaries).
const LINEARS: u8 = 8;
/// As many classes as sets of joints (four bits; [`weights`] tells them apart).
pub(super) const CLASSES: usize = 16;

/// Which rotaries turn the table side and which the head: bit i set where rotary i does.
pub(super) struct Sides {
    table: u8,
    head: u8,
}

impl Sides {
    pub(super) fn of(m: &Machine) -> Sides {
        let on = |mount: Mount| (0..m.rotaries.len()).filter(|&i| m.rotaries[i].mount == mount).fold(0, |t, i| t | (1 << i));
        Sides {
            table: on(Mount::Table),
            head: on(Mount::Head),
        }
    }

    /// The joints that move link `l` relative to the bed. Each side's links are moved by a
    /// prefix of its chain and the two sides share no joint, so the joints between two links
    /// (those that move one relative to the other) are the two sets' symmetric difference.
    pub(super) fn joints_of(&self, l: Link) -> u8 {
        let upto = |i: usize| (2u8 << i) - 1;
        match l {
            Link::Bed => 0,
            Link::TableRotary(i) => self.table & upto(i),
            Link::Table | Link::Stock | Link::Fixture => self.table,
            Link::Ram => LINEARS,
            Link::HeadRotary(i) => LINEARS | (self.head & upto(i)),
            Link::Spindle | Link::Holder | Link::Cutter => LINEARS | self.head,
        }
    }
}

/// How far a class's pairs (or every pair) may move before one must be asked again: the pairs
/// but the cutter against the stock, and all of them, that one counted too (at a rapid).
#[derive(Clone, Copy)]
struct Limit {
    without_stock: f64,
    with_stock: f64,
}

impl Limit {
    /// Nothing known: every pair must be asked.
    const NONE: Limit = Limit {
        without_stock: f64::NEG_INFINITY,
        with_stock: f64::NEG_INFINITY,
    };

    fn of(&self, stock: bool) -> f64 {
        if stock { self.with_stock } else { self.without_stock }
    }

    /// The lesser of the two, field by field (see [`least`]).
    fn least(&self, o: &Limit) -> Limit {
        Limit {
            without_stock: least(self.without_stock, o.without_stock),
            with_stock: least(self.with_stock, o.with_stock),
        }
    }
}

/// The pairs whose bodies move relative to each other by the same joints.
struct Class {
    /// 1 for each of [`Motion::by_joint`]'s terms that moves its pairs, else 0.
    weights: [f64; 4],
    /// Set at each pass from the least of its pairs' `lower` less each one's limit: its pairs
    /// are clear while their motion since stays below it.
    limit: Limit,
}

/// The least margin of a class's pairs at a pass (their lower bound less their limit): of the
/// cutter against the stock, and of the others.
#[derive(Clone, Copy)]
pub(super) struct Slack {
    others: f64,
    stock: f64,
}

impl Slack {
    pub(super) const NONE: Slack = Slack {
        others: f64::INFINITY,
        stock: f64::INFINITY,
    };

    /// Takes a pair of `kind` with `margin` into account.
    pub(super) fn add(&mut self, kind: PairKind, margin: f64) {
        let s = match kind {
            PairKind::CutterStock => &mut self.stock,
            PairKind::Contact | PairKind::Cutter => &mut self.others,
        };
        *s = least(*s, margin);
    }
}

/// The classes of the pairs, their limits, and the motion since the last pass over the pairs.
pub(super) struct Bounds {
    /// The pairs moved by the same joints share a bound on their motion, so that a head-side
    /// body against a bed-fixed one counts only the linears.
    classes: Vec<Class>,
    /// The least of the classes' limits: while every joint's motion together stays below it,
    /// no class needs a look of its own.
    least: Limit,
    /// The motion since the last pass over the pairs, joint by joint.
    since: Since,
}

impl Bounds {
    pub(super) fn new() -> Bounds {
        Bounds {
            classes: Vec::new(),
            least: Limit::NONE,
            since: Since::ZERO,
        }
    }

    /// No classes (the pairs are listed again) and nothing clear.
    pub(super) fn reset(&mut self) {
        self.classes.clear();
        self.least = Limit::NONE;
    }

    /// The index of the class moved by `joints` (bits as [`Sides::joints_of`]'s), added if new.
    pub(super) fn class_of(&mut self, joints: u8) -> u8 {
        let w = weights(joints);
        let c = self.classes.iter().position(|k| k.weights == w).unwrap_or_else(|| {
            self.classes.push(Class {
                weights: w,
                limit: Limit::NONE,
            });
            self.classes.len() - 1
        });
        c as u8
    }

    /// Counts `m` into the motion since the last pass.
    pub(super) fn moved(&mut self, m: &Motion) {
        self.since = self.since.plus(m);
    }

    /// Whether every pair is still clear by its bound less the motion since the last pass.
    pub(super) fn clear(&self, stock: bool) -> bool {
        self.clear_by(&self.since, stock)
    }

    /// Counts `m` into the motion since the last pass where every pair stays clear with it;
    /// where not, counts nothing and says so.
    pub(super) fn moved_clear(&mut self, m: &Motion, stock: bool) -> bool {
        let since = self.since.plus(m);
        if !self.clear_by(&since, stock) {
            return false;
        }
        self.since = since;
        true
    }

    /// All joints' motion against every class's limit at once, else class by class.
    fn clear_by(&self, since: &Since, stock: bool) -> bool {
        since.of(&[1.0; 4]) < self.least.of(stock) || self.classes.iter().all(|c| since.of(&c.weights) < c.limit.of(stock))
    }

    /// Per class, the motion of its pairs since the last pass.
    pub(super) fn since(&self) -> [f64; CLASSES] {
        let mut moved = [0.0; CLASSES];
        for (c, m) in self.classes.iter().zip(&mut moved) {
            *m = self.since.of(&c.weights);
        }
        moved
    }

    /// A pass over the pairs is done, each class's least margin in `slack`: the motion starts
    /// again from nothing and the limits are the margins.
    pub(super) fn passed(&mut self, slack: [Slack; CLASSES]) {
        self.since = Since::ZERO;
        self.least = Limit {
            without_stock: f64::INFINITY,
            with_stock: f64::INFINITY,
        };
        for (class, s) in self.classes.iter_mut().zip(slack) {
            // Clear while the motion stays below the slack less a margin (1e-9 of it).
            let below = |s: f64| if s.is_finite() { s - 1e-9 * (1.0 + s.abs()) } else { s };
            class.limit = Limit {
                without_stock: below(s.others),
                with_stock: least(below(s.others), below(s.stock)),
            };
            self.least = self.least.least(&class.limit);
        }
    }
}

/// How far body points may have moved since the last pass over the pairs, joint by joint.
#[derive(Clone, Copy)]
struct Since {
    /// As [`Motion::by_joint`], summed and rounded up: never short of the motion.
    by_joint: [f64; 4],
    /// Unknown (the first check, or another tool length or work offset since).
    unknown: bool,
}

impl Since {
    const ZERO: Since = Since {
        by_joint: [0.0; 4],
        unknown: false,
    };

    fn plus(&self, m: &Motion) -> Since {
        let mut s = *self;
        s.unknown |= !m.known;
        for (a, d) in s.by_joint.iter_mut().zip(m.by_joint) {
            *a = (*a + d) * (1.0 + 2.0 * f64::EPSILON);
        }
        s
    }

    /// The motion of points moved by the joints `w` weighs (a class's), rounded up.
    fn of(&self, w: &[f64; 4]) -> f64 {
        let d = &self.by_joint;
        let sum = (w[0] * d[0] + w[1] * d[1] + w[2] * d[2] + w[3] * d[3]) * (1.0 + 4.0 * f64::EPSILON);
        if self.unknown { f64::INFINITY } else { sum }
    }
}

/// How far body points can move between two joint sets, by the joints that move them.
pub(super) struct Motion {
    /// False: nothing known (no joints checked before, or another tool length or work offset).
    known: bool,
    /// The linear move, then per rotary its turn times the farthest a body point can be from
    /// its axis.
    by_joint: [f64; 4],
}

impl Motion {
    pub(super) const UNKNOWN: Motion = Motion {
        known: false,
        by_joint: [0.0; 4],
    };

    pub(super) fn known(by_joint: [f64; 4]) -> Motion {
        Motion { known: true, by_joint }
    }

    pub(super) fn total(&self) -> f64 {
        if self.known { self.by_joint.iter().sum() } else { f64::INFINITY }
    }
}

/// A class's [`Class::weights`] for `joints` (bits as [`Sides::joints_of`]'s).
fn weights(joints: u8) -> [f64; 4] {
    let on = |bit: u8| if joints & bit != 0 { 1.0 } else { 0.0 };
    [on(LINEARS), on(1), on(2), on(4)]
}

/// The lesser, or NaN where either is (a NaN bound, from NaN joints, must keep its class from
/// ever counting as clear).
fn least(a: f64, b: f64) -> f64 {
    if a.is_nan() || b.is_nan() { f64::NAN } else { a.min(b) }
}

/// Where a touching pair's last measured distance still tells it well enough that it need not
/// be asked again: its bodies moved at most `measured − lower` since, so it is within that of
/// the distance now. Enough: what it tells is sure (within `limit`; overlapping or not, the
/// bound either way) and that is at most the sample spacing, or a quarter of the measure where
/// more (an overlap of 40 mm plunging on is still a collision of about 40). A pair overlapping
/// at every sample of a long move cost a penetration query at each: 99% of the time of a
/// program posted under the table.
pub(super) fn settled(measured: f64, lower: f64, limit: f64, spacing: f64) -> Option<f64> {
    let moved = measured - lower;
    let upper = measured + moved;
    let sure = upper <= limit && (upper < 0.0 || lower >= 0.0);
    (sure && moved <= spacing.max(0.25 * measured.abs())).then_some(measured)
}
