//! What `MOVARC`'s sweep and `CLEARP` / `RETRCT` ask of the path.

use super::{Item, Source};
use crate::cl::Plane;
use crate::diag::{Code, Severity};
use crate::kinematics::Vec3;
use std::f64::consts::TAU;
use std::io::BufRead;

/// How far (radians) a `MOVARC`'s stated sweep may be from its end point's.
const SWEEP_TOLERANCE: f64 = 1e-3;

impl<R: BufRead> Source<R> {
    /// The arc a `MOVARC` means: its sweep `want` decides the sense (an older Autodesk post
    /// kept a clockwise arc's axis, so it runs clockwise about it) and the whole turns. None:
    /// neither sense sweeps it, and the move is taken as straight, an error.
    pub(super) fn movarc_sense(&mut self, line: u32, k: Vec3, sweep: f64, want: f64) -> Option<(Vec3, f64)> {
        let turns = |s: f64| ((want - s) / TAU).round().max(0.0);
        let fits = |s: f64| (want - (s + turns(s) * TAU)).abs() <= SWEEP_TOLERANCE;
        let other = TAU - sweep.rem_euclid(TAU);
        if fits(sweep) {
            return Some((k, sweep + turns(sweep) * TAU));
        }
        if other > 1e-9 && fits(other) {
            let msg = format!(
                "MOVARC: its ANGLE of {:.4}° is swept clockwise about its axis (a post that kept a clockwise arc's axis): cut that way",
                want.to_degrees()
            );
            self.diag(Code::ArcLinearized, Severity::Info, line, msg);
            return Some((-k, other + turns(other) * TAU));
        }
        let msg = format!(
            "MOVARC: its ANGLE of {:.4}° is swept neither way from the start to this end ({:.4}° or {:.4}°): taken as a straight move",
            want.to_degrees(),
            sweep.to_degrees(),
            other.to_degrees()
        );
        self.diag(Code::BadRecord, Severity::Error, line, msg);
        None
    }

    /// `CLEARP`: the plane, taken into the part frame now (the frame may change before the
    /// `RETRCT`).
    pub(super) fn clearance(&mut self, plane: Option<Plane>) {
        self.clearance = plane.map(|p| {
            let n = Vec3::from(p.normal);
            let on = self.to_part_point(n * p.offset);
            let n = self.to_part(n);
            (n, n.dot(&on))
        });
    }

    /// `RETRCT`: at rapid along the tool axis to the clearance plane, from where the tool is.
    pub(super) fn retract(&mut self, line: u32) {
        let (Some((n, offset)), Some(tip)) = (self.clearance, self.tip) else {
            let why = if self.clearance.is_none() { "no clearance plane (CLEARP) in force" } else { "no position yet" };
            self.diag(Code::IgnoredRecord, Severity::Warning, line, format!("RETRCT: {why}: no retract written"));
            return;
        };
        let from = self.to_part_point(tip);
        let along = n.dot(&self.axis);
        let s = (offset - n.dot(&from)) / along;
        if along.abs() < 1e-9 || !s.is_finite() {
            let msg = "RETRCT: the tool axis is parallel to the clearance plane: no retract written";
            self.diag(Code::IgnoredRecord, Severity::Warning, line, msg.into());
            return;
        }
        if s <= 0.0 {
            let msg = "RETRCT: the tool is at or beyond the clearance plane already: no move";
            self.diag(Code::IgnoredRecord, Severity::Info, line, msg.into());
            return;
        }
        let to = self.to_cl_point(from + self.axis * s);
        let pt = self.motion_pt(line, to, true, true, Some("RETRCT"));
        self.out.push_back(Item::Motion(pt));
        self.tip = Some(to);
    }
}
