//! Which pairs of bodies are checked, what is told of each, and the bound each keeps on its
//! bodies' distance.

use super::geometry::Link;

/// What is told of a pair, and when it is asked.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum PairKind {
    /// Any contact, and any approach closer than the clearance.
    Contact,
    /// The cutter against what it may cut into: only a depth beyond the chord tolerance.
    Cutter,
    /// The cutter against the stock: as [`PairKind::Cutter`], and only at rapids (a feed cuts
    /// the stock by design).
    CutterStock,
}

impl PairKind {
    /// Which pairs are checked: head-side bodies against the table side and the bed; the cutter
    /// only by its depth (and against stock only at rapid); the table side against the bed.
    pub(super) fn of(a: Link, b: Link) -> Option<PairKind> {
        let table_side = |l: Link| matches!(l, Link::TableRotary(_) | Link::Table | Link::Stock | Link::Fixture);
        match (a, b) {
            (Link::Cutter, Link::Stock) => Some(PairKind::CutterStock),
            (Link::Cutter, b) if table_side(b) || b == Link::Bed => Some(PairKind::Cutter),
            (Link::Cutter, _) => None,
            (a, b) if a.head_side() && (table_side(b) || b == Link::Bed) => Some(PairKind::Contact),
            (Link::TableRotary(_) | Link::Table, Link::Bed) => Some(PairKind::Contact),
            _ => None,
        }
    }

    /// Told below this distance: the clearance, or for the cutter the depth it may cut.
    pub(super) fn limit(self, clearance: f64, cut_depth: f64) -> f64 {
        match self {
            PairKind::Contact => clearance,
            PairKind::Cutter | PairKind::CutterStock => -cut_depth,
        }
    }

    /// Whether it is asked at this block (`stock`: the cutter is checked against the stock).
    pub(super) fn asked(self, stock: bool) -> bool {
        self != PairKind::CutterStock || stock
    }
}

/// Two bodies that can touch (indices into the world's bodies), and what is known of their
/// distance.
pub(super) struct Pair {
    pub(super) a: usize,
    pub(super) b: usize,
    pub(super) kind: PairKind,
    /// The index of the class of pairs moved by the same joints (`bounds::Bounds::class_of`).
    pub(super) class: u8,
    /// A lower bound on its bodies' distance: the last one measured, less how far its bodies
    /// could move relative to each other up to the last pass (`bounds::Bounds` keeps the rest).
    /// A pair still farther than it must be is not queried again; most pairs stay clear for
    /// many blocks, and parry's queries are the check's cost.
    pub(super) lower: f64,
    /// The distance its last query measured (NaN where it gave a bound only): with `lower`, how
    /// far the bodies can have moved since.
    pub(super) measured: f64,
}

impl Pair {
    /// A pair of bodies `a` and `b`, nothing known of their distance yet.
    pub(super) fn new(a: usize, b: usize, kind: PairKind, class: u8) -> Pair {
        Pair {
            a,
            b,
            kind,
            class,
            lower: f64::NEG_INFINITY,
            measured: f64::NAN,
        }
    }
}
