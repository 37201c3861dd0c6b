//! Dialect files: `dialects/<id>.toml` (`--dialects DIR`, `KINEPOST_DIALECTS`) beside the
//! built-in five, which the binary carries. A file's `extends` names a built-in dialect, so
//! what a dialect means never depends on the order files load in or on a later API write.

use super::Error;
use crate::nc::{self, Dialect};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// The dialects a process posts with: the built-ins, then a directory's files (a file of a
/// built-in's id replaces it).
#[derive(Clone, Debug)]
pub struct Dialects {
    by_id: BTreeMap<String, Arc<Dialect>>,
    /// The directory read, if any (the built-ins alone have none).
    pub dir: Option<PathBuf>,
}

impl Default for Dialects {
    fn default() -> Self {
        Dialects {
            by_id: nc::builtins().iter().map(|d| (d.name.clone(), d.clone())).collect(),
            dir: None,
        }
    }
}

/// Parses a dialect's text (named `file` in errors); `id`: the id it must have.
pub fn parse(text: &str, file: &str, id: Option<&str>) -> Result<Dialect, Error> {
    nc::parse_dialect(text, file, id, &nc::dialect).map_err(|message| Error::Parse {
        file: file.to_string(),
        message: message.strip_prefix(&format!("{file}: ")).unwrap_or(&message).to_string(),
    })
}

impl Dialects {
    /// The built-ins and every `*.toml` of `dir`; the first bad file fails the load. A missing
    /// directory is the built-ins alone.
    pub fn load_dir(dir: &Path) -> Result<Dialects, Error> {
        let mut out = Dialects::default();
        if !dir.is_dir() {
            return Ok(out);
        }
        for p in super::toml_files(dir)? {
            let text = super::read_text(&p).map_err(|source| Error::Io {
                path: p.display().to_string(),
                source,
            })?;
            let stem = p.file_stem().and_then(|s| s.to_str()).unwrap_or_default();
            let d = parse(&text, &p.display().to_string(), Some(stem))?;
            out.by_id.insert(d.name.clone(), Arc::new(d));
        }
        out.dir = Some(dir.to_path_buf());
        Ok(out)
    }

    pub fn get(&self, id: &str) -> Option<Arc<Dialect>> {
        self.by_id.get(id).cloned()
    }

    pub fn iter(&self) -> impl Iterator<Item = &Arc<Dialect>> {
        self.by_id.values()
    }

    /// The text of dialect `id` as its file has it: the directory's file, else the built-in's.
    pub fn file_text(&self, id: &str) -> std::io::Result<String> {
        file_text(self.dir.as_deref(), id)
    }
}

/// The text of dialect `id` in `dir`, else the built-in's.
pub fn file_text(dir: Option<&Path>, id: &str) -> std::io::Result<String> {
    if let Some(dir) = dir {
        let p = dir.join(format!("{id}.toml"));
        if p.is_file() {
            return super::read_text(&p);
        }
    }
    nc::BUILTIN_FILES
        .iter()
        .find(|(b, _)| *b == id)
        .map(|(_, t)| t.to_string())
        .ok_or_else(|| std::io::Error::new(std::io::ErrorKind::NotFound, format!("no dialect {id}")))
}

/// Where the dialect files live: `$KINEPOST_DIALECTS`, else `dialects/` in the working
/// directory, else the one beside the crate.
pub fn default_dir() -> PathBuf {
    if let Ok(d) = std::env::var("KINEPOST_DIALECTS") {
        return PathBuf::from(d);
    }
    let cwd = PathBuf::from("dialects");
    if cwd.is_dir() {
        return cwd;
    }
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("dialects")
}
