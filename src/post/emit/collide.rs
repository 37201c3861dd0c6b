//! The collision check of each block and of the motion to it from the block before: the
//! machine's bodies, the tool and the stock posed by the joints (`collide::World`).

use super::{At, Emitter};
use crate::collide::{Hit, ToolShape};
use crate::diag::{Code, Diagnostic, Severity};
use crate::kinematics::Units;
use crate::post::Sink;

impl<S: Sink + ?Sized> Emitter<'_, S> {
    /// Diagnostics of the bodies that overlap (`collision`, an error) or come closer than the
    /// clearance (`near_collision`, a warning) at `to` or on the way from `prev`.
    pub(super) fn collisions(&mut self, prev: Option<&At>, to: &At, rapid: bool, line: u32, diags: &mut Vec<Diagnostic>) {
        let shape = self.tool_shape();
        let Some(world) = self.world.as_mut() else { return };
        world.set_tool(shape);
        let stock = world.stock_at_rapid(rapid);
        let (m, len, wo) = (self.m, self.setup.tool_length, self.setup.work_offset);
        let mut hits: Vec<Hit> = Vec::new();
        // The move from the block before (not across a tool change: the machine went elsewhere).
        let from = prev.filter(|_| !self.tool_changed);
        let n = from.map_or(1, |p| {
            world.samples(m, (&p.joints.linear, &p.actual), (&to.joints.linear, &to.actual), len)
        });
        for k in 1..=n {
            let t = k as f64 / n as f64;
            let (mut lin, mut act) = (to.joints.linear, to.actual);
            if let Some(p) = from.filter(|_| k < n) {
                for i in 0..3 {
                    lin[i] = p.joints.linear[i] + (to.joints.linear[i] - p.joints.linear[i]) * t;
                    act[i] = p.actual[i] + (to.actual[i] - p.actual[i]) * t;
                }
            }
            world.check_at(m, &lin, &act, len, &wo, stock, &mut hits);
        }
        let unit = self.m.units.as_str();
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
