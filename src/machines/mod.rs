//! Machine profiles: TOML files (`machines/<id>.toml`) → validated [`Machine`]s.
//!
//! The file format lives here, not in `kinematics`, which knows no serde. Every error names the
//! file, the key and the problem, so a shop editing a profile knows what to fix.

use crate::kinematics::{self, AngleError, Linear, Machine, MachineSpec, Mount, Rotary, Units, Vec3};
use crate::text::quote;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

pub mod catalog;
pub mod dialects;
pub mod meshes;
pub mod policy;
pub mod tools;
pub use catalog::{Catalog, Current, Expect, Kind, Shelf};

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("{file}: {message}")]
    Parse { file: String, message: String },
    #[error("{file}: {key}: {problem}")]
    Invalid { file: String, key: String, problem: String },
    #[error("{path}: {source}")]
    Io { path: String, source: std::io::Error },
    #[error("no machine profile {}", crate::text::quote(.0))]
    NotFound(String),
    #[error("machine {} exists (version {version}): replace it with PUT", crate::text::quote(.id))]
    Exists { id: String, version: i64 },
    /// `If-Match` named another version than the current one (or the profile is gone).
    #[error("machine {} is at {}: the write was based on another", crate::text::quote(.id), current.map_or("no version (deleted or never created)".to_string(), |v| format!("version {v}")))]
    Precondition { id: String, current: Option<i64> },
    #[error("machine profiles are read-only in this process (no store)")]
    ReadOnly,
    #[error("machine store: {0}")]
    Store(String),
    /// The store does not answer now (a lost connection, a restarting database): asked again
    /// later, the same request may succeed.
    #[error("the machine store is not answering now: {0}")]
    Unavailable(String),
    /// The store's disk is full: the write was not made.
    #[error("no room for the profile in the machine store: {0}")]
    NoSpace(String),
}

/// The TOML document of one profile, exactly as `machine-model.md` shows it.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ProfileDoc {
    pub id: String,
    #[serde(default)]
    pub name: Option<String>,
    pub units: String,
    #[serde(default)]
    pub controller: Option<String>,
    #[serde(default)]
    pub description: Option<String>,
    #[serde(default)]
    pub linear: Vec<LinearDoc>,
    #[serde(default)]
    pub rotary: Vec<RotaryDoc>,
    #[serde(default)]
    pub tool: Option<ToolDoc>,
    #[serde(default)]
    pub spindle: Option<SpindleDoc>,
    #[serde(default)]
    pub policy: Option<PolicyDoc>,
    /// The machine's bodies for the collision check (`collide`); none: nothing is checked.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub body: Vec<BodyDoc>,
}

/// One body of the machine: a box, a cylinder or a mesh on a link, at home (`docs/machines.md`).
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct BodyDoc {
    pub name: String,
    /// `bed`, `table`, `ram`, `spindle` or a rotary's name.
    pub on: String,
    /// `[x0, y0, z0, x1, y1, z1]`: opposite corners.
    #[serde(default, rename = "box", skip_serializing_if = "Option::is_none")]
    pub box_: Option<[f64; 6]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cylinder: Option<CylinderDoc>,
    /// An STL file beside the profile (a bare file name): see `meshes`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mesh: Option<String>,
    /// Where the numbers come from.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source: Option<String>,
}

#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CylinderDoc {
    pub from: [f64; 3],
    pub to: [f64; 3],
    pub radius: f64,
}

/// How the shop wants this machine to move where the CL does not say: a job may override each.
/// The text as written (the API shows it); [`Profile::policy`] holds it parsed.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct PolicyDoc {
    /// `machine-z`, `axis:D` or `plane:Z` (`policy::Retract`).
    #[serde(default)]
    pub retract: Option<String>,
    /// A rotary's side where both IK branches can cut: `B-`, `A+` (`policy::Prefer`).
    #[serde(default)]
    pub prefer: Option<String>,
    /// `inverse-time`, `dpm` or `combined` (`policy::RotaryFeed`).
    #[serde(default)]
    pub feed_mode: Option<String>,
    /// `retract` or `rapids` (`policy::Unwind`).
    #[serde(default)]
    pub unwind: Option<String>,
    /// `auto`, `off`, `rough` or `finish` (`policy::Smoothing`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub smoothing: Option<String>,
}

#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct LinearDoc {
    pub name: String,
    pub min: f64,
    pub max: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_feed: Option<f64>,
    /// Units/s² (rotaries: °/s²): the cycle-time estimate's trapezoids.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_accel: Option<f64>,
}

#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RotaryDoc {
    pub name: String,
    pub on: String,
    pub axis: [f64; 3],
    pub pivot: [f64; 3],
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_feed: Option<f64>,
    /// Units/s² (rotaries: °/s²): the cycle-time estimate's trapezoids.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_accel: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub angle_error: Option<AngleErrorDoc>,
    /// NC words that lock and unlock the axis (e.g. `["M10", "M11"]`): written around
    /// positioning moves. Not kinematics: an output option of the machine.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clamp: Option<[String; 2]>,
}

#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct AngleErrorDoc {
    pub coefficients: Vec<f64>,
    pub range: [f64; 2],
}

/// What the spindle turns at: an S outside it is an alarm or a different cut, never a word.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SpindleDoc {
    #[serde(default)]
    pub min_rpm: Option<f64>,
    pub max_rpm: f64,
}

#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ToolDoc {
    #[serde(default)]
    pub default_length: Option<f64>,
}

impl Profile {
    /// Lock/unlock words per rotary, in chain order.
    pub fn clamps(&self) -> [Option<(String, String)>; 3] {
        let mut out: [Option<(String, String)>; 3] = Default::default();
        for (i, r) in self.doc.rotary.iter().enumerate().take(3) {
            out[i] = r.clamp.as_ref().map(|[lock, unlock]| (lock.clone(), unlock.clone()));
        }
        out
    }

    /// The machine's bodies, validated (and their meshes read) when the profile was loaded.
    pub fn geometry(&self) -> crate::collide::Geometry {
        self.bodies.clone()
    }

    /// The spindle's speeds in RPM, `[1, MAX_SPINDLE_SPEED]` where the profile does not say.
    pub fn spindle_range(&self) -> (f64, f64) {
        let s = self.doc.spindle.as_ref();
        let min = s.and_then(|s| s.min_rpm).unwrap_or(1.0);
        (min, s.map_or(MAX_SPINDLE_SPEED, |s| s.max_rpm))
    }
}

/// The largest spindle speed taken, a profile's or a job's: above any machining spindle (a
/// typo's extra digit fails).
pub const MAX_SPINDLE_SPEED: f64 = 200_000.0;

/// A loaded profile: the validated machine plus the document it came from (for listings/API).
#[derive(Clone, Debug)]
pub struct Profile {
    pub machine: Machine,
    pub doc: ProfileDoc,
    /// The `[policy]` keys, parsed at load.
    pub policy: policy::Policy,
    /// Built once: a mesh is read and its BVH built here, not per post.
    bodies: crate::collide::Geometry,
}

/// Parses and validates one profile. `stem` is the file stem the id must equal, if any. It has
/// no directory: a body with a mesh is refused (see [`parse_profile_in`]).
pub fn parse_profile(text: &str, file: &str, stem: Option<&str>) -> Result<Profile, Error> {
    parse_profile_in(text, file, stem, None)
}

/// Parses and validates one profile whose meshes are files of `dir` (the library's).
pub fn parse_profile_in(text: &str, file: &str, stem: Option<&str>, dir: Option<&Path>) -> Result<Profile, Error> {
    let doc: ProfileDoc = toml::from_str(text).map_err(|e| Error::Parse {
        file: file.into(),
        message: one_line(&e),
    })?;
    let invalid = |key: &str, problem: String| Error::Invalid {
        file: file.into(),
        key: key.into(),
        problem,
    };
    if let Some(stem) = stem
        && doc.id != stem
    {
        return Err(invalid(
            "id",
            format!("{} differs from the file name {}", quote(&doc.id), quote(stem)),
        ));
    }
    let units = match doc.units.as_str() {
        "mm" => Units::Mm,
        "inch" => Units::Inch,
        other => return Err(invalid("units", format!("{} must be \"mm\" or \"inch\"", quote(other)))),
    };
    let mut linears: [Option<Linear>; 3] = [None, None, None];
    for (i, l) in doc.linear.iter().enumerate() {
        let idx = match l.name.as_str() {
            "X" => 0,
            "Y" => 1,
            "Z" => 2,
            other => {
                return Err(invalid(
                    &format!("linear[{i}].name"),
                    format!("{} must be X, Y or Z", quote(other)),
                ));
            }
        };
        if linears[idx].is_some() {
            return Err(invalid(
                &format!("linear[{i}].name"),
                format!("duplicate linear axis {}", l.name),
            ));
        }
        linears[idx] = Some(Linear {
            min: l.min,
            max: l.max,
            max_feed: l.max_feed,
            max_accel: l.max_accel,
        });
    }
    let mut rotaries = Vec::new();
    for (i, r) in doc.rotary.iter().enumerate() {
        let key = |k: &str| format!("rotary[{i}].{k}");
        let mut chars = r.name.chars();
        let name = match (chars.next(), chars.next()) {
            (Some(c @ ('A' | 'B' | 'C')), None) => c,
            _ => return Err(invalid(&key("name"), format!("{} must be A, B or C", quote(&r.name)))),
        };
        let mount = match r.on.as_str() {
            "table" => Mount::Table,
            "head" => Mount::Head,
            other => return Err(invalid(&key("on"), format!("{} must be \"table\" or \"head\"", quote(other)))),
        };
        if let Some(c) = &r.clamp
            && c.iter().any(|w| !is_one_word(w))
        {
            // One word each: `M10 M30` put a program end at every clamp.
            return Err(invalid(
                &key("clamp"),
                "give two NC words, lock then unlock, one word each, e.g. [\"M10\", \"M11\"]".into(),
            ));
        }
        let limits = match (r.min, r.max) {
            (Some(lo), Some(hi)) => Some((lo.to_radians(), hi.to_radians())),
            (None, None) => None,
            _ => {
                return Err(invalid(
                    &key("min/max"),
                    "give both min and max, or neither for an unbounded axis".into(),
                ));
            }
        };
        rotaries.push(Rotary {
            name,
            mount,
            axis: Vec3::from(r.axis),
            pivot: Vec3::from(r.pivot),
            limits,
            max_feed: r.max_feed.map(f64::to_radians),
            max_accel: r.max_accel.map(f64::to_radians),
            angle_error: r
                .angle_error
                .as_ref()
                .map(|e| AngleError::new(e.coefficients.clone(), (e.range[0], e.range[1]))),
        });
    }
    if let Some(s) = &doc.spindle {
        check_spindle(s).map_err(|(key, problem)| invalid(key, problem))?;
    }
    if let Some(c) = &doc.controller
        && crate::nc::dialect(c).is_none()
    {
        // An unknown controller posted Fanuc without a word.
        return Err(invalid(
            "controller",
            format!(
                "{} is not a dialect kinepost writes: one of {:?}",
                quote(c),
                crate::nc::DIALECTS
            ),
        ));
    }
    let spec = MachineSpec {
        id: doc.id.clone(),
        name: doc.name.clone().unwrap_or_else(|| doc.id.clone()),
        units,
        controller: doc.controller.clone().unwrap_or_else(|| "fanuc".into()),
        description: doc.description.clone().unwrap_or_default(),
        linears,
        rotaries,
        // Absent means 0, as in the reference verifier: every shipped profile states it.
        default_tool_length: doc.tool.as_ref().and_then(|t| t.default_length).unwrap_or(0.0),
    };
    let machine = Machine::new(spec).map_err(|e| match e {
        kinematics::Error::Profile { key, problem } => invalid(&key, problem),
        other => invalid("", other.to_string()),
    })?;
    let policy = match &doc.policy {
        Some(p) => policy::Policy::parse(p, &machine).map_err(|(key, problem)| invalid(&key, problem))?,
        None => policy::Policy::default(),
    };
    let bodies = geometry(&doc, &machine, &mut meshes::MeshReader::new(dir)).map_err(|(key, problem)| invalid(&key, problem))?;
    Ok(Profile { machine, doc, policy, bodies })
}

/// The profile's `[[body]]` entries as bodies, or the key that is wrong and why.
fn geometry(doc: &ProfileDoc, m: &Machine, meshes: &mut meshes::MeshReader) -> Result<crate::collide::Geometry, (String, String)> {
    use crate::collide::{Body, Link, Solid};
    if doc.body.len() > crate::collide::MAX_BODIES {
        return Err(("body".into(), format!("more than {} bodies", crate::collide::MAX_BODIES)));
    }
    let mut bodies = Vec::new();
    for (i, b) in doc.body.iter().enumerate() {
        let key = |k: &str| format!("body[{i}].{k}");
        if b.name.is_empty() || b.name.len() > 64 || doc.body[..i].iter().any(|o| o.name == b.name) {
            return Err((key("name"), format!("{} must be a unique name of 1 to 64 characters", quote(&b.name))));
        }
        let link = Link::parse(&b.on, m).map_err(|e| (key("on"), e))?;
        let solid = match (&b.box_, &b.cylinder, &b.mesh) {
            (Some(c), None, None) => Solid::Box {
                min: Vec3::new(c[0], c[1], c[2]),
                max: Vec3::new(c[3], c[4], c[5]),
            },
            (None, Some(c), None) => Solid::Cylinder {
                from: Vec3::from(c.from),
                to: Vec3::from(c.to),
                radius: c.radius,
            },
            (None, None, Some(f)) => Solid::Mesh(meshes.mesh(f).map_err(|e| (key("mesh"), e))?),
            _ => return Err((key("box"), "give one shape: box, cylinder or mesh".into())),
        };
        let shape = if b.box_.is_some() { "box" } else if b.cylinder.is_some() { "cylinder" } else { "mesh" };
        solid.check().map_err(|e| (key(shape), e))?;
        bodies.push(Body {
            name: b.name.clone(),
            link,
            solid,
        });
    }
    Ok(crate::collide::Geometry { bodies })
}

/// The spindle's range, or the key that is wrong and why.
fn check_spindle(s: &SpindleDoc) -> Result<(), (&'static str, String)> {
    let top = MAX_SPINDLE_SPEED;
    if !(s.max_rpm.is_finite() && (1.0..=top).contains(&s.max_rpm)) {
        return Err(("spindle.max_rpm", format!("{} is not from 1 to {top}", s.max_rpm)));
    }
    match s.min_rpm {
        Some(m) if !(m.is_finite() && (1.0..=s.max_rpm).contains(&m)) => Err((
            "spindle.min_rpm",
            format!("{m} is not from 1 to max_rpm {}", s.max_rpm),
        )),
        _ => Ok(()),
    }
}

fn one_line(e: &toml::de::Error) -> String {
    e.to_string().split_whitespace().collect::<Vec<_>>().join(" ")
}

/// The largest profile file read: a profile is a few kilobytes (`machines validate /dev/zero`
/// grew to 9.6 GB).
pub const MAX_PROFILE_BYTES: u64 = 1 << 20;

/// A profile file's text, at most [`MAX_PROFILE_BYTES`].
pub fn read_text(path: &Path) -> std::io::Result<String> {
    use std::io::Read;
    let mut text = String::new();
    std::fs::File::open(path)?
        .take(MAX_PROFILE_BYTES + 1)
        .read_to_string(&mut text)?;
    if text.len() as u64 > MAX_PROFILE_BYTES {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("larger than {MAX_PROFILE_BYTES} bytes: not a machine profile"),
        ));
    }
    Ok(text)
}

/// Reads one profile file; its id must equal the file stem.
pub fn load_file(path: &Path) -> Result<Profile, Error> {
    let file = path.display().to_string();
    let text = read_text(path).map_err(|source| Error::Io {
        path: file.clone(),
        source,
    })?;
    let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or_default();
    parse_profile_in(&text, &file, Some(stem), path.parent())
}

/// The machine library: every `*.toml` of a directory, by id, with each machine's standing tool
/// table (`<id>.tools.toml`) where there is one.
#[derive(Clone, Debug, Default)]
pub struct Library {
    profiles: BTreeMap<String, Arc<Profile>>,
    tools: BTreeMap<String, Arc<tools::ToolTable>>,
    pub dir: PathBuf,
    /// The dialects posts are written in: the built-ins and a directory's files.
    pub dialects: dialects::Dialects,
}

impl Library {
    /// Loads every profile; the first bad one fails the whole load (a server must not start with
    /// a library the operator believes complete).
    pub fn load_dir(dir: &Path) -> Result<Library, Error> {
        let paths = toml_files(dir)?;
        let is_table = |p: &Path| p.to_string_lossy().ends_with(tools::TABLE_SUFFIX);
        let mut profiles = BTreeMap::new();
        for p in paths.iter().filter(|p| !is_table(p)) {
            let prof = load_file(p)?;
            profiles.insert(prof.machine.id.clone(), Arc::new(prof));
        }
        let mut tables = BTreeMap::new();
        for p in paths.iter().filter(|p| is_table(p)) {
            let name = p.file_name().map(|n| n.to_string_lossy().to_string()).unwrap_or_default();
            let id = name.trim_end_matches(tools::TABLE_SUFFIX);
            if !profiles.contains_key(id) {
                // A table for no machine is a typo in its name: it would never be used.
                return Err(Error::Invalid {
                    file: p.display().to_string(),
                    key: String::new(),
                    problem: format!("a tool table for no machine profile: no {}", quote(&format!("{id}.toml"))),
                });
            }
            tables.insert(id.to_string(), Arc::new(tools::load_tool_table(p)?));
        }
        Ok(Library {
            profiles,
            tools: tables,
            dir: dir.to_path_buf(),
            dialects: dialects::Dialects::default(),
        })
    }

    /// The same library with the dialect files of `dir` beside the built-ins.
    pub fn with_dialects(mut self, dir: &Path) -> Result<Library, Error> {
        self.dialects = dialects::Dialects::load_dir(dir)?;
        Ok(self)
    }

    /// Machine `id`'s standing tool table, if its file is there.
    pub fn tools(&self, id: &str) -> Option<Arc<tools::ToolTable>> {
        self.tools.get(id).cloned()
    }

    pub fn get(&self, id: &str) -> Result<Arc<Profile>, Error> {
        self.profiles.get(id).cloned().ok_or_else(|| Error::NotFound(id.into()))
    }

    pub fn iter(&self) -> impl Iterator<Item = &Arc<Profile>> {
        self.profiles.values()
    }

    pub fn len(&self) -> usize {
        self.profiles.len()
    }

    pub fn is_empty(&self) -> bool {
        self.profiles.is_empty()
    }
}

/// The `*.toml` files of `dir`, sorted.
fn toml_files(dir: &Path) -> Result<Vec<PathBuf>, Error> {
    let rd = std::fs::read_dir(dir).map_err(|source| Error::Io {
        path: dir.display().to_string(),
        source,
    })?;
    let mut paths: Vec<PathBuf> = rd
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    paths.sort();
    Ok(paths)
}

/// Where the shipped profiles live: `$KINEPOST_MACHINES`, else `machines/` in the working
/// directory, else the one beside the crate (for tests and `cargo run` from anywhere).
pub fn default_dir() -> PathBuf {
    if let Ok(d) = std::env::var("KINEPOST_MACHINES") {
        return PathBuf::from(d);
    }
    let cwd = PathBuf::from("machines");
    if cwd.is_dir() {
        return cwd;
    }
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("machines")
}

/// One NC word: an address letter and a number (`M10`, `M82.1`), nothing else on the line.
fn is_one_word(w: &str) -> bool {
    let mut c = w.chars();
    c.next().is_some_and(|a| a.is_ascii_alphabetic())
        && w.len() <= 16
        && c.clone().next().is_some()
        && c.all(|ch| ch.is_ascii_digit() || ch == '.')
}
