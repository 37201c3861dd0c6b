//! One post's world: the machine's bodies, the tool and the job's stock and fixtures, placed on
//! their links, the pairs that can touch, and what the last checks left known of them. Each
//! question takes the machine, the setup and the joints it is asked at, as parry's queries take
//! the poses.

use super::bounds::{Bounds, CLASSES, Motion, Sides, Slack, settled};
use super::distance::{Gap, distance};
use super::geometry::{Geometry, Link, Placed, Solid, ToolShape};
use super::links::{Axes, Links};
use super::pairs::{Pair, PairKind};
use super::samples::{Allowance, Coarse};
use crate::kinematics::{Machine, Setup, Vec3};

/// What the check found between two bodies at one pose.
#[derive(Clone, Debug, PartialEq)]
pub struct Hit {
    pub a: String,
    pub b: String,
    /// Negative: the depth they overlap by; else their distance (below the clearance).
    pub dist: f64,
}

/// The setup of the last check, and its work offset's length: another tool length or work
/// offset moves the bodies unknowably.
struct Frame {
    setup: Setup,
    offset: f64,
}

impl Frame {
    fn of(setup: &Setup) -> Frame {
        Frame {
            setup: *setup,
            offset: setup.work_offset.norm(),
        }
    }
}

/// The bodies of one post, built once, and the pairs that can touch.
pub struct World {
    bodies: Vec<Placed>,
    pairs: Vec<Pair>,
    clearance: f64,
    /// The depth a cutter may cut into what it touches (the chord tolerance).
    cut_depth: f64,
    /// Half the smallest body's size.
    step: f64,
    /// The farthest any body point is from its link's origin.
    reach: f64,
    tool: Option<ToolShape>,
    sides: Sides,
    /// Twice the sum of the rotaries' pivots' distances from the origin: in how far a body
    /// point can be from an axis.
    pivots: f64,
    bounds: Bounds,
    /// The joints of the last check.
    last: Option<Axes>,
    frame: Frame,
    /// The block before was a rapid (or there was none): see [`World::stock_at_rapid`].
    prev_rapid: bool,
    allowance: Allowance,
}

impl std::fmt::Debug for World {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("World").field("bodies", &self.bodies.len()).finish()
    }
}

impl World {
    /// The bodies of `g` on `m`, the job's stock and fixture boxes (in W), checked with
    /// `clearance`.
    pub fn new(m: &Machine, g: &Geometry, stock: &[Solid], fixtures: &[Solid], clearance: f64, cut_depth: f64) -> World {
        let mut w = World {
            bodies: Vec::new(),
            pairs: Vec::new(),
            clearance,
            cut_depth,
            step: f64::INFINITY,
            reach: 0.0,
            tool: None,
            prev_rapid: true,
            sides: Sides::of(m),
            pivots: 2.0 * m.rotaries.iter().map(|r| r.pivot.norm()).sum::<f64>(),
            bounds: Bounds::new(),
            last: None,
            frame: Frame::of(&Setup::new(0.0, Vec3::zeros())),
            allowance: Allowance::default(),
        };
        for b in &g.bodies {
            w.add(&b.name, b.link, &b.solid, 0.0);
        }
        for s in stock {
            w.add("stock", Link::Stock, s, 0.0);
        }
        for (i, s) in fixtures.iter().enumerate() {
            w.add(&format!("fixture {}", i + 1), Link::Fixture, s, 0.0);
        }
        w
    }

    fn add(&mut self, name: &str, link: Link, s: &Solid, round: f64) {
        let (shape, local) = s.shape(round);
        let sphere = shape.compute_local_bounding_sphere();
        let half = s.smallest() / 2.0;
        self.step = self.step.min(half);
        self.reach = self.reach.max(s.reach());
        let probe = shape.as_trimesh().map_or(sphere.center, |t| t.vertices()[0]);
        self.bodies.push(Placed {
            name: name.into(),
            link,
            centre: local * sphere.center,
            radius: sphere.radius,
            shape,
            local,
            probe,
            half,
        });
    }

    /// Whether the cutter is checked against the stock on this block: at rapids, except the
    /// first rapid after a cut, which leaves the material along what the cut removed (the stock
    /// is a box, not what is left of it).
    pub fn stock_at_rapid(&mut self, rapid: bool) -> bool {
        let check = rapid && self.prev_rapid;
        self.prev_rapid = rapid;
        check
    }

    /// Twice the sum of the rotaries' pivots' distances from the origin: in how far a point can
    /// be from an axis.
    pub fn pivots(&self) -> f64 {
        self.pivots
    }

    /// Whether the profile gave any machine body (without one nothing is checked).
    pub fn is_empty(&self) -> bool {
        !self.bodies.iter().any(|b| !matches!(b.link, Link::Stock | Link::Fixture))
    }

    /// Puts the tool on the spindle (again, when it changed) and lists the pairs to check.
    pub fn set_tool(&mut self, t: ToolShape) {
        if self.tool == Some(t) {
            return;
        }
        self.bodies.retain(|b| !matches!(b.link, Link::Holder | Link::Cutter));
        if let Some(holder) = t.holder() {
            self.add("holder", Link::Holder, &holder, 0.0);
        }
        if let Some(cutter) = t.cutter() {
            self.add("cutter", Link::Cutter, &cutter, t.corner_radius);
        }
        // The spacing of the bodies there now: another tool's no longer counts.
        self.step = self.bodies.iter().map(|b| b.half).fold(f64::INFINITY, f64::min);
        self.tool = Some(t);
        self.pairs.clear();
        self.bounds.reset();
        for (i, a) in self.bodies.iter().enumerate() {
            for (j, b) in self.bodies.iter().enumerate() {
                if let Some(kind) = PairKind::of(a.link, b.link) {
                    let class = self.bounds.class_of(self.sides.joints_of(a.link) ^ self.sides.joints_of(b.link));
                    self.pairs.push(Pair::new(i, j, kind, class));
                }
            }
        }
        self.last = None;
    }

    /// How far any point of any body can move relative to any other between two joint sets (the
    /// joints interpolated linearly between them, or the linears along a path no longer than
    /// `path`), joint by joint: the linear move, and each rotary's turn times the farthest a body
    /// point can be from its axis.
    fn motion(&self, m: &Machine, frame: &Frame, from: &Axes, to: &Axes, path: f64) -> Motion {
        let (a, b) = (Vec3::from(from.linear), Vec3::from(to.linear));
        let far = self.reach + frame.offset + a.norm_squared().max(b.norm_squared()).sqrt() + frame.setup.tool_length.abs() + self.pivots;
        let mut by_joint = [(a - b).norm().max(path), 0.0, 0.0, 0.0];
        for i in 0..m.rotaries.len() {
            by_joint[1 + i] = (from.actual[i] - to.actual[i]).abs() * far;
        }
        Motion::known(by_joint)
    }

    /// Hits at `at` with `setup`, the deepest per pair into `out` (a pair already there keeps
    /// its deeper one); `stock`: the cutter is checked against the stock.
    pub fn check_at(&mut self, m: &Machine, setup: &Setup, at: &Axes, stock: bool, out: &mut Vec<Hit>) {
        self.check(m, setup, at, stock, false, out);
    }

    /// As [`World::check_at`], at a sample on the way between two blocks, where a pair found
    /// touching may be told by its last measure (see [`settled`]): within the sample spacing, or
    /// a quarter of the measure told (a third of the distance there), of its distance there.
    pub fn check_on_the_way(&mut self, m: &Machine, setup: &Setup, at: &Axes, stock: bool, out: &mut Vec<Hit>) {
        self.check(m, setup, at, stock, true, out);
    }

    fn check(&mut self, m: &Machine, setup: &Setup, at: &Axes, stock: bool, on_the_way: bool, out: &mut Vec<Hit>) {
        let moved = match &self.last {
            Some(last) if self.frame.setup == *setup => self.motion(m, &self.frame, last, at, 0.0),
            _ => {
                self.frame = Frame::of(setup);
                Motion::UNKNOWN
            }
        };
        self.last = Some(*at);
        self.bounds.moved(&moved);
        if self.bounds.clear(stock) {
            return;
        }
        // The links' poses only where a pair must be asked.
        let mut links = None;
        let spacing = self.spacing();
        let mut slack = [Slack::NONE; CLASSES];
        let moved = self.bounds.since();
        for p in self.pairs.iter_mut() {
            let c = usize::from(p.class);
            p.lower -= moved[c];
            let limit = p.kind.limit(self.clearance, self.cut_depth);
            // Not above the limit (a NaN bound too): asked.
            if p.kind.asked(stock) && !(p.lower > limit) {
                let told = match settled(p.measured, p.lower, limit, spacing).filter(|_| on_the_way) {
                    Some(d) => d,
                    None => {
                        let l = links.get_or_insert_with(|| Links::at(m, setup, at));
                        let (bi, bj) = (&self.bodies[p.a], &self.bodies[p.b]);
                        let (li, lj) = (l.pose_of(bi.link), l.pose_of(bj.link));
                        let centres = (li * bi.centre).distance(lj * bj.centre);
                        let (lower, measured, told) = match distance(bi, bj, &(li * bi.local), &(lj * bj.local), centres, limit) {
                            Gap::Apart(d) => (d, f64::NAN, f64::NAN),
                            Gap::Touching { dist, exact } => (dist, if exact { dist } else { f64::NAN }, dist),
                        };
                        (p.lower, p.measured) = (lower, measured);
                        told
                    }
                };
                if told <= limit {
                    let (a, b) = (&self.bodies[p.a].name, &self.bodies[p.b].name);
                    match out.iter_mut().find(|h| h.a == *a && h.b == *b) {
                        Some(h) => h.dist = h.dist.min(told),
                        None => out.push(Hit {
                            a: a.clone(),
                            b: b.clone(),
                            dist: told,
                        }),
                    }
                }
            }
            slack[c].add(p.kind, p.lower - limit);
        }
        self.bounds.passed(slack);
    }

    /// Whether the whole move from `from` (none: from wherever the machine is) to `to` is clear
    /// by the pairs' bounds, taken at once, where it starts at the joints last checked: the
    /// move's motion bounds how far any body point goes at every point of the move, samples and
    /// the stretches between them alike. Where it is, no sample needs a look; where not, nothing
    /// is counted and the samples are checked. `path`: how long the linears' path may be where
    /// they do not move in a straight line (TCP: the control moves the tip straight).
    pub fn move_clear(&mut self, m: &Machine, setup: &Setup, from: Option<&Axes>, to: &Axes, stock: bool, path: f64) -> bool {
        let Some(last) = &self.last else { return false };
        if from.is_some_and(|f| f != last) || self.frame.setup != *setup {
            return false;
        }
        let motion = self.motion(m, &self.frame, last, to, path);
        if !self.bounds.moved_clear(&motion, stock) {
            return false;
        }
        self.last = Some(*to);
        true
    }

    /// How far apart the samples of a move are kept: half the smallest body's size, and the
    /// clearance where it is less (see [`World::samples`]).
    fn spacing(&self) -> f64 {
        match self.clearance > 0.0 {
            true => self.step.min(self.clearance),
            false => self.step,
        }
        .max(1e-6)
    }

    /// How many samples the motion between two joint sets needs so that no body moves more than
    /// half the smallest body's size between them (none passes through another unseen), nor
    /// more than the clearance (an overlap between two leaves one of them closer than the
    /// clearance, and one deeper than half of it overlapping), at most
    /// [`super::MAX_SAMPLES`]; where that cuts them, how coarse they are. The work offset
    /// carries the stock and fixtures away from the table's axes: a part far off them swings
    /// farther. `path` as for [`World::move_clear`].
    pub fn samples(&mut self, m: &Machine, setup: &Setup, from: &Axes, to: &Axes, path: f64) -> (usize, Option<Coarse>) {
        let moved = self.motion(m, &Frame::of(setup), from, to, path).total();
        self.allowance.take(moved, self.spacing())
    }
}
