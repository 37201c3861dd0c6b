//! How many samples the motion between two blocks is checked at, and what one post's check may
//! spend on them.

/// The most samples of the motion between two blocks: a bound on one block's cost. A move that
/// needs more is told (`collision_coarse`).
pub const MAX_SAMPLES: usize = 16384;
/// What one post's check may spend: [`MAX_SAMPLES`] once, then 256 a move on average; past it a
/// move gets what is left, at least 64, and is told coarse. A stock of ±1e8 (its far corners
/// swinging metres a degree), a 1e-6 mm fixture or a 1e-9 clearance asked the most of every
/// move and multiplied a post's time by 40 to thousands; now its cost is bounded by its moves.
pub const SAMPLES_PER_MOVE: u64 = 256;
const COARSE_SAMPLES: u64 = 64;

/// Samples too few for a move's motion: how far apart they are (the most a body moves between
/// two), and how far apart the check keeps them where it can (profile units).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Coarse {
    pub apart: f64,
    pub step: f64,
}

/// The moves sampled in one post, and the samples they took: the post's allowance
/// ([`SAMPLES_PER_MOVE`]).
#[derive(Default)]
pub(super) struct Allowance {
    moves: u64,
    spent: u64,
}

impl Allowance {
    /// The samples of a move whose bodies move at most `moved`, kept `step` apart where the
    /// allowance lets them (at least one), and where it does not, how coarse they are.
    pub(super) fn take(&mut self, moved: f64, step: f64) -> (usize, Option<Coarse>) {
        let n = (moved / step).ceil();
        self.moves += 1;
        let left = (MAX_SAMPLES as u64 + SAMPLES_PER_MOVE * self.moves).saturating_sub(self.spent);
        let most = left.clamp(COARSE_SAMPLES, MAX_SAMPLES as u64) as usize;
        let (n, coarse) = match n.is_finite() && n <= most as f64 {
            true => ((n as usize).max(1), None),
            false => (most, Some(Coarse { apart: moved / most as f64, step })),
        };
        self.spent += n as u64;
        (n, coarse)
    }
}
