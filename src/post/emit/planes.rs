//! Tilted working planes (G68.2, G254, CYCLE800, PLANE SPATIAL) for fixed-axis runs: when one
//! may be used, entering and leaving it, and plane coordinates both ways.

use super::Emitter;
use crate::diag::Code;
use crate::kinematics::{self, Vec3, angle_between};
use crate::post::setups::WorkOffsets;
use crate::post::{Mode, Sink, Summary};
use crate::post::Stop;

/// The frames and planes the program's words are in, as the control has them selected: the
/// tilted working plane (G68.2 …), the plane of circular interpolation (G17/G18/G19), and with
/// `setups=work-offsets` the work offset (G54 …).
#[derive(Debug)]
pub(super) struct Frames {
    tilt: Option<Tilt>,
    /// Tilted planes written (the summary's count).
    tilts: u64,
    /// The circular-interpolation plane word in force.
    circular: &'static str,
    /// `setups=work-offsets`: the offsets used, and the one in force.
    offsets: Option<WorkOffsets>,
    offset_at: usize,
}

impl Frames {
    pub(super) fn new(offsets: Option<WorkOffsets>) -> Frames {
        Frames {
            tilt: None,
            tilts: 0,
            circular: "G17",
            offsets,
            offset_at: 0,
        }
    }

    /// The tilted working plane in force, if any.
    #[inline]
    pub(super) fn tilt(&self) -> Option<Tilt> {
        self.tilt
    }

    /// The circular-interpolation plane `word` selected: whether it was not already.
    pub(super) fn circular(&mut self, word: &'static str) -> bool {
        std::mem::replace(&mut self.circular, word) != word
    }

    /// The work offsets of `setups=work-offsets` (none otherwise).
    pub(super) fn offsets(&mut self) -> Option<&mut WorkOffsets> {
        self.offsets.as_mut()
    }

    /// Work offset `i` selected: whether it was not already.
    pub(super) fn select_offset(&mut self, i: usize) -> bool {
        std::mem::replace(&mut self.offset_at, i) != i
    }

    pub(super) fn summary(&self, sum: &mut Summary) {
        sum.tilted_planes = self.tilts;
    }
}

/// A tilted working plane in force: the rotary words it stands on (radians), its frame as the
/// control builds it from the words written, and the CL tool axis of its run.
#[derive(Clone, Copy, Debug)]
pub(in crate::post) struct Tilt {
    pub(in crate::post) rotary: [f64; 3],
    pub(in crate::post) frame: nalgebra::Matrix3<f64>,
    pub(in crate::post) axis: Vec3,
}

impl<S: Sink + ?Sized> Emitter<'_, S> {
    /// The job writes fixed-axis runs in tilted planes where it can.
    pub(in crate::post) fn tilted_planes(&self) -> bool {
        self.o.tilted_planes
    }

    /// Why a fixed-axis run is not written in a tilted plane, if it cannot be.
    pub(super) fn plane_refused(&self) -> Option<&'static str> {
        let m = self.m;
        if self.o.mode != Mode::Joint {
            return Some("tilted planes are written in joint mode only (TCP moves the tool in part coordinates already)");
        }
        if self.o.dialect.planes == crate::nc::Planes::None {
            return Some("this dialect has no tilted-plane command");
        }
        if m.linears.iter().any(|l| l.is_none()) || m.rotaries.len() != 2 {
            return Some("tilted planes need three linear and two rotary axes");
        }
        if self.o.dialect.planes == crate::nc::Planes::Haas && m.rotaries.iter().any(|r| r.mount != kinematics::Mount::Table) {
            return Some("G254 (dynamic work offset) needs a table-table machine");
        }
        None
    }

    /// Tilts the working plane where the machine stands (the rapid to `tip` just written), if
    /// the tool axis there is tilted and the machine and dialect allow it.
    pub(super) fn enter_plane(&mut self, tip: &Vec3) -> Result<(), Stop> {
        let Some(at) = self.at else { return Ok(()) };
        if (at.pose.tip - tip).norm() > 1e-9 || angle_between(&at.pose.axis, &Vec3::z()) < 1e-6 {
            return Ok(());
        }
        if let Some(why) = self.plane_refused() {
            return self.say_once(why, Code::IgnoredRecord, None, "3+2 written as 5-axis positioning");
        }
        self.cancel_cycle()?;
        let m = self.m;
        let frame = kinematics::machine_frame(m, &self.written_rotaries(&at.joints.rotary));
        // The tilting rotary is the one that is not free about the singular direction.
        let free = kinematics::outer_rotary(m);
        let master = (0..m.rotaries.len()).find(|&i| Some(i) != free).unwrap_or(0);
        let positive = at.joints.rotary[master] >= 0.0;
        self.cutcom_end("a tilted plane's start")?;
        let c = self.f.comment("TILTED WORK PLANE").to_string();
        self.out(&c)?;
        self.comp_cancel()?;
        let (lines, written) = self.f.plane_on(&frame, positive);
        for l in &lines {
            self.out(l)?;
        }
        self.frames.tilt = Some(Tilt {
            rotary: at.joints.rotary,
            frame: written,
            axis: at.pose.axis,
        });
        self.frames.tilts += 1;
        self.template("plane_on", Some(self.written.last_line()))?;
        self.ensure_comp(self.written.last_line())
    }

    /// Back to untilted coordinates; `recomp`: length compensation on again for the blocks that
    /// follow (not before a tool change, which sets its own).
    pub(super) fn leave_plane(&mut self, recomp: bool) -> Result<(), Stop> {
        if self.frames.tilt.is_none() {
            return Ok(());
        }
        self.cutcom_end("a tilted plane's end")?;
        self.frames.tilt = None;
        self.cancel_cycle()?;
        self.comp_cancel()?;
        self.template("plane_off", Some(self.written.last_line()))?;
        if let Some(l) = self.f.plane_off() {
            self.out(&l)?;
        }
        if recomp { self.ensure_comp(self.written.last_line()) } else { Ok(()) }
    }

    /// Length compensation off (word-address controls with a G43-style word) around a plane
    /// change, which redefines the direction it applies in.
    pub(super) fn comp_cancel(&mut self) -> Result<(), Stop> {
        let d = self.o.dialect.clone();
        if self.tool.comp_on() && !d.length_comp.is_empty() && d.style == crate::nc::Style::WordAddress {
            if let Some(l) = self.f.line(&d.tcp_off, self.tool.number().unwrap_or(1), 0) {
                self.out(&l)?;
            }
            self.tool.comp_off();
        }
        Ok(())
    }

    /// The tip in the plane's coordinates (its origin is the joint-mode program zero).
    pub(super) fn plane_coords(&self, t: &Tilt, tip_w: &Vec3) -> Vec3 {
        t.frame.transpose() * (tip_w + self.tool.setup().work_offset)
    }

    /// The inverse, from the words as written (rounded): where the control puts the tip.
    pub(super) fn plane_tip(&self, t: &Tilt, words: [f64; 3]) -> Vec3 {
        let q = Vec3::new(
            self.f.written(words[0], 0),
            self.f.written(words[1], 1),
            self.f.written(words[2], 2),
        );
        t.frame * q - self.tool.setup().work_offset
    }

    /// The plane in force, if the rotary words `rotary` stand on it.
    pub(super) fn plane_at(&self, rotary: &[f64; 3]) -> Option<Tilt> {
        self.frames
            .tilt
            .filter(|t| (0..self.m.rotaries.len()).all(|i| (rotary[i] - t.rotary[i]).abs() <= 1e-9))
    }

    /// Rotary words (radians) as the control reads them back from the written degrees.
    pub(super) fn written_rotaries(&self, rotary: &[f64; 3]) -> [f64; 3] {
        let mut w = [0.0; 3];
        for (i, r) in self.m.rotaries.iter().enumerate() {
            w[i] = self.f.written(rotary[i].to_degrees(), r.slot()).to_radians();
        }
        w
    }
}
