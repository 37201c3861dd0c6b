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

pub use store::{Job, JobSettings, JobState, Store, Submission};

use crate::machines::{Catalog, Library, Profile};
use crate::output::preview::{Caps, PreviewBuilder};
use crate::output::{ErrorBody, FileSink, Record};
use crate::post::{self, BlockInfo, Sink, Stop, Summary};
use crate::spool::blocks::BlockWriter;
use crate::spool::{Paths, lines};
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
    /// The upload broke off (the client, its pace, its size): the error it broke with.
    #[error("reading the upload: {0}")]
    Upload(std::io::Error),
    /// The spool's disk is full: nothing was accepted.
    #[error("no room for the upload in the job spool: {0}")]
    NoSpace(String),
    /// A row the store cannot read back (written by another version, or damaged).
    #[error("job store: {0}")]
    Corrupt(String),
    /// The store could not be opened or failed its check: the service does not start.
    #[error("job store {store}: {error}")]
    Open { store: String, error: String },
    /// The store did not confirm a job's row (its answers were lost): not acknowledged. A row
    /// that did land keeps its input, so a retry with the same idempotency key finds the job.
    #[error("the job store did not confirm the job ({0}); submit it again, with the same Idempotency-Key")]
    Unconfirmed(String),
    #[error("no job {0}")]
    NotFound(String),
    #[error("the queue is full ({0} jobs waiting)")]
    Full(u64),
    /// One client may not fill the queue for everyone.
    #[error("{client} has {active} jobs queued or running (the limit per client)")]
    ClientLimit { client: String, active: u64 },
    /// An Idempotency-Key given again with a request other than the one its job was accepted
    /// with: answering with that job would answer another question.
    #[error("Idempotency-Key {} is job {job}'s, which was submitted with {what}: a new request needs a new key", crate::text::quote(.key))]
    KeyReused { key: String, job: String, what: &'static str },
    #[error("job {id} is {state}")]
    WrongState { id: String, state: JobState },
    #[error("machine catalog: {0}")]
    Machines(#[from] crate::machines::Error),
}

/// Queue settings.
#[derive(Clone, Debug)]
pub struct Config {
    pub data_dir: PathBuf,
    /// Jobs run at once (default: one per core); 0: none on this node (another replica runs them).
    pub workers: usize,
    /// Jobs waiting at most; more are refused (the service answers 503).
    pub max_queued: u64,
    /// Jobs one client (address) may have queued or running; 0: no limit.
    pub max_per_client: u64,
    /// Finished jobs and their files are removed after this long.
    pub retention: Duration,
    /// PostgreSQL shared by replicas; `None`: SQLite in `data_dir`.
    pub database_url: Option<String>,
    /// The spool (inputs and outputs); replicas share one. Default `data_dir/spool`.
    pub spool_dir: Option<PathBuf>,
    /// A running job whose node has not reported for this long is taken over by another.
    pub lease: Duration,
    /// What one job's post may cost (output per CL byte, seconds).
    pub budget: crate::post::Budget,
    /// Threads a job's post runs on (`post::threads`); 0: two while this node runs fewer jobs
    /// than it has cores, else one ([`Queue::threads_for_next`]).
    pub threads: usize,
    /// Runs a job may have, counting those a fault outside it ended (a full spool, the store
    /// not answering, a replica that stopped): after that many it fails with the last cause.
    pub max_attempts: u32,
    /// The pause before a job's second run after such a fault, doubled before each next one
    /// (at most [`MAX_BACKOFF`]).
    pub retry_backoff: Duration,
}

pub use store::MAX_BACKOFF;

impl Error {
    /// The store does not answer now (a lost connection, a restarting database, a pool with no
    /// connection to give): asked again later, the same thing may succeed.
    pub fn not_now(&self) -> bool {
        match self {
            Error::Db(e) => crate::db::not_now(e),
            Error::Machines(crate::machines::Error::Unavailable(_)) => true,
            _ => false,
        }
    }
}

/// How a run ended without its program.
#[derive(Debug)]
enum Failed {
    /// The job's own fault (its input, its settings, its budget): it fails, naming it.
    Job(String),
    /// The job was cancelled while it ran.
    Cancelled,
    /// A cause outside the job (the spool, the store): it runs again.
    Fault(String),
}

/// An operating system's error on a spool file (a full disk, an I/O error): no fault of the
/// job's. (A cancel or a budget is a [`Stop`] of its own, never an I/O error.)
fn os_fault(e: &std::io::Error) -> bool {
    e.raw_os_error().is_some() || matches!(e.kind(), std::io::ErrorKind::StorageFull | std::io::ErrorKind::QuotaExceeded)
}

/// The store plus the workers' shared state: which jobs run here, and their cancel flags.
pub struct Queue {
    pub store: Store,
    pub config: Config,
    machines: Arc<Catalog>,
    running: Mutex<HashMap<String, Arc<AtomicBool>>>,
    wake: tokio::sync::Notify,
    /// Told how each run ended and how long it ran (the service's metrics).
    observer: std::sync::OnceLock<Observer>,
}

/// A run's outcome (`succeeded`, `failed`, `cancelled`) and its seconds.
pub type Observer = Box<dyn Fn(&'static str, f64) + Send + Sync>;

impl Queue {
    /// Opens the store and the machine catalog in it (the profile files of `files` as first
    /// versions), puts jobs cut off by a crash back in the queue, and starts the workers and the
    /// cleaner on the current runtime.
    pub async fn start(config: Config, files: &Library) -> Result<(Arc<Queue>, Arc<Catalog>), Error> {
        let store = Store::open(
            &config.data_dir,
            config.database_url.as_deref(),
            config.spool_dir.as_deref(),
            config.lease,
        )
        .await?;
        let machines = Catalog::open(files, store.pool().clone()).await?;
        if store.backend() == store::Backend::Postgres {
            // Replicas: each sees the others' profile writes within a second.
            let m = machines.clone();
            tokio::spawn(async move {
                loop {
                    tokio::time::sleep(Duration::from_secs(1)).await;
                    if let Err(e) = m.refresh().await {
                        tracing::warn!(error = %e, "refreshing machine profiles");
                    }
                }
            });
        }
        let requeued = store.recover().await?;
        let (files, bytes) = store.sweep(true).await?;
        store.started().await;
        if requeued > 0 {
            tracing::warn!(requeued, "jobs cut off by a restart run again from the start");
        }
        if files > 0 {
            tracing::warn!(files, bytes, "removed spool files no job owns (left by a process cut off)");
        }
        let q = Arc::new(Queue {
            store,
            config,
            machines: machines.clone(),
            running: Mutex::new(HashMap::new()),
            wake: tokio::sync::Notify::new(),
            observer: std::sync::OnceLock::new(),
        });
        for _ in 0..q.config.workers {
            tokio::spawn(q.clone().worker());
        }
        tokio::spawn(q.clone().cleaner());
        Ok((q, machines))
    }

    /// Accepts a job: the input is streamed to the spool and fsynced before the row commits, the
    /// limits counted as the row is inserted (the counts before spooling only refuse early).
    /// With an idempotency key already seen, returns that job (and `false`), if this is the
    /// request it was accepted with (`KeyReused` else).
    pub async fn submit(
        &self,
        settings: JobSettings,
        machine_version: i64,
        filename: Option<String>,
        idempotency_key: Option<String>,
        client: Option<String>,
        input: impl tokio::io::AsyncRead + Unpin,
    ) -> Result<(Job, bool), Error> {
        let options = store::options_digest(&settings);
        if let Some(k) = &idempotency_key
            && let Some(j) = self.store.by_key(k).await?
        {
            return Ok((self.store.resubmitted(j, &options, input).await?, false));
        }
        let waiting = self.store.count(JobState::Queued).await?;
        if waiting >= self.config.max_queued {
            return Err(Error::Full(waiting));
        }
        if let Some(c) = &client
            && self.config.max_per_client > 0
        {
            let active = self.store.active_for(c).await?;
            if active >= self.config.max_per_client {
                return Err(Error::ClientLimit {
                    client: c.clone(),
                    active,
                });
            }
        }
        let submission = Submission {
            settings,
            machine_version,
            client,
            filename,
            key: idempotency_key,
            options,
            max_queued: self.config.max_queued,
            max_per_client: self.config.max_per_client,
        };
        let r = self.store.insert(submission, input).await?;
        self.wake.notify_one();
        Ok(r)
    }

    /// Sets who hears of finished runs (once).
    pub fn observe(&self, f: Observer) {
        let _ = self.observer.set(f);
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
            match self.store.claim(self.config.max_attempts.into()).await {
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

    /// Expires finished jobs, and now and then sweeps the spool of what no job owns (another
    /// replica's leftovers, once they are an hour old).
    async fn cleaner(self: Arc<Self>) {
        let mut swept = std::time::Instant::now();
        loop {
            match self.store.expire(self.config.retention).await {
                Ok(n) if n > 0 => tracing::info!(removed = n, "expired finished jobs"),
                Ok(_) => {}
                Err(e) => tracing::error!(error = %e, "expiring jobs"),
            }
            if swept.elapsed() >= Duration::from_secs(600) {
                swept = std::time::Instant::now();
                match self.store.sweep(false).await {
                    Ok((files, bytes)) if files > 0 => tracing::info!(files, bytes, "removed spool files no job owns"),
                    Ok(_) => {}
                    Err(e) => tracing::error!(error = %e, "sweeping the spool"),
                }
            }
            tokio::time::sleep(Duration::from_secs(60).min(self.config.retention.max(Duration::from_secs(1)))).await;
        }
    }

    async fn run(&self, job: Job) {
        let id = job.id.clone();
        let cancel = Arc::new(AtomicBool::new(false));
        if let Ok(mut m) = self.running.lock() {
            m.insert(id.clone(), cancel.clone());
        }
        let progress = Arc::new(Progress::default());
        let started = std::time::Instant::now();
        // The version it was submitted with, even if the profile changed or went since.
        let profile = match job.machine_version {
            Some(v) => self.machines.version(&job.machine, v).await,
            None => self.machines.get(&job.machine).map(|c| c.item),
        }
        .map_err(|e| catalog_failed(e, format!("machine {:?}", job.machine)));
        // And the machine's tool table it was submitted with, if it took one.
        let tools = match job.settings.machine_tools_version {
            Some(v) => match self.machines.tools.version(&job.machine, v).await {
                Ok(t) => Ok(Some((t, format!("THE MACHINE'S TOOL TABLE V{v}")))),
                Err(e) => Err(catalog_failed(e, format!("machine {:?}: tool table version {v}", job.machine))),
            },
            None => Ok(None),
        };
        // And the dialect's version, where the job recorded one (the built-ins else).
        let dialect = match (&profile, job.settings.dialect_version) {
            (Ok(p), Some(v)) => {
                let id = job.settings.post.dialect.clone().unwrap_or_else(|| p.machine.controller.clone());
                self.machines
                    .dialects
                    .version(&id, v)
                    .await
                    .map(Some)
                    .map_err(|e| catalog_failed(e, format!("dialect {id:?} version {v}")))
            }
            _ => Ok(None),
        };
        let task = {
            let (job, cancel, progress) = (job.clone(), cancel.clone(), progress.clone());
            let spool = self.store.spool().to_path_buf();
            let run = (self.config.budget, self.threads_for_next());
            tokio::task::spawn_blocking(move || {
                execute(profile?, tools?, dialect?, &spool, &job, run, &cancel, &progress)
            })
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
        let secs = started.elapsed().as_secs_f64();
        // Read once: the label and the handling must agree even if a cancel lands in between.
        let cancelled = cancel.load(Ordering::Relaxed);
        let end = match result {
            Ok(Ok(s)) => End::Succeeded(Box::new(s)),
            Ok(Err(Failed::Cancelled)) => End::Cancelled,
            Ok(Err(_)) if cancelled => End::Cancelled,
            Ok(Err(Failed::Fault(cause))) => End::Fault(cause),
            Ok(Err(Failed::Job(msg))) => End::Failed(msg),
            Err(join) => End::Failed(format!("the engine stopped: {join}")),
        };
        if let Some(f) = self.observer.get() {
            f(end.label(), secs);
        }
        self.record(&job, end).await;
    }

    /// Records how a run ended. A store that does not answer now (a lost connection, a
    /// restarting database, a full disk under SQLite) is asked again for some 16 s;
    /// after that the job stays `running` under this node's lapsing lease, and is run again
    /// when the store is back. A run that cannot publish its outputs (the spool) goes back to
    /// the queue like one the spool stopped midway.
    async fn record(&self, job: &Job, mut end: End) {
        const PAUSES_MS: [u64; 7] = [0, 250, 500, 1000, 2000, 4000, 8000];
        let mut last = None;
        for pause in PAUSES_MS {
            tokio::time::sleep(Duration::from_millis(pause)).await;
            let r = match &end {
                End::Succeeded(s) => self.store.succeed(job, s).await,
                End::Cancelled => {
                    self.store.remove_outputs(job);
                    Ok(())
                }
                End::Failed(msg) => self.store.fail(job, msg).await,
                End::Fault(cause) => {
                    let (max, first) = (self.config.max_attempts.into(), self.config.retry_backoff);
                    match self.store.retry(job, cause, max, first).await {
                        Ok(true) => {
                            tracing::warn!(job = %job.id, attempt = job.attempts, error = %cause, "a run failed for a cause outside the job: queued again");
                            Ok(())
                        }
                        r => r.map(drop),
                    }
                }
            };
            match r {
                Ok(()) => return,
                Err(Error::Io(e)) if matches!(end, End::Succeeded(_)) && os_fault(&e) => {
                    end = End::Fault(format!("job spool: publishing the outputs: {e}"));
                }
                Err(e) if e.not_now() || matches!(&e, Error::Db(d) if crate::db::disk_full(d)) => {
                    last = Some(e);
                }
                Err(e) => {
                    tracing::error!(job = %job.id, error = %e, "recording a job's end");
                    return;
                }
            }
        }
        if let Some(e) = last {
            tracing::error!(job = %job.id, error = %e, "the job store did not answer: the job runs again once its lease lapses");
        }
    }
}

/// How a run ended, to be recorded.
enum End {
    Succeeded(Box<Summary>),
    Cancelled,
    /// The job's own fault.
    Failed(String),
    /// A cause outside the job: queued again (bounded).
    Fault(String),
}

impl End {
    /// The outcome as the metrics count it.
    fn label(&self) -> &'static str {
        match self {
            End::Succeeded(_) => "succeeded",
            End::Cancelled => "cancelled",
            End::Failed(_) => "failed",
            End::Fault(_) => "retried",
        }
    }
}

/// A profile, tool table or dialect version the job needs and the catalog did not give: the
/// store not answering (or its disk) is no fault of the job's; anything else (gone, damaged) is.
fn catalog_failed(e: crate::machines::Error, what: String) -> Failed {
    use crate::machines::Error as E;
    match e {
        e @ (E::Unavailable(_) | E::NoSpace(_) | E::Io { .. }) => Failed::Fault(format!("{what}: {e}")),
        e => Failed::Job(format!("{what}: {e}")),
    }
}

impl Queue {
    /// The threads a job starting now runs on. Where the setting leaves it to the node: the
    /// second thread where a core is idle (the job alone, or fewer running than cores), since
    /// it costs some 10 % more CPU and buys nothing on a busy node (reliability.md).
    fn threads_for_next(&self) -> usize {
        if self.config.threads != 0 {
            return self.config.threads;
        }
        let running = self.running.lock().map(|m| m.len()).unwrap_or(usize::MAX);
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        if running < cores { 2 } else { 1 }
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

/// Read twice (the first pass that finds the tools' order, then the post): the progress is
/// where the reading stands, so it starts again with it.
impl<R: std::io::Seek> std::io::Seek for Counting<R> {
    fn seek(&mut self, pos: std::io::SeekFrom) -> std::io::Result<u64> {
        let at = self.inner.seek(pos)?;
        self.progress.bytes.store(at, Ordering::Relaxed);
        Ok(at)
    }
}

/// The spool files' sink (NC, block store, compact line map, and the preview beside them), counting
/// blocks and stopping when the job is cancelled.
struct JobSink<'a> {
    files: FileSink<std::fs::File, std::fs::File>,
    blocks: BlockWriter<std::io::BufWriter<std::fs::File>>,
    lines: lines::Writer<std::io::BufWriter<std::fs::File>>,
    preview: PreviewBuilder,
    progress: &'a Progress,
    cancel: &'a AtomicBool,
}

impl Sink for JobSink<'_> {
    fn line(&mut self, text: &str, b: Option<&BlockInfo>) -> Result<(), Stop> {
        // Motion blocks, as the summary counts them (it counted every line, header and M codes).
        let n = self.progress.blocks.fetch_add(b.is_some() as u64, Ordering::Relaxed);
        if n % 1024 == 0 && self.cancel.load(Ordering::Relaxed) {
            return Err(Stop::Cancelled);
        }
        if let Some(b) = b {
            self.preview.block(text, b);
        }
        self.lines.line(text, b)?;
        self.blocks.line(text, b)?;
        self.files.line(text, b)
    }
    fn diagnostic(&mut self, d: &crate::diag::Diagnostic) -> Result<(), Stop> {
        self.preview.note(d, None);
        Ok(self.blocks.record(&Record::Diagnostic { diagnostic: d })?)
    }
    fn diagnostic_at(&mut self, d: &crate::diag::Diagnostic, pose: &crate::kinematics::Pose) -> Result<(), Stop> {
        self.preview.note(d, Some(pose));
        Ok(self.blocks.record(&Record::Diagnostic { diagnostic: d })?)
    }
    fn summary(&mut self, s: &Summary) -> Result<(), Stop> {
        Ok(self.blocks.record(&Record::Summary { summary: s })?)
    }
    fn tool(&mut self, first_block: u64, t: &crate::collide::ToolShape) {
        self.preview.tool(first_block, t)
    }
    fn halted(&mut self) -> Option<Stop> {
        self.cancel.load(Ordering::Relaxed).then_some(Stop::Cancelled)
    }
}

/// One job on a blocking thread: spool input → `.tmp` outputs, fsynced. The error is the
/// message a user reads in the job's `error` (or its `last_cause`, when it runs again).
fn execute(
    profile: Arc<Profile>,
    tools: Option<(Arc<crate::machines::tools::ToolTable>, String)>,
    dialect: Option<Arc<crate::nc::Dialect>>,
    spool: &std::path::Path,
    job: &Job,
    (budget, threads): (post::Budget, usize),
    cancel: &AtomicBool,
    progress: &Arc<Progress>,
) -> Result<Summary, Failed> {
    let paths = Paths::new(spool, &job.id, job.attempts);
    let mut opts = job
        .settings
        .post
        .profile_options_with(&profile, tools, &|id| match &dialect {
            Some(d) if d.name == id => Some(d.clone()),
            _ => crate::nc::dialect(id),
        })
        .map_err(|e| Failed::Job(e.to_string()))?;
    opts.budget = budget;
    opts.threads = threads;
    opts.header.push(format!("JOB {}", job.id));
    if let Some(f) = &job.filename {
        opts.header.push(format!("SOURCE {f}"));
    }
    let io = |e: std::io::Error| {
        let msg = format!("job spool: {e}");
        if os_fault(&e) { Failed::Fault(msg) } else { Failed::Job(msg) }
    };
    if opts.setup_offsets {
        // The spool can be read twice: the header lists the offsets the program selects.
        let first = std::io::BufReader::new(std::fs::File::open(&paths.input).map_err(io)?);
        opts.header.extend(post::setups::header_lines(first, &profile.machine, &opts).unwrap_or_default());
    }
    let input = std::fs::File::open(&paths.input).map_err(io)?;
    let input = std::io::BufReader::with_capacity(
        64 * 1024,
        Counting {
            inner: input,
            progress: progress.clone(),
        },
    );
    let nc = std::fs::File::create(&paths.nc_tmp).map_err(io)?;
    let blocks = std::io::BufWriter::with_capacity(1 << 16, std::fs::File::create(&paths.blocks_tmp).map_err(io)?);
    let lines = std::io::BufWriter::new(std::fs::File::create(&paths.lines_tmp).map_err(io)?);
    let mut sink = JobSink {
        files: FileSink::new(nc, None),
        blocks: BlockWriter::new(blocks).map_err(io)?,
        lines: lines::Writer::new(lines).map_err(io)?,
        preview: PreviewBuilder::new(&profile.machine, opts.mode, Caps::default()).with_scene(
            &profile.machine,
            &profile.geometry(),
            opts.work_offset.into(),
            &opts.stock,
            &opts.fixtures,
        ),
        progress,
        cancel,
    };
    let res = post::post_seekable(input, &profile.machine, &opts, &mut sink);
    let res = match res {
        Ok(s) => Ok(s),
        Err(e) => {
            // The diagnostics of a failed job end with the error: never a silent truncation.
            let msg = e.to_string();
            let _ = sink.blocks.record(&Record::Error {
                error: ErrorBody::from_engine(&e),
            });
            // A spool file the system failed (full, an I/O error) is no fault of the job's.
            Err(match e {
                post::Error::Stop(Stop::Cancelled) => Failed::Cancelled,
                e if e.io().is_some_and(os_fault) => Failed::Fault(msg),
                _ => Failed::Job(msg),
            })
        }
    };
    let (nc, _) = sink.files.into_inner().map_err(io)?;
    nc.sync_all().map_err(io)?;
    let lines = sink.lines.finish().map_err(io)?.into_inner().map_err(|e| io(e.into_error()))?;
    lines.sync_all().map_err(io)?;
    let blocks = sink.blocks.into_inner().into_inner().map_err(|e| io(e.into_error()))?;
    blocks.sync_all().map_err(io)?;
    if !cancel.load(Ordering::Relaxed) {
        let mut source = std::io::BufReader::with_capacity(64 * 1024, std::fs::File::open(&paths.input).map_err(io)?);
        let preview = sink.preview.finish(res.as_ref().ok(), Some(&mut source));
        let mut f = std::io::BufWriter::new(std::fs::File::create(&paths.preview_tmp).map_err(io)?);
        serde_json::to_writer(&mut f, &preview).map_err(|e| io(e.into()))?;
        f.into_inner().map_err(|e| io(e.into_error()))?.sync_all().map_err(io)?;
    }
    res
}
