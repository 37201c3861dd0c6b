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
//!
//! By concept: `geometry` the bodies' and the tool's shapes, `mesh` a mesh body, `links` each
//! link's pose from the joints, `world` a post's bodies and the questions asked of them,
//! `pairs` which pairs are checked and what each keeps known, `bounds` the cheap bounds that
//! spare most queries, `distance` the queries (parry3d), `samples` the samples of a move.

mod bounds;
mod distance;
mod geometry;
mod links;
mod mesh;
mod pairs;
mod samples;
mod world;

pub use geometry::{Body, Geometry, Link, Solid, ToolShape};
pub use links::Axes;
pub use mesh::Mesh;
pub use samples::{Coarse, MAX_SAMPLES, SAMPLES_PER_MOVE};
pub use world::{Hit, World};

use crate::kinematics::Vec3;
use parry3d_f64::math::Vector;

/// A kinematics vector as parry's.
pub(super) fn v(p: &Vec3) -> Vector {
    Vector::new(p.x, p.y, p.z)
}

/// The most bodies a profile may give: a machine model, not a CAD assembly.
pub const MAX_BODIES: usize = 64;
