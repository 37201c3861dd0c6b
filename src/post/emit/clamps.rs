//! Rotary clamps: the profile's lock and unlock words, one writer of them. A clamped rotary is
//! unlocked before a block that turns it and locked again after positioning and at the end;
//! an operation that turns a rotary while cutting keeps them all open to its end.

use super::Emitter;
use crate::diag::{Code, Diagnostic, Severity};
use crate::kinematics::Joints;
use crate::post::Sink;
use crate::post::Stop;

/// Which clamped rotaries are locked (a clamped axis is taken as locked at the start).
#[derive(Debug)]
pub(super) struct Clamps {
    locked: [bool; 3],
    /// The operation ahead turns a rotary while cutting: no clamp is locked until it ends.
    cut_turns: bool,
    /// Per rotary: its clamp words are no codes of the dialect's control, and not written.
    unknown: [bool; 3],
}

impl Default for Clamps {
    fn default() -> Clamps {
        Clamps {
            locked: [true; 3],
            cut_turns: false,
            unknown: [false; 3],
        }
    }
}

impl Clamps {
    /// Whether the operation ahead turns a rotary while cutting (seen in the look-ahead; at the
    /// end, none does).
    pub(super) fn operation_ahead(&mut self, turns: bool) {
        self.cut_turns = turns;
    }
}

impl<S: Sink + ?Sized> Emitter<'_, S> {
    /// The profile clamps a rotary.
    pub(in crate::post) fn clamped(&self) -> bool {
        self.o.clamps.iter().any(Option::is_some)
    }

    /// The look-ahead's finding at a rapid or an operation's start: whether the cut ahead
    /// `turns` a rotary while cutting, and if so every clamp released now, before its first move.
    pub(in crate::post) fn operation_ahead(&mut self, turns: bool) -> Result<(), Stop> {
        self.clamps.cut_turns = turns;
        if turns { self.unlock_all() } else { Ok(()) }
    }

    /// Lock every clamped rotary that is unlocked (after positioning, at the end), unless the
    /// operation ahead turns a rotary while cutting: then it stays unlocked to its end.
    pub(super) fn lock_all(&mut self) -> Result<(), Stop> {
        if self.clamps.cut_turns {
            return Ok(());
        }
        self.set_clamps(true)
    }

    /// Unlock every locked clamp: before an operation that turns a rotary while cutting.
    fn unlock_all(&mut self) -> Result<(), Stop> {
        self.set_clamps(false)
    }

    /// Lock (or unlock) every clamped rotary not already so.
    fn set_clamps(&mut self, lock: bool) -> Result<(), Stop> {
        for i in 0..self.m.rotaries.len() {
            self.clamp(i, lock)?;
        }
        Ok(())
    }

    /// Write rotary `i`'s lock (or unlock) word where its clamp's state differs, and note the
    /// new state; a clamp whose state is unknown (a passed-through word set it) is left alone.
    fn clamp(&mut self, i: usize, lock: bool) -> Result<(), Stop> {
        let Some((on, off)) = &self.o.clamps[i] else { return Ok(()) };
        if self.clamps.locked[i] == lock || self.clamps.unknown[i] {
            return Ok(());
        }
        let (open, close) = self.o.dialect.comment.clone();
        let word = if lock { on.clone() } else { off.clone() };
        let what = if lock { "LOCK" } else { "UNLOCK" };
        let l = format!("{} {open}{} {what}{close}", self.f.words(&word), self.m.rotaries[i].name);
        self.out(&l)?;
        self.clamps.locked[i] = lock;
        Ok(())
    }

    /// Unlock the clamped rotaries this move turns.
    pub(super) fn unlock_moving(&mut self, to: &Joints) -> Result<(), Stop> {
        // Before the first block the machine stands at home: rotaries at 0.
        let from = self.at.map_or([0.0; 3], |p| p.joints.rotary);
        for i in 0..self.m.rotaries.len() {
            if (to.rotary[i] - from[i]).abs() > 1e-12 {
                self.clamp(i, false)?;
            }
        }
        Ok(())
    }

    /// Clamp words the control does not know stop the program where it reads them: not
    /// written, told once per rotary at the start.
    pub(super) fn unknown_clamps(&mut self) -> Result<(), Stop> {
        for i in 0..self.m.rotaries.len() {
            let Some((lock, unlock)) = &self.o.clamps[i] else { continue };
            let d = self.o.dialect.clone();
            let bad: Vec<&str> = [lock, unlock].into_iter().map(String::as_str).filter(|w| !d.knows(w)).collect();
            if bad.is_empty() {
                continue;
            }
            self.clamps.unknown[i] = true;
            let msg = format!(
                "the profile's clamp words for {} ({}) are no {} codes: not written, so {} turns and cuts unclamped; give the profile the codes this control's configuration provides",
                self.m.rotaries[i].name,
                bad.join(", "),
                d.title,
                self.m.rotaries[i].name
            );
            self.note(Diagnostic::new(Code::UnknownWord, Severity::Warning, None, msg))?;
        }
        Ok(())
    }
}
