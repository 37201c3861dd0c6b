//! The live machine library: the profile files as the first versions, then every change made
//! over the API as a new version, in the same store as the jobs. A job names the version it was
//! submitted with and runs with that one, whatever happens to the profile meanwhile.
//!
//! Reads come from memory (the current version of each profile); writes go to the store in one
//! transaction each, then to memory, one writer at a time.

use super::{Error, Library, Profile, parse_profile};
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

/// The current version of a profile.
#[derive(Clone, Debug)]
pub struct Current {
    pub version: i64,
    pub profile: Arc<Profile>,
    pub source: Source,
    pub created_ms: i64,
}

impl Current {
    /// A strong validator: a version never changes once written.
    pub fn etag(&self) -> String {
        format!("\"{}-v{}\"", self.profile.machine.id, self.version)
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

pub struct Catalog {
    db: Option<AnyPool>,
    current: RwLock<BTreeMap<String, Current>>,
    /// Versions jobs asked for, parsed once.
    old: Mutex<HashMap<(String, i64), Arc<Profile>>>,
    /// One writer at a time, so memory follows the store in commit order.
    write: tokio::sync::Mutex<()>,
}

const SCHEMA: &str = "CREATE TABLE IF NOT EXISTS machine_versions (
    id TEXT NOT NULL,
    version BIGINT NOT NULL,
    toml TEXT,
    source TEXT NOT NULL,
    created_ms BIGINT NOT NULL,
    PRIMARY KEY (id, version)
)";

fn now_ms() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_millis() as i64)
        .unwrap_or(0)
}

/// Whether a database error is its disk being full: SQLite's `SQLITE_FULL`, PostgreSQL's
/// `disk_full`, or the OS's `ENOSPC`/`EDQUOT` (the job store asks too).
pub(crate) fn disk_full(e: &sqlx::Error) -> bool {
    match e {
        sqlx::Error::Database(d) => d
            .code()
            .is_some_and(|c| c == "53100" || c.parse::<i32>().is_ok_and(|n| n & 0xff == 13)),
        sqlx::Error::Io(e) => matches!(e.kind(), std::io::ErrorKind::StorageFull | std::io::ErrorKind::QuotaExceeded),
        _ => false,
    }
}

fn db_err(e: sqlx::Error) -> Error {
    if disk_full(&e) {
        return Error::NoSpace(e.to_string());
    }
    Error::Store(e.to_string())
}

impl Catalog {
    /// The files only, read-only (a process without a store: benches, tools).
    pub fn files_only(files: &Library) -> Arc<Catalog> {
        let current = files
            .iter()
            .map(|p| {
                (
                    p.machine.id.clone(),
                    Current {
                        version: 1,
                        profile: p.clone(),
                        source: Source::File,
                        created_ms: 0,
                    },
                )
            })
            .collect();
        Arc::new(Catalog {
            db: None,
            current: RwLock::new(current),
            old: Mutex::new(HashMap::new()),
            write: tokio::sync::Mutex::new(()),
        })
    }

    /// Opens the catalog on a store. A profile file becomes a new version when its text differs
    /// from the last version that came from a file and no API write or deletion came after it:
    /// a shop's own changes are never overwritten by a file at start-up.
    pub async fn open(files: &Library, db: AnyPool) -> Result<Arc<Catalog>, Error> {
        sqlx::query(SCHEMA).execute(&db).await.map_err(db_err)?;
        for p in files.iter() {
            let id = &p.machine.id;
            let path = files.dir.join(format!("{id}.toml"));
            let text = &tokio::fs::read_to_string(&path).await.map_err(|source| Error::Io {
                path: path.display().to_string(),
                source,
            })?;
            let last =
                sqlx::query("SELECT version, toml, source FROM machine_versions WHERE id = $1 ORDER BY version DESC LIMIT 1")
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
                            tracing::info!(machine = %id, version = v, "kept the API's version over the profile file");
                            None
                        }
                        _ => None,
                    }
                }
            };
            if let Some(v) = next {
                sqlx::query(
                    "INSERT INTO machine_versions (id, version, toml, source, created_ms) VALUES ($1, $2, $3, 'file', $4)",
                )
                .bind(id)
                .bind(v)
                .bind(text)
                .bind(now_ms())
                .execute(&db)
                .await
                .map_err(db_err)?;
            }
        }
        let catalog = Arc::new(Catalog {
            db: Some(db),
            current: RwLock::new(BTreeMap::new()),
            old: Mutex::new(HashMap::new()),
            write: tokio::sync::Mutex::new(()),
        });
        catalog.refresh().await?;
        Ok(catalog)
    }

    pub fn get(&self, id: &str) -> Result<Current, Error> {
        self.current
            .read()
            .map_err(|_| Error::Store("catalog lock poisoned".into()))?
            .get(id)
            .cloned()
            .ok_or_else(|| Error::NotFound(id.into()))
    }

    pub fn list(&self) -> Vec<Current> {
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

    /// A version's profile (a job's); the current one without a store.
    pub async fn version(&self, id: &str, version: i64) -> Result<Arc<Profile>, Error> {
        if let Ok(c) = self.get(id)
            && c.version == version
        {
            return Ok(c.profile);
        }
        if let Some(p) = self.old.lock().ok().and_then(|m| m.get(&(id.to_string(), version)).cloned()) {
            return Ok(p);
        }
        let text = self.text(id, version).await?;
        let p = Arc::new(parse_profile(&text, &format!("{id} v{version}"), Some(id))?);
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
        let row = sqlx::query("SELECT toml FROM machine_versions WHERE id = $1 AND version = $2")
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
            sqlx::query("SELECT version, source, created_ms, CAST(CASE WHEN toml IS NULL THEN 1 ELSE 0 END AS BIGINT) FROM machine_versions WHERE id = $1 ORDER BY version")
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
    pub async fn put(&self, text: &str, id: Option<&str>, expect: Expect) -> Result<(Current, bool), Error> {
        let profile = parse_profile(text, "request body", id)?;
        let id = profile.machine.id.clone();
        let _w = self.write.lock().await;
        let (version, created) = self.append(&id, Some(text), expect).await?;
        let cur = Current {
            version,
            profile: Arc::new(profile),
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
        let last = sqlx::query(
            "SELECT version, CAST(CASE WHEN toml IS NULL THEN 1 ELSE 0 END AS BIGINT) FROM machine_versions
             WHERE id = $1 ORDER BY version DESC LIMIT 1",
        )
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
            sqlx::query("INSERT INTO machine_versions (id, version, toml, source, created_ms) VALUES ($1, $2, $3, 'api', $4)")
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
        let rows = sqlx::query("SELECT id, MAX(version) FROM machine_versions GROUP BY id")
            .fetch_all(db)
            .await
            .map_err(db_err)?;
        for r in rows {
            let (id, v): (String, i64) = (r.get(0), r.get(1));
            if self.get(&id).ok().is_some_and(|c| c.version == v) {
                continue;
            }
            let row = sqlx::query("SELECT toml, source, created_ms FROM machine_versions WHERE id = $1 AND version = $2")
                .bind(&id)
                .bind(v)
                .fetch_one(db)
                .await
                .map_err(db_err)?;
            let (text, source, created_ms): (Option<String>, String, i64) = (row.get(0), row.get(1), row.get(2));
            let Ok(mut m) = self.current.write() else { continue };
            match text.map(|t| parse_profile(&t, &format!("{id} v{v}"), Some(&id))) {
                None => {
                    m.remove(&id);
                }
                Some(Ok(p)) => {
                    m.insert(
                        id,
                        Current {
                            version: v,
                            profile: Arc::new(p),
                            source: Source::parse(&source),
                            created_ms,
                        },
                    );
                }
                Some(Err(e)) => tracing::error!(error = %e, "a stored machine version no longer loads; not served"),
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
