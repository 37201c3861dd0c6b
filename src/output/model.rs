//! The machine as a page draws it: the kinematic chain (enough to compute every link's pose from
//! the joints exactly as `kinematics::fk` and `collide` do) and the bodies on its links. The job
//! preview carries it (`machine`), and `GET /v1/machines/{id}` carries the bodies in the same form.

use crate::collide::{Body, Geometry, Link, Solid};
use crate::kinematics::{LINEAR_NAMES, Machine, Mount};
use serde::Serialize;

/// A linear axis: its travel (profile units).
#[derive(Clone, Debug, Serialize, utoipa::ToSchema)]
pub struct ModelLinear {
    pub name: String,
    pub min: f64,
    pub max: f64,
}

/// A rotary joint in chain order (tables from the bed outward, heads from the ram outward).
#[derive(Clone, Debug, Serialize, utoipa::ToSchema)]
pub struct ModelRotary {
    pub name: String,
    /// `table` or `head`.
    pub on: String,
    /// Unit vector: +angle turns the body about it (right-hand rule).
    pub axis: [f64; 3],
    /// Table: a point in M; head: relative to the gauge point at home.
    pub pivot: [f64; 3],
    /// Degrees; absent for an unbounded axis.
    pub min: Option<f64>,
    pub max: Option<f64>,
    /// The axis stands at `c + Δ(c)` when commanded `c` (Δ a polynomial in degrees, its word
    /// clamped into `range`).
    pub angle_error: Option<ModelAngleError>,
}

#[derive(Clone, Debug, Serialize, utoipa::ToSchema)]
pub struct ModelAngleError {
    pub coefficients: Vec<f64>,
    pub range: [f64; 2],
}

/// A cylinder: the axis's end points and the radius.
#[derive(Clone, Debug, Serialize, utoipa::ToSchema)]
pub struct ModelCylinder {
    pub from: [f64; 3],
    pub to: [f64; 3],
    pub radius: f64,
}

/// A triangle mesh: its triangles are `GET /v1/machines/{id}/meshes/{file}` (binary STL).
#[derive(Clone, Debug, Serialize, utoipa::ToSchema)]
pub struct ModelMesh {
    pub file: String,
    pub triangles: usize,
    /// `[x0, y0, z0, x1, y1, z1]`: its bounding box, to frame the view before it is fetched.
    pub bounds: [f64; 6],
}

/// A body on a link, at home (every joint zero), as the profile's `[[body]]` gives it: bodies on
/// `bed`, `table` and the table rotaries in M, those on `ram`, the head rotaries and `spindle`
/// relative to the gauge point. One of `box`, `cylinder` and `mesh`.
#[derive(Clone, Debug, Serialize, utoipa::ToSchema)]
pub struct ModelBody {
    pub name: String,
    /// `bed`, `table`, `ram`, `spindle` or a rotary's name.
    pub on: String,
    /// `[x0, y0, z0, x1, y1, z1]`: opposite corners.
    #[serde(rename = "box", skip_serializing_if = "Option::is_none")]
    pub box_: Option<[f64; 6]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cylinder: Option<ModelCylinder>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mesh: Option<ModelMesh>,
}

/// The machine for drawing and for FK in a page.
#[derive(Clone, Debug, Serialize, utoipa::ToSchema)]
pub struct MachineModel {
    pub id: String,
    pub name: String,
    /// `mm` or `inch`.
    pub units: String,
    /// table-table, head-head, head-table, 4-axis, 3-axis, 3-rotary/2-linear …
    pub kinematics: String,
    /// The linears the machine has (X, Y, Z; a missing one stands at 0).
    pub linear: Vec<ModelLinear>,
    pub rotary: Vec<ModelRotary>,
    pub default_tool_length: f64,
    /// Empty where the profile gives none (the page then draws a schematic).
    pub bodies: Vec<ModelBody>,
}

/// The `on` of a link, as a profile writes it.
fn link_name(m: &Machine, l: Link) -> String {
    match l {
        Link::Bed => "bed".into(),
        Link::Table => "table".into(),
        Link::Ram => "ram".into(),
        Link::Spindle => "spindle".into(),
        Link::TableRotary(i) | Link::HeadRotary(i) => m.rotaries[i].name.to_string(),
        Link::Stock => "stock".into(),
        Link::Fixture => "fixture".into(),
        Link::Holder => "holder".into(),
        Link::Cutter => "cutter".into(),
    }
}

/// A box as `[x0, y0, z0, x1, y1, z1]`, or a cylinder (a mesh is neither: see [`mesh`]).
pub fn solid(s: &Solid) -> (Option<[f64; 6]>, Option<ModelCylinder>) {
    match s {
        Solid::Mesh(_) => (None, None),
        Solid::Box { min, max } => (Some([min.x, min.y, min.z, max.x, max.y, max.z]), None),
        Solid::Cylinder { from, to, radius } => (
            None,
            Some(ModelCylinder {
                from: (*from).into(),
                to: (*to).into(),
                radius: *radius,
            }),
        ),
    }
}

/// A mesh body's file and size, for the page to fetch it.
pub fn mesh(s: &Solid) -> Option<ModelMesh> {
    let Solid::Mesh(m) = s else { return None };
    let (a, b) = m.bounds();
    Some(ModelMesh {
        file: m.file.clone(),
        triangles: m.triangles().len(),
        bounds: [a.x, a.y, a.z, b.x, b.y, b.z],
    })
}

/// The bodies of a geometry as the page reads them.
pub fn bodies(m: &Machine, g: &Geometry) -> Vec<ModelBody> {
    g.bodies
        .iter()
        .map(|Body { name, link, solid: s }| {
            let (box_, cylinder) = solid(s);
            ModelBody {
                name: name.clone(),
                on: link_name(m, *link),
                box_,
                cylinder,
                mesh: mesh(s),
            }
        })
        .collect()
}

impl MachineModel {
    pub fn new(m: &Machine, g: &Geometry) -> MachineModel {
        MachineModel {
            id: m.id.clone(),
            name: m.name.clone(),
            units: m.units.as_str().into(),
            kinematics: m.kinematics_kind(),
            linear: m
                .linears
                .iter()
                .enumerate()
                .filter_map(|(i, l)| {
                    l.as_ref().map(|l| ModelLinear {
                        name: LINEAR_NAMES[i].to_string(),
                        min: l.min,
                        max: l.max,
                    })
                })
                .collect(),
            rotary: m
                .rotaries
                .iter()
                .map(|r| ModelRotary {
                    name: r.name.to_string(),
                    on: match r.mount {
                        Mount::Table => "table",
                        Mount::Head => "head",
                    }
                    .into(),
                    axis: r.axis.into(),
                    pivot: r.pivot.into(),
                    min: r.limits.map(|l| l.0.to_degrees()),
                    max: r.limits.map(|l| l.1.to_degrees()),
                    angle_error: r.angle_error.as_ref().map(|e| ModelAngleError {
                        coefficients: e.coefficients_deg.clone(),
                        range: [e.range_deg.0, e.range_deg.1],
                    }),
                })
                .collect(),
            default_tool_length: m.default_tool_length,
            bodies: bodies(m, g),
        }
    }
}
