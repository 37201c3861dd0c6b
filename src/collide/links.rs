//! Where the machine's links are at one set of joints: the pose in M of every link a body can
//! be on (`http/web/kin.js` writes the same for the page).

use super::geometry::Link;
use super::v;
use crate::kinematics::{Machine, Mount, Setup, Vec3};
use parry3d_f64::math::{Pose, Rotation, Vector};

/// Where the machine's axes are: the linears (profile units) and the rotaries' actual angles
/// (radians, after angle-error compensation: where the axes really stand, not the NC words).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Axes {
    pub linear: [f64; 3],
    pub actual: [f64; 3],
}

/// The pose of every link at one set of joints.
pub(super) struct Links {
    table: [Pose; 3],
    table_all: Pose,
    head: [Pose; 3],
    ram: Pose,
    spindle: Pose,
    work: Pose,
}

impl Links {
    /// The links of `m` at `at`, with `setup`'s tool length (the spindle above the gauge point)
    /// and work offset (W on the table).
    pub(super) fn at(m: &Machine, setup: &Setup, at: &Axes) -> Links {
        let (linear, actual) = (&at.linear, &at.actual);
        let mut table = [Pose::IDENTITY; 3];
        let mut head = [Pose::IDENTITY; 3];
        let mut t = Pose::IDENTITY;
        let mut h = Pose::from_translation(Vector::new(linear[0], linear[1], linear[2] + setup.tool_length));
        let ram = h;
        for (i, r) in m.rotaries.iter().enumerate() {
            match r.mount {
                Mount::Table => {
                    t *= turn(&r.axis, &r.pivot, actual[i]);
                    table[i] = t;
                }
                Mount::Head => {
                    h *= turn(&r.axis, &r.pivot, actual[i]);
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
            work: t * Pose::from_translation(v(&setup.work_offset)),
        }
    }

    /// The pose of `link`.
    pub(super) fn pose_of(&self, link: Link) -> Pose {
        match link {
            Link::Bed => Pose::IDENTITY,
            Link::TableRotary(i) => self.table[i],
            Link::Table => self.table_all,
            Link::Ram => self.ram,
            Link::HeadRotary(i) => self.head[i],
            Link::Spindle | Link::Holder | Link::Cutter => self.spindle,
            Link::Stock | Link::Fixture => self.work,
        }
    }
}

/// The turn by `angle` about `axis` through `pivot`.
fn turn(axis: &Vec3, pivot: &Vec3, angle: f64) -> Pose {
    let r = Rotation::from_axis_angle(v(axis), angle);
    let q = v(pivot);
    Pose::from_parts(q - r * q, r)
}
