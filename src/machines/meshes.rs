//! Triangle-mesh bodies: the STL files a profile names beside it (`mesh = "table.stl"`), read
//! once when the profile loads into a shared [`Mesh`], within bounds a machine model needs.
//!
//! Binary and ASCII STL (`stl_io`). Only a bare file name is read, from the profile's own
//! directory (the library's): a profile must not reach other files of the server.

use crate::collide::Mesh;
use crate::kinematics::Vec3;
use std::collections::HashMap;
use std::io::Read;
use std::path::Path;
use std::sync::Arc;

/// The largest STL file read (a binary file of 200 000 triangles is 10 MB).
pub const MAX_MESH_BYTES: u64 = 16 << 20;
/// The most triangles of one body: a machine model, not a scan.
pub const MAX_MESH_TRIANGLES: usize = 200_000;
/// The most triangles of all a profile's meshes together.
pub const MAX_PROFILE_TRIANGLES: usize = 1_000_000;

/// Where a profile's meshes come from: its directory, or nowhere (a profile with no file, e.g.
/// one parsed from a request with no library directory to read from).
#[derive(Debug)]
pub struct MeshReader<'a> {
    dir: Option<&'a Path>,
    /// Each file once per profile, however many bodies name it.
    read: HashMap<String, Arc<Mesh>>,
    triangles: usize,
}

impl<'a> MeshReader<'a> {
    pub fn new(dir: Option<&'a Path>) -> MeshReader<'a> {
        MeshReader {
            dir,
            read: HashMap::new(),
            triangles: 0,
        }
    }

    /// The mesh of file `name`, or what is wrong (the caller names the key).
    pub fn mesh(&mut self, name: &str) -> Result<Arc<Mesh>, String> {
        if !is_bare_name(name) {
            return Err(format!(
                "{} must be a file name beside the profile ending in .stl: no directories, no \"..\"",
                crate::text::quote(name)
            ));
        }
        // Counted per body: 64 bodies naming one 200 000-triangle file were 12.8 M triangles
        // for the check, counted once.
        if let Some(m) = self.read.get(name) {
            let n = m.triangles().len();
            if self.triangles + n > MAX_PROFILE_TRIANGLES {
                return Err(over_profile(self.triangles, n));
            }
            self.triangles += n;
            return Ok(m.clone());
        }
        let dir = self
            .dir
            .ok_or("meshes are read from the machine library's directory only, and this profile has none")?;
        let bytes = read_bounded(&dir.join(name)).map_err(|e| format!("{}: {e}", crate::text::quote(name)))?;
        let mesh = parse_stl(name, bytes, MAX_MESH_TRIANGLES)?;
        let n = mesh.triangles().len();
        if self.triangles + n > MAX_PROFILE_TRIANGLES {
            return Err(over_profile(self.triangles, n));
        }
        self.triangles += n;
        self.read.insert(name.to_string(), mesh.clone());
        Ok(mesh)
    }
}

/// The profile's triangles over its bound: `before` in the bodies before this one, `this` in it.
fn over_profile(before: usize, this: usize) -> String {
    format!(
        "the profile's meshes would have {} triangles ({before} in the bodies before this one, {this} in it), beyond {MAX_PROFILE_TRIANGLES} a profile (a file counts once for each body that names it)",
        before + this
    )
}

/// A file name without a directory, `..` or anything a shell or URL would read otherwise.
fn is_bare_name(name: &str) -> bool {
    (5..=128).contains(&name.len())
        && name.to_ascii_lowercase().ends_with(".stl")
        && !name.starts_with('.')
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '.' | '_' | '-'))
}

/// The file's bytes, at most [`MAX_MESH_BYTES`].
fn read_bounded(path: &Path) -> std::io::Result<Vec<u8>> {
    let mut bytes = Vec::new();
    std::fs::File::open(path)?.take(MAX_MESH_BYTES + 1).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > MAX_MESH_BYTES {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("larger than {MAX_MESH_BYTES} bytes"),
        ));
    }
    Ok(bytes)
}

/// The mesh of an STL file's bytes (binary or ASCII), at most `budget` triangles (and
/// [`MAX_MESH_TRIANGLES`]), every coordinate finite.
pub fn parse_stl(name: &str, mut bytes: Vec<u8>, budget: usize) -> Result<Arc<Mesh>, String> {
    let digest = fnv1a(&bytes);
    let max = budget.min(MAX_MESH_TRIANGLES);
    // Many exporters begin a binary file's header with "solid" too: a file whose size is a
    // binary STL's for its count is read as binary.
    if bytes.len() >= 84 {
        let n = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as u64;
        if 84 + 50 * n == bytes.len() as u64 {
            bytes[..5].fill(0);
        }
    }
    let mut cursor = std::io::Cursor::new(bytes);
    let bad = |e: std::io::Error| format!("not an STL file: {e}");
    let reader = stl_io::create_stl_reader(&mut cursor).map_err(bad)?;
    let (mut vertices, mut triangles) = (Vec::new(), Vec::new());
    let mut index: HashMap<[u32; 3], u32> = HashMap::new();
    for t in reader {
        let t = t.map_err(bad)?;
        if triangles.len() == max {
            return Err(format!(
                "more than {max} triangles (at most {MAX_MESH_TRIANGLES} a body, {MAX_PROFILE_TRIANGLES} a profile)"
            ));
        }
        let mut tri = [0u32; 3];
        for (k, p) in t.vertices.iter().enumerate() {
            if !p.0.iter().all(|c| c.is_finite()) {
                return Err(format!(
                    "triangle {} has a coordinate that is not a finite number",
                    triangles.len() + 1
                ));
            }
            tri[k] = *index.entry(p.0.map(f32::to_bits)).or_insert_with(|| {
                vertices.push(Vec3::new(p.0[0] as f64, p.0[1] as f64, p.0[2] as f64));
                vertices.len() as u32 - 1
            });
        }
        triangles.push(tri);
    }
    if triangles.is_empty() {
        return Err("no triangles".into());
    }
    let mesh = Arc::new(Mesh::new(name, digest, vertices, triangles)?);
    crate::collide::Solid::Mesh(mesh.clone()).check()?;
    Ok(mesh)
}

/// FNV-1a, 64 bits: a stable digest of a file (the same on every build, unlike `DefaultHasher`).
fn fnv1a(bytes: &[u8]) -> u64 {
    bytes
        .iter()
        .fold(0xcbf2_9ce4_8422_2325, |h, b| (h ^ *b as u64).wrapping_mul(0x100_0000_01b3))
}

/// A mesh as a binary STL (what the page draws): normals from the winding, f32 coordinates.
pub fn to_binary_stl(m: &Mesh) -> Vec<u8> {
    let v: Vec<Vec3> = m.vertices().collect();
    let tris = m.triangles();
    let mut out = Vec::with_capacity(84 + 50 * tris.len());
    out.extend_from_slice(&[0u8; 80]);
    out.extend_from_slice(&(tris.len() as u32).to_le_bytes());
    for t in tris {
        let [a, b, c] = t.map(|i| v[i as usize]);
        let n = (b - a).cross(&(c - a)).try_normalize(0.0).unwrap_or_else(Vec3::zeros);
        for p in [n, a, b, c] {
            for x in p.iter() {
                out.extend_from_slice(&(*x as f32).to_le_bytes());
            }
        }
        out.extend_from_slice(&[0, 0]);
    }
    out
}
