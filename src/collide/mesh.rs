//! Mesh bodies: a profile's STL triangles as parry's `TriMesh`, built once when the profile
//! loads and shared by every post's world.

use super::v;
use crate::kinematics::Vec3;
use parry3d_f64::math::Vector;
use parry3d_f64::shape::{SharedShape, TriMesh};
use std::sync::Arc;

/// A triangle mesh body (read from an STL file by `machines`): parry's `TriMesh`, a BVH of its
/// triangles, each tested against the other body. A closed mesh wound outward is a solid: a body
/// wholly inside it, touching no triangle, is found by a point of it (a ray cast). An open one is a surface only (the sampling between blocks keeps a body from
/// crossing it unseen).
pub struct Mesh {
    /// The file it was read from (a bare name beside the profile).
    pub file: String,
    /// A digest of the file's bytes: the same file, the same mesh (an ETag).
    pub digest: u64,
    pub(super) shape: SharedShape,
    pub(super) min: Vec3,
    pub(super) max: Vec3,
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
