//! The collision check of each block and of the motion to it from the block before: the
//! machine's bodies, the tool and the stock posed by the joints (`collide::World`).

use super::{At, Emitter};
use crate::collide::{Axes, Coarse, Hit, ToolShape, World};
use crate::diag::{Code, Diagnostic, Severity};
use crate::kinematics::{self, Machine, Pose, Setup, Units, Vec3};
use crate::nc::Canned;
use crate::post::{ArcSpec, Mode, Options, Sink};

/// The collision check's state: the machine's bodies, the tool and the stock, when it is on.
pub(super) struct Check {
    world: Option<crate::collide::World>,
}

impl Check {
    /// `scale`: the CL's units to the profile's (the job gives stock and fixtures in the CL's
    /// units, known once the reader has looked ahead).
    pub(super) fn new(m: &Machine, o: &Options, scale: f64) -> Check {
        let world = o.geometry.as_ref().map(|g| {
            let k = |v: &[crate::collide::Solid]| v.iter().map(|s| s.scaled(scale)).collect::<Vec<_>>();
            crate::collide::World::new(m, g, &k(&o.stock), &k(&o.fixtures), o.collision_clearance, o.tolerance.max(1e-3))
        });
        Check { world }
    }

    /// The check is on.
    #[inline]
    pub(super) fn on(&self) -> bool {
        self.world.is_some()
    }
}

/// A block's arc, as the collision check follows it: the whole arc's start and end tips, the
/// arc, and the stretch of it (fractions) this block takes.
pub(super) type ArcPath = (Vec3, Vec3, ArcSpec, [f64; 2]);

/// How the machine moves between two blocks: the joints in a straight line, or with TCP the
/// control moving the tip (X Y Z words, W) and the rotary words in a straight line and placing
/// the linears for each, with its nominal kinematics.
enum Way {
    Joints,
    Tcp { tip: [Vec3; 2], words: [[f64; 3]; 2], setup: Setup },
    /// G2/G3 (the rotaries still): the tip along the arc, fractions `f` of the whole arc from
    /// `tips[0]` to `tips[1]`.
    Arc { tips: [Vec3; 2], arc: ArcSpec, f: [f64; 2], actual: [f64; 3], setup: Setup },
}

impl Way {
    /// The joints a fraction `t` of the way from `a` to `b`.
    fn at(&self, m: &Machine, a: &Axes, b: &Axes, t: f64) -> Axes {
        let lerp = |x: &[f64; 3], y: &[f64; 3]| std::array::from_fn(|i| x[i] + (y[i] - x[i]) * t);
        match self {
            Way::Joints => Axes {
                linear: lerp(&a.linear, &b.linear),
                actual: lerp(&a.actual, &b.actual),
            },
            Way::Tcp { tip, words, setup } => {
                let w = lerp(&words[0], &words[1]);
                let q = kinematics::controlled_point(m, &w, &(tip[0] + (tip[1] - tip[0]) * t), setup);
                Axes {
                    linear: [q.x, q.y, q.z],
                    actual: m.actual_angles(&w),
                }
            }
            Way::Arc { tips, arc, f, actual, setup } => {
                let tip = super::arcs::helix_tip(tips[0], tips[1], arc, f[0] + (f[1] - f[0]) * t);
                let q = kinematics::controlled_point(m, actual, &tip, setup);
                Axes {
                    linear: [q.x, q.y, q.z],
                    actual: *actual,
                }
            }
        }
    }

    /// How long the linears' path can be beyond their chord (0: no longer): the tip's move and
    /// each rotary word's turn times the farthest the controlled point can be from its axis
    /// (`pivots`: [`crate::collide::World::pivots`]).
    fn path(&self, m: &Machine, pivots: f64) -> f64 {
        if let Way::Arc { tips, arc, f, .. } = self {
            // The arc's length (the rotaries still: the same in the machine), a little over.
            let r = tips[0] - arc.center;
            let (h, rise) = (arc.normal.dot(&r), arc.normal.dot(&(tips[1] - arc.center)));
            let turn = (r - arc.normal * h).norm() * arc.sweep.abs();
            return turn.hypot(rise - h) * (f[1] - f[0]).abs() * (1.0 + 1e-9);
        }
        let Way::Tcp { tip, words, setup } = self else { return 0.0 };
        let lever = tip[0].norm().max(tip[1].norm())
            + setup.work_offset.norm()
            + setup.tool_length.abs()
            + pivots;
        let turn: f64 = (0..m.rotaries.len()).map(|i| (words[1][i] - words[0][i]).abs()).sum();
        (tip[1] - tip[0]).norm() + turn * lever
    }
}

/// What the samples of one block's moves found: the deepest hit per pair, how many samples,
/// and where they were too few (`World::samples`) the coarsest.
#[derive(Default)]
struct Found {
    samples: usize,
    hits: Vec<Hit>,
    coarse: Option<Coarse>,
}

/// One move to check: from where (none: the machine got to `to` some other way), to where, the
/// way the machine goes, and whether the cutter is checked against the stock.
struct Move {
    from: Option<Axes>,
    to: Axes,
    way: Way,
    stock: bool,
}

/// The samples along the move `mv`, into `found`; cut short when `halted` says the run is
/// stopping (over its time, its reader gone): a move of thousands of samples on meshes can
/// take minutes.
fn sweep(world: &mut World, m: &Machine, setup: &Setup, mv: &Move, found: &mut Found, halted: &mut dyn FnMut() -> bool) {
    let (from, to, stock) = (mv.from.as_ref(), &mv.to, mv.stock);
    let path = from.map_or(0.0, |_| mv.way.path(m, world.pivots()));
    if world.move_clear(m, setup, from, to, stock, path) {
        found.samples += 1;
        return;
    }
    let (n, coarse) = from.map_or((1, None), |f| world.samples(m, setup, f, to, path));
    if coarse.is_some_and(|c| found.coarse.is_none_or(|was| c.apart > was.apart)) {
        found.coarse = coarse;
    }
    found.samples += n;
    let hits = &mut found.hits;
    for k in 1..=n {
        if halted() {
            return;
        }
        let at = match from.filter(|_| k < n) {
            Some(f) => mv.way.at(m, f, to, k as f64 / n as f64),
            None => *to,
        };
        match k < n {
            true => world.check_on_the_way(m, setup, &at, stock, hits),
            false => world.check_at(m, setup, &at, stock, hits),
        }
    }
}

impl<S: Sink + ?Sized> Emitter<'_, S> {
    /// Diagnostics of the bodies that overlap (`collision`, an error) or come closer than the
    /// clearance (`near_collision`, a warning) at `to` or on the way from `prev`.
    pub(super) fn collisions(
        &mut self,
        prev: Option<&At>,
        to: &At,
        rapid: bool,
        arc: Option<ArcPath>,
        line: u32,
        diags: &mut Vec<Diagnostic>,
    ) {
        let mut found = Found::default();
        self.sweep_to(prev, to, rapid, arc, &mut found);
        self.tell(found, line, diags);
    }

    /// The move to `to` from `prev` (a rapid or not, an `arc` or not), its samples checked into
    /// `found`.
    fn sweep_to(&mut self, prev: Option<&At>, to: &At, rapid: bool, arc: Option<ArcPath>, found: &mut Found) {
        let tool = self.tool_shape();
        let Some(world) = self.collide.world.as_mut() else { return };
        world.set_tool(tool);
        let stock = world.stock_at_rapid(rapid);
        // The move from the block before (not across a tool change: the machine went elsewhere).
        let prev = prev.filter(|_| !self.tool.changed());
        let way = match (arc, self.o.mode, prev) {
            (Some((from, end, arc, f)), _, Some(_)) => Way::Arc {
                tips: [from, end],
                arc,
                f,
                actual: to.actual,
                setup: *self.tool.setup(),
            },
            (_, Mode::Tcp, Some(p)) => Way::Tcp {
                tip: [self.tcp_xyz(p), self.tcp_xyz(to)],
                words: [p.joints.rotary, to.joints.rotary],
                setup: *self.tool.setup(),
            },
            _ => Way::Joints,
        };
        let Some(world) = self.collide.world.as_mut() else { return };
        let axes = |a: &At| Axes {
            linear: a.joints.linear,
            actual: a.actual,
        };
        let mv = Move {
            from: prev.map(axes),
            to: axes(to),
            way,
            stock,
        };
        let sink = &mut *self.sink;
        sweep(world, self.m, self.tool.setup(), &mv, found, &mut || sink.halted().is_some());
    }

    /// What `found` found, as diagnostics of the block at `line`.
    fn tell(&self, found: Found, line: u32, diags: &mut Vec<Diagnostic>) {
        let unit = self.m.units.as_str();
        if let Some(Coarse { apart, step }) = found.coarse {
            diags.push(Diagnostic::new(
                Code::CollisionCoarse,
                Severity::Warning,
                Some(line),
                format!(
                    "the move to this block was checked for collisions at {} samples, up to {apart:.3} {unit} of body motion apart where the check keeps them within {step:.3} {unit} (the clearance, or half the smallest body where less): a thin body or a shallow overlap could pass between two unseen",
                    found.samples
                ),
            ));
        }
        for h in found.hits {
            let (code, severity, what) = if h.dist < 0.0 {
                (Code::Collision, Severity::Error, format!("overlap by {:.3} {unit}", -h.dist))
            } else {
                (Code::NearCollision, Severity::Warning, format!("{:.3} {unit} apart", h.dist))
            };
            let on = if found.samples > 1 { "at or on the way to this block" } else { "at this block" };
            let mut d = Diagnostic::new(code, severity, Some(line), format!("{} and {}: {what} {on}", h.a, h.b));
            d.bodies = Some(Box::new(crate::diag::Bodies {
                a: h.a,
                b: h.b,
                distance: h.dist,
            }));
            diags.push(d);
        }
    }

    /// A canned hole's strokes as the control makes them: down to the R plane (rapid), to the
    /// bottom (feed), back to the level it returns to (rapid, G98's start or G99's R), and where
    /// the cycle goes on from the hole before (`from`), across at that level. One diagnostic per
    /// pair, the deepest of all the strokes (a collision where any overlaps), for the cycle's one
    /// block.
    pub(super) fn hole_collisions(&mut self, from: Option<&At>, start: &At, cb: &Canned, line: u32, diags: &mut Vec<Diagnostic>) {
        if !self.collide.on() {
            return;
        }
        let lift = cb.z_start.max(cb.z_r) - cb.z_start;
        let top = self.along(start, lift);
        let mut found = Found::default();
        let first = match from {
            Some(p) => {
                let across = self.along(p, lift);
                self.sweep_to(Some(&across), &top, true, None, &mut found);
                top
            }
            None => *start,
        };
        let (r, bottom) = (self.along(start, cb.z_r - cb.z_start), self.along(start, cb.z_bottom - cb.z_start));
        self.sweep_to(Some(&first), &r, true, None, &mut found);
        self.sweep_to(Some(&r), &bottom, false, None, &mut found);
        self.sweep_to(Some(&bottom), &top, true, None, &mut found);
        self.tell(found, line, diags);
    }

    /// `at` with the tip moved `by` along the tool axis, the rotaries standing.
    fn along(&self, at: &At, by: f64) -> At {
        let tip = at.pose.tip + at.pose.axis.normalize() * by;
        let q = kinematics::controlled_point(self.m, &at.actual, &tip, self.tool.setup());
        let mut to = *at;
        to.joints.linear = [q.x, q.y, q.z];
        to.pose = Pose { tip, axis: at.pose.axis };
        to
    }

    /// The tool in the spindle: the tool table's diameter, corner radius and holder where it
    /// gives them, else the cutter the CL describes, else the defaults; the length in force.
    pub(super) fn tool_shape(&self) -> ToolShape {
        let mm = self.m.units == Units::Mm;
        let mut s = ToolShape::default_for(self.tool.setup().tool_length, mm);
        if let Some((d, r)) = self.tool.cutter() {
            (s.diameter, s.corner_radius) = (d, r);
        }
        let Some(table) = self.o.tool_table.as_ref() else { return s };
        let Some(t) = self.tool.number().and_then(|n| table.get(n)) else { return s };
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
