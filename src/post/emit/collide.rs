//! The collision check of each block and of the motion to it from the block before: the
//! machine's bodies, the tool and the stock posed by the joints (`collide::World`).

use super::{At, Emitter};
use crate::collide::{Hit, ToolShape};
use crate::diag::{Code, Diagnostic, Severity};
use crate::kinematics::Units;
use crate::kinematics::{Machine, Vec3};
use crate::post::Sink;

/// Joints at one end of a move: linears, actual rotary angles (radians).
type Ends<'a> = (&'a [f64; 3], &'a [f64; 3]);

/// The samples along the move from `from` (none: the machine got to `to` some other way) to
/// `to`, the deepest hit per pair, and where the samples were too few (`World::samples`).
fn sweep(world: &mut crate::collide::World, m: &Machine, from: Option<Ends>, to: Ends, len: f64, wo: &Vec3, stock: bool) -> (usize, Vec<Hit>, Option<(f64, f64)>) {
    let mut hits: Vec<Hit> = Vec::new();
    let (to_lin, to_act) = to;
    if world.move_clear(m, from, to, len, wo, stock) {
        return (1, hits, None);
    }
    let (n, coarse) = from.map_or((1, None), |f| world.samples(m, f, to, len, wo));
    for k in 1..=n {
        let t = k as f64 / n as f64;
        let (mut lin, mut act) = (*to_lin, *to_act);
        if let Some((p_lin, p_act)) = from.filter(|_| k < n) {
            for i in 0..3 {
                lin[i] = p_lin[i] + (to_lin[i] - p_lin[i]) * t;
                act[i] = p_act[i] + (to_act[i] - p_act[i]) * t;
            }
        }
        world.check_at(m, &lin, &act, len, wo, stock, &mut hits);
    }
    (n, hits, coarse)
}

impl<S: Sink + ?Sized> Emitter<'_, S> {
    /// Diagnostics of the bodies that overlap (`collision`, an error) or come closer than the
    /// clearance (`near_collision`, a warning) at `to` or on the way from `prev`.
    pub(super) fn collisions(&mut self, prev: Option<&At>, to: &At, rapid: bool, line: u32, diags: &mut Vec<Diagnostic>) {
        let tool = self.tool_shape();
        let Some(world) = self.world.as_mut() else { return };
        world.set_tool(tool);
        let stock = world.stock_at_rapid(rapid);
        // The move from the block before (not across a tool change: the machine went elsewhere).
        let from = prev.filter(|_| !self.tool_changed).map(|p| (&p.joints.linear, &p.actual));
        let to = (&to.joints.linear, &to.actual);
        let (n, hits, coarse) = sweep(world, self.m, from, to, self.setup.tool_length, &self.setup.work_offset, stock);
        let unit = self.m.units.as_str();
        if let Some((apart, step)) = coarse {
            diags.push(Diagnostic::new(
                Code::CollisionCoarse,
                Severity::Warning,
                Some(line),
                format!(
                    "the move to this block was checked for collisions at {} samples, up to {apart:.3} {unit} of body motion apart where the check keeps them within {step:.3} {unit} (the clearance, or half the smallest body where less): a thin body or a shallow overlap could pass between two unseen",
                    crate::collide::MAX_SAMPLES
                ),
            ));
        }
        for h in hits {
            let (code, severity, what) = if h.dist < 0.0 {
                (Code::Collision, Severity::Error, format!("overlap by {:.3} {unit}", -h.dist))
            } else {
                (Code::NearCollision, Severity::Warning, format!("{:.3} {unit} apart", h.dist))
            };
            let on = if n > 1 { "at or on the way to this block" } else { "at this block" };
            let mut d = Diagnostic::new(code, severity, Some(line), format!("{} and {}: {what} {on}", h.a, h.b));
            d.bodies = Some(Box::new(crate::diag::Bodies {
                a: h.a,
                b: h.b,
                distance: h.dist,
            }));
            diags.push(d);
        }
    }

    /// The tool in the spindle: the tool table's diameter, corner radius and holder where it
    /// gives them, else the cutter the CL describes, else the defaults; the length in force.
    pub(super) fn tool_shape(&self) -> ToolShape {
        let mm = self.m.units == Units::Mm;
        let mut s = ToolShape::default_for(self.setup.tool_length, mm);
        if let Some((d, r)) = self.cl_cutter {
            (s.diameter, s.corner_radius) = (d, r);
        }
        let Some(table) = self.o.tool_table.as_ref() else { return s };
        let Some(t) = self.tool.and_then(|n| table.get(n)) else { return s };
        let k = table.units.factor_to(self.m.units);
        if let Some(d) = t.diameter {
            s.diameter = d * k;
        }
        if let Some(r) = t.corner_radius {
            s.corner_radius = r * k;
        }
        if let Some(h) = t.holder {
            s.holder_diameter = h.diameter * k;
            s.holder_length = h.length * k;
        }
        s
    }
}
