//! The machine's bodies and the collision check of every posted block (issue 31).
//!
//! Pure like `kinematics`: no IO. The profile's `[[body]]` entries (read in `machines`) become a
//! [`Geometry`]; a post builds one [`World`] from it, the tool and the job's stock, and asks it at
//! each block (and between blocks, sampled) which bodies touch or come closer than the
//! clearance. The distance queries are parry's (GJK/EPA on boxes and cylinders; a triangle mesh
//! is a BVH of triangles, each tested as a convex shape, and a closed one an inside test too).
//!
//! Where a body sits, at home (every joint zero): bodies on the bed, the table and the table
//! rotaries are given in M; bodies on the ram, the head rotaries and the spindle relative to the
//! gauge point, as head pivots are (`machine-model.md`). Stock and fixtures are boxes in W.

use crate::kinematics::{Machine, Mount, Vec3};
use parry3d_f64::math::{Pose, Rotation, Vector};
use parry3d_f64::query;
use parry3d_f64::shape::{Cuboid, Cylinder, RoundShape, SharedShape, TriMesh};
use std::sync::Arc;

/// The most bodies a profile may give: a machine model, not a CAD assembly.
pub const MAX_BODIES: usize = 64;
/// The most samples of the motion between two blocks: a bound on one block's cost. A move that
/// needs more is told (`collision_coarse`).
pub const MAX_SAMPLES: usize = 16384;
/// What one post's check may spend: [`MAX_SAMPLES`] once, then 256 a move on average; past it a
/// move gets what is left, at least 64, and is told coarse. A stock of ±1e8 (its far corners
/// swinging metres a degree), a 1e-6 mm fixture or a 1e-9 clearance asked the most of every
/// move and multiplied a post's time by 40 to thousands; now its cost is bounded by its moves.
pub const SAMPLES_PER_MOVE: u64 = 256;
const COARSE_SAMPLES: u64 = 64;

/// What a body moves with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Link {
    /// Fixed in M.
    Bed,
    /// Turns with table rotary `i` (chain index) and the table rotaries before it.
    TableRotary(usize),
    /// The workpiece side: after every table rotary.
    Table,
    /// Moves with X Y Z.
    Ram,
    /// Turns with head rotary `i` and the head rotaries before it, and moves with X Y Z.
    HeadRotary(usize),
    /// After every head rotary.
    Spindle,
    /// The job's stock (W, turning with the table).
    Stock,
    /// The job's fixtures (W, turning with the table).
    Fixture,
    /// The tool's holder, on the spindle.
    Holder,
    /// The cutter, on the spindle.
    Cutter,
}

impl Link {
    /// Parses a profile's `on`: `bed`, `table`, `ram`, `spindle` or a rotary's name.
    pub fn parse(on: &str, m: &Machine) -> Result<Link, String> {
        Ok(match on {
            "bed" => Link::Bed,
            "table" => Link::Table,
            "ram" => Link::Ram,
            "spindle" => Link::Spindle,
            _ => {
                let i = m
                    .rotaries
                    .iter()
                    .position(|r| r.name.to_string() == on)
                    .ok_or_else(|| format!("{on:?} must be bed, table, ram, spindle or a rotary's name"))?;
                match m.rotaries[i].mount {
                    Mount::Table => Link::TableRotary(i),
                    Mount::Head => Link::HeadRotary(i),
                }
            }
        })
    }

    fn head_side(self) -> bool {
        matches!(self, Link::Ram | Link::HeadRotary(_) | Link::Spindle | Link::Holder | Link::Cutter)
    }
}

/// A body's shape, at home, in its link's coordinates (see the module's text).
#[derive(Clone, Debug, PartialEq)]
pub enum Solid {
    /// Opposite corners.
    Box { min: Vec3, max: Vec3 },
    /// The axis from `from` to `to`, and the radius.
    Cylinder { from: Vec3, to: Vec3, radius: f64 },
    /// A triangle mesh, built once when the profile loads and shared by every post.
    Mesh(Arc<Mesh>),
}

/// A triangle mesh body (read from an STL file by `machines`): parry's `TriMesh`, a BVH of its
/// triangles, each tested against the other body. A closed mesh wound outward is a solid: a body
/// wholly inside it, touching no triangle, is found by a point of it (a ray cast). An open one is a surface only (the sampling between blocks keeps a body from
/// crossing it unseen).
pub struct Mesh {
    /// The file it was read from (a bare name beside the profile).
    pub file: String,
    /// A digest of the file's bytes: the same file, the same mesh (an ETag).
    pub digest: u64,
    shape: SharedShape,
    min: Vec3,
    max: Vec3,
    /// The file the page draws, made once and shared by every download (each made its own
    /// 10 MB copy: 150 unread ones took a gigabyte).
    drawn: std::sync::OnceLock<Arc<[u8]>>,
}

impl Mesh {
    /// The mesh of these vertices and triangles, or why not (none, an index out of range).
    pub fn new(file: &str, digest: u64, vertices: Vec<Vec3>, triangles: Vec<[u32; 3]>) -> Result<Mesh, String> {
        let (mut min, mut max) = (Vec3::repeat(f64::INFINITY), Vec3::repeat(f64::NEG_INFINITY));
        for p in &vertices {
            min = min.inf(p);
            max = max.sup(p);
        }
        let points: Vec<Vector> = vertices.iter().map(v).collect();
        let tri = match closed(&points, &triangles) {
            Some(t) => t,
            None => TriMesh::new(points, triangles).map_err(|e| format!("not a triangle mesh: {e}"))?,
        };
        Ok(Mesh {
            file: file.into(),
            digest,
            shape: SharedShape::new(tri),
            min,
            max,
            drawn: std::sync::OnceLock::new(),
        })
    }

    /// What `make` writes of it, made at the first call and shared after.
    pub fn drawn(&self, make: impl FnOnce(&Mesh) -> Vec<u8>) -> Arc<[u8]> {
        self.drawn.get_or_init(|| make(self).into()).clone()
    }

    /// Whether it is closed and wound outward: then it is a solid, and a body wholly inside it
    /// is a hit too.
    pub fn is_solid(&self) -> bool {
        self.tri().pseudo_normals_if_oriented().is_some()
    }

    fn tri(&self) -> &TriMesh {
        self.shape.as_trimesh().expect("a Mesh's shape is a TriMesh")
    }

    /// Its vertices (profile units, at home in its link's coordinates).
    pub fn vertices(&self) -> impl ExactSizeIterator<Item = Vec3> + '_ {
        self.tri().vertices().iter().map(|p| Vec3::new(p.x, p.y, p.z))
    }

    /// Its triangles, as indices into [`Mesh::vertices`].
    pub fn triangles(&self) -> &[[u32; 3]] {
        self.tri().indices()
    }

    /// Its bounding box at home: `(min, max)`.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        (self.min, self.max)
    }
}

/// The mesh with its pseudo-normals (the mark of a solid) where it is closed (every edge shared
/// by two triangles), consistently oriented and wound outward (a positive volume); else `None`.
fn closed(points: &[Vector], triangles: &[[u32; 3]]) -> Option<TriMesh> {
    use parry3d_f64::shape::TriMeshFlags;
    let volume: f64 = triangles
        .iter()
        .map(|t| t.map(|i| points.get(i as usize).copied().unwrap_or(Vector::ZERO)))
        .map(|[a, b, c]| a.dot(b.cross(c)))
        .sum();
    if volume.is_nan() || volume <= 0.0 {
        return None;
    }
    let flags = TriMeshFlags::HALF_EDGE_TOPOLOGY | TriMeshFlags::ORIENTED;
    let t = TriMesh::with_flags(points.to_vec(), triangles.to_vec(), flags).ok()?;
    t.topology()?.half_edges.iter().all(|h| h.twin != u32::MAX).then_some(t)
}

impl PartialEq for Mesh {
    fn eq(&self, o: &Mesh) -> bool {
        self.file == o.file && self.digest == o.digest
    }
}

impl std::fmt::Debug for Mesh {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Mesh").field("file", &self.file).field("triangles", &self.triangles().len()).finish()
    }
}

impl Solid {
    /// The same solid with every length times `k` (CL units into the profile's).
    pub fn scaled(&self, k: f64) -> Solid {
        match *self {
            // Meshes are the machine's, in profile units already: never a job's solid.
            Solid::Mesh(ref m) => Solid::Mesh(m.clone()),
            Solid::Box { min, max } => Solid::Box { min: min * k, max: max * k },
            Solid::Cylinder { from, to, radius } => Solid::Cylinder {
                from: from * k,
                to: to * k,
                radius: radius * k,
            },
        }
    }

    /// A box or cylinder of positive, finite size, or what is wrong with it.
    pub fn check(&self) -> Result<(), String> {
        let finite = |v: &Vec3| v.iter().all(|c| c.is_finite() && c.abs() <= crate::kinematics::MAX_COORD);
        match self {
            Solid::Box { min, max } => {
                if !(finite(min) && finite(max)) || (0..3).any(|k| max[k] <= min[k]) {
                    return Err("a box is [x0, y0, z0, x1, y1, z1], each max above its min".into());
                }
            }
            Solid::Cylinder { from, to, radius } => {
                if !(finite(from) && finite(to)) || (to - from).norm() <= 0.0 || !(*radius > 0.0 && *radius <= crate::kinematics::MAX_COORD) {
                    return Err("a cylinder needs two distinct finite end points and a positive radius".into());
                }
            }
            Solid::Mesh(m) => {
                if !(finite(&m.min) && finite(&m.max)) {
                    return Err(format!("every coordinate must be finite and within ±{}", crate::kinematics::MAX_COORD));
                }
                if (m.max - m.min).max() <= 0.0 {
                    return Err("its triangles all sit at one point".into());
                }
            }
        }
        Ok(())
    }

    /// Its smallest dimension.
    fn smallest(&self) -> f64 {
        match self {
            Solid::Box { min, max } => (max - min).min(),
            Solid::Cylinder { from, to, radius } => (2.0 * radius).min((to - from).norm()),
            // A flat mesh (a plate of zero thickness) would ask for endless samples: its
            // largest extent bounds the step instead of its smallest.
            Solid::Mesh(m) => {
                let d = m.max - m.min;
                if d.min() > 0.0 { d.min() } else { d.max() }
            }
        }
    }

    /// The farthest any of its points is from the origin of its link's coordinates.
    fn reach(&self) -> f64 {
        match self {
            Solid::Box { min, max } => min.abs().sup(&max.abs()).norm(),
            Solid::Cylinder { from, to, radius } => from.norm().max(to.norm()) + radius,
            Solid::Mesh(m) => m.min.abs().sup(&m.max.abs()).norm(),
        }
    }

    /// The parry shape and where it sits in the link's coordinates.
    fn shape(&self, round: f64) -> (SharedShape, Pose) {
        match *self {
            Solid::Box { min, max } => {
                let half = (max - min) / 2.0;
                let c = (max + min) / 2.0;
                (SharedShape::new(Cuboid::new(v(&half))), Pose::from_translation(v(&c)))
            }
            Solid::Mesh(ref m) => (m.shape.clone(), Pose::IDENTITY),
            Solid::Cylinder { from, to, radius } => {
                let d = to - from;
                let c = (from + to) / 2.0;
                let rot = Rotation::from_rotation_arc(Vector::Y, v(&d.normalize()));
                let half = d.norm() / 2.0;
                let shape = if round > 0.0 {
                    let r = round.min(radius).min(half);
                    SharedShape::new(RoundShape {
                        inner_shape: Cylinder::new(half - r, radius - r),
                        border_radius: r,
                    })
                } else {
                    SharedShape::new(Cylinder::new(half, radius))
                };
                (shape, Pose::from_parts(v(&c), rot))
            }
        }
    }
}

fn v(p: &Vec3) -> Vector {
    Vector::new(p.x, p.y, p.z)
}

/// A named body of the machine.
#[derive(Clone, Debug, PartialEq)]
pub struct Body {
    pub name: String,
    pub link: Link,
    pub solid: Solid,
}

/// The machine's bodies, validated (profile units).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Geometry {
    pub bodies: Vec<Body>,
}

/// The tool as the check sees it (profile units): the cutter from the tip up, the holder from
/// the gauge line down.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ToolShape {
    pub length: f64,
    pub diameter: f64,
    pub corner_radius: f64,
    pub holder_diameter: f64,
    pub holder_length: f64,
}

impl ToolShape {
    /// The cutter and holder the check assumes where nothing says (mm; scaled for inch).
    pub fn default_for(length: f64, mm: bool) -> ToolShape {
        let k = if mm { 1.0 } else { 1.0 / 25.4 };
        ToolShape {
            length,
            diameter: 10.0 * k,
            corner_radius: 0.0,
            holder_diameter: 40.0 * k,
            holder_length: 40.0 * k,
        }
    }
}

/// What the check found between two bodies at one pose.
#[derive(Clone, Debug, PartialEq)]
pub struct Hit {
    pub a: String,
    pub b: String,
    /// Negative: the depth they overlap by; else their distance (below the clearance).
    pub dist: f64,
}

struct Placed {
    name: String,
    link: Link,
    /// Shared: a mesh's is the profile's, not a copy per post.
    shape: SharedShape,
    local: Pose,
    /// The bounding sphere in the link's coordinates: the cheap first test of a pair.
    centre: Vector,
    radius: f64,
    /// A point of the body (the shape's coordinates): inside a solid mesh, the whole body is,
    /// where no triangle touches it.
    probe: Vector,
    /// Half its smallest size: the samples keep its motion within it.
    half: f64,
}

/// The bodies of one post, built once, and the pairs that can touch.
pub struct World {
    bodies: Vec<Placed>,
    /// (a, b, kind, class): kind 0 any contact, 1 the cutter (depth only), 2 the cutter against
    /// stock (rapids only); class an index into `classes`.
    pairs: Vec<(usize, usize, u8, u8)>,
    clearance: f64,
    /// The depth a cutter may cut into what it touches (the chord tolerance).
    cut_depth: f64,
    step: f64,
    reach: f64,
    tool: Option<ToolShape>,
    /// Bit i set where rotary i turns the table side, and where it turns the head ([`joints_of`]).
    table: u8,
    head: u8,
    /// Twice the sum of the rotaries' pivots' distances from the origin: in how far a body
    /// point can be from an axis.
    pivots: f64,
    /// Per pair, a lower bound on its bodies' distance: the last one measured, less how far
    /// its bodies could move relative to each other up to the last pass (`since` is the rest).
    /// A pair still farther than it must be is not queried again; most pairs stay clear for
    /// many blocks, and parry's queries are the check's cost.
    lower: Vec<f64>,
    /// Per pair, the distance its last query measured (NaN where it gave a bound only): with
    /// `lower`, how far the bodies can have moved since.
    measured: Vec<f64>,
    /// The pairs moved by the same joints share a bound on their motion, so that a head-side
    /// body against a bed-fixed one counts only the linears.
    classes: Vec<Class>,
    /// The least of the classes' `limit`s: while every joint's motion together stays below it,
    /// no class needs a look of its own.
    least: [f64; 2],
    /// The motion since the last pass over the pairs, joint by joint.
    since: Since,
    /// The joints (linear; actual rotary angles) of the last check.
    last: Option<([f64; 3], [f64; 3])>,
    /// The work offset, tool length and the offset's length of the last check: another offset
    /// or length moves the bodies unknowably.
    frame: (Vec3, f64, f64),
    /// The block before was a rapid (or there was none): see [`World::stock_at_rapid`].
    prev_rapid: bool,
    /// Moves sampled, and the samples they took: the post's allowance ([`SAMPLES_PER_MOVE`]).
    moves: u64,
    spent: u64,
}

impl std::fmt::Debug for World {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("World").field("bodies", &self.bodies.len()).finish()
    }
}

/// The pose of every link at one set of joints (actual angles, radians).
struct Links {
    table: [Pose; 3],
    table_all: Pose,
    head: [Pose; 3],
    ram: Pose,
    spindle: Pose,
    work: Pose,
}

fn turn(axis: &Vec3, pivot: &Vec3, angle: f64) -> Pose {
    let r = Rotation::from_axis_angle(v(axis), angle);
    let q = v(pivot);
    Pose::from_parts(q - r * q, r)
}

impl World {
    /// The bodies of `g` on `m`, the job's stock and fixture boxes (in W), checked with
    /// `clearance`.
    pub fn new(m: &Machine, g: &Geometry, stock: &[Solid], fixtures: &[Solid], clearance: f64, cut_depth: f64) -> World {
        let on = |mount: Mount| (0..m.rotaries.len()).filter(|&i| m.rotaries[i].mount == mount).fold(0, |t, i| t | (1 << i));
        let (table, head) = (on(Mount::Table), on(Mount::Head));
        let mut w = World {
            bodies: Vec::new(),
            pairs: Vec::new(),
            clearance,
            cut_depth,
            step: f64::INFINITY,
            reach: 0.0,
            tool: None,
            prev_rapid: true,
            table,
            head,
            pivots: 2.0 * m.rotaries.iter().map(|r| r.pivot.norm()).sum::<f64>(),
            lower: Vec::new(),
            measured: Vec::new(),
            classes: Vec::new(),
            least: [f64::NEG_INFINITY; 2],
            since: Since::ZERO,
            last: None,
            frame: (Vec3::zeros(), 0.0, 0.0),
            moves: 0,
            spent: 0,
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
        let z = Vec3::z();
        let stick = (t.length - t.holder_length).max(t.length * 0.2);
        let holder = Solid::Cylinder {
            from: -z * (t.length - stick),
            to: Vec3::zeros(),
            radius: t.holder_diameter / 2.0,
        };
        let cutter = Solid::Cylinder {
            from: -z * t.length,
            to: -z * (t.length - stick),
            radius: t.diameter / 2.0,
        };
        // A body no longer than this is no body (a tool of length 0: the gauge point is the
        // spindle nose); one kept would ask for samples a thousandth of a micron apart.
        const SHORTEST: f64 = 1e-3;
        if t.holder_length > 0.0 && t.holder_diameter > 0.0 && t.length - stick >= SHORTEST {
            self.add("holder", Link::Holder, &holder, 0.0);
        }
        if stick >= SHORTEST {
            self.add("cutter", Link::Cutter, &cutter, t.corner_radius);
        }
        // The spacing of the bodies there now: another tool's no longer counts.
        self.step = self.bodies.iter().map(|b| b.half).fold(f64::INFINITY, f64::min);
        self.tool = Some(t);
        self.pairs.clear();
        self.classes.clear();
        let of = |l: Link| joints_of(l, self.table, self.head);
        for (i, a) in self.bodies.iter().enumerate() {
            for (j, b) in self.bodies.iter().enumerate() {
                if let Some(kind) = pair_kind(a.link, b.link) {
                    self.pairs.push((i, j, kind, class_of(&mut self.classes, of(a.link) ^ of(b.link))));
                }
            }
        }
        self.lower = vec![f64::NEG_INFINITY; self.pairs.len()];
        self.measured = vec![f64::NAN; self.pairs.len()];
        self.least = [f64::NEG_INFINITY; 2];
        self.last = None;
    }

    /// How far any point of any body can move relative to any other between two joint sets (the
    /// joints interpolated linearly between them, or the linears along a path no longer than
    /// `path`), joint by joint: the linear move, and each rotary's turn times the farthest a body
    /// point can be from its axis.
    fn motion(&self, m: &Machine, from: (&[f64; 3], &[f64; 3]), to: (&[f64; 3], &[f64; 3]), tool_length: f64, wo_norm: f64, path: f64) -> Motion {
        let (a, b) = (Vec3::from(*from.0), Vec3::from(*to.0));
        let far = self.reach + wo_norm + a.norm_squared().max(b.norm_squared()).sqrt() + tool_length.abs() + self.pivots;
        let mut by_joint = [(a - b).norm().max(path), 0.0, 0.0, 0.0];
        for i in 0..m.rotaries.len() {
            by_joint[1 + i] = (from.1[i] - to.1[i]).abs() * far;
        }
        Motion { known: true, by_joint }
    }

    fn links(m: &Machine, linear: &[f64; 3], actual: &[f64; 3], tool_length: f64, work_offset: &Vec3) -> Links {
        let mut table = [Pose::IDENTITY; 3];
        let mut head = [Pose::IDENTITY; 3];
        let mut t = Pose::IDENTITY;
        let mut h = Pose::from_translation(Vector::new(linear[0], linear[1], linear[2] + tool_length));
        let ram = h;
        for (i, r) in m.rotaries.iter().enumerate() {
            match r.mount {
                Mount::Table => {
                    t = t * turn(&r.axis, &r.pivot, actual[i]);
                    table[i] = t;
                }
                Mount::Head => {
                    h = h * turn(&r.axis, &r.pivot, actual[i]);
                    head[i] = h;
                }
            }
        }
        Links {
            table,
            table_all: t,
            head,
            ram,
            spindle: h,
            work: t * Pose::from_translation(v(work_offset)),
        }
    }

    fn pose_of(l: &Links, link: Link) -> Pose {
        match link {
            Link::Bed => Pose::IDENTITY,
            Link::TableRotary(i) => l.table[i],
            Link::Table => l.table_all,
            Link::Ram => l.ram,
            Link::HeadRotary(i) => l.head[i],
            Link::Spindle | Link::Holder | Link::Cutter => l.spindle,
            Link::Stock | Link::Fixture => l.work,
        }
    }

    /// Hits at one set of joints (linears; actual rotary angles, radians), the deepest per pair
    /// into `out` (a pair already there keeps its deeper one).
    #[allow(clippy::too_many_arguments)]
    pub fn check_at(&mut self, m: &Machine, linear: &[f64; 3], actual: &[f64; 3], tool_length: f64, work_offset: &Vec3, stock: bool, out: &mut Vec<Hit>) {
        self.check(m, (linear, actual), tool_length, work_offset, stock, false, out);
    }

    /// As [`World::check_at`], at a sample on the way between two blocks, where a pair found
    /// touching may be told by its last measure (see [`settled`]): within the sample spacing, or
    /// a quarter of the measure told (a third of the distance there), of its distance there.
    #[allow(clippy::too_many_arguments)]
    pub fn check_on_the_way(&mut self, m: &Machine, linear: &[f64; 3], actual: &[f64; 3], tool_length: f64, work_offset: &Vec3, stock: bool, out: &mut Vec<Hit>) {
        self.check(m, (linear, actual), tool_length, work_offset, stock, true, out);
    }

    #[allow(clippy::too_many_arguments)]
    fn check(&mut self, m: &Machine, (linear, actual): (&[f64; 3], &[f64; 3]), tool_length: f64, work_offset: &Vec3, stock: bool, on_the_way: bool, out: &mut Vec<Hit>) {
        let moved = match &self.last {
            Some((l0, a0)) if self.in_frame(work_offset, tool_length) => self.motion(m, (l0, a0), (linear, actual), tool_length, self.frame.2, 0.0),
            _ => {
                self.frame = (*work_offset, tool_length, work_offset.norm());
                Motion::UNKNOWN
            }
        };
        self.last = Some((*linear, *actual));
        self.since = self.since.plus(&moved);
        if self.clear(&self.since, stock) {
            return;
        }
        // The links' poses only where a pair must be asked.
        let mut links = None;
        let spacing = self.spacing();
        let mut slack = [[f64::INFINITY; 2]; CLASSES];
        let mut moved = [0.0; CLASSES];
        for (c, m) in self.classes.iter().zip(&mut moved) {
            *m = self.since.of(&c.weights);
        }
        for (p, &(i, j, kind, c)) in self.pairs.iter().enumerate() {
            let c = usize::from(c);
            self.lower[p] -= moved[c];
            // Told below this distance: the clearance, or for the cutter the depth it may cut.
            let limit = if kind == 0 { self.clearance } else { -self.cut_depth };
            // Not above the limit (a NaN bound too): asked.
            if (kind != 2 || stock) && !(self.lower[p] > limit) {
                let told = match settled(self.measured[p], self.lower[p], limit, spacing).filter(|_| on_the_way) {
                    Some(d) => d,
                    None => {
                        let l = links.get_or_insert_with(|| Self::links(m, linear, actual, tool_length, work_offset));
                        let (bi, bj) = (&self.bodies[i], &self.bodies[j]);
                        let (li, lj) = (Self::pose_of(l, bi.link), Self::pose_of(l, bj.link));
                        let centres = (li * bi.centre).distance(lj * bj.centre);
                        let (lower, measured, told) = match distance(bi, bj, &(li * bi.local), &(lj * bj.local), centres, limit) {
                            Apart(d) => (d, f64::NAN, f64::NAN),
                            Touching(d, exact) => (d, if exact { d } else { f64::NAN }, d),
                        };
                        (self.lower[p], self.measured[p]) = (lower, measured);
                        told
                    }
                };
                if told <= limit {
                    let (a, b) = (&self.bodies[i].name, &self.bodies[j].name);
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
            let s = &mut slack[c][usize::from(kind == 2)];
            *s = least(*s, self.lower[p] - limit);
        }
        self.since = Since::ZERO;
        self.least = [f64::INFINITY; 2];
        for (class, [s0, s1]) in self.classes.iter_mut().zip(slack) {
            // Clear while the motion stays below the slack less a margin (1e-9 of it).
            let below = |s: f64| if s.is_finite() { s - 1e-9 * (1.0 + s.abs()) } else { s };
            class.limit = [below(s0), least(below(s0), below(s1))];
            self.least = [least(self.least[0], class.limit[0]), least(self.least[1], class.limit[1])];
        }
    }

    /// Whether every pair is still clear by its bound less the motion `since` the last pass:
    /// all joints' motion against every class's limit at once, else class by class.
    fn clear(&self, since: &Since, stock: bool) -> bool {
        let s = usize::from(stock);
        since.of(&[1.0; 4]) < self.least[s] || self.classes.iter().all(|c| since.of(&c.weights) < c.limit[s])
    }

    fn in_frame(&self, work_offset: &Vec3, tool_length: f64) -> bool {
        self.frame.0 == *work_offset && self.frame.1 == tool_length
    }

    /// Whether the whole move from `from` (none: from wherever the machine is) to `to` is clear
    /// by the pairs' bounds, taken at once, where it starts at the joints last checked: the
    /// move's motion bounds how far any body point goes at every point of the move, samples and
    /// the stretches between them alike. Where it is, no sample needs a look; where not, nothing
    /// is counted and the samples are checked. `path`: how long the linears' path may be where
    /// they do not move in a straight line (TCP: the control moves the tip straight).
    #[allow(clippy::too_many_arguments)]
    pub fn move_clear(&mut self, m: &Machine, from: Option<(&[f64; 3], &[f64; 3])>, to: (&[f64; 3], &[f64; 3]), tool_length: f64, work_offset: &Vec3, stock: bool, path: f64) -> bool {
        let Some((l0, a0)) = &self.last else { return false };
        if from.is_some_and(|(l, a)| l != l0 || a != a0) || !self.in_frame(work_offset, tool_length) {
            return false;
        }
        let since = self.since.plus(&self.motion(m, (l0, a0), to, tool_length, self.frame.2, path));
        if !self.clear(&since, stock) {
            return false;
        }
        self.since = since;
        self.last = Some((*to.0, *to.1));
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
    /// clearance, and one deeper than half of it overlapping), at most [`MAX_SAMPLES`]; where
    /// that cuts them, how far a body may move between two and how far it should have. The work
    /// offset carries the stock and fixtures away from the table's axes: a part far off them
    /// swings farther. `path` as for [`World::move_clear`].
    #[allow(clippy::too_many_arguments)]
    pub fn samples(&mut self, m: &Machine, from: (&[f64; 3], &[f64; 3]), to: (&[f64; 3], &[f64; 3]), tool_length: f64, work_offset: &Vec3, path: f64) -> (usize, Option<(f64, f64)>) {
        let moved = self.motion(m, from, to, tool_length, work_offset.norm(), path).total();
        let step = self.spacing();
        let n = (moved / step).ceil();
        self.moves += 1;
        let left = (MAX_SAMPLES as u64 + SAMPLES_PER_MOVE * self.moves).saturating_sub(self.spent);
        let most = left.clamp(COARSE_SAMPLES, MAX_SAMPLES as u64) as usize;
        let (n, coarse) = match n.is_finite() && n <= most as f64 {
            true => ((n as usize).max(1), None),
            false => (most, Some((moved / most as f64, step))),
        };
        self.spent += n as u64;
        (n, coarse)
    }
}

/// Bit 3 of a set of joints: the linears (bits 0–2: the rotaries).
const LINEARS: u8 = 8;
/// As many classes as sets of joints (four bits; [`weights`] tells them apart).
const CLASSES: usize = 16;

/// The joints that move link `l` relative to the bed (`table`, `head`: the rotaries on each
/// side). Each side's links are moved by a prefix of its chain and the two sides share no joint,
/// so the joints between two links (those that move one relative to the other) are the two
/// sets' symmetric difference.
fn joints_of(l: Link, table: u8, head: u8) -> u8 {
    let upto = |i: usize| (2u8 << i) - 1;
    match l {
        Link::Bed => 0,
        Link::TableRotary(i) => table & upto(i),
        Link::Table | Link::Stock | Link::Fixture => table,
        Link::Ram => LINEARS,
        Link::HeadRotary(i) => LINEARS | (head & upto(i)),
        Link::Spindle | Link::Holder | Link::Cutter => LINEARS | head,
    }
}

/// The pairs whose bodies move relative to each other by the same joints.
struct Class {
    /// 1 for each of [`Motion::by_joint`]'s terms that moves its pairs, else 0.
    weights: [f64; 4],
    /// Set at each pass from the least of its pairs' `lower` less each one's limit: its pairs
    /// are clear while their motion since stays below `limit[0]`, or with the cutter against
    /// the stock counted too, `limit[1]`.
    limit: [f64; 2],
}

/// How far body points may have moved since the last pass over the pairs, joint by joint.
#[derive(Clone, Copy)]
struct Since {
    /// As [`Motion::by_joint`], summed and rounded up: never short of the motion.
    by_joint: [f64; 4],
    /// Unknown (the first check, or another tool length or work offset since).
    unknown: bool,
}

impl Since {
    const ZERO: Since = Since {
        by_joint: [0.0; 4],
        unknown: false,
    };

    fn plus(&self, m: &Motion) -> Since {
        let mut s = *self;
        s.unknown |= !m.known;
        for (a, d) in s.by_joint.iter_mut().zip(m.by_joint) {
            *a = (*a + d) * (1.0 + 2.0 * f64::EPSILON);
        }
        s
    }

    /// The motion of points moved by the joints `w` weighs (a class's), rounded up.
    fn of(&self, w: &[f64; 4]) -> f64 {
        let d = &self.by_joint;
        let sum = (w[0] * d[0] + w[1] * d[1] + w[2] * d[2] + w[3] * d[3]) * (1.0 + 4.0 * f64::EPSILON);
        if self.unknown { f64::INFINITY } else { sum }
    }
}

/// How far body points can move between two joint sets, by the joints that move them.
struct Motion {
    /// False: nothing known (no joints checked before, or another tool length or work offset).
    known: bool,
    /// The linear move, then per rotary its turn times the farthest a body point can be from
    /// its axis.
    by_joint: [f64; 4],
}

impl Motion {
    const UNKNOWN: Motion = Motion {
        known: false,
        by_joint: [0.0; 4],
    };

    fn total(&self) -> f64 {
        if self.known { self.by_joint.iter().sum() } else { f64::INFINITY }
    }
}

/// The index in `classes` of the class moved by `joints` (bits as [`joints_of`]'s), added if new.
fn class_of(classes: &mut Vec<Class>, joints: u8) -> u8 {
    let w = weights(joints);
    let c = classes.iter().position(|k| k.weights == w).unwrap_or_else(|| {
        classes.push(Class {
            weights: w,
            limit: [f64::NEG_INFINITY; 2],
        });
        classes.len() - 1
    });
    c as u8
}

/// A class's [`Class::weights`] for `joints` (bits as [`joints_of`]'s).
fn weights(joints: u8) -> [f64; 4] {
    let on = |bit: u8| if joints & bit != 0 { 1.0 } else { 0.0 };
    [on(LINEARS), on(1), on(2), on(4)]
}

/// The lesser, or NaN where either is (a NaN bound, from NaN joints, must keep its class from
/// ever counting as clear).
fn least(a: f64, b: f64) -> f64 {
    if a.is_nan() || b.is_nan() { f64::NAN } else { a.min(b) }
}

/// A pair's distance as far as it matters: apart (a lower bound, beyond `limit`), or touching
/// (the signed distance: negative, the depth they overlap by), at or below it, and whether
/// that is the distance itself (parry's) or a bound on it (a body inside a mesh).
enum Gap {
    Apart(f64),
    Touching(f64, bool),
}
use Gap::{Apart, Touching};

/// Where a touching pair's last measured distance still tells it well enough that it need not
/// be asked again: its bodies moved at most `measured − lower` since, so it is within that of
/// the distance now. Enough: what it tells is sure (within `limit`; overlapping or not, the
/// bound either way) and that is at most the sample spacing, or a quarter of the measure where
/// more (an overlap of 40 mm plunging on is still a collision of about 40). A pair overlapping
/// at every sample of a long move cost a penetration query at each: 99% of the time of a
/// program posted under the table.
fn settled(measured: f64, lower: f64, limit: f64, spacing: f64) -> Option<f64> {
    let moved = measured - lower;
    let upper = measured + moved;
    let sure = upper <= limit && (upper < 0.0 || lower >= 0.0);
    (sure && moved <= spacing.max(0.25 * measured.abs())).then_some(measured)
}

/// The cheap bounds first (bounding spheres `centres` apart, boxes), then parry's contact query
/// with a horizon beyond `limit` (the larger body's bounding radius), so that a pair found clear
/// comes back with its distance and is not asked again soon. (`query::distance` is not used: on
/// two cuboids parry 0.31 returned 4.47 where they were 1.21 apart, and the contact query 1.21.)
fn distance(bi: &Placed, bj: &Placed, pi: &Pose, pj: &Pose, centres: f64, limit: f64) -> Gap {
    let spheres = centres - bi.radius - bj.radius;
    if spheres > limit {
        return Apart(spheres);
    }
    let (a, b) = (bi.shape.compute_aabb(pi), bj.shape.compute_aabb(pj));
    let boxes = (0..3).map(|k| (a.mins[k] - b.maxs[k]).max(b.mins[k] - a.maxs[k])).fold(f64::MIN, f64::max);
    if boxes > limit {
        return Apart(boxes);
    }
    // A mesh's contact query tests every triangle whose box comes within the horizon of the
    // other body: none beyond what is told (a table's 300 mm, or even a holder's 20, took in
    // the thousands of slivers of a fine mesh's disc, and a post 15 times as long).
    let mesh = bi.shape.as_trimesh().is_some() || bj.shape.as_trimesh().is_some();
    let horizon = limit.max(0.0) + if mesh { 0.0 } else { bi.radius.max(bj.radius) };
    let gap = match query::contact(pi, &*bi.shape, pj, &*bj.shape, horizon) {
        Ok(Some(c)) if c.dist <= limit => return Touching(c.dist, true),
        Ok(Some(c)) => c.dist,
        Ok(None) => horizon,
        // A pair of shapes parry cannot query: asked again every time, as it is never told.
        Err(_) => f64::NEG_INFINITY,
    };
    // Clear of every triangle of a solid mesh, and yet wholly inside it.
    match inside(bi, pi, &(pj * bj.probe)).or_else(|| inside(bj, pj, &(pi * bi.probe))) {
        Some(d) => Touching(d.min(limit), false),
        None => Apart(gap),
    }
}

/// When `a` is a solid mesh (posed at `pa`) and another body's probe point (in M) is inside it:
/// minus the probe's depth (a lower bound of the overlap).
///
/// Cheap where nothing is wrong: a box test, then one ray cast (inside where the first triangle
/// it meets faces away); the depth (a projection) only for a hit.
fn inside(a: &Placed, pa: &Pose, probe: &Vector) -> Option<f64> {
    use parry3d_f64::query::{PointQuery, Ray, RayCast};
    use parry3d_f64::shape::FeatureId;
    let t = a.shape.as_trimesh().filter(|t| t.pseudo_normals_if_oriented().is_some())?;
    let p = pa.inverse_transform_point(*probe);
    if !t.local_aabb().contains_local_point(p) {
        return None;
    }
    // Along no axis or diagonal: a ray through an edge or a vertex is unlikely.
    let ray = Ray::new(p, Vector::new(0.5377, 0.6161, 0.5756).normalize());
    let hit = t.cast_local_ray_and_get_normal(&ray, f64::MAX, false)?;
    // Face(1): the triangle was met from behind.
    (hit.feature == FeatureId::Face(1)).then(|| -t.project_local_point(p, false).point.distance(p))
}

/// Which pairs are checked: head-side bodies against the table side and the bed; the cutter
/// only by its depth (and against stock only at rapid); the table side against the bed.
fn pair_kind(a: Link, b: Link) -> Option<u8> {
    let table_side = |l: Link| matches!(l, Link::TableRotary(_) | Link::Table | Link::Stock | Link::Fixture);
    match (a, b) {
        (Link::Cutter, Link::Stock) => Some(2),
        (Link::Cutter, b) if table_side(b) || b == Link::Bed => Some(1),
        (Link::Cutter, _) => None,
        (a, b) if a.head_side() && (table_side(b) || b == Link::Bed) => Some(0),
        (a, Link::Bed) if matches!(a, Link::TableRotary(_) | Link::Table) => Some(0),
        _ => None,
    }
}
