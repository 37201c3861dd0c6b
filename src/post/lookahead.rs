//! What must see ahead before it is written: a singular point the machine positions onto waits
//! for the point that fixes its free rotary, and with tilted planes a fixed-axis run is known to
//! end at a rapid. Items wait here, bounded by [`LOOK_AHEAD`].

use super::emit::{Ahead, Emitter};
use super::plan::Out;
use super::{Error, PLANE_AXIS_EPS, ProgEvent, Sink};
use crate::kinematics::{Vec3, angle_between};
use std::collections::VecDeque;
use super::Stop;

/// The free rotary's angle at the first point ahead of a singular one that fixes it, within the
/// cut (up to a rapid, a tool change or the end, and [`LOOK_AHEAD`] items): what a machine that
/// positions onto the singular point turns to, instead of turning it during the cut that follows.
fn free_angle_ahead(free: usize, ahead: &VecDeque<Out>) -> Option<f64> {
    ahead.iter().take(LOOK_AHEAD).find_map(|o| free_angle_at(o, free)).flatten()
}

/// What `o` says of the free angle (rotary `free`) of a singular point before it: `Some(Some(a))`
/// a point that fixes it at `a`, `Some(None)` the cut ends first (a rapid, a tool change, the
/// end), `None` nothing yet.
fn free_angle_at(o: &Out, free: usize) -> Option<Option<f64>> {
    match o {
        Out::Event(ev) => matches!(ev, ProgEvent::Tool { .. } | ProgEvent::End).then_some(None),
        Out::Point(c) if c.pt.rapid => Some(None),
        // The planner's word: a bounded table's winding is there, not in the IK's angle.
        Out::Point(c) => match &c.cand {
            Some(k) if k.sol.singular.is_none() => Some(Some(k.sol.joints.rotary[free])),
            _ => None,
        },
    }
}

/// Items held back for the tilted-plane look-ahead (about one planner commit).
const LOOK_AHEAD: usize = 256;

/// Whether the run of points after a rapid keeps `axis` until a rapid with another axis, a tool
/// change or the end, as far as the next [`LOOK_AHEAD`] items show (beyond them, the run is taken
/// as fixed: a later cut that turns the axis is repositioned out of the plane). Exactly that far,
/// however much the planner happened to commit at once, so that the output does not depend on it.
fn fixed_run_ahead(axis: &Vec3, ahead: &VecDeque<Out>) -> bool {
    for o in ahead.iter().take(LOOK_AHEAD) {
        match o {
            Out::Event(ProgEvent::Tool { .. } | ProgEvent::End) => return true,
            Out::Event(_) => {}
            Out::Point(c) => {
                if angle_between(axis, &c.pt.pose.axis) > PLANE_AXIS_EPS {
                    return c.pt.rapid;
                }
            }
        }
    }
    true
}

/// Whether the cut ahead of a rapid (or of an operation's start) at tool axis `axis` turns a
/// rotary while cutting: a feed move to another tool axis before the operation ends (the next
/// `TOOL PATH`, a tool change, the end) or a rapid to another axis (a reposition, which decides
/// its own run), as far as [`LOOK_AHEAD`] items show. Such a rotary is left unlocked for the
/// whole operation: a clamp word between two feed moves stops the machine mid-surface.
fn turns_while_cutting(axis: &Vec3, ahead: &VecDeque<Out>) -> bool {
    let mut prev = *axis;
    for o in ahead.iter().take(LOOK_AHEAD) {
        match o {
            Out::Event(ProgEvent::Tool { .. } | ProgEvent::End | ProgEvent::Operation(_)) => return false,
            Out::Event(_) => {}
            Out::Point(c) => {
                if angle_between(&prev, &c.pt.pose.axis) > PLANE_AXIS_EPS {
                    return !c.pt.rapid;
                }
                prev = c.pt.pose.axis;
            }
        }
    }
    false
}

/// Hands what the planner committed to the emitter: at once, or with tilted planes through the
/// look-ahead queue (see [`Emitter::drain`]). The first error stops the rest.
pub(super) fn deliver<S: Sink + ?Sized>(e: &mut Emitter<'_, S>, pending: &mut VecDeque<Out>, failed: &mut Option<Error>, x: Out) {
    if failed.is_some() {
        return;
    }
    if e.looks_ahead() {
        pending.push_back(x);
        return;
    }
    // A singular point the machine positions onto waits for the point that fixes its free
    // rotary (see `free_angle_ahead`); everything else goes straight through.
    if pending.is_empty() && !e.positions_onto_singular(&x) {
        if let Err(err) = e.take(x, pending) {
            *failed = Some(err);
        }
        return;
    }
    // Whatever the free rotary's index, the same items settle it.
    let resolves = free_angle_at(&x, 0).is_some();
    pending.push_back(x);
    if resolves || pending.len() > LOOK_AHEAD {
        while let Some(o) = pending.pop_front() {
            if let Err(err) = e.take(o, pending) {
                *failed = Some(err);
                return;
            }
        }
    }
}

impl<S: Sink + ?Sized> Emitter<'_, S> {
    /// Writes what the planner committed, keeping [`LOOK_AHEAD`] items back (until `all`) when
    /// tilted planes are on: whether a fixed-axis run ends at a rapid is decided from them.
    pub(in crate::post) fn drain(&mut self, pending: &mut VecDeque<Out>, all: bool) -> Result<(), Error> {
        // Without tilted planes or clamps only a held singular point waits here (`deliver`
        // releases it).
        if !all && !self.looks_ahead() {
            return Ok(());
        }
        let keep = if all || !self.looks_ahead() { 0 } else { LOOK_AHEAD };
        while pending.len() > keep {
            let Some(o) = pending.pop_front() else { break };
            self.take(o, pending)?;
        }
        Ok(())
    }

    /// A committed singular point that the machine reaches by positioning (the first move, after
    /// a tool change, a rapid): its free rotary is best taken from the cut that follows.
    pub(in crate::post) fn positions_onto_singular(&self, x: &Out) -> bool {
        match x {
            Out::Point(c) => c.cand.as_ref().is_some_and(|k| k.sol.singular.is_some()) && self.positioning(&c.pt),
            Out::Event(_) => false,
        }
    }

    /// Whether items wait in the look-ahead: for tilted planes, and for clamps (whether an
    /// operation turns a rotary while cutting).
    pub(in crate::post) fn looks_ahead(&self) -> bool {
        self.tilted_planes() || self.clamped()
    }

    /// At a rapid or an operation's start: whether the cut ahead turns a rotary while cutting,
    /// and if so the clamps released now, before its first move (see [`turns_while_cutting`]).
    fn clamps_ahead(&mut self, axis: Option<Vec3>, ahead: &VecDeque<Out>) -> Result<(), Stop> {
        let Some(axis) = axis.filter(|_| self.clamped()) else {
            return Ok(());
        };
        let turns = turns_while_cutting(&axis, ahead);
        self.operation_ahead(turns)
    }

    /// One committed item, with what is known to follow it (the tilted-plane and clamp
    /// look-ahead).
    pub(in crate::post) fn take(&mut self, o: Out, ahead: &VecDeque<Out>) -> Result<(), Error> {
        match o {
            Out::Event(ev) => {
                if matches!(ev, ProgEvent::Operation(_)) {
                    let first = ahead.iter().find_map(|o| match o {
                        Out::Point(c) => Some(c.pt.pose.axis),
                        Out::Event(_) => None,
                    });
                    self.clamps_ahead(first, ahead)?;
                }
                self.event(ev)
            }
            Out::Point(c) => {
                if c.pt.rapid {
                    self.clamps_ahead(Some(c.pt.pose.axis), ahead)?;
                }
                let found = Ahead {
                    plane: c.pt.rapid && self.tilted_planes() && fixed_run_ahead(&c.pt.pose.axis, ahead),
                    free: c
                        .cand
                        .as_ref()
                        .and_then(|k| k.sol.singular)
                        .and_then(|free| free_angle_ahead(free, ahead)),
                };
                self.point(c, found)
            }
        }
    }
}
