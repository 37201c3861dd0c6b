//! Arcs: G2/G3 (Heidenhain CC + C) where the pose allows, else chords within the tolerance.

use super::block::Move;
use super::{ArcBlock, At, Emitter};
use crate::diag::{Code, Diagnostic, Severity};
use crate::kinematics::{self, Pose, Vec3};
use crate::post::{ArcSpec, Error, Mode, MotionPt, Sink};

impl<S: Sink + ?Sized> Emitter<'_, S> {
    /// An arc from `a` to `b`: G2/G3 (Heidenhain: CC + C) where the tool axis stays put and the
    /// arc's plane is a principal plane of the output coordinates (the machine's in joint mode,
    /// the part's in TCP mode), else chords within the tolerance (with the rotaries still, chords are straight in
    /// the machine too, so no further check is needed).
    pub(super) fn arc_move(&mut self, a: At, b: At, arc: &ArcSpec, pt: &MotionPt, diags: Vec<Diagnostic>) -> Result<(), Error> {
        let m = self.m;
        let still = (0..m.rotaries.len()).all(|i| (a.joints.rotary[i] - b.joints.rotary[i]).abs() < 1e-9);
        let tcp = self.o.mode == Mode::Tcp;
        let full_linears = m.linears.iter().all(|l| l.is_some());
        let conversational = self.o.dialect.style == crate::nc::Style::Conversational;
        // In a tilted plane (the arc's end stands on the plane's rotaries): plane coordinates.
        let tilt = self.plane_at(&b.joints.rotary);
        let (center, normal, start) = if let Some(t) = &tilt {
            (
                self.plane_coords(t, &arc.center),
                t.frame.transpose() * arc.normal,
                self.plane_coords(t, &a.pose.tip),
            )
        } else if tcp && !m.has_angle_error() {
            (arc.center, arc.normal, a.pose.tip)
        } else if tcp {
            // The words' frame is the nominal one: the CL's frame moved rigidly at still rotaries.
            let c = self.tcp_xyz(&self.at_tip(&b, arc.center));
            let n = self.tcp_xyz(&self.at_tip(&b, arc.center + arc.normal)) - c;
            (c, n, self.tcp_xyz(&a))
        } else {
            let c = kinematics::controlled_point(m, &b.actual, &arc.center, self.tool.setup());
            let n = kinematics::controlled_point(m, &b.actual, &(arc.center + arc.normal), self.tool.setup()) - c;
            (c, n, Vec3::from(a.joints.linear))
        };
        // Along the helix (a flat arc: no rise): what the tool travels at F.
        let length = (arc.radius * arc.sweep).hypot(arc.normal.dot(&(b.pose.tip - a.pose.tip)));
        // G17: normal ±Z (I J), G18: ±Y (I K), G19: ±X (J K).
        let plane = [(2usize, "G17", [0usize, 1]), (1, "G18", [0, 2]), (0, "G19", [1, 2])]
            .into_iter()
            .find(|(k, _, _)| normal[*k].abs() > 1.0 - 1e-9);
        if let (true, true, false, Some((k, word, ij))) = (still, tcp || full_linears, conversational, plane) {
            let ccw = normal[k] > 0.0;
            if self.frames.circular(word) {
                let l = self.f.words(word).to_string();
                self.out(&l)?;
            }
            // A helix of several turns (NX's TIMES): one block can say at most one, and an end on
            // its start reads as a full circle on some controls only. Half turns say it anywhere.
            let pieces = if arc.sweep > std::f64::consts::TAU + 1e-9 {
                (arc.sweep / std::f64::consts::PI).ceil() as usize
            } else {
                1
            };
            let mut from = start;
            for i in 1..=pieces {
                let to = if i == pieces {
                    b
                } else {
                    self.at_tip(&b, helix_tip(a.pose.tip, b.pose.tip, arc, i as f64 / pieces as f64))
                };
                let d = center - from;
                let dec = self.f.fmt.linear;
                let mut words = String::new();
                for idx in ij {
                    words.push(['I', 'J', 'K'][idx]);
                    crate::nc::write_fixed(&mut words, crate::nc::round_to(d[idx], dec), dec);
                    words.push(' ');
                }
                let piece = ArcBlock {
                    ccw,
                    words: words.trim_end().to_string(),
                    length: length / pieces as f64,
                    path: (a.pose.tip, b.pose.tip, *arc, [(i - 1) as f64, i as f64].map(|k| k / pieces as f64)),
                };
                if i == pieces {
                    return self.write(b, pt, Move::Arc(piece), diags, pt.inserted, None);
                }
                from = match &tilt {
                    Some(t) => self.plane_coords(t, &to.pose.tip),
                    None if tcp => self.tcp_xyz(&to),
                    None => Vec3::from(to.joints.linear),
                };
                self.write(to, pt, Move::Arc(piece), Vec::new(), true, None)?;
            }
        }
        // Heidenhain: `CC` (the centre, absolute) then `C` to the end point with `DR+`/`DR-`, for a
        // flat arc in the working plane (XY: the tool along Z); anything else as chords.
        let end = match &tilt {
            Some(t) => self.plane_coords(t, &b.pose.tip),
            None if tcp => self.tcp_xyz(&b),
            None => Vec3::from(b.joints.linear),
        };
        if let (true, true, true, Some((2, _, _))) = (still, tcp || full_linears, conversational, plane)
            && (end[2] - start[2]).abs() < 1e-9
        {
            let ccw = normal[2] > 0.0;
            let dec = self.f.fmt.linear;
            let mut cc = String::from("CC");
            for (idx, name) in [(0usize, 'X'), (1, 'Y')] {
                let r = crate::nc::round_to(center[idx], dec);
                cc.push(' ');
                cc.push(name);
                if r >= 0 {
                    cc.push('+');
                }
                crate::nc::write_fixed(&mut cc, r, dec);
            }
            let l = self.f.words(&cc).to_string();
            self.out(&l)?;
            let block = ArcBlock {
                ccw,
                words: if ccw { "DR+" } else { "DR-" }.to_string(),
                length,
                path: (a.pose.tip, b.pose.tip, *arc, [0.0, 1.0]),
            };
            return self.write(b, pt, Move::Arc(block), diags, pt.inserted, None);
        }
        self.chords(a, b, arc, pt, diags, full_linears)
    }

    /// The arc as chords within the tolerance: swept in the part frame, the tool axis fixed, the
    /// linears from the rotaries.
    fn chords(&mut self, a: At, b: At, arc: &ArcSpec, pt: &MotionPt, diags: Vec<Diagnostic>, full_linears: bool) -> Result<(), Error> {
        let step = 2.0 * (1.0 - (self.o.tolerance / arc.radius).min(1.0)).acos();
        let segs = ((arc.sweep / step.max(1e-6)).ceil() as usize).clamp(1, 100_000);
        let mut diags = diags;
        if segs > 1 {
            diags.push(Diagnostic::new(
                Code::ArcLinearized,
                Severity::Info,
                Some(pt.line),
                format!("arc of {:.1}° written as {segs} chords", arc.sweep.to_degrees()),
            ));
        }
        let chord_tip = |i: usize| helix_tip(a.pose.tip, b.pose.tip, arc, i as f64 / segs as f64);
        if !full_linears {
            // Without a linear the rotaries place the tip too: every chord end is an exact
            // solution (the one nearest the last), and every chord a feed segment, linearized
            // (it held the end's rotaries: 9.6 mm off on propeller-3r2l).
            let mut prev = a;
            let mut skipped = Vec::new();
            for i in 1..segs {
                let pose = Pose {
                    tip: chord_tip(i),
                    axis: b.pose.axis,
                };
                let Some(at) = self.exact_near(pose, &prev) else {
                    // The next chord spans this end too; its own checks judge the result.
                    skipped.push(Diagnostic::new(
                        Code::Unreachable,
                        Severity::Warning,
                        Some(pt.line),
                        format!("chord end {i} of the arc's {segs} has no solution: the next chord spans two"),
                    ));
                    continue;
                };
                self.segment(prev, at, pt, std::mem::take(&mut skipped))?;
                prev = at;
            }
            diags.append(&mut skipped);
            self.segment(prev, b, pt, diags)?;
            return Ok(());
        }
        for i in 1..segs {
            let at = self.at_tip(&b, chord_tip(i));
            self.block(at, pt, false, Vec::new(), true, None)?;
        }
        self.block(b, pt, false, diags, pt.inserted, None)
    }
}

/// The tip a fraction `t` along `arc` (a helix: the height along its normal in proportion to the
/// angle) from `from` to `to`.
pub(super) fn helix_tip(from: Vec3, to: Vec3, arc: &ArcSpec, t: f64) -> Vec3 {
    let k = arc.normal;
    let (ra, rb) = (from - arc.center, to - arc.center);
    let (h0, h1) = (k.dot(&ra), k.dot(&rb));
    let ap = ra - k * h0;
    let (s, c) = (arc.sweep * t).sin_cos();
    arc.center + ap * c + k.cross(&ap) * s + k * (h0 + (h1 - h0) * t)
}
