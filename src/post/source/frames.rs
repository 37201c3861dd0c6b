//! The frames CL points are written in, each taken into the part frame: a `ROTABL` index
//! (CAMWorks writes the path in the turned part) and the operation's MCS (NX `MSYS`: the first
//! operation's MCS is the program's frame).

use super::{Item, ProgEvent, Source};
use crate::diag::{Code, Severity};
use crate::kinematics::{Units, Vec3};
use nalgebra::{Matrix3, Rotation3, Unit};
use std::io::BufRead;

impl<R: BufRead> Source<R> {
    /// A vector of the CL's frame (indexed, in its MCS) in the part frame.
    pub(super) fn to_part(&self, v: Vec3) -> Vec3 {
        self.to_program(self.frame.map_or(v, |r| r * v))
    }

    /// A vector of the operation's MCS in the program's (the first MCS).
    pub(super) fn to_program(&self, v: Vec3) -> Vec3 {
        self.mcs.map_or(v, |(r, _)| r * v)
    }

    /// A point of the CL's frame (CL units) in the part frame, profile units.
    pub(super) fn to_part_point(&self, p: Vec3) -> Vec3 {
        self.to_part(p) * self.scale + self.mcs_shift()
    }

    fn mcs_shift(&self) -> Vec3 {
        self.mcs.map_or(Vec3::zeros(), |(_, t)| t * Units::Mm.factor_to(self.profile_units))
    }

    /// A part-frame vector in the CL's frame: [`Self::to_part`] undone.
    pub(super) fn to_cl(&self, v: Vec3) -> Vec3 {
        let v = self.mcs.map_or(v, |(r, _)| r.transpose() * v);
        self.frame.map_or(v, |r| r.transpose() * v)
    }

    /// A part-frame point (profile units) in the CL's frame and units: [`Self::to_part_point`]
    /// undone.
    pub(super) fn to_cl_point(&self, p: Vec3) -> Vec3 {
        self.to_cl(p - self.mcs_shift()) / self.scale
    }

    /// NX's `MSYS`: the first is the program's frame; a later one's points and axes are taken
    /// into it, so a program of several setups is cut where each was programmed. The modal tool
    /// axis and the last point keep their numbers, now read in the new MCS.
    pub(super) fn mcs(&mut self, origin: [f64; 3], x: [f64; 3], y: [f64; 3], line: u32) {
        let (x, y) = (Vec3::from(x).normalize(), Vec3::from(y));
        let y = (y - x * x.dot(&y)).normalize();
        let r = Matrix3::from_columns(&[x, y, x.cross(&y)]);
        let o = Vec3::from(origin) * self.cl_units.factor_to(Units::Mm);
        let Some((r0, o0)) = self.mcs0 else {
            self.mcs0 = Some((r, o));
            return;
        };
        let (rel, shift) = (r0.transpose() * r, r0.transpose() * (o - o0));
        let new = ((rel - Matrix3::identity()).amax() > 1e-9 || shift.amax() > 1e-9).then_some((rel, shift));
        if new == self.mcs {
            return;
        }
        let axis_cl = self.to_cl(self.axis);
        let tip_part = self.tip.map(|p| self.to_part_point(p));
        self.mcs = new;
        self.axis = self.to_part(axis_cl);
        self.tip = tip_part.map(|p| self.to_cl_point(p));
        let (said, comment) = describe_mcs(new, self.cl_units);
        self.diag(Code::CoordinateSystem, Severity::Info, line, format!("MSYS: {said}"));
        let turned = new.is_some_and(|(r, _)| (r - Matrix3::identity()).amax() > 1e-9);
        let shift = self.mcs_shift();
        self.out.push_back(Item::Event(ProgEvent::Setup { shift, turned, line, comment }));
    }

    /// The frame a `ROTABL` index puts the CL in, where the CL itself confirms it: CAMWorks
    /// writes `TLAXIS` in the part frame and the path after `ROTABL` in the turned one (plunges
    /// along its Z, arcs about its Z), its angle in radians where ICAM-style APT has degrees,
    /// and either sense is in use (CLW/CCLW). The one reading that turns the CL's +Z onto the
    /// tool axis in force is taken; none or several (an index about the tool axis itself) is an
    /// error and the CL taken as written, never a guess.
    pub(super) fn resolve_frame(&mut self, line: u32) {
        self.frame_pending = false;
        self.frame = None;
        match self.index_frame() {
            Ok(None) => {}
            Ok(Some((r, told))) => {
                self.frame = Some(r);
                self.diag(Code::TableIndex, Severity::Info, line, told);
            }
            Err(problem) => self.diag(
                Code::TableIndex,
                Severity::Error,
                line,
                format!("{problem}: the frame of the CL from here is not known; taken as written"),
            ),
        }
    }

    /// [`Self::resolve_frame`]'s reading of the index in force: none, the one frame with what to
    /// say of it, or why there is none.
    fn index_frame(&self) -> Result<Option<(Matrix3<f64>, String)>, String> {
        let names = ['A', 'B', 'C'];
        let at = self.table_line;
        let turned: Vec<usize> = (0..3).filter(|&i| self.table[i] != 0.0).collect();
        let i = match turned.as_slice() {
            [] => return Ok(None),
            [i] => *i,
            _ => {
                let axes: Vec<String> = turned.iter().map(|&i| names[i].to_string()).collect();
                return Err(format!(
                    "ROTABL (line {at}) indexes {} at once: the order they turn in is not known",
                    axes.join(", ")
                ));
            }
        };
        let (v, axis) = (self.table[i], names[i]);
        let about = Unit::new_normalize(Vec3::from(std::array::from_fn(|k| f64::from(u8::from(k == i)))));
        let mut found: Vec<(Rotation3<f64>, &str)> = Vec::new();
        for (angle, unit) in [(v, "radians"), (v.to_radians(), "degrees")] {
            for s in [1.0, -1.0] {
                let r = Rotation3::from_axis_angle(&about, s * angle);
                if (r * Vec3::z() - self.axis).norm() < 1e-4 && !found.iter().any(|(f, _)| f.angle_to(&r) < 1e-9) {
                    found.push((r, unit));
                }
            }
        }
        let (i_, j_, k_) = (self.axis.x, self.axis.y, self.axis.z);
        match found.as_slice() {
            [(r, unit)] => {
                let deg = r.scaled_axis().dot(&about).to_degrees();
                Ok(Some((
                    *r.matrix(),
                    format!(
                        "ROTABL {v} about {axis} (line {at}, {unit}): the CL from here is in the part turned {deg:.4}° about {axis}, the tool axis in force ({i_:.4}, {j_:.4}, {k_:.4}) its Z: taken into the part frame"
                    ),
                )))
            }
            [] => Err(format!(
                "ROTABL {v} about {axis} (line {at}): no reading of it (radians or degrees, either sense) turns the CL's Z onto the tool axis in force ({i_:.4}, {j_:.4}, {k_:.4})"
            )),
            _ => Err(format!(
                "ROTABL {v} about {axis} (line {at}): the tool axis in force ({i_:.4}, {j_:.4}, {k_:.4}) does not tell which way, or by how much, the part is turned"
            )),
        }
    }

}

/// What an MCS relative to the first is, for the diagnostic and the NC comment (CL units).
fn describe_mcs(rel: Option<(Matrix3<f64>, Vec3)>, u: Units) -> (String, String) {
    let Some((r, t)) = rel else {
        let s = "the first operation's MCS again: points taken as written";
        return (s.into(), "MCS OF THE FIRST OPERATION".into());
    };
    let t = t * Units::Mm.factor_to(u);
    let moved = format!("{:.4}, {:.4}, {:.4} {}", t.x, t.y, t.z, u.as_str());
    let turn = Rotation3::from_matrix_unchecked(r).axis_angle().map(|(a, angle)| {
        let deg = angle.to_degrees();
        (format!(", turned {deg:.4}° about ({:.4}, {:.4}, {:.4})", a.x, a.y, a.z), format!(" TURNED {deg:.3} DEG"))
    });
    let (turn_said, turn_nc) = turn.unwrap_or_default();
    (
        format!("this operation's MCS is the first's moved by ({moved}){turn_said}: its points and tool axes are taken into the first MCS"),
        format!("MCS MOVED {moved}{turn_nc} FROM THE FIRST: POINTS TAKEN INTO IT").to_ascii_uppercase(),
    )
}
