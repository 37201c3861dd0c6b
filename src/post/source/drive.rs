//! A drive statement (`TLON,GOFWD/(CIRCLE/…),ON,(LINE/…)`) resolved into motion: from the
//! current point along the drive curve, the way the tool is going, to where the stop condition
//! on the check surface first holds. A circle becomes the arc the engine writes (G2/G3 or
//! chords within tolerance); what cannot be resolved is an error at the statement's line, and
//! no motion.

use super::{MotionPt, Source};
use crate::cl::drive::{Drive, Geometry, Go, Stop, ToolSide};
use crate::diag::{Code, Severity};
use crate::kinematics::{Units, Vec3};
use std::f64::consts::TAU;
use std::io::BufRead;

/// A plane n·x = d, or a circle (centre projected into the drive's plane, radius).
enum Check {
    Plane(Vec3, f64),
    Circle(Vec3, f64),
}

impl<R: BufRead> Source<R> {
    /// `INDIRV` / `INDIRP`: the direction the next drive statement goes from.
    pub(super) fn indir(&mut self, v: [f64; 3], point: bool, line: u32) {
        let d = match (point, self.tip) {
            (false, _) => Vec3::from(v),
            (true, Some(tip)) => Vec3::from(v) - tip,
            (true, None) => {
                let msg = "INDIRP: no current point to point from: not used".to_string();
                return self.diag(Code::BadRecord, Severity::Error, line, msg);
            }
        };
        self.indir = d.try_normalize(1e-12);
    }

    /// The drive statement's motion: an arc or a straight move to its end, or an error.
    pub(super) fn drive(&mut self, line: u32, d: Drive) -> Option<MotionPt> {
        let fwd = self.indir.take().or(self.last_dir);
        match self.resolve_drive(&d, fwd) {
            Ok((end, arc, tangent)) => {
                let rapid = self.rapid_next || self.feed.is_none();
                match (arc, self.tip) {
                    // No arc is written at rapid: points on it, 5° apart, so that the path is
                    // the circle's, never the chord across it.
                    (Some((center, axis, _)), Some(start)) if rapid => {
                        let (a, b) = (start - center, end - center);
                        let mut sweep = axis.dot(&a.cross(&b)).atan2(a.dot(&b));
                        if sweep <= 1e-9 {
                            sweep += TAU;
                        }
                        let n = (sweep / 5f64.to_radians()).ceil().max(1.0) as usize;
                        let asked = self.rapid_next;
                        for i in 1..n {
                            let turn = nalgebra::Rotation3::from_axis_angle(
                                &nalgebra::Unit::new_normalize(axis),
                                sweep * i as f64 / n as f64,
                            );
                            self.rapid_next = asked;
                            if let Some(pt) = self.motion(line, center + turn * a) {
                                self.out.push_back(super::Item::Motion(pt));
                            }
                        }
                        self.rapid_next = asked;
                    }
                    (Some((center, axis, radius)), _) => {
                        self.circle = Some((center.into(), axis.into(), Some(radius)));
                        (self.circle_cw, self.circle_turns, self.circle_sweep) = (false, 1, None);
                    }
                    _ => {}
                }
                let pt = self.motion(line, end);
                self.last_dir = Some(tangent);
                pt
            }
            Err(why) => {
                let msg = format!("{}: {why}: the motion is not written", d.word);
                self.diag(Code::BadRecord, Severity::Error, line, msg);
                None
            }
        }
    }

    /// The tool's radius in CL units, where a CUTTER gave it.
    fn tool_radius(&self) -> Option<f64> {
        self.diameter_mm.map(|d| d / 2.0 / self.cl_units.factor_to(Units::Mm))
    }

    /// The end point, the arc to it (centre, axis it turns counter-clockwise about, radius) and
    /// the direction of travel at the end.
    #[allow(clippy::type_complexity)]
    fn resolve_drive(&self, d: &Drive, fwd: Option<Vec3>) -> Result<(Vec3, Option<(Vec3, Vec3, f64)>, Vec3), String> {
        let start = self.tip.ok_or("no current point to start from")?;
        let fwd = fwd.ok_or("no direction to go from (no INDIRV and no move before it)")?;
        // A tenth of a hundredth of a millimetre beyond what CATIA's 5 decimals round.
        let tol = 0.01 / self.cl_units.factor_to(Units::Mm);
        let radius = self.tool_radius();
        let need_r = || radius.ok_or("TO, PAST, TLLFT and TLRGT need the tool's radius, and no CUTTER gave it");
        match d.drive {
            Geometry::Circle { center, axis, radius: r } => {
                let k = Vec3::from(axis);
                let c = Vec3::from(center) + k * k.dot(&(start - Vec3::from(center)));
                let rs = start - c;
                let r0 = rs.norm();
                if r0 < tol {
                    return Err("the current point is the circle's centre".into());
                }
                let u = rs / r0;
                let dir = turned(fwd, k, d.go);
                let s = k.cross(&u).dot(&dir);
                if s.abs() < 0.05 {
                    return Err("the direction to go is across the circle: it does not say which way round".into());
                }
                let kk = if s > 0.0 { k } else { -k };
                let want = match d.side {
                    ToolSide::On => r,
                    // Going counter-clockwise about kk, the centre is on the tool's left.
                    ToolSide::Left => r - need_r()?,
                    ToolSide::Right => r + need_r()?,
                };
                if (r0 - want).abs() > tol {
                    return Err(format!(
                        "the current point is {:.4} off the circle the tool follows (radius {want})",
                        (r0 - want).abs()
                    ));
                }
                let v = kk.cross(&u);
                let at = |t: f64| c + (u * t.cos() + v * t.sin()) * r0;
                let theta = self.circle_stop(d, &Followed { at: &at, c, kk, r0 }, start, tol, radius)?;
                let end = at(theta);
                if theta < 1e-6 {
                    return Err("the check surface is where the tool stands".into());
                }
                let tangent = kk.cross(&(end - c)) / r0;
                Ok((end, Some((c, kk, r0)), tangent))
            }
            Geometry::Line { a, b } => {
                if d.side != ToolSide::On {
                    return Err("a LINE followed beside the tool (TLLFT, TLRGT) is a form kinepost does not read".into());
                }
                let (a, b) = (Vec3::from(a), Vec3::from(b));
                let mut e = (b - a).normalize();
                let off = (start - a) - e * e.dot(&(start - a));
                if off.norm() > tol {
                    return Err(format!(
                        "the current point is {:.4} off the line the tool follows",
                        off.norm()
                    ));
                }
                let dir = turned(fwd, self.axis_cl(), d.go);
                if e.dot(&dir) < 0.0 {
                    e = -e;
                }
                let t = match check(d, self.axis_cl(), start) {
                    Check::Plane(n, dd) => {
                        let target = offset(d.stop, (n.dot(&start) - dd).signum(), need_r)?;
                        let nd = n.dot(&e);
                        if nd.abs() < 1e-9 {
                            return Err("the line never meets the check surface".into());
                        }
                        (target + dd - n.dot(&start)) / nd
                    }
                    Check::Circle(c2, r2) => {
                        let w = start - c2;
                        let inside = w.norm() < r2;
                        let rho = match d.stop {
                            Stop::On | Stop::Tanto => r2,
                            Stop::To => r2 + if inside { -need_r()? } else { need_r()? },
                            Stop::Past => r2 + if inside { need_r()? } else { -need_r()? },
                        };
                        let (p, q) = (e.dot(&w), w.norm_squared() - rho * rho);
                        let disc = p * p - q;
                        if disc < -tol * tol {
                            return Err("the line never meets the check circle".into());
                        }
                        let h = disc.max(0.0).sqrt();
                        [-p - h, -p + h]
                            .into_iter()
                            .find(|t| *t > 1e-6)
                            .ok_or("the check circle is behind the tool")?
                    }
                };
                if t <= 1e-6 {
                    return Err("the check surface is behind the tool".into());
                }
                Ok((start + e * t, None, e))
            }
            Geometry::Plane { .. } => Err("the tool follows a CIRCLE or a LINE".into()),
        }
    }

    /// The tool axis in the CL's frame: the axis of a LINE read as APT's plane.
    fn axis_cl(&self) -> Vec3 {
        self.to_cl(self.axis)
    }

    /// The angle (counter-clockwise about `kk` from the start) at which the motion along the
    /// circle `at` first meets the stop condition on the check surface.
    fn circle_stop(&self, d: &Drive, circle: &Followed, start: Vec3, tol: f64, radius: Option<f64>) -> Result<f64, String> {
        let Followed { at, c, kk, r0 } = *circle;
        let need_r = || radius.ok_or("TO and PAST need the tool's radius, and no CUTTER gave it");
        let angle = |p: Vec3| {
            let (u, v) = ((at(0.0) - c) / r0, kk.cross(&((at(0.0) - c) / r0)));
            let t = (p - c).dot(&v).atan2((p - c).dot(&u));
            if t < 1e-9 { t + TAU } else { t }
        };
        let mut found: Vec<f64> = Vec::new();
        match check(d, kk, start) {
            Check::Plane(n, dd) => {
                // n·at(t) − dd = n·c − dd + A cos t + B sin t
                let (u, v) = ((at(0.0) - c) / r0, kk.cross(&((at(0.0) - c) / r0)));
                let (a, b) = (r0 * n.dot(&u), r0 * n.dot(&v));
                let m = a.hypot(b);
                if m < 1e-9 {
                    return Err("the circle lies in the check plane's direction: it never meets it".into());
                }
                let phi = b.atan2(a);
                if d.stop == Stop::Tanto {
                    let t = [phi, phi + std::f64::consts::PI]
                        .into_iter()
                        .min_by(|x, y| (n.dot(&at(*x)) - dd).abs().total_cmp(&(n.dot(&at(*y)) - dd).abs()))
                        .unwrap_or(phi);
                    if (n.dot(&at(t)) - dd).abs() > tol {
                        return Err("TANTO: the circle is not tangent to the check surface".into());
                    }
                    found.push(angle(at(t)));
                } else {
                    let target = offset(d.stop, (n.dot(&start) - dd).signum(), need_r)?;
                    let rhs = (target + dd - n.dot(&c)) / m;
                    if rhs.abs() > 1.0 + tol / m {
                        return Err("the circle never meets the check surface".into());
                    }
                    let w = rhs.clamp(-1.0, 1.0).acos();
                    found.extend([phi + w, phi - w].map(|t| angle(at(t))));
                }
            }
            Check::Circle(c2, r2) => {
                let e = c2 - c;
                let dist = e.norm();
                if dist < tol {
                    return Err("the check circle is concentric with the one followed".into());
                }
                let e = e / dist;
                if d.stop == Stop::Tanto {
                    let p = [c + e * r0, c - e * r0]
                        .into_iter()
                        .min_by(|x, y| ((*x - c2).norm() - r2).abs().total_cmp(&((*y - c2).norm() - r2).abs()))
                        .unwrap_or(c);
                    if ((p - c2).norm() - r2).abs() > tol {
                        return Err("TANTO: the circles do not touch".into());
                    }
                    found.push(angle(p));
                } else {
                    let inside = (start - c2).norm() < r2;
                    let rho = match d.stop {
                        Stop::To => r2 + if inside { -need_r()? } else { need_r()? },
                        Stop::Past => r2 + if inside { need_r()? } else { -need_r()? },
                        _ => r2,
                    };
                    let a = (r0 * r0 - rho * rho + dist * dist) / (2.0 * dist);
                    let h2 = r0 * r0 - a * a;
                    if h2 < -tol * r0 {
                        return Err("the circles never meet".into());
                    }
                    let h = h2.max(0.0).sqrt();
                    let across = kk.cross(&e);
                    found.extend([c + e * a + across * h, c + e * a - across * h].map(angle));
                }
            }
        }
        found
            .into_iter()
            .filter(|t| t.is_finite())
            .min_by(f64::total_cmp)
            .ok_or_else(|| "the circle never meets the check surface".to_string())
    }
}

/// The circle the tool follows: its point at an angle (counter-clockwise about `kk` from the
/// start), its centre, the axis and its radius.
#[derive(Clone, Copy)]
struct Followed<'a> {
    at: &'a dyn Fn(f64) -> Vec3,
    c: Vec3,
    kk: Vec3,
    r0: f64,
}

/// The direction `go` turns `fwd` to, about the tool axis `k`.
fn turned(fwd: Vec3, k: Vec3, go: Go) -> Vec3 {
    match go {
        Go::Fwd => fwd,
        Go::Back => -fwd,
        Go::Left => k.cross(&fwd),
        Go::Right => fwd.cross(&k),
    }
}

/// Where the tool centre stops against a plane it starts on the `side` of (±1): on it, short
/// of it by the tool's radius (TO), or beyond it (PAST).
fn offset(stop: Stop, side: f64, need_r: impl Fn() -> Result<f64, &'static str>) -> Result<f64, String> {
    Ok(match stop {
        Stop::On | Stop::Tanto => 0.0,
        Stop::To => side * need_r()?,
        Stop::Past => -side * need_r()?,
    })
}

/// The check surface as a plane (a LINE is APT's plane through it along `k`) or as a circle
/// projected into the plane through `start` across `k`.
fn check(d: &Drive, k: Vec3, start: Vec3) -> Check {
    match d.check {
        Geometry::Plane { normal, d } => Check::Plane(Vec3::from(normal), d),
        Geometry::Line { a, b } => {
            let (a, b) = (Vec3::from(a), Vec3::from(b));
            let n = (b - a).cross(&k).try_normalize(1e-12).unwrap_or_else(|| (b - a).normalize());
            Check::Plane(n, n.dot(&a))
        }
        Geometry::Circle { center, radius, .. } => {
            let c2 = Vec3::from(center);
            Check::Circle(c2 + k * k.dot(&(start - c2)), radius)
        }
    }
}
