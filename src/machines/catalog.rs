//! The live machine library: the profile files (and each machine's tool table beside its
//! profile) as the first versions, then every change made over the API as a new version, in the
//! same store as the jobs. A job names the versions it was submitted with and runs with those,
//! whatever happens to the profile or the table meanwhile.
//!
//! Reads come from memory (the current version of each); writes go to the store in one
//! transaction each, then to memory, one writer at a time. Profiles and tool tables are two
//! [`Shelf`]s of the same kind of history, each in its own table of the store.

use super::tools::{TABLE_SUFFIX, ToolTable, parse_tool_table};
use super::{Error, Library, Profile, parse_profile_in};
use std::path::{Path, PathBuf};
use crate::nc::Dialect;
use sqlx::AnyPool;
use sqlx::Row;
use std::collections::{BTreeMap, HashMap};
use std::sync::{Arc, Mutex, RwLock};

/// Where a version came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Source {
    /// A profile file of the library directory (at start-up).
    File,
    /// A write over the API.
    Api,
}

impl Source {
    pub fn as_str(self) -> &'static str {
        match self {
            Source::File => "file",
            Source::Api => "api",
        }
    }
    fn parse(s: &str) -> Source {
        if s == "file" { Source::File } else { Source::Api }
    }
}

/// What a [`Shelf`] keeps versions of: machine profiles, and each machine's tool table.
pub trait Kind: Send + Sync + Sized + 'static {
    /// The store's table of versions (the same columns for every kind).
    const TABLE: &'static str;
    /// A file of this kind in the library directory is `<id><SUFFIX>`.
    const SUFFIX: &'static str;
    /// Between the id and the version in an ETag (`"id-v3"`, `"id-tools-v3"`): the two never
    /// stand for each other in `If-Match`.
    const ETAG: &'static str;
    /// What it is, in messages.
    const WHAT: &'static str;
    /// Parses and validates `text` (named `file` in errors); `id`: the id it must have; `dir`:
    /// the library directory, where a profile's meshes are read. Returns its id.
    fn parse(text: &str, file: &str, id: Option<&str>, dir: &Path) -> Result<(String, Self), Error>;
    /// The library's files of this kind, by id.
    fn files(lib: &Library) -> Vec<(String, Arc<Self>)>;
    /// The text of the library's file `id` of this kind.
    fn file_text(lib: &Library, id: &str) -> std::io::Result<String> {
        super::read_text(&lib.dir.join(format!("{id}{}", Self::SUFFIX)))
    }
}

impl Kind for Dialect {
    const TABLE: &'static str = "dialect_versions";
    const SUFFIX: &'static str = ".toml";
    const ETAG: &'static str = "-dialect-v";
    const WHAT: &'static str = "dialect";
    fn parse(text: &str, file: &str, id: Option<&str>, _: &Path) -> Result<(String, Self), Error> {
        let d = super::dialects::parse(text, file, id)?;
        Ok((d.name.clone(), d))
    }
    fn files(lib: &Library) -> Vec<(String, Arc<Self>)> {
        lib.dialects.iter().map(|d| (d.name.clone(), d.clone())).collect()
    }
    fn file_text(lib: &Library, id: &str) -> std::io::Result<String> {
        lib.dialects.file_text(id)
    }
}

impl Kind for Profile {
    const TABLE: &'static str = "machine_versions";
    const SUFFIX: &'static str = ".toml";
    const ETAG: &'static str = "-v";
    const WHAT: &'static str = "machine";
    /// A stored profile has no directory of its own: its meshes are the library directory's
    /// files (an API write names a file the operator put there; it uploads none).
    fn parse(text: &str, file: &str, id: Option<&str>, dir: &Path) -> Result<(String, Self), Error> {
        let p = parse_profile_in(text, file, id, Some(dir))?;
        Ok((p.machine.id.clone(), p))
    }
    fn files(lib: &Library) -> Vec<(String, Arc<Self>)> {
        lib.iter().map(|p| (p.machine.id.clone(), p.clone())).collect()
    }
}

impl Kind for ToolTable {
    const TABLE: &'static str = "tool_table_versions";
    const SUFFIX: &'static str = TABLE_SUFFIX;
    const ETAG: &'static str = "-tools-v";
    const WHAT: &'static str = "tool table of machine";
    fn parse(text: &str, file: &str, id: Option<&str>, _: &Path) -> Result<(String, Self), Error> {
        // A table is always written to a machine's path: its id is the machine's.
        let id = id.ok_or_else(|| Error::Store("a tool table needs its machine's id".into()))?;
        Ok((id.to_string(), parse_tool_table(text, file)?))
    }
    fn files(lib: &Library) -> Vec<(String, Arc<Self>)> {
        lib.iter().filter_map(|p| Some((p.machine.id.clone(), lib.tools(&p.machine.id)?))).collect()
    }
}

/// The current version of a profile (or tool table).
#[derive(Debug)]
pub struct Current<T = Profile> {
    pub id: String,
    pub version: i64,
    pub item: Arc<T>,
    pub source: Source,
    pub created_ms: i64,
}

// Not derived: that would ask `T: Clone`, and only the `Arc` is cloned.
impl<T> Clone for Current<T> {
    fn clone(&self) -> Self {
        Current {
            id: self.id.clone(),
            version: self.version,
            item: self.item.clone(),
            source: self.source,
            created_ms: self.created_ms,
        }
    }
}

impl<T: Kind> Current<T> {
    /// A strong validator: a version never changes once written.
    pub fn etag(&self) -> String {
        format!("\"{}{}{}\"", self.id, T::ETAG, self.version)
    }
}

/// One entry of a profile's history.
#[derive(Clone, Debug)]
pub struct Version {
    pub version: i64,
    pub source: Source,
    pub created_ms: i64,
    /// A deletion is a version too (with no profile).
    pub deleted: bool,
}

/// What a write expects to find: the conditions of POST, PUT with `If-Match`, and plain PUT.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Expect {
    /// Create only: no current profile with this id.
    Absent,
    /// Exactly this current version (`If-Match: "id-vN"`).
    Version(i64),
    /// Any current version (`If-Match: *`).
    Present,
    /// Create or replace.
    Any,
}

/// The machine profiles, with each machine's tool table beside them. Reads of profiles go
/// straight to the profiles' shelf (`Deref`).
pub struct Catalog {
    profiles: Shelf<Profile>,
    pub tools: Shelf<ToolTable>,
    pub dialects: Shelf<Dialect>,
}

impl std::ops::Deref for Catalog {
    type Target = Shelf<Profile>;
    fn deref(&self) -> &Shelf<Profile> {
        &self.profiles
    }
}

impl Catalog {
    /// The files only, read-only (a process without a store: benches, tools).
    pub fn files_only(files: &Library) -> Arc<Catalog> {
        Arc::new(Catalog {
            profiles: Shelf::files_only(files),
            tools: Shelf::files_only(files),
            dialects: Shelf::files_only(files),
        })
    }

    /// Opens both shelves on a store (see [`Shelf::open`]).
    pub async fn open(files: &Library, db: AnyPool) -> Result<Arc<Catalog>, Error> {
        Ok(Arc::new(Catalog {
            profiles: Shelf::open(files, db.clone()).await?,
            tools: Shelf::open(files, db.clone()).await?,
            dialects: Shelf::open(files, db).await?,
        }))
    }

    /// Re-reads both shelves' current versions from the store.
    pub async fn refresh(&self) -> Result<(), Error> {
        self.profiles.refresh().await?;
        self.tools.refresh().await?;
        self.dialects.refresh().await
    }

    /// A dialect by id as a post resolves it: its current version (a job's recorded one goes
    /// through [`Shelf::version`]).
    pub fn dialect(&self, id: &str) -> Option<Arc<Dialect>> {
        self.dialects.get(id).ok().map(|c| c.item)
    }
}

/// The versions of one kind: the current ones in memory, the history in the store.
pub struct Shelf<T: Kind> {
    db: Option<AnyPool>,
    /// The library directory (a profile's meshes).
    dir: PathBuf,
    current: RwLock<BTreeMap<String, Current<T>>>,
    /// Versions jobs asked for, parsed once.
    old: Mutex<HashMap<(String, i64), Arc<T>>>,
    /// One writer at a time, so memory follows the store in commit order.
    write: tokio::sync::Mutex<()>,
}

/// A statement on kind `T`'s table: `{table}` in `sql` names it (a constant, never input).
fn sql<T: Kind>(sql: &str) -> sqlx::AssertSqlSafe<String> {
    sqlx::AssertSqlSafe(sql.replace("{table}", T::TABLE))
}

fn now_ms() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_millis() as i64)
        .unwrap_or(0)
}

use crate::db::{disk_full, not_now};

fn db_err(e: sqlx::Error) -> Error {
    if disk_full(&e) {
        return Error::NoSpace(e.to_string());
    }
    if not_now(&e) {
        return Error::Unavailable(e.to_string());
    }
    Error::Store(e.to_string())
}

impl<T: Kind> Shelf<T> {
    fn files_only(files: &Library) -> Shelf<T> {
        let current = T::files(files)
            .into_iter()
            .map(|(id, item)| {
                let c = Current {
                    id: id.clone(),
                    version: 1,
                    item,
                    source: Source::File,
                    created_ms: 0,
                };
                (id, c)
            })
            .collect();
        Shelf {
            db: None,
            dir: files.dir.clone(),
            current: RwLock::new(current),
            old: Mutex::new(HashMap::new()),
            write: tokio::sync::Mutex::new(()),
        }
    }

    /// Opens the shelf on a store. A file becomes a new version when its text differs from the
    /// last version that came from a file and no API write or deletion came after it: a shop's
    /// own changes are never overwritten by a file at start-up.
    async fn open(files: &Library, db: AnyPool) -> Result<Shelf<T>, Error> {
        crate::db::schema::versions(&db, T::TABLE).await.map_err(db_err)?;
        for (id, _) in T::files(files) {
            let id = &id;
            let text = &T::file_text(files, id).map_err(|source| Error::Io {
                path: format!("{}{}", id, T::SUFFIX),
                source,
            })?;
            let last = sqlx::query(sql::<T>("SELECT version, toml, source FROM {table} WHERE id = $1 ORDER BY version DESC LIMIT 1"))
                .bind(id)
                .fetch_optional(&db)
                .await
                .map_err(db_err)?;
            let next = match &last {
                None => Some(1),
                Some(r) => {
                    let (v, t, s): (i64, Option<String>, String) = (r.get(0), r.get(1), r.get(2));
                    match (Source::parse(&s), t) {
                        (Source::File, Some(t)) if t != *text => Some(v + 1),
                        (Source::Api, _) | (_, None) => {
                            tracing::info!(machine = %id, version = v, table = T::TABLE, "kept the API's version over the file");
                            None
                        }
                        _ => None,
                    }
                }
            };
            if let Some(v) = next {
                sqlx::query(sql::<T>(
                    "INSERT INTO {table} (id, version, toml, source, created_ms) VALUES ($1, $2, $3, 'file', $4)",
                ))
                .bind(id)
                .bind(v)
                .bind(text)
                .bind(now_ms())
                .execute(&db)
                .await
                .map_err(db_err)?;
            }
        }
        let shelf = Shelf {
            db: Some(db),
            dir: files.dir.clone(),
            current: RwLock::new(BTreeMap::new()),
            old: Mutex::new(HashMap::new()),
            write: tokio::sync::Mutex::new(()),
        };
        shelf.refresh().await?;
        Ok(shelf)
    }

    pub fn get(&self, id: &str) -> Result<Current<T>, Error> {
        self.current
            .read()
            .map_err(|_| Error::Store("catalog lock poisoned".into()))?
            .get(id)
            .cloned()
            .ok_or_else(|| Error::NotFound(id.into()))
    }

    pub fn list(&self) -> Vec<Current<T>> {
        self.current.read().map(|m| m.values().cloned().collect()).unwrap_or_default()
    }

    pub fn len(&self) -> usize {
        self.current.read().map(|m| m.len()).unwrap_or(0)
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    fn db(&self) -> Result<&AnyPool, Error> {
        self.db.as_ref().ok_or(Error::ReadOnly)
    }

    /// A version (a job's); the current one without a store.
    pub async fn version(&self, id: &str, version: i64) -> Result<Arc<T>, Error> {
        if let Ok(c) = self.get(id)
            && c.version == version
        {
            return Ok(c.item);
        }
        if let Some(p) = self.old.lock().ok().and_then(|m| m.get(&(id.to_string(), version)).cloned()) {
            return Ok(p);
        }
        let text = self.text(id, version).await?;
        let p = Arc::new(T::parse(&text, &format!("{id} v{version}"), Some(id), &self.dir)?.1);
        if let Ok(mut m) = self.old.lock() {
            if m.len() > 256 {
                m.clear();
            }
            m.insert((id.to_string(), version), p.clone());
        }
        Ok(p)
    }

    /// The TOML of a version, exactly as written (`None`: the version is a deletion).
    pub async fn text(&self, id: &str, version: i64) -> Result<String, Error> {
        let row = sqlx::query(sql::<T>("SELECT toml FROM {table} WHERE id = $1 AND version = $2"))
            .bind(id)
            .bind(version)
            .fetch_optional(self.db()?)
            .await
            .map_err(db_err)?;
        match row.map(|r| r.get::<Option<String>, _>(0)) {
            Some(Some(t)) => Ok(t),
            Some(None) => Err(Error::NotFound(format!("{id} version {version} (a deletion)"))),
            None => Err(Error::NotFound(format!("{id} version {version}"))),
        }
    }

    /// A profile's history, oldest first; empty for an id never seen.
    pub async fn versions(&self, id: &str) -> Result<Vec<Version>, Error> {
        let rows =
            sqlx::query(sql::<T>("SELECT version, source, created_ms, CAST(CASE WHEN toml IS NULL THEN 1 ELSE 0 END AS BIGINT) FROM {table} WHERE id = $1 ORDER BY version"))
                .bind(id)
                .fetch_all(self.db()?)
                .await
                .map_err(db_err)?;
        Ok(rows
            .iter()
            .map(|r| Version {
                version: r.get(0),
                source: Source::parse(&r.get::<String, _>(1)),
                created_ms: r.get(2),
                deleted: r.get::<i64, _>(3) != 0,
            })
            .collect())
    }

    /// Validates `text` with the files' loader and stores it as the next version. `id`: the id
    /// it must have (PUT's path). Returns the new current version and whether it created the
    /// profile.
    pub async fn put(&self, text: &str, id: Option<&str>, expect: Expect) -> Result<(Current<T>, bool), Error> {
        let (id, item) = T::parse(text, "request body", id, &self.dir)?;
        let _w = self.write.lock().await;
        let (version, created) = self.append(&id, Some(text), expect).await?;
        let cur = Current {
            id: id.clone(),
            version,
            item: Arc::new(item),
            source: Source::Api,
            created_ms: now_ms(),
        };
        if let Ok(mut m) = self.current.write() {
            m.insert(id, cur.clone());
        }
        Ok((cur, created))
    }

    /// Deletes a profile: a version without a profile. Jobs already submitted keep theirs.
    pub async fn delete(&self, id: &str, expect: Expect) -> Result<i64, Error> {
        let _w = self.write.lock().await;
        let (version, _) = self.append(id, None, expect).await?;
        if let Ok(mut m) = self.current.write() {
            m.remove(id);
        }
        Ok(version)
    }

    /// Checks `expect` against the store's latest version (another replica may have written)
    /// and appends the next, in one transaction. A concurrent writer makes the insert collide on
    /// the key: that is a failed precondition, not an error.
    async fn append(&self, id: &str, text: Option<&str>, expect: Expect) -> Result<(i64, bool), Error> {
        let mut tx = self.db()?.begin().await.map_err(db_err)?;
        // A write first, so the transaction holds the write lock before it reads: on SQLite one
        // that reads and then writes cannot wait for a writer that came between (a job's
        // progress): "database is locked" at once, busy timeout or not. PostgreSQL: a no-op.
        sqlx::query(sql::<T>("UPDATE {table} SET version = version WHERE 1 = 0"))
            .execute(&mut *tx)
            .await
            .map_err(db_err)?;
        let last = sqlx::query(sql::<T>(
            "SELECT version, CAST(CASE WHEN toml IS NULL THEN 1 ELSE 0 END AS BIGINT) FROM {table}
             WHERE id = $1 ORDER BY version DESC LIMIT 1",
        ))
        .bind(id)
        .fetch_optional(&mut *tx)
        .await
        .map_err(db_err)?
        .map(|r| (r.get::<i64, _>(0), r.get::<i64, _>(1) != 0));
        let present = last.and_then(|(v, deleted)| (!deleted).then_some(v));
        if text.is_none() && present.is_none() {
            return Err(Error::NotFound(id.into()));
        }
        check(id, present, expect)?;
        let version = last.map_or(0, |(v, _)| v) + 1;
        let inserted =
            sqlx::query(sql::<T>("INSERT INTO {table} (id, version, toml, source, created_ms) VALUES ($1, $2, $3, 'api', $4)"))
                .bind(id)
                .bind(version)
                .bind(text)
                .bind(now_ms())
                .execute(&mut *tx)
                .await;
        match inserted {
            Err(sqlx::Error::Database(d)) if d.is_unique_violation() => {
                return Err(Error::Precondition {
                    id: id.into(),
                    current: None,
                });
            }
            Err(e) => return Err(db_err(e)),
            Ok(_) => {}
        }
        tx.commit().await.map_err(db_err)?;
        Ok((version, present.is_none()))
    }

    /// Re-reads the current versions from the store (all of them at start-up): replicas see each
    /// other's writes. A stored version this build rejects is reported, not served.
    pub async fn refresh(&self) -> Result<(), Error> {
        let Ok(db) = self.db() else { return Ok(()) };
        let rows = sqlx::query(sql::<T>("SELECT id, MAX(version) FROM {table} GROUP BY id"))
            .fetch_all(db)
            .await
            .map_err(db_err)?;
        for r in rows {
            let (id, v): (String, i64) = (r.get(0), r.get(1));
            if self.get(&id).ok().is_some_and(|c| c.version == v) {
                continue;
            }
            let row = sqlx::query(sql::<T>("SELECT toml, source, created_ms FROM {table} WHERE id = $1 AND version = $2"))
                .bind(&id)
                .bind(v)
                .fetch_one(db)
                .await
                .map_err(db_err)?;
            let (text, source, created_ms): (Option<String>, String, i64) = (row.get(0), row.get(1), row.get(2));
            let Ok(mut m) = self.current.write() else { continue };
            match text.map(|t| T::parse(&t, &format!("{id} v{v}"), Some(&id), &self.dir)) {
                None => {
                    m.remove(&id);
                }
                Some(Ok((_, p))) => {
                    m.insert(
                        id.clone(),
                        Current {
                            id,
                            version: v,
                            item: Arc::new(p),
                            source: Source::parse(&source),
                            created_ms,
                        },
                    );
                }
                Some(Err(e)) => tracing::error!(error = %e, table = T::TABLE, "a stored version no longer loads; not served"),
            }
        }
        Ok(())
    }
}

fn check(id: &str, present: Option<i64>, expect: Expect) -> Result<(), Error> {
    match (expect, present) {
        (Expect::Absent, Some(c)) => Err(Error::Exists {
            id: id.into(),
            version: c,
        }),
        (Expect::Version(v), Some(c)) if c != v => Err(Error::Precondition {
            id: id.into(),
            current: Some(c),
        }),
        (Expect::Version(_) | Expect::Present, None) => Err(Error::Precondition {
            id: id.into(),
            current: None,
        }),
        _ => Ok(()),
    }
}
