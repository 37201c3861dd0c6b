//! Cutter radius compensation (CL `CUTCOM`): G41/G42 … G40 (Siemens without a D of its own,
//! Heidenhain RL/RR … R0), started and ended on a straight move.
//!
//! A control offsets the path in its working plane: in joint mode the machine's X-Y plane (or a
//! tilted plane's own), in TCP mode the part's. That is a radius across the tool only where the
//! tool axis is the plane's normal; elsewhere, and where the tool axis turns under compensation,
//! only a control's 3D compensation (TCP mode) offsets right. Anything else is an error naming
//! the CUTCOM's line and no compensation: never a radius silently cut off, nor one offset askew.

use super::{At, Emitter};
use crate::cl::{CutterComp, Side};
use crate::diag::{Code, Diagnostic, Severity};
use crate::kinematics::{Vec3, fk};
use crate::nc::Style;
use crate::post::{Mode, Sink};
use crate::post::Stop;

/// cos 0.01°: a tool axis this close to the plane's normal is along it.
const ALONG: f64 = 0.999_999_984_769;

/// Compensation the CL asks for: a side, the register it names, its CUTCOM's line, and where
/// the tool axis turns before its `OFF` (read ahead by the source).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Want {
    side: Side,
    register: Option<u32>,
    line: u32,
    turns: Option<u32>,
}

/// Compensation the NC has on, and the words that end it.
#[derive(Clone, Debug, PartialEq)]
pub(in crate::post) struct Active {
    want: Want,
    off: String,
}

#[derive(Debug, Default)]
pub(in crate::post) struct State {
    want: Option<Want>,
    on: Option<Active>,
    /// The last side the CL named, with its register: what `CUTCOM/ON` alone repeats.
    last: Option<(Side, Option<u32>)>,
    /// A `CUTCOM/ON` with no side yet (CAMWorks writes `ON`, then `LEFT`): its line.
    unsided: Option<u32>,
    /// What the CL said of its path: the tool centre (true) or the contour, its words, its line.
    path: Option<(bool, String, u32)>,
    /// The path's meaning is written in the program (the header, or where compensation starts).
    said: bool,
    /// The arc that kept a start or an end waiting was told.
    arc_told: bool,
}

impl State {
    /// `path`: what the CL said of its path before its first move (the header states it).
    pub(super) fn new(path: Option<(bool, String, u32)>) -> State {
        State {
            path,
            ..Default::default()
        }
    }

    /// Nothing asked and nothing on: the common block's one test.
    #[inline]
    pub(super) fn idle(&self) -> bool {
        self.want.is_none() && self.on.is_none() && self.unsided.is_none()
    }

    /// A block written with compensation words: `now` is what is on after it.
    pub(super) fn written(&mut self, now: Option<Active>) {
        self.on = now;
    }

    fn pending(&self) -> bool {
        match (self.want, &self.on) {
            (None, None) => false,
            (Some(w), Some(a)) => w.side != a.want.side || w.register != a.want.register,
            _ => true,
        }
    }
}

fn name(s: Side) -> &'static str {
    match s {
        Side::Left => "LEFT",
        Side::Right => "RIGHT",
    }
}

fn error(line: u32, msg: String) -> Diagnostic {
    Diagnostic::new(Code::CutterComp, Severity::Error, Some(line), msg)
}

impl<S: Sink + ?Sized> Emitter<'_, S> {
    /// `CUTCOM`: what the next straight move starts or ends.
    pub(super) fn cutter_comp(&mut self, comp: CutterComp, line: u32, turns: Option<u32>) {
        let c = &mut self.cutcom;
        match comp {
            CutterComp::Off => (c.want, c.unsided) = (None, None),
            CutterComp::On { side: None, register } => match c.last {
                Some((side, r)) => {
                    c.want = Some(Want {
                        side,
                        register: register.or(r),
                        line,
                        turns,
                    })
                }
                None => c.unsided = Some(line),
            },
            CutterComp::On {
                side: Some(side),
                register,
            } => {
                c.want = Some(Want {
                    side,
                    register,
                    line,
                    turns,
                });
                (c.last, c.unsided) = (Some((side, register)), None);
            }
        }
        c.arc_told = false;
    }

    /// The CL's word on its path, said where compensation next starts (unless the header said it).
    pub(super) fn path_meaning(&mut self, centre: bool, said: String, line: u32) {
        if self.cutcom.path.as_ref().is_some_and(|p| p.2 == line) {
            return;
        }
        (self.cutcom.path, self.cutcom.said) = (Some((centre, said, line)), false);
    }

    /// The header's line on the path's meaning, where the CL stated it before its first move.
    pub(super) fn path_header(&mut self) -> Option<String> {
        let (centre, said, line) = self.cutcom.path.clone()?;
        self.cutcom.said = true;
        Some(format!(
            "CUTTER COMPENSATION: {} (CL LINE {line}: {said})",
            self.meaning(centre)
        ))
    }

    /// What the path is and what the control's radius must hold for it.
    fn meaning(&self, centre: bool) -> String {
        let r = self.o.dialect.cutcom_radius.clone();
        if centre {
            format!("TOOL CENTRE PATH: {r} = WEAR ONLY")
        } else {
            format!("CONTOUR PATH: {r} = FULL TOOL RADIUS")
        }
    }

    /// The compensation words a motion block to `to` (CL `line`) carries, with what is on once it
    /// is written; problems go on the block. A start or an end waits for a straight move.
    pub(super) fn cutcom_words(
        &mut self,
        to: &At,
        line: u32,
        arc: bool,
        diags: &mut Vec<Diagnostic>,
    ) -> Result<Option<(String, Option<Active>)>, Stop> {
        if let Some(l) = self.cutcom.unsided.take() {
            diags.push(error(
                l,
                "CUTCOM/ON names no side (LEFT, RIGHT) and none came before it: no compensation written".into(),
            ));
        }
        if !self.cutcom.pending() {
            return Ok(None);
        }
        let off = self.cutcom.on.as_ref().map(|a| (a.off.clone(), None));
        if arc {
            if !std::mem::replace(&mut self.cutcom.arc_told, true) {
                let (what, at) = match (self.cutcom.want, self.cutcom.on.as_ref()) {
                    (Some(w), _) => ("start", w.line),
                    (None, a) => ("end", a.map_or(line, |a| a.want.line)),
                };
                diags.push(error(
                    line,
                    format!("cutter compensation (CUTCOM at line {at}) cannot {what} on an arc: this arc is cut without the change, which the next straight move makes"),
                ));
            }
            return Ok(None);
        }
        let Some(w) = self.cutcom.want else { return Ok(off) };
        let words = match self.comp_frame(to, &w) {
            Ok(words) => words,
            Err(why) => {
                diags.push(error(w.line, format!("CUTCOM/{} not written: {why}", name(w.side))));
                self.cutcom.want = None;
                return Ok(off);
            }
        };
        let d = self.o.dialect.clone();
        let register = w.register.unwrap_or(self.tool.number().unwrap_or(1));
        let template = words[if w.side == Side::Left { 0 } else { 1 }].clone();
        if template.contains("{t}") && register > d.ranges.register {
            let msg = format!(
                "CUTCOM/{}: offset {register} is beyond what {} takes (at most {}): not written",
                name(w.side),
                d.name,
                d.ranges.register
            );
            diags.push(Diagnostic::new(Code::WordRange, Severity::Error, Some(w.line), msg));
            self.cutcom.want = None;
            return Ok(off);
        }
        if let Some(r) = w.register.filter(|_| !template.contains("{t}")) {
            let msg = format!(
                "CUTCOM offset {r} not written: {} takes the radius from its {}",
                d.name, d.cutcom_radius
            );
            diags.push(Diagnostic::new(Code::CutterComp, Severity::Warning, Some(w.line), msg));
        }
        self.say_path(w.line)?;
        let text = template.replace("{t}", &register.to_string());
        Ok(Some((text, Some(Active { want: w, off: words[2].clone() }))))
    }

    /// The dialect's words (left, right, off) that compensate across the tool at `to`, with the
    /// sides swapped where the plane faces the tool the other way; or why none does.
    fn comp_frame(&mut self, to: &At, w: &Want) -> Result<[String; 3], String> {
        let d = self.o.dialect.clone();
        let tcp = self.o.mode == Mode::Tcp;
        if let Some(l) = w.turns {
            return match (tcp, d.cutcom_3d.clone()) {
                (true, Some(words)) => Ok(words),
                (true, None) => Err(format!(
                    "the tool axis turns under it (line {l}) and {} has no 3D cutter compensation",
                    d.name
                )),
                (false, _) => Err(format!(
                    "the tool axis turns under it (line {l}): in joint mode the control compensates in the machine's X-Y plane only (TCP mode writes 3D compensation where the control has it)"
                )),
            };
        }
        let (normal, plane) = match &self.frames.tilt() {
            Some(t) => (t.frame.column(0).cross(&t.frame.column(1)), "tilted plane"),
            None if tcp => (Vec3::z(), "part's X-Y plane"),
            None => (self.machine_normal(to)?, "machine's X-Y plane"),
        };
        let c = normal.dot(&to.pose.axis);
        let mut words = d.cutcom.clone();
        if c <= -ALONG {
            // The control's left, seen from its +Z, is the CL's right, seen from the tool.
            words.swap(0, 1);
            return Ok(words);
        }
        match (c >= ALONG, tcp, d.cutcom_3d.clone()) {
            (true, ..) => Ok(words),
            (false, true, Some(words)) => Ok(words),
            (false, true, None) => Err(format!(
                "the tool axis is {:.3}° off the {plane}'s normal, and {} has no 3D cutter compensation",
                c.clamp(-1.0, 1.0).acos().to_degrees(),
                d.name
            )),
            (false, false, _) => Err(format!(
                "the tool axis is {:.3}° off the {plane}'s normal, where the control compensates (a tilted head: post with tilted planes)",
                c.clamp(-1.0, 1.0).acos().to_degrees()
            )),
        }
    }

    /// The normal of the plane the machine's X and Y words move the tool in, in the part frame,
    /// where it stands at `to` (a turned table turns it).
    fn machine_normal(&self, to: &At) -> Result<Vec3, String> {
        let m = self.m;
        if m.linears[0].is_none() || m.linears[1].is_none() {
            return Err(format!("{} has no X and Y axes to compensate with", m.id));
        }
        let base = fk(m, &to.joints, self.tool.setup()).tip;
        let step = |k: usize| {
            let mut j = to.joints;
            j.linear[k] += 1.0;
            fk(m, &j, self.tool.setup()).tip - base
        };
        let n = step(0).cross(&step(1));
        if n.norm() < 1e-9 {
            return Err(format!("{}'s X and Y axes span no plane", m.id));
        }
        Ok(n.normalize())
    }

    /// Where compensation first starts after the CL said what its path is (or said nothing):
    /// a comment on what the register must hold, once.
    fn say_path(&mut self, line: u32) -> Result<(), Stop> {
        if std::mem::replace(&mut self.cutcom.said, true) {
            return Ok(());
        }
        let (text, d) = match self.cutcom.path.clone() {
            Some((centre, said, at)) => {
                let m = self.meaning(centre);
                let msg = format!("cutter compensation: {m} (line {at}: {said})");
                (
                    format!("CUTTER COMPENSATION: {m} (CL LINE {at}: {said})"),
                    Diagnostic::new(Code::CutterComp, Severity::Info, Some(line), msg),
                )
            }
            None => {
                let m = self.meaning(true);
                let msg = format!(
                    "cutter compensation: the CL does not say whether its path is the contour or the tool centre: taken as the tool centre ({m})"
                );
                (
                    format!("CUTTER COMPENSATION: {m} (ASSUMED: THE CL DOES NOT SAY)"),
                    Diagnostic::new(Code::CutterComp, Severity::Warning, Some(line), msg),
                )
            }
        };
        let c = self.f.comment(&text).to_string();
        self.out(&c)?;
        self.note(d)
    }

    /// Compensation still on where the CL reaches `what` (a tool change, a plane change, the
    /// end) without `CUTCOM/OFF`: ended there, told. Word address: `G40` on its own line; a TNC
    /// ends it with `R0` on the next move (the retract), which in a tilted plane comes too late.
    pub(super) fn cutcom_end(&mut self, what: &str) -> Result<(), Stop> {
        (self.cutcom.want, self.cutcom.unsided) = (None, None);
        let Some(a) = self.cutcom.on.clone() else { return Ok(()) };
        let msg = format!(
            "cutter compensation (CUTCOM at line {}) is still on at {what}: the CL has no CUTCOM/OFF before it; ended there",
            a.want.line
        );
        let conversational = self.o.dialect.style == Style::Conversational;
        let severity = if conversational && self.frames.tilt().is_some() {
            Severity::Error
        } else {
            Severity::Warning
        };
        self.note(Diagnostic::new(Code::CutterComp, severity, Some(a.want.line), msg))?;
        if !conversational {
            let l = self.f.words(&a.off).to_string();
            self.out(&l)?;
            self.cutcom.on = None;
        }
        Ok(())
    }
}
