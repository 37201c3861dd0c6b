//! `kinepost verify`: replays an NC program (from kinepost or anywhere) through FK against its CL
//! file. The same check as the self-verification, streaming both inputs: each CL point must be
//! reproduced, in order, by a block; blocks between two matched feed points must lie on the CL
//! segment.

use super::source::{HolePart, Item, ProgEvent, Source};
use super::{Mode, seg_dist};
use crate::kinematics::{Joints, Machine, Setup, Units, Vec3, angle_between, fk};
use crate::nc::read::{NcBlock, NcReader};
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
}

/// The pose a block reaches, in profile units: FK of its words (TCP: its X Y Z are the tip).
fn block_joints(m: &Machine, b: &NcBlock) -> Option<Joints> {
    if b.plane.is_some() {
        return None; // plane coordinates, not joints: the control moves straight in the plane
    }
    let s = b.units.factor_to(m.units);
    let mut j = Joints::default();
    for i in 0..3 {
        j.linear[i] = match (b.axes[i], m.linears[i].is_some()) {
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
    let mut j = Joints::default();
    for i in 0..3 {
        j.linear[i] = match (b.axes[i], m.linears[i].is_some() || o.mode == Mode::Tcp) {
            (Some(v), _) => v * s,
            (None, true) => return None,
            (None, false) => 0.0,
        };
    }
    for (i, r) in m.rotaries.iter().enumerate() {
        j.rotary[i] = b.axes[r.slot()].unwrap_or(0.0).to_radians();
    }
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
    let mut reader = NcReader::new(nc, m.units);
    let mut ahead: VecDeque<(NcBlock, Option<(Vec3, Vec3)>)> = VecDeque::new();
    let mut rep = Report {
        machine: m.id.clone(),
        mode: Some(o.mode),
        tolerance: o.tolerance,
        ..Default::default()
    };
    let mut nc_done = false;
    let mut last: Option<(Vec3, Vec3, bool)> = None; // previous CL tip and axis, and whether it was matched
    let mut last_block: Option<NcBlock> = None; // the block that matched it
    let mut setup = o.setup;
    while let Some(item) = src.next_item()? {
        let pt = match item {
            Item::Motion(pt) => pt,
            // From here on the CL is cut with this length: so are the blocks not yet matched.
            Item::Event(ProgEvent::ToolLength(l)) if o.cl_tool_length => {
                setup.tool_length = l;
                for (b, p) in ahead.iter_mut() {
                    *p = block_pose(m, b, o, &setup);
                }
                continue;
            }
            Item::Event(_) => continue,
        };
        if pt.inserted {
            continue; // arcs and cycles expanded by the reader are not CL points of the file
        }
        rep.cl_points += 1;
        let mut found = None;
        let mut nearest: Option<(u32, f64, f64)> = None;
        let mut i = 0;
        loop {
            if i == ahead.len() {
                if nc_done || ahead.len() >= LOOKAHEAD {
                    break;
                }
                match reader.next_block()? {
                    Some(b) => {
                        rep.nc_blocks += 1;
                        let p = block_pose(m, &b, o, &setup);
                        ahead.push_back((b, p));
                    }
                    None => {
                        nc_done = true;
                        break;
                    }
                }
            }
            if let Some((tip, axis)) = ahead[i].1 {
                let mut dp = (tip - pt.pose.tip).norm();
                // A hole's top (its CL point) lies on a canned cycle's feed into the hole.
                if pt.hole.as_deref() == Some(&HolePart::Top)
                    && !ahead[i].0.rapid
                    && let Some(Some((from, _))) = i.checked_sub(1).map(|k| ahead[k].1)
                {
                    dp = dp.min(seg_dist(&pt.pose.tip, &from, &tip));
                }
                let da = angle_between(&axis, &pt.pose.axis).to_degrees();
                let score = |p: f64, a: f64| p / o.tolerance + a / o.angle_tolerance_deg;
                let ok = dp <= o.tolerance && da <= o.angle_tolerance_deg;
                if let Some((_, fp, fa)) = found {
                    // A run of blocks that all reproduce the point (near a singular direction
                    // the machine turns about a standing tip on its way there): the closest is
                    // the point, the others lead to it. Matching the first made the last ones
                    // part of the next segment, and off it.
                    if !ok {
                        break;
                    }
                    if score(dp, da) < score(fp, fa) {
                        found = Some((i, dp, da));
                    }
                } else if ok {
                    found = Some((i, dp, da));
                } else if nearest.is_none_or(|(_, p, a)| score(dp, da) < score(p, a)) {
                    nearest = Some((ahead[i].0.line, dp, da));
                }
            }
            i += 1;
        }
        match found {
            Some((i, dp, da)) => {
                rep.matched += 1;
                rep.max_tip_error = rep.max_tip_error.max(dp);
                rep.max_axis_error_deg = rep.max_axis_error_deg.max(da);
                // Blocks between two matched feed points must lie on the CL segment (a rapid
                // among them makes it a reposition, exempt). The front block is the last point's
                // match (kept: a repeated point matches it again), not between them: counted, its
                // rapid exempted every cut's first segment.
                let between = || ahead.iter().take(i).skip(1);
                if let Some((prev_tip, prev_axis, true)) = last
                    && !pt.rapid
                    && pt.arc.is_none()
                    && !between().any(|(b, _)| b.rapid)
                {
                    for (_, p) in between() {
                        if let Some((tip, axis)) = p {
                            let d = seg_dist(tip, &prev_tip, &pt.pose.tip);
                            rep.max_off_segment = rep.max_off_segment.max(d);
                            if d > o.tolerance {
                                rep.off_segment_blocks += 1;
                            }
                            let da = angle_from_arc(axis, &prev_axis, &pt.pose.axis).to_degrees();
                            rep.max_axis_off_arc_deg = rep.max_axis_off_arc_deg.max(da);
                        }
                    }
                    // TCP with angle error: the control interpolates the words, the real tip bends.
                    if (o.mode == Mode::Joint || m.has_angle_error())
                        && let Some(first) = &last_block
                    {
                        let chain = std::iter::once(first).chain(ahead.iter().take(i + 1).map(|(b, _)| b));
                        let joints: Vec<Option<Joints>> = chain.map(|b| block_joints(m, b)).collect();
                        for w in joints.windows(2) {
                            let (Some(ja), Some(jb)) = (w[0], w[1]) else { continue };
                            for t in super::NONLINEAR_SAMPLES {
                                let mut j = ja;
                                for k in 0..3 {
                                    j.linear[k] += t * (jb.linear[k] - ja.linear[k]);
                                    j.rotary[k] += t * (jb.rotary[k] - ja.rotary[k]);
                                }
                                let tip = match o.mode {
                                    Mode::Tcp => crate::kinematics::tcp_fk(m, &Vec3::from(j.linear), &j.rotary, &setup).tip,
                                    Mode::Joint => fk(m, &j, &setup).tip,
                                };
                                let d = seg_dist(&tip, &prev_tip, &pt.pose.tip);
                                rep.max_nonlinear = rep.max_nonlinear.max(d);
                                if d > o.tolerance {
                                    rep.nonlinear_blocks += 1;
                                    break;
                                }
                            }
                        }
                    }
                }
                last_block = Some(ahead[i].0.clone());
                ahead.drain(..i);
                last = Some((pt.pose.tip, pt.pose.axis, true));
            }
            None => {
                if rep.misses.len() < 20 {
                    rep.misses.push(Miss {
                        cl_line: pt.line,
                        nearest_nc_line: nearest.map(|n| n.0),
                        tip_error: nearest.map(|n| n.1),
                        axis_error_deg: nearest.map(|n| n.2),
                    });
                }
                last = Some((pt.pose.tip, pt.pose.axis, false));
                last_block = None;
            }
        }
    }
    rep.ok = rep.matched == rep.cl_points && rep.off_segment_blocks == 0 && rep.nonlinear_blocks == 0;
    Ok(rep)
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
