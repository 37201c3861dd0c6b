//! One post on two threads: the CL read and planned (the source, IK candidates, the Viterbi
//! window) on a second thread, emitting, formatting, the collision check and the sink on the
//! caller's. The reading half hands over the same [`Op`]s a single thread applies as it goes,
//! in batches (one message per point would cost more than planning it) through a bounded
//! channel, so the output is the same byte for byte and memory stays flat.
//! The collision check stays with the emitter: it is about a third of a post, and replaying the
//! emitter on the reading thread to run part of it there cost more than it saved
//! (`docs/reliability.md`).
//!
//! The sink stays on the caller's thread (the CLI's, HTTP's and jobs' sinks need not be `Send`).
//! When the emitting half stops (an error, strict mode, the budget), it drops the channel: the
//! reading half's next send fails and it ends, so the caller never waits on a full queue.

use super::{Apply, Down, Error, Op, Plan, Sink, Summary};
use std::io::BufRead;
use std::sync::mpsc::{Receiver, SyncSender, TryRecvError, sync_channel};
use std::sync::Mutex;

/// Ops a batch: a CL point is about three (its bytes read, the point, its end), a batch some
/// 340 points and 240 KiB (512 woke the emitting half twice as often, for 7 % more CPU).
const BATCH: usize = 1024;
/// Batches queued between the halves: enough to ride out a slow block or a slow read, few
/// enough to keep memory flat (about 1.5 MB in flight at most).
const QUEUED: usize = 4;

/// The two-thread post. If no thread can be started, the post runs on this one.
pub(super) fn run<R: BufRead + Send, S: Sink + ?Sized>(plan: Plan<'_, R>, mut apply: Apply<'_, '_, S>) -> Result<Summary, Error> {
    // The reading half, where a failed spawn can take it back.
    let slot = Mutex::new(Some(plan));
    let threaded = std::thread::scope(|scope| {
        let (tx, rx) = sync_channel::<Vec<Op>>(QUEUED);
        let (back_tx, back_rx) = sync_channel::<Vec<Op>>(QUEUED + 2);
        let started = std::thread::Builder::new().name("kinepost-read".into()).spawn_scoped(scope, || {
            let taken = slot.lock().ok().and_then(|mut p| p.take());
            if let Some(plan) = taken {
                let mut down = Batches {
                    tx,
                    back: back_rx,
                    buf: Vec::with_capacity(BATCH),
                };
                if plan.produce(&mut down).is_ok() {
                    down.flush();
                }
            }
        });
        match started {
            Ok(_) => Some(consume(rx, back_tx, &mut apply)),
            Err(_) => None,
        }
        // Leaving the scope joins the reading half: `rx` is dropped by now, so it is not
        // blocked on a full queue.
    });
    match threaded {
        Some(r) => r,
        None => {
            let plan = slot.into_inner().ok().flatten().ok_or(Error::Engine("no reading thread"))?;
            let mut direct = super::Direct { apply, summary: None };
            plan.produce(&mut direct)?;
            direct.summary.ok_or(Error::Engine("the post ended without its end"))
        }
    }
}

/// The emitting half: applies the batches in order until the end or the first error. Takes the
/// receiver by value, so that returning closes the queue.
fn consume<S: Sink + ?Sized>(rx: Receiver<Vec<Op>>, back: SyncSender<Vec<Op>>, apply: &mut Apply<'_, '_, S>) -> Result<Summary, Error> {
    for mut batch in rx.iter() {
        for op in batch.drain(..) {
            if let Some(s) = apply.op(op)? {
                return Ok(s);
            }
        }
        // Back to the reading half for its next batch (none wanted: dropped).
        let _ = back.try_send(batch);
    }
    // The reading half ended without its end: it panicked (the scope says so when it joins).
    Err(Error::Engine("the reading thread stopped"))
}

/// The reading half's end of the queue.
struct Batches {
    tx: SyncSender<Vec<Op>>,
    back: Receiver<Vec<Op>>,
    buf: Vec<Op>,
}

impl Batches {
    /// Sends what is buffered; false: the emitting half is gone.
    fn flush(&mut self) -> bool {
        if self.buf.is_empty() {
            return true;
        }
        let next = match self.back.try_recv() {
            Ok(v) => v,
            Err(TryRecvError::Empty | TryRecvError::Disconnected) => Vec::with_capacity(BATCH),
        };
        self.tx.send(std::mem::replace(&mut self.buf, next)).is_ok()
    }
}

impl Down for Batches {
    fn op(&mut self, op: Op) -> Result<(), Error> {
        // The last op of a run goes at once.
        let last = matches!(op, Op::End | Op::Fail(_) | Op::Strict(_) | Op::ItemEnd(Some(_)));
        self.buf.push(op);
        if (last || self.buf.len() >= BATCH) && !self.flush() {
            return Err(Error::Engine("the emitting half stopped"));
        }
        Ok(())
    }
}
