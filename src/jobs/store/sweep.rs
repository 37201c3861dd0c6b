//! The spool holds what jobs own: a job's input and outputs while its row exists, and the
//! temporaries of uploads and runs in progress. What a process killed mid-way leaves (uploads,
//! runs' temporaries, an input whose row never committed, the files of a row deleted) goes: at
//! start-up what this node's previous process left and, with one node, everything no row owns;
//! at any time what no row owns and has not been written for an hour (another replica may be
//! between writing an input and committing its row).

use super::{Backend, Store};
use crate::jobs::Error;
use sqlx::Row;
use std::collections::HashMap;
use std::time::{Duration, SystemTime};

/// Unowned files younger than this may be another node's work in progress.
const EXPIRED: Duration = Duration::from_secs(3600);

/// An upload's temporary name: the job id, the node writing it.
pub(super) fn upload_name(id: &str, node: &str) -> String {
    format!("{id}.{node}.cl.tmp")
}

/// What a spool file is to the job whose id starts its name.
#[derive(Debug, PartialEq)]
enum Kind {
    /// `<id>.cl`
    Input,
    /// `<id>.nc`, `<id>.blocks`, `<id>.nc.partial`, `<id>.preview.json`, `<id>.lines` (and
    /// `<id>.ndjson`, from before the block store)
    Output,
    /// `<id>.<node>.cl.tmp` (`<id>.cl.tmp`, from before uploads named their node: `None`)
    Upload(Option<String>),
    /// `<id>.<output>.<attempt>.tmp`: one run's output before it is published.
    RunTemp(i64),
}

fn classify(name: &str) -> Option<(&str, Kind)> {
    let (id, rest) = name.split_at_checked(32)?;
    let rest = rest.strip_prefix('.')?;
    if !id.bytes().all(|b| b.is_ascii_hexdigit()) {
        return None;
    }
    let kind = match rest {
        "cl" => Kind::Input,
        "nc" | "blocks" | "nc.partial" | "ndjson" | "preview.json" | "lines" => Kind::Output,
        "cl.tmp" => Kind::Upload(None),
        r => {
            let r = r.strip_suffix(".tmp")?;
            if let Some(node) = r.strip_suffix(".cl") {
                Kind::Upload(Some(node.to_string()))
            } else {
                let (out, attempt) = r.rsplit_once('.')?;
                if !matches!(out, "nc" | "blocks" | "ndjson" | "preview.json" | "lines") {
                    return None;
                }
                Kind::RunTemp(attempt.parse().ok()?)
            }
        }
    };
    Some((id, kind))
}

/// A job's row as far as its files are concerned.
struct Owner {
    running: bool,
    attempts: i64,
    node: Option<String>,
}

impl Store {
    /// Removes spool files no job owns (see the module's doc); `startup`: this node has nothing
    /// in progress yet. Returns the files and bytes removed.
    pub(in crate::jobs) async fn sweep(&self, startup: bool) -> Result<(u64, u64), Error> {
        // Listed before the rows are read: a run's temporary listed here was made after its claim
        // committed, so the rows read next know that run.
        let spool = self.spool.clone();
        let files = tokio::task::spawn_blocking(
            move || -> std::io::Result<Vec<(std::path::PathBuf, String, SystemTime, u64)>> {
                let mut out = Vec::new();
                for e in std::fs::read_dir(&spool)? {
                    let e = e?;
                    let name = e.file_name().to_string_lossy().into_owned();
                    if classify(&name).is_none() {
                        continue;
                    }
                    if let Ok(m) = e.metadata() {
                        out.push((e.path(), name, m.modified().unwrap_or(SystemTime::now()), m.len()));
                    }
                }
                Ok(out)
            },
        )
        .await
        .map_err(std::io::Error::other)??;
        if files.is_empty() {
            return Ok((0, 0));
        }
        let rows = sqlx::query("SELECT id, state, attempts, owner FROM jobs")
            .fetch_all(&self.pool)
            .await?;
        let mut owners = HashMap::with_capacity(rows.len());
        for r in rows {
            // A damaged row still owns its files (its run temporaries are dead either way).
            let Ok(id) = r.try_get::<String, _>(0) else { continue };
            owners.insert(
                id,
                Owner {
                    running: r.try_get::<String, _>(1).is_ok_and(|s| s == "running"),
                    attempts: r.try_get(2).unwrap_or(-1),
                    node: r.try_get(3).unwrap_or_default(),
                },
            );
        }
        // One node on its own spool: nothing is in progress anywhere at its start-up.
        let alone = startup && self.backend == Backend::Sqlite;
        let now = SystemTime::now();
        let (mut n, mut bytes) = (0, 0);
        for (path, name, modified, len) in files {
            let Some((id, kind)) = classify(&name) else { continue };
            let expired = now.duration_since(modified).is_ok_and(|age| age > EXPIRED.max(self.lease));
            let owner = owners.get(id);
            let dead = match kind {
                Kind::Output => owner.is_none(),
                Kind::Input => owner.is_none() && (alone || expired),
                Kind::Upload(node) => alone || expired || (startup && node.as_deref() == Some(self.node.as_str())),
                // Live only while its row runs that attempt, on a node that is not this one
                // restarting.
                Kind::RunTemp(attempt) => !owner.is_some_and(|o| {
                    o.running && o.attempts == attempt && !(startup && o.node.as_deref() == Some(self.node.as_str()))
                }),
            };
            if dead && std::fs::remove_file(&path).is_ok() {
                n += 1;
                bytes += len;
            }
        }
        Ok((n, bytes))
    }
}

#[cfg(test)]
mod tests {
    use super::{Kind, classify};

    #[test]
    fn spool_names_are_told_apart() {
        let id = "0123456789abcdef0123456789abcdef";
        assert_eq!(classify(&format!("{id}.cl")), Some((id, Kind::Input)));
        assert_eq!(classify(&format!("{id}.preview.json")), Some((id, Kind::Output)));
        assert_eq!(classify(&format!("{id}.cl.tmp")), Some((id, Kind::Upload(None))));
        assert_eq!(
            classify(&format!("{id}.web-1.example-0a1b2c3d.cl.tmp")),
            Some((id, Kind::Upload(Some("web-1.example-0a1b2c3d".into()))))
        );
        assert_eq!(classify(&format!("{id}.preview.json.3.tmp")), Some((id, Kind::RunTemp(3))));
        assert_eq!(classify(&format!("{id}.nc.12.tmp")), Some((id, Kind::RunTemp(12))));
        assert_eq!(classify(&format!("{id}.blocks.2.tmp")), Some((id, Kind::RunTemp(2))));
        for out in ["blocks", "nc.partial", "ndjson"] {
            assert_eq!(classify(&format!("{id}.{out}")), Some((id, Kind::Output)));
        }
        for other in [
            ".readyz",
            "notes.txt",
            &format!("{id}.txt"),
            &format!("{id}.x.1.tmp"),
            "0123.cl",
        ] {
            assert_eq!(classify(other), None, "{other}");
        }
    }
}
