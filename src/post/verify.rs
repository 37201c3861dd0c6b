//! `kinepost verify`: replays an NC program (from kinepost or anywhere) through FK against its CL
//! file. The same check as the self-verification, streaming both inputs: each CL point must be
//! reproduced, in order, by a block; blocks between two matched feed points must lie on the CL
//! segment.

use super::source::{HolePart, Item, MotionPt, ProgEvent, Source};
use super::setups::WorkOffsets;
use super::tools::Lengths;
use super::{Mode, seg_dist};
use crate::kinematics::{Joints, Machine, Setup, Units, Vec3, angle_between, fk};
use crate::nc::read::{NcBlock, NcReader, WCS_CODES};
use serde::Serialize;
use std::collections::VecDeque;
use std::io::BufRead;

/// Blocks looked ahead for one CL point before it is declared missing.
const LOOKAHEAD: usize = 20_000;

#[derive(Clone, Debug, Serialize)]
pub struct Miss {
    pub cl_line: u32,
    /// The nearest block seen, and by how much it missed.
    pub nearest_nc_line: Option<u32>,
    pub tip_error: Option<f64>,
    pub axis_error_deg: Option<f64>,
}

#[derive(Clone, Debug, Default, Serialize)]
pub struct Report {
    pub ok: bool,
    pub machine: String,
    pub mode: Option<Mode>,
    pub cl_points: u64,
    pub matched: u64,
    pub nc_blocks: u64,
    pub max_tip_error: f64,
    pub max_axis_error_deg: f64,
    /// Largest distance of a block between two matched feed points from their CL segment.
    pub max_off_segment: f64,
    pub off_segment_blocks: u64,
    /// Largest angle (degrees) from the tool axis of such a block to the CL great-circle arc
    /// between the two points' axes: reported, not failed (a singular tolerance allows some).
    pub max_axis_off_arc_deg: f64,
    /// Joint mode: largest distance from the CL segment of the joint-space motion between two
    /// blocks (sampled as the engine does, every eighth), and how many block pairs exceed the
    /// tolerance.
    pub max_nonlinear: f64,
    pub nonlinear_blocks: u64,
    pub misses: Vec<Miss>,
    pub tolerance: f64,
}

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error(transparent)]
    Cl(#[from] super::source::Error),
    #[error(transparent)]
    Nc(#[from] crate::nc::read::Error),
}

pub struct VerifyOptions {
    pub mode: Mode,
    pub setup: Setup,
    pub tolerance: f64,
    pub angle_tolerance_deg: f64,
    pub cl_units: Option<Units>,
    /// Take the tool length the CL file sets (`LOADTL/n,LENGTH,l`, `TLDATA`) from where it sets
    /// it, as `post` does when the job fixes none (`setup`'s length until then).
    pub cl_tool_length: bool,
    /// The tool table the program was posted with: each tool's length as `post` weighs it
    /// (`post::tools`), unless `cl_tool_length` is off (one length for every tool).
    pub tool_table: Option<std::sync::Arc<crate::machines::tools::ToolTable>>,
}

/// The joints a block commands, for the motion between blocks.
fn block_joints(m: &Machine, b: &NcBlock) -> Option<Joints> {
    if b.plane.is_some() {
        return None; // plane coordinates, not joints: the control moves straight in the plane
    }
    joints_of(m, b, |i| m.linears[i].is_some())
}

/// A block's words as joints, profile units and radians: `None` while a linear that `needed`
/// names has no value yet, 0 for the others.
fn joints_of(m: &Machine, b: &NcBlock, needed: impl Fn(usize) -> bool) -> Option<Joints> {
    let s = b.units.factor_to(m.units);
    let mut j = Joints::default();
    for i in 0..3 {
        j.linear[i] = match (b.axes[i], needed(i)) {
            (Some(v), _) => v * s,
            (None, true) => return None,
            (None, false) => 0.0,
        };
    }
    for (i, r) in m.rotaries.iter().enumerate() {
        j.rotary[i] = b.axes[r.slot()].unwrap_or(0.0).to_radians();
    }
    Some(j)
}

/// Tip and tool axis of a block with the tool length in force (`setup`, not `o.setup`).
fn block_pose(m: &Machine, b: &NcBlock, o: &VerifyOptions, setup: &Setup) -> Option<(Vec3, Vec3)> {
    let s = b.units.factor_to(m.units);
    let j = joints_of(m, b, |i| m.linears[i].is_some() || o.mode == Mode::Tcp)?;
    let p = fk(m, &j, setup);
    if let Some(pl) = &b.plane {
        // A tilted plane: X Y Z in it, from its origin in the untilted program coordinates (the
        // joint-mode zero); a dynamic work offset's frame is the rotaries'.
        let f = pl.frame.unwrap_or_else(|| crate::kinematics::machine_frame(m, &j.rotary));
        let q = Vec3::from(j.linear);
        let tip = Vec3::from(pl.origin) * s + f * q - setup.work_offset;
        return Some((tip, p.axis));
    }
    let tip = if o.mode == Mode::Tcp && m.has_angle_error() {
        crate::kinematics::tcp_fk(m, &Vec3::from(j.linear), &j.rotary, setup).tip
    } else if o.mode == Mode::Tcp {
        Vec3::from(j.linear)
    } else {
        p.tip
    };
    Some((tip, p.axis))
}

pub fn verify<C: BufRead, N: BufRead>(cl: C, nc: N, m: &Machine, o: &VerifyOptions) -> Result<Report, Error> {
    let mut src = Source::new(cl, m.units, o.cl_units, false)?;
    let mut replay = Replay {
        m,
        o,
        reader: NcReader::new(nc, m.units),
        ahead: VecDeque::new(),
        nc_done: false,
        setup: o.setup,
        last: None,
        last_block: None,
        offsets: None,
        rep: Report {
            machine: m.id.clone(),
            mode: Some(o.mode),
            tolerance: o.tolerance,
            ..Default::default()
        },
    };
    let fixed = (!o.cl_tool_length).then_some(o.setup.tool_length);
    let mut lengths = Lengths::new(m.units, fixed, o.tool_table.as_deref(), o.setup.tool_length);
    while let Some(item) = src.next_item()? {
        let step = match item {
            Item::Motion(pt) => {
                if let Some((l, _)) = lengths.motion().set {
                    replay.tool_length(l);
                }
                // Arcs and cycles expanded by the reader are not CL points of the file.
                if !pt.inserted {
                    replay.point(&pt)?;
                }
                continue;
            }
            Item::Event(ProgEvent::ToolLength { length, line }) => lengths.cl_length(length, line),
            Item::Event(ProgEvent::Tool { number, line, .. }) => lengths.tool(number, line),
            Item::Event(ProgEvent::Setup { shift, turned, .. }) => {
                replay.setup(shift, turned);
                continue;
            }
            Item::Event(_) => continue,
        };
        if let Some((l, _)) = step.set {
            replay.tool_length(l);
        }
    }
    let mut rep = replay.rep;
    rep.ok = rep.matched == rep.cl_points && rep.off_segment_blocks == 0 && rep.nonlinear_blocks == 0;
    Ok(rep)
}

/// The replay of the NC against the CL, one CL point at a time.
struct Replay<'a, N> {
    m: &'a Machine,
    o: &'a VerifyOptions,
    reader: NcReader<N>,
    /// Blocks read and not yet matched, with their poses.
    ahead: VecDeque<(NcBlock, Option<(Vec3, Vec3)>)>,
    nc_done: bool,
    /// The tool length in force.
    setup: Setup,
    /// The previous CL tip and axis, and whether it was matched.
    last: Option<(Vec3, Vec3, bool)>,
    /// The block that matched it.
    last_block: Option<NcBlock>,
    /// The work offsets of the program's setups (NX `MSYS`), from the one its first block is in:
    /// a block in another is measured from that one's origin.
    offsets: Option<WorkOffsets>,
    rep: Report,
}

/// Looking ahead for one CL point.
#[derive(Default)]
struct Search {
    /// The block (index into `ahead`) that reproduces it, with its tip and axis errors.
    found: Option<(usize, f64, f64)>,
    /// Else the nearest block seen (its NC line), with its errors.
    nearest: Option<(u32, f64, f64)>,
}

impl Search {
    /// Weighs block `i` (NC `line`) with these errors; false once a run of matching blocks ends.
    fn weigh(&mut self, i: usize, line: u32, dp: f64, da: f64, o: &VerifyOptions) -> bool {
        let score = |p: f64, a: f64| p / o.tolerance + a / o.angle_tolerance_deg;
        let ok = dp <= o.tolerance && da <= o.angle_tolerance_deg;
        match self.found {
            // A run of blocks that all reproduce the point (near a singular direction the machine
            // turns about a standing tip on its way there): the closest is the point, the others
            // lead to it. Matching the first made the last ones part of the next segment, and off
            // it.
            Some(_) if !ok => return false,
            Some((_, fp, fa)) if score(dp, da) < score(fp, fa) => self.found = Some((i, dp, da)),
            Some(_) => {}
            None if ok => self.found = Some((i, dp, da)),
            None if self.nearest.is_none_or(|(_, p, a)| score(dp, da) < score(p, a)) => self.nearest = Some((line, dp, da)),
            None => {}
        }
        true
    }
}

impl<N: BufRead> Replay<'_, N> {
    /// From here on the CL is cut with this length: so are the blocks not yet matched.
    fn tool_length(&mut self, l: f64) {
        self.setup.tool_length = l;
        for (b, p) in self.ahead.iter_mut() {
            *p = block_pose(self.m, b, self.o, &self.setup);
        }
    }

    /// The CL's next setup: as `post` gives each distinct one the next work offset, a block in
    /// that offset is measured from its origin, the blocks read ahead in it too.
    fn setup(&mut self, shift: Vec3, turned: bool) {
        let Some(offsets) = self.offsets.as_mut() else {
            return;
        };
        let known = offsets.listing().count();
        let Ok(i) = offsets.pick(shift, turned) else {
            return;
        };
        if i <= known {
            return;
        }
        let code = offsets.code(i).to_string();
        for k in 0..self.ahead.len() {
            if self.ahead[k].0.wcs == Some(code.as_str()) {
                let mut b = self.ahead[k].0.clone();
                self.shift_block(&mut b);
                let p = block_pose(self.m, &b, self.o, &self.setup);
                self.ahead[k] = (b, p);
            }
        }
    }

    /// A block's X Y Z from its work offset's origin to the first's.
    fn shift_block(&self, b: &mut NcBlock) {
        let Some(shift) = self.offsets.as_ref().zip(b.wcs).and_then(|(o, c)| o.index_of(c).map(|i| o.shift(i))) else {
            return;
        };
        let s = b.units.factor_to(self.m.units);
        for i in 0..3 {
            if let Some(v) = b.axes[i].as_mut() {
                *v += shift[i] / s;
            }
        }
    }

    /// One CL point of the file: matched to a block, or a miss.
    fn point(&mut self, pt: &MotionPt) -> Result<(), Error> {
        self.rep.cl_points += 1;
        let s = self.look_ahead(pt)?;
        match s.found {
            Some((i, dp, da)) => self.matched(pt, i, dp, da),
            None => self.missed(pt, s.nearest),
        }
        Ok(())
    }

    fn look_ahead(&mut self, pt: &MotionPt) -> Result<Search, Error> {
        let mut s = Search::default();
        let mut i = 0;
        while self.fill(i)? {
            if let Some((dp, da)) = self.errors(i, pt)
                && !s.weigh(i, self.ahead[i].0.line, dp, da, self.o)
            {
                break;
            }
            i += 1;
        }
        Ok(s)
    }

    /// Whether there is a block `i` ahead, reading it from the NC if need be (at most
    /// [`LOOKAHEAD`] blocks ahead).
    fn fill(&mut self, i: usize) -> Result<bool, Error> {
        if i < self.ahead.len() {
            return Ok(true);
        }
        if self.nc_done || self.ahead.len() >= LOOKAHEAD {
            return Ok(false);
        }
        let Some(mut b) = self.reader.next_block()? else {
            self.nc_done = true;
            return Ok(false);
        };
        self.rep.nc_blocks += 1;
        if self.offsets.is_none()
            && let Some(first) = b.wcs
        {
            self.offsets = Some(WorkOffsets::new(&WCS_CODES.map(String::from), first));
        }
        self.shift_block(&mut b);
        let p = block_pose(self.m, &b, self.o, &self.setup);
        self.ahead.push_back((b, p));
        Ok(true)
    }

    /// Tip error and axis error (degrees) of block `i` at `pt`; `None` for a block without a pose.
    fn errors(&self, i: usize, pt: &MotionPt) -> Option<(f64, f64)> {
        let (tip, axis) = self.ahead[i].1?;
        let mut dp = (tip - pt.pose.tip).norm();
        // A hole's top (its CL point) lies on a canned cycle's feed into the hole.
        if pt.hole.as_deref() == Some(&HolePart::Top)
            && !self.ahead[i].0.rapid
            && let Some(Some((from, _))) = i.checked_sub(1).map(|k| self.ahead[k].1)
        {
            dp = dp.min(seg_dist(&pt.pose.tip, &from, &tip));
        }
        Some((dp, angle_between(&axis, &pt.pose.axis).to_degrees()))
    }

    fn matched(&mut self, pt: &MotionPt, i: usize, dp: f64, da: f64) {
        let rep = &mut self.rep;
        rep.matched += 1;
        rep.max_tip_error = rep.max_tip_error.max(dp);
        rep.max_axis_error_deg = rep.max_axis_error_deg.max(da);
        // Blocks between two matched feed points must lie on the CL segment (a rapid among them
        // makes it a reposition, exempt). The front block is the last point's match (kept: a
        // repeated point matches it again), not between them: counted, its rapid exempted every
        // cut's first segment.
        if let Some((prev_tip, prev_axis, true)) = self.last
            && !pt.rapid
            && pt.arc.is_none()
            && !self.ahead.iter().take(i).skip(1).any(|(b, _)| b.rapid)
        {
            self.check_between(i, &prev_tip, &prev_axis, pt);
            // TCP with angle error: the control interpolates the words, the real tip bends.
            if self.o.mode == Mode::Joint || self.m.has_angle_error() {
                self.check_nonlinear(i, &prev_tip, pt);
            }
        }
        self.last_block = Some(self.ahead[i].0.clone());
        self.ahead.drain(..i);
        self.last = Some((pt.pose.tip, pt.pose.axis, true));
    }

    /// The blocks between the last match and block `i` against the CL segment, and their axes
    /// against the arc between the two points' axes.
    fn check_between(&mut self, i: usize, prev_tip: &Vec3, prev_axis: &Vec3, pt: &MotionPt) {
        let rep = &mut self.rep;
        for (tip, axis) in self.ahead.iter().take(i).skip(1).filter_map(|(_, p)| p.as_ref()) {
            let d = seg_dist(tip, prev_tip, &pt.pose.tip);
            rep.max_off_segment = rep.max_off_segment.max(d);
            if d > self.o.tolerance {
                rep.off_segment_blocks += 1;
            }
            let da = angle_from_arc(axis, prev_axis, &pt.pose.axis).to_degrees();
            rep.max_axis_off_arc_deg = rep.max_axis_off_arc_deg.max(da);
        }
    }

    /// The joint-space motion from the last match's block through block `i`, pair by pair,
    /// against the CL segment.
    fn check_nonlinear(&mut self, i: usize, prev_tip: &Vec3, pt: &MotionPt) {
        let Some(first) = &self.last_block else { return };
        let chain = std::iter::once(first).chain(self.ahead.iter().take(i + 1).map(|(b, _)| b));
        let joints: Vec<Option<Joints>> = chain.map(|b| block_joints(self.m, b)).collect();
        for w in joints.windows(2) {
            if let (Some(ja), Some(jb)) = (w[0], w[1]) {
                self.sample_pair(&ja, &jb, prev_tip, &pt.pose.tip);
            }
        }
    }

    /// The tip between two blocks, sampled as the engine does ([`super::NONLINEAR_SAMPLES`]): its
    /// distance from the segment `a`–`b`; the first sample beyond the tolerance counts the pair.
    fn sample_pair(&mut self, ja: &Joints, jb: &Joints, a: &Vec3, b: &Vec3) {
        for t in super::NONLINEAR_SAMPLES {
            let mut j = *ja;
            for k in 0..3 {
                j.linear[k] += t * (jb.linear[k] - ja.linear[k]);
                j.rotary[k] += t * (jb.rotary[k] - ja.rotary[k]);
            }
            let tip = match self.o.mode {
                Mode::Tcp => crate::kinematics::tcp_fk(self.m, &Vec3::from(j.linear), &j.rotary, &self.setup).tip,
                Mode::Joint => fk(self.m, &j, &self.setup).tip,
            };
            let d = seg_dist(&tip, a, b);
            self.rep.max_nonlinear = self.rep.max_nonlinear.max(d);
            if d > self.o.tolerance {
                self.rep.nonlinear_blocks += 1;
                break;
            }
        }
    }

    fn missed(&mut self, pt: &MotionPt, nearest: Option<(u32, f64, f64)>) {
        if self.rep.misses.len() < 20 {
            self.rep.misses.push(Miss {
                cl_line: pt.line,
                nearest_nc_line: nearest.map(|n| n.0),
                tip_error: nearest.map(|n| n.1),
                axis_error_deg: nearest.map(|n| n.2),
            });
        }
        self.last = Some((pt.pose.tip, pt.pose.axis, false));
        self.last_block = None;
    }
}

/// Angle (radians) from `a` to the shorter great-circle arc from `u1` to `u2`; 0 between
/// opposite axes, which every half great circle joins (a reversal names no arc).
fn angle_from_arc(a: &Vec3, u1: &Vec3, u2: &Vec3) -> f64 {
    let Some(n) = u1.cross(u2).try_normalize(1e-12) else {
        return if u1.dot(u2) < 0.0 { 0.0 } else { angle_between(a, u1) };
    };
    // Within the arc's lune: the angle to its plane; else to the nearer end.
    let p = a - n * a.dot(&n);
    if u1.cross(&p).dot(&n) >= 0.0 && p.cross(u2).dot(&n) >= 0.0 {
        (a.dot(&n).abs() / a.norm()).min(1.0).asin()
    } else {
        angle_between(a, u1).min(angle_between(a, u2))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn angle_from_arc_measures_to_the_arc_not_its_great_circle() {
        let (x, y, z) = (Vec3::x(), Vec3::y(), Vec3::z());
        let d = |a: Vec3, u1: Vec3, u2: Vec3| angle_from_arc(&a, &u1, &u2).to_degrees();
        assert!(d((x + y).normalize(), x, y) < 1e-12); // on it
        assert!((d(z, x, y) - 90.0).abs() < 1e-9); // off its plane
        assert!((d(-x, x, y) - 90.0).abs() < 1e-9); // on the great circle, beyond the end at y
        let tilted = (x + y + z * 0.1).normalize();
        assert!((d(tilted, x, y) - 0.1f64.atan2(2f64.sqrt()).to_degrees()).abs() < 1e-9);
        assert!((d(x, z, z) - 90.0).abs() < 1e-9); // a point arc
        assert_eq!(d(x, z, -z), 0.0); // a reversal: every half great circle joins its ends
    }
}
