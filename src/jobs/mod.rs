//! The job queue: large CL files handed over, post-processed in the background, fetched later.
//!
//! Durable on one node. The job table lives in SQLite (WAL, synchronous FULL) in the data
//! directory, inputs and outputs in its `spool/`. A job exists once its input is fsynced and its
//! row committed, so an accepted job survives `kill -9`. Outputs are written under `.tmp` names
//! and renamed only when the job has succeeded: a half-written program is never served as
//! finished. A job found `running` at start-up was cut off by a crash; it goes back to the queue
//! and runs again from the start.
//!
//! Knows nothing of HTTP: the service edge maps [`Error`] to statuses and [`Job`] to its DTO.

mod store;

pub use store::{Job, State, Store};

use crate::machines::Library;
use crate::post::{self, BlockInfo, FileSink, Sink, Summary};
use std::collections::HashMap;
use std::io::Read;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("job store: {0}")]
    Db(#[from] sqlx::Error),
    #[error("job spool: {0}")]
    Io(#[from] std::io::Error),
    #[error("reading the upload: {0}")]
    Upload(String),
    /// A row the store cannot read back (written by another version, or damaged).
    #[error("job store: {0}")]
    Corrupt(String),
    #[error("no job {0}")]
    NotFound(String),
    #[error("the queue is full ({0} jobs waiting)")]
    Full(u64),
    #[error("job {id} is {state}")]
    WrongState { id: String, state: State },
}

/// Queue settings.
#[derive(Clone, Debug)]
pub struct Config {
    pub data_dir: PathBuf,
    /// Jobs run at once (default: one per core).
    pub workers: usize,
    /// Jobs waiting at most; more are refused (the service answers 503).
    pub max_queued: u64,
    /// Finished jobs and their files are removed after this long.
    pub retention: Duration,
}

/// The store plus the workers' shared state: which jobs run here, and their cancel flags.
pub struct Queue {
    pub store: Store,
    pub config: Config,
    library: Library,
    running: Mutex<HashMap<String, Arc<AtomicBool>>>,
    wake: tokio::sync::Notify,
}

impl Queue {
    /// Opens the store, puts jobs cut off by a crash back in the queue, and starts the workers
    /// and the cleaner on the current runtime.
    pub async fn start(config: Config, library: Library) -> Result<Arc<Queue>, Error> {
        let store = Store::open(&config.data_dir).await?;
        let requeued = store.recover().await?;
        if requeued > 0 {
            tracing::warn!(requeued, "jobs cut off by a restart run again from the start");
        }
        let q = Arc::new(Queue {
            store,
            config,
            library,
            running: Mutex::new(HashMap::new()),
            wake: tokio::sync::Notify::new(),
        });
        for _ in 0..q.config.workers.max(1) {
            tokio::spawn(q.clone().worker());
        }
        tokio::spawn(q.clone().cleaner());
        Ok(q)
    }

    /// Accepts a job: the input is streamed to the spool and fsynced before the row commits.
    /// With an idempotency key already seen, returns that job (and `false`).
    pub async fn submit(
        &self,
        settings: post::Settings,
        filename: Option<String>,
        idempotency_key: Option<String>,
        input: impl tokio::io::AsyncRead + Unpin,
    ) -> Result<(Job, bool), Error> {
        if let Some(k) = &idempotency_key
            && let Some(j) = self.store.by_key(k).await?
        {
            return Ok((j, false));
        }
        let waiting = self.store.count(State::Queued).await?;
        if waiting >= self.config.max_queued {
            return Err(Error::Full(waiting));
        }
        let r = self.store.insert(settings, filename, idempotency_key, input).await?;
        self.wake.notify_one();
        Ok(r)
    }

    /// Cancels a queued or running job (a running one stops at its next progress check).
    pub async fn cancel(&self, id: &str) -> Result<Job, Error> {
        let j = self.store.cancel(id).await?;
        if let Some(flag) = self.running.lock().ok().and_then(|m| m.get(id).cloned()) {
            flag.store(true, Ordering::Relaxed);
        }
        Ok(j)
    }

    async fn worker(self: Arc<Self>) {
        loop {
            match self.store.claim().await {
                Ok(Some(job)) => self.run(job).await,
                Ok(None) => {
                    let _ = tokio::time::timeout(Duration::from_secs(2), self.wake.notified()).await;
                }
                Err(e) => {
                    tracing::error!(error = %e, "claiming a job");
                    tokio::time::sleep(Duration::from_secs(1)).await;
                }
            }
        }
    }

    async fn cleaner(self: Arc<Self>) {
        loop {
            match self.store.expire(self.config.retention).await {
                Ok(n) if n > 0 => tracing::info!(removed = n, "expired finished jobs"),
                Ok(_) => {}
                Err(e) => tracing::error!(error = %e, "expiring jobs"),
            }
            tokio::time::sleep(Duration::from_secs(60).min(self.config.retention.max(Duration::from_secs(1))))
                .await;
        }
    }

    async fn run(&self, job: Job) {
        let id = job.id.clone();
        let cancel = Arc::new(AtomicBool::new(false));
        if let Ok(mut m) = self.running.lock() {
            m.insert(id.clone(), cancel.clone());
        }
        let progress = Arc::new(Progress::default());
        let task = {
            let (job, cancel, progress) = (job.clone(), cancel.clone(), progress.clone());
            let library = self.library.clone();
            let spool = self.store.spool().to_path_buf();
            tokio::task::spawn_blocking(move || execute(&library, &spool, &job, &cancel, &progress))
        };
        tokio::pin!(task);
        let result = loop {
            tokio::select! {
                r = &mut task => break r,
                _ = tokio::time::sleep(Duration::from_millis(200)) => {
                    let (b, n) = progress.snapshot();
                    // A job no longer `running` in the store was cancelled (maybe by another node).
                    if let Ok(false) = self.store.progress(&id, b, n).await {
                        cancel.store(true, Ordering::Relaxed);
                    }
                }
            }
        };
        if let Ok(mut m) = self.running.lock() {
            m.remove(&id);
        }
        let (b, n) = progress.snapshot();
        let _ = self.store.progress(&id, b, n).await;
        let outcome = match result {
            Ok(Ok(s)) => self.store.succeed(&id, &s).await,
            Ok(Err(_)) if cancel.load(Ordering::Relaxed) => {
                self.store.remove_outputs(&id);
                Ok(())
            }
            Ok(Err(msg)) => self.store.fail(&id, &msg).await,
            Err(join) => self.store.fail(&id, &format!("the engine stopped: {join}")).await,
        };
        if let Err(e) = outcome {
            tracing::error!(job = %id, error = %e, "recording a job's end");
        }
    }
}

#[derive(Default)]
struct Progress {
    bytes: AtomicU64,
    blocks: AtomicU64,
}

impl Progress {
    /// Bytes read and blocks written so far.
    fn snapshot(&self) -> (u64, u64) {
        (self.bytes.load(Ordering::Relaxed), self.blocks.load(Ordering::Relaxed))
    }
}

/// Counts what the engine has read, for progress.
struct Counting<R> {
    inner: R,
    progress: Arc<Progress>,
}

impl<R: Read> Read for Counting<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.progress.bytes.fetch_add(n as u64, Ordering::Relaxed);
        Ok(n)
    }
}

/// The spool files' sink, counting blocks and stopping when the job is cancelled.
struct JobSink<'a> {
    files: FileSink<std::fs::File, std::fs::File>,
    progress: &'a Progress,
    cancel: &'a AtomicBool,
}

impl Sink for JobSink<'_> {
    fn line(&mut self, text: &str, b: Option<&BlockInfo>) -> std::io::Result<()> {
        let n = self.progress.blocks.fetch_add(1, Ordering::Relaxed);
        if n % 1024 == 0 && self.cancel.load(Ordering::Relaxed) {
            return Err(std::io::Error::other("cancelled"));
        }
        self.files.line(text, b)
    }
    fn diagnostic(&mut self, d: &crate::diag::Diagnostic) -> std::io::Result<()> {
        self.files.diagnostic(d)
    }
    fn summary(&mut self, s: &Summary) -> std::io::Result<()> {
        self.files.summary(s)
    }
}

/// One job on a blocking thread: spool input → `.tmp` outputs, fsynced. The error is the
/// message a user reads in the job's `error`.
fn execute(
    library: &Library,
    spool: &std::path::Path,
    job: &Job,
    cancel: &AtomicBool,
    progress: &Arc<Progress>,
) -> Result<Summary, String> {
    let paths = store::Paths::new(spool, &job.id);
    let profile = library
        .get(&job.machine)
        .map_err(|_| format!("unknown machine {:?}", job.machine))?;
    let mut opts = job.settings.profile_options(&profile)?;
    opts.header.push(format!("JOB {}", job.id));
    if let Some(f) = &job.filename {
        opts.header.push(format!("SOURCE {f}"));
    }
    let io = |e: std::io::Error| format!("job spool: {e}");
    let input = std::fs::File::open(&paths.input).map_err(io)?;
    let input = std::io::BufReader::with_capacity(
        64 * 1024,
        Counting {
            inner: input,
            progress: progress.clone(),
        },
    );
    let nc = std::fs::File::create(&paths.nc_tmp).map_err(io)?;
    let nd = std::fs::File::create(&paths.diag_tmp).map_err(io)?;
    let mut sink = JobSink {
        files: FileSink::new(nc, Some(nd)),
        progress,
        cancel,
    };
    let res = post::post(input, &profile.machine, &opts, &mut sink);
    let res = match res {
        Ok(s) => Ok(s),
        Err(e) => {
            // The diagnostics of a failed job end with the error: never a silent truncation.
            let msg = e.to_string();
            let _ = sink.files.json(&serde_json::json!({"type": "error", "error": msg}));
            Err(msg)
        }
    };
    let (nc, nd) = sink.files.into_inner().map_err(io)?;
    nc.sync_all().map_err(io)?;
    if let Some(nd) = nd {
        nd.sync_all().map_err(io)?;
    }
    res
}
