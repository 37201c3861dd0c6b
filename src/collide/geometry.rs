//! The bodies' shapes, at home in their links' coordinates, and the tool's: what a profile's
//! `[[body]]` entries, a job's stock and fixtures and the tool in the spindle are to the check.

use super::mesh::Mesh;
use super::v;
use crate::kinematics::{MAX_COORD, Machine, Mount, Vec3};
use parry3d_f64::math::{Pose, Rotation, Vector};
use parry3d_f64::shape::{Cuboid, Cylinder, RoundShape, SharedShape};
use std::sync::Arc;


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

    pub(super) fn head_side(self) -> bool {
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
        let finite = |v: &Vec3| v.iter().all(|c| c.is_finite() && c.abs() <= MAX_COORD);
        match self {
            Solid::Box { min, max } => {
                if !(finite(min) && finite(max)) || (0..3).any(|k| max[k] <= min[k]) {
                    return Err("a box is [x0, y0, z0, x1, y1, z1], each max above its min".into());
                }
            }
            Solid::Cylinder { from, to, radius } => {
                if !(finite(from) && finite(to)) || (to - from).norm() <= 0.0 || !(*radius > 0.0 && *radius <= MAX_COORD) {
                    return Err("a cylinder needs two distinct finite end points and a positive radius".into());
                }
            }
            Solid::Mesh(m) => {
                if !(finite(&m.min) && finite(&m.max)) {
                    return Err(format!("every coordinate must be finite and within ±{}", MAX_COORD));
                }
                if (m.max - m.min).max() <= 0.0 {
                    return Err("its triangles all sit at one point".into());
                }
            }
        }
        Ok(())
    }

    /// Its smallest dimension.
    pub(super) fn smallest(&self) -> f64 {
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
    pub(super) fn reach(&self) -> f64 {
        match self {
            Solid::Box { min, max } => min.abs().sup(&max.abs()).norm(),
            Solid::Cylinder { from, to, radius } => from.norm().max(to.norm()) + radius,
            Solid::Mesh(m) => m.min.abs().sup(&m.max.abs()).norm(),
        }
    }

    /// The parry shape and where it sits in the link's coordinates.
    pub(super) fn shape(&self, round: f64) -> (SharedShape, Pose) {
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

    /// How far the cutter sticks out of the holder: the length below it, a fifth of the tool
    /// at least.
    fn stick(&self) -> f64 {
        (self.length - self.holder_length).max(self.length * 0.2)
    }

    /// The holder, on the spindle from the gauge line down to the cutter, where it has a size.
    pub(super) fn holder(&self) -> Option<Solid> {
        let stick = self.stick();
        let z = Vec3::z();
        (self.holder_length > 0.0 && self.holder_diameter > 0.0 && self.length - stick >= SHORTEST).then(|| Solid::Cylinder {
            from: -z * (self.length - stick),
            to: Vec3::zeros(),
            radius: self.holder_diameter / 2.0,
        })
    }

    /// The cutter, from the tip up to the holder (its corner radius the rounding of its shape).
    pub(super) fn cutter(&self) -> Option<Solid> {
        let stick = self.stick();
        let z = Vec3::z();
        (stick >= SHORTEST).then(|| Solid::Cylinder {
            from: -z * self.length,
            to: -z * (self.length - stick),
            radius: self.diameter / 2.0,
        })
    }
}

/// A body no longer than this is no body (a tool of length 0: the gauge point is the spindle
/// nose); one kept would ask for samples a thousandth of a micron apart.
const SHORTEST: f64 = 1e-3;

/// A body placed on its link, as parry queries it.
pub(super) struct Placed {
    pub(super) name: String,
    pub(super) link: Link,
    /// Shared: a mesh's is the profile's, not a copy per post.
    pub(super) shape: SharedShape,
    pub(super) local: Pose,
    /// The bounding sphere in the link's coordinates: the cheap first test of a pair.
    pub(super) centre: Vector,
    pub(super) radius: f64,
    /// A point of the body (the shape's coordinates): inside a solid mesh, the whole body is,
    /// where no triangle touches it.
    pub(super) probe: Vector,
    /// Half its smallest size: the samples keep its motion within it.
    pub(super) half: f64,
}
