//! `kinepost verify`: replays an NC program (from kinepost or anywhere) through FK against its CL
//! file. The same check as the self-verification, streaming both inputs: each CL point must be
//! reproduced, in order, by a block; blocks between two matched feed points must lie on the CL
//! segment.

use super::source::{HolePart, Item, Source};
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
    /// Joint mode: largest distance from the CL segment of the joint-space motion between two
    /// blocks (sampled at ¼, ½, ¾), and how many block pairs exceed the tolerance.
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
}

/// The pose a block reaches, in profile units: FK of its words (TCP: its X Y Z are the tip).
fn block_joints(m: &Machine, b: &NcBlock, o: &VerifyOptions) -> Option<Joints> {
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
    let _ = o;
    Some(j)
}

fn block_pose(m: &Machine, b: &NcBlock, o: &VerifyOptions) -> Option<(Vec3, Vec3)> {
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
    let p = fk(m, &j, &o.setup);
    if let Some(pl) = &b.plane {
        // A tilted plane: X Y Z in it, from its origin in the untilted program coordinates (the
        // joint-mode zero); a dynamic work offset's frame is the rotaries'.
        let f = pl.frame.unwrap_or_else(|| crate::kinematics::machine_frame(m, &j.rotary));
        let q = Vec3::from(j.linear);
        let tip = Vec3::from(pl.origin) * s + f * q - o.setup.work_offset;
        return Some((tip, p.axis));
    }
    let tip = if o.mode == Mode::Tcp {
        Vec3::new(j.linear[0], j.linear[1], j.linear[2])
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
    let mut last: Option<(Vec3, bool)> = None; // previous matched CL tip, and whether it was matched
    let mut last_block: Option<NcBlock> = None; // the block that matched it
    while let Some(item) = src.next_item()? {
        let Item::Motion(pt) = item else { continue };
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
                        let p = block_pose(m, &b, o);
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
                // among them makes it a reposition, exempt).
                if let Some((prev_tip, true)) = last
                    && !pt.rapid
                    && pt.arc.is_none()
                    && !ahead.iter().take(i).any(|(b, _)| b.rapid)
                {
                    for (_, p) in ahead.iter().take(i) {
                        if let Some((tip, _)) = p {
                            let d = seg_dist(tip, &prev_tip, &pt.pose.tip);
                            rep.max_off_segment = rep.max_off_segment.max(d);
                            if d > o.tolerance {
                                rep.off_segment_blocks += 1;
                            }
                        }
                    }
                    if o.mode == Mode::Joint
                        && let Some(first) = &last_block
                    {
                        let chain = std::iter::once(first).chain(ahead.iter().take(i + 1).map(|(b, _)| b));
                        let joints: Vec<Option<Joints>> = chain.map(|b| block_joints(m, b, o)).collect();
                        for w in joints.windows(2) {
                            let (Some(ja), Some(jb)) = (w[0], w[1]) else { continue };
                            for t in [0.25, 0.5, 0.75] {
                                let mut j = ja;
                                for k in 0..3 {
                                    j.linear[k] += t * (jb.linear[k] - ja.linear[k]);
                                    j.rotary[k] += t * (jb.rotary[k] - ja.rotary[k]);
                                }
                                let d = seg_dist(&fk(m, &j, &o.setup).tip, &prev_tip, &pt.pose.tip);
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
                last = Some((pt.pose.tip, true));
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
                last = Some((pt.pose.tip, false));
                last_block = None;
            }
        }
    }
    rep.ok = rep.matched == rep.cl_points && rep.off_segment_blocks == 0 && rep.nonlinear_blocks == 0;
    Ok(rep)
}
