//! What one post may cost, enforced where output is written: the sink the engine writes through
//! stops the run at the [`Budget`]'s bound (output records per CL byte read, seconds). The time
//! and the reader's going are also looked at where the engine works without writing (between CL
//! items, between a collision check's samples: [`Sink::halted`]), so that the run stops within a
//! second of either, not at its next write.

use super::{BlockInfo, Budget, Sink, Stop, Summary};
use crate::diag::Diagnostic;
use crate::kinematics::Pose;
use std::time::Instant;

/// The caller's sink, behind the budget: past it, every write fails with [`Stop::Budget`].
pub(super) struct Metered<'a, S: Sink + ?Sized> {
    /// The caller's sink: what must be told past the bound (the reader's held words at a stop)
    /// is written to it directly.
    pub inner: &'a mut S,
    budget: Budget,
    /// CL bytes read so far, as the driver last said.
    pub read: u64,
    started: Instant,
    /// Lines and diagnostics written, and the count at which the bound is next worked out.
    written: u64,
    next_check: u64,
    /// Looks since the clock was last read ([`Sink::halted`]).
    polls: u32,
    /// Why the budget stopped the run, once it has: every write after fails the same way.
    tripped: Option<String>,
}

impl<'a, S: Sink + ?Sized> Metered<'a, S> {
    pub fn new(inner: &'a mut S, budget: Budget) -> Self {
        Metered {
            inner,
            budget,
            read: 0,
            started: Instant::now(),
            written: 0,
            next_check: 0,
            polls: 0,
            tripped: None,
        }
    }

    /// Counts one record; fails past the bound. The bound and the clock are looked at every
    /// 256 records (the clock per block would cost a few percent).
    fn count(&mut self) -> Result<(), Stop> {
        if let Some(why) = &self.tripped {
            return Err(Stop::Budget(why.clone()));
        }
        self.written += 1;
        if self.written < self.next_check {
            return Ok(());
        }
        self.next_check = self.written + 256;
        let secs = self.started.elapsed().as_secs_f64();
        match self.budget.exceeded(self.written, self.read, secs) {
            Some(why) => {
                self.tripped = Some(why.clone());
                Err(Stop::Budget(why))
            }
            None => Ok(()),
        }
    }
}

impl<S: Sink + ?Sized> Sink for Metered<'_, S> {
    fn line(&mut self, text: &str, block: Option<&BlockInfo>) -> Result<(), Stop> {
        self.count()?;
        self.inner.line(text, block)
    }
    fn diagnostic(&mut self, d: &Diagnostic) -> Result<(), Stop> {
        self.count()?;
        self.inner.diagnostic(d)
    }
    fn diagnostic_at(&mut self, d: &Diagnostic, pose: &Pose) -> Result<(), Stop> {
        self.count()?;
        self.inner.diagnostic_at(d, pose)
    }
    fn summary(&mut self, s: &Summary) -> Result<(), Stop> {
        self.inner.summary(s)
    }
    fn tool(&mut self, first_block: u64, t: &crate::collide::ToolShape) {
        self.inner.tool(first_block, t)
    }
    /// The reader's going at every look, the clock at every 16th (a look costs a few ns, the
    /// clock some 25; looks come at least once per CL item and per collision sample).
    fn halted(&mut self) -> Option<Stop> {
        if let Some(why) = &self.tripped {
            return Some(Stop::Budget(why.clone()));
        }
        // The caller's reason (a cancel, a reader gone): it keeps it, and says it again.
        if let Some(stop) = self.inner.halted() {
            return Some(stop);
        }
        self.polls += 1;
        if self.polls < 16 {
            return None;
        }
        self.polls = 0;
        // The time only: the output bound is counted where output is written, as before.
        let secs = self.started.elapsed().as_secs_f64();
        self.tripped = self.budget.exceeded(0, self.read, secs);
        self.tripped.clone().map(Stop::Budget)
    }
}
