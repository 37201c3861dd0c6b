//! The command line: a thin edge over the library. Degrees and JSON live here.

/// `println!` that stops quietly where the reader went away (`kinepost machines validate … | head`):
/// a closed pipe ends the output, it is not a panic (exit 101).
macro_rules! say {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        if let Err(e) = writeln!(std::io::stdout().lock(), $($t)*) {
            if e.kind() == std::io::ErrorKind::BrokenPipe {
                std::process::exit(0);
            }
            eprintln!("kinepost: writing to standard output: {e}");
            std::process::exit(2);
        }
    }};
}

mod machines_cmd;

use clap::{Parser, Subcommand};
use machines_cmd::{MachinesCmd, machines_cmd};
use kinepost::kinematics::{self, IkOptions, Joints, Pose, Setup, Units, Vec3};
use kinepost::machines::{self, Library};
use kinepost::output::{solution_json, utc_now};
use kinepost::post::parse_triple;
use serde_json::{Value, json};
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser, Debug)]
#[command(
    name = "kinepost",
    version,
    about = "5-axis CNC postprocessor: exact inverse kinematics for any machine profile"
)]
pub struct Cli {
    /// Directory of machine profiles (default: ./machines, or the one shipped with kinepost).
    #[arg(long, global = true, env = "KINEPOST_MACHINES")]
    pub machines: Option<PathBuf>,
    /// Directory of dialect files beside the built-in five (default: ./dialects, or the one
    /// shipped with kinepost); a file may `extends = "fanuc"` and say only what differs.
    #[arg(long, global = true, env = "KINEPOST_DIALECTS")]
    pub dialects: Option<PathBuf>,
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// List the machine profiles.
    Machines {
        /// One JSON object per line instead of a table.
        #[arg(long)]
        json: bool,
        #[command(subcommand)]
        action: Option<MachinesCmd>,
    },
    /// List the NC dialects: the built-in five and the files of --dialects.
    Dialects {
        /// One JSON object per line instead of a table.
        #[arg(long)]
        json: bool,
    },
    /// Forward kinematics: axis words → tool pose in the part frame, as JSON.
    Fk {
        #[arg(long)]
        machine: String,
        #[command(flatten)]
        setup: SetupArgs,
        /// Axis words, e.g. X=10 Y=0 Z=-5 B=30 C=-90 (degrees for rotaries). Missing ones are 0.
        #[arg(required = true, allow_hyphen_values = true)]
        words: Vec<String>,
    },
    /// Run the HTTP service (REST API, web form, OpenAPI at /openapi.json, Swagger UI at /docs).
    Serve(ServeArgs),
    /// Post-process a CL file into NC for a machine; NC on stdout (or --output), summary on stderr.
    Post(PostArgs),
    /// Write a generated 5-axis CL path for a profile (smooth joint motion within travel, through
    /// FK): a smoke test for a new profile, and the benchmark's input.
    Generate {
        #[arg(long)]
        machine: String,
        #[arg(long, default_value_t = 1000)]
        points: usize,
        #[arg(long, default_value_t = 1)]
        seed: u64,
        #[arg(long, allow_hyphen_values = true)]
        tool_length: Option<f64>,
    },
    /// Replay an NC program (fanuc-style word address, from anywhere) through FK against its CL
    /// file: every CL point reproduced in order, blocks between them on the CL segment. JSON
    /// report on stdout; exit 1 when a check fails.
    Verify {
        #[arg(long)]
        machine: String,
        #[arg(long)]
        cl: String,
        #[arg(long)]
        nc: String,
        #[arg(long, value_enum, default_value = "joint")]
        mode: ModeArg,
        #[command(flatten)]
        setup: SetupArgs,
        /// Position tolerance in profile units (default 0.01 mm / 0.0004 in).
        #[arg(long, allow_hyphen_values = true)]
        tolerance: Option<f64>,
        #[arg(long)]
        #[arg(value_enum)]
        cl_units: Option<UnitsArg>,
        /// The tool table the program was posted with (default: the machine's,
        /// `machines/<id>.tools.toml`, if there is one).
        #[arg(long)]
        tool_table: Option<PathBuf>,
    },
    /// Read a CL file and report its diagnostics and record counts (JSON summary on stdout).
    Lint {
        /// CL file, or - for standard input.
        input: String,
        /// Print every diagnostic, one per line, on stderr.
        #[arg(long)]
        verbose: bool,
    },
    /// Inverse kinematics: tool pose x y z i j k → every joint solution, as JSON.
    Ik {
        #[arg(long)]
        machine: String,
        #[command(flatten)]
        setup: SetupArgs,
        /// Units of x y z (default: the profile's).
        #[arg(long)]
        #[arg(value_enum)]
        units: Option<UnitsArg>,
        /// x y z i j k in the part frame.
        #[arg(num_args = 6, required = true, allow_negative_numbers = true)]
        pose: Vec<f64>,
    },
}

#[derive(clap::Args, Debug, Clone)]
pub struct ServeArgs {
    /// Address to listen on.
    #[arg(long, env = "KINEPOST_BIND", default_value = "127.0.0.1:8080")]
    pub bind: String,
    /// Where the service keeps its data (jobs, spool); default `$XDG_DATA_HOME/kinepost`, else
    /// `~/.local/share/kinepost` (not the working directory: a checkout grew by a job's spool).
    #[arg(long, env = "KINEPOST_DATA_DIR")]
    pub data_dir: Option<PathBuf>,
    /// Largest upload in bytes (streamed, not buffered).
    #[arg(long, env = "KINEPOST_MAX_UPLOAD", default_value_t = 4 << 30)]
    pub max_upload: u64,
    /// Longest a non-streaming request may take, seconds.
    #[arg(long, env = "KINEPOST_REQUEST_TIMEOUT", default_value_t = 30)]
    pub request_timeout: u64,
    /// Post streams at once; more are answered 503 with Retry-After.
    #[arg(long, env = "KINEPOST_MAX_STREAMS", default_value_t = 64)]
    pub max_streams: usize,
    /// Seconds a new connection has to send its first request's headers; then it is closed.
    #[arg(long, env = "KINEPOST_HEADER_TIMEOUT", default_value_t = 30.0, allow_hyphen_values = true)]
    pub header_timeout: f64,
    /// Seconds a connection may stay open with no request in flight (keep-alive).
    #[arg(long, env = "KINEPOST_IDLE_TIMEOUT", default_value_t = 60.0, allow_hyphen_values = true)]
    pub idle_timeout: f64,
    /// Seconds a response may wait on a client that reads nothing; then its connection is
    /// closed and what it held freed. 0: no limit.
    #[arg(long, env = "KINEPOST_WRITE_TIMEOUT", default_value_t = 30.0, allow_hyphen_values = true)]
    pub write_timeout: f64,
    /// Downloads (a job's NC, diagnostics, input and line map; mesh files) one client address may
    /// have in flight at once; more are answered 429. 0: no limit.
    #[arg(long, env = "KINEPOST_MAX_DOWNLOADS_PER_CLIENT", default_value_t = 8)]
    pub max_downloads_per_client: usize,
    /// Connections open at once (fewer if the open-file limit holds fewer); at the limit the one
    /// idle longest is closed to let a new one in.
    #[arg(long, env = "KINEPOST_MAX_CONNECTIONS", default_value_t = 4096)]
    pub max_connections: usize,
    /// Bytes a second an upload must average over --upload-rate-window; a slower one is cut off
    /// (408). 0: no minimum.
    #[arg(long, env = "KINEPOST_MIN_UPLOAD_RATE", default_value_t = 1024)]
    pub min_upload_rate: u64,
    /// Seconds over which --min-upload-rate is averaged.
    #[arg(
        long,
        env = "KINEPOST_UPLOAD_RATE_WINDOW",
        default_value_t = 30.0,
        allow_hyphen_values = true
    )]
    pub upload_rate_window: f64,
    /// Origins allowed by CORS, comma-separated (e.g. a CAM plugin's web view).
    #[arg(long, env = "KINEPOST_CORS_ORIGINS", value_delimiter = ',')]
    pub cors_origins: Vec<String>,
    /// Jobs run at once (default: one per core).
    #[arg(long, env = "KINEPOST_WORKERS")]
    pub workers: Option<usize>,
    /// Jobs waiting at most; more are answered 503 with Retry-After.
    #[arg(long, env = "KINEPOST_MAX_QUEUED", default_value_t = 1000)]
    pub max_queued: u64,
    /// Jobs one client address may have queued or running (429 beyond); 0: no limit.
    #[arg(long, env = "KINEPOST_MAX_JOBS_PER_CLIENT", default_value_t = 100)]
    pub max_jobs_per_client: u64,
    /// Hours a finished job and its files are kept.
    #[arg(
        long,
        env = "KINEPOST_JOB_RETENTION_HOURS",
        default_value_t = 168.0,
        allow_hyphen_values = true
    )]
    pub job_retention_hours: f64,
    /// Log format: text or json.
    #[arg(long, env = "KINEPOST_LOG_FORMAT", default_value = "text")]
    pub log_format: String,
    /// Bearer token for writes to machine profiles over the API; without one, they are off.
    /// Prefer the environment variable (a flag shows in `ps`).
    #[arg(long, env = "KINEPOST_ADMIN_TOKEN", hide_env_values = true)]
    pub admin_token: Option<String>,
    /// PostgreSQL URL (postgres://…) for replicas sharing one job queue and machine catalog;
    /// without it, SQLite in the data directory.
    #[arg(long, env = "KINEPOST_DATABASE_URL", hide_env_values = true)]
    pub database_url: Option<String>,
    /// Spool directory for job inputs and outputs, shared by replicas (default DATA_DIR/spool).
    #[arg(long, env = "KINEPOST_SPOOL_DIR")]
    pub spool_dir: Option<std::path::PathBuf>,
    /// Seconds without a report after which another replica takes a running job over.
    #[arg(long, env = "KINEPOST_JOB_LEASE_SECS", default_value_t = 30.0, allow_hyphen_values = true)]
    pub job_lease_secs: f64,
    /// Runs a job may have, counting those that a fault outside the job ended (the spool full or
    /// failing, the database not answering, a replica that stopped); then it fails.
    #[arg(long, env = "KINEPOST_JOB_MAX_ATTEMPTS", default_value_t = 5)]
    pub job_max_attempts: u32,
    /// Seconds before a job runs again after such a fault, doubled before each next run (at
    /// most 300).
    #[arg(long, env = "KINEPOST_JOB_RETRY_SECS", default_value_t = 2.0, allow_hyphen_values = true)]
    pub job_retry_secs: f64,
    /// Seconds requests in flight get after SIGTERM before the server stops anyway (jobs
    /// running then resume on the next start).
    #[arg(long, env = "KINEPOST_SHUTDOWN_GRACE", default_value_t = 60.0, allow_hyphen_values = true)]
    pub shutdown_grace: f64,
    /// Threads each streamed post (`POST /v1/post`) runs on: 1 or 2.
    #[arg(long, env = "KINEPOST_POST_THREADS", default_value_t = 1)]
    pub post_threads: u32,
    /// Threads each job's post runs on: 1 or 2; 0: two while this node runs fewer jobs than it
    /// has cores (counting the job), else one.
    #[arg(long, env = "KINEPOST_JOB_THREADS", default_value_t = 0)]
    pub job_threads: u32,
    #[command(flatten)]
    pub budget: BudgetArgs,
}

/// What one post may cost (the server's streams and jobs, the CLI's run).
#[derive(clap::Args, Debug, Clone)]
pub struct BudgetArgs {
    /// Blocks a post may write per CL byte read, beyond the 100 000 any program gets (0: no
    /// bound): a few bytes of helix at a fine tolerance cannot write gigabytes.
    #[arg(long, env = "KINEPOST_MAX_BLOCKS_PER_BYTE", default_value_t = 8)]
    pub max_blocks_per_byte: u64,
    /// Seconds a post may run (0: no bound).
    #[arg(long, env = "KINEPOST_MAX_POST_SECONDS", default_value_t = 3600.0, allow_hyphen_values = true)]
    pub max_post_seconds: f64,
}

impl BudgetArgs {
    fn budget(&self) -> Result<kinepost::post::Budget, String> {
        kinepost::post::Budget::new(self.max_blocks_per_byte, self.max_post_seconds)
    }
}

/// `--mode`: joint or tcp.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum ModeArg {
    Joint,
    Tcp,
}

impl From<ModeArg> for kinepost::post::Mode {
    fn from(m: ModeArg) -> Self {
        match m {
            ModeArg::Joint => kinepost::post::Mode::Joint,
            ModeArg::Tcp => kinepost::post::Mode::Tcp,
        }
    }
}

/// `--units` / `--cl-units`: mm or inch.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum UnitsArg {
    Mm,
    Inch,
}

impl From<UnitsArg> for Units {
    fn from(u: UnitsArg) -> Self {
        match u {
            UnitsArg::Mm => Units::Mm,
            UnitsArg::Inch => Units::Inch,
        }
    }
}

/// `kinepost post`: the post options (one definition, `post::Settings`, which HTTP takes too)
/// and what only the command line has: its input and output files, the tool table as a file,
/// the threads, the budget, and the shorthand flags it had before `--cycles` and `--planes`.
#[derive(clap::Args, Debug, Clone)]
pub struct PostArgs {
    #[command(flatten)]
    pub settings: kinepost::post::Settings,
    /// Hole cycles as the control's canned cycles: `--cycles canned`.
    #[arg(long, conflicts_with = "cycles")]
    pub canned_cycles: bool,
    /// Fixed-axis (3+2) runs in a tilted working plane: `--planes tilted`.
    #[arg(long, conflicts_with = "planes")]
    pub tilted_planes: bool,
    #[command(flatten)]
    pub budget: BudgetArgs,
    /// Threads for the post: 1, or 2 (the CL read and planned beside the NC written; the same
    /// output). Default: 2 where the machine has two cores or more.
    #[arg(long, default_value_t = default_threads())]
    pub threads: u32,
    /// A tool table (TOML: units, [[tool]] number, length …): each tool's length in joint mode
    /// on a head machine. Replaces the machine's (`machines/<id>.tools.toml`) for this job.
    #[arg(long)]
    pub tool_table: Option<PathBuf>,
    /// Write per-block diagnostics as NDJSON to this file.
    #[arg(long)]
    pub diagnostics: Option<PathBuf>,
    /// Write the NC here instead of stdout.
    #[arg(long, short)]
    pub output: Option<PathBuf>,
    /// CL file, or - for standard input.
    pub input: String,
}

#[derive(clap::Args, Debug, Clone)]
pub struct SetupArgs {
    /// Tool length (gauge line to tip), profile units (default: the profile's).
    #[arg(long, allow_hyphen_values = true)]
    pub tool_length: Option<f64>,
    /// Work offset x,y,z in profile units: the part origin in the machine frame at home.
    #[arg(long, allow_hyphen_values = true)]
    pub work_offset: Option<String>,
}

impl SetupArgs {
    fn setup(&self, m: &kinematics::Machine) -> Result<Setup, String> {
        let wo = match &self.work_offset {
            Some(s) => parse_triple(s)?,
            None => Vec3::zeros(),
        };
        Setup::checked(m, self.tool_length, wo)
    }
}

/// Why a command did not succeed, and so its exit status: 1 for output written that must not be
/// trusted as it is (a program with error diagnostics, a verify check failed), 2 for nothing
/// done (strict refusal, unreadable input, bad arguments).
pub enum Failure {
    Written(String),
    Refused(String),
}

impl From<String> for Failure {
    fn from(s: String) -> Self {
        Failure::Refused(s)
    }
}

pub fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(Failure::Written(e)) => {
            eprintln!("kinepost: {e}");
            ExitCode::from(1)
        }
        Err(Failure::Refused(e)) => {
            eprintln!("kinepost: {e}");
            ExitCode::from(2)
        }
    }
}

fn library(cli: &Cli) -> Result<Library, String> {
    let dir = cli.machines.clone().unwrap_or_else(machines::default_dir);
    let dialects = cli.dialects.clone().unwrap_or_else(machines::dialects::default_dir);
    Library::load_dir(&dir).and_then(|l| l.with_dialects(&dialects)).map_err(|e| e.to_string())
}

/// Opens a CL input: a path, or `-` for standard input.
/// Two threads for a post where there are two cores (one post is the machine's whole load).
fn default_threads() -> u32 {
    match std::thread::available_parallelism() {
        Ok(n) if n.get() >= 2 => 2,
        _ => 1,
    }
}

pub fn open_input(path: &str) -> Result<Box<dyn std::io::BufRead + Send>, String> {
    if path == "-" {
        Ok(Box::new(std::io::BufReader::with_capacity(1 << 16, std::io::stdin())))
    } else {
        let f = std::fs::File::open(path).map_err(|e| format!("{path}: {e}"))?;
        Ok(Box::new(std::io::BufReader::with_capacity(1 << 16, f)))
    }
}

/// A post of the CL at `path`: a file is read twice where that readies the next tool
/// (`post::post_seekable`), standard input once.
fn post_input<S: kinepost::post::Sink + ?Sized>(
    path: &str,
    m: &kinepost::kinematics::Machine,
    o: &kinepost::post::Options,
    sink: &mut S,
) -> Result<Result<kinepost::post::Summary, kinepost::post::Error>, String> {
    if path == "-" {
        return Ok(kinepost::post::post(open_input(path)?, m, o, sink));
    }
    let f = std::fs::File::open(path).map_err(|e| format!("{path}: {e}"))?;
    Ok(kinepost::post::post_seekable(
        std::io::BufReader::with_capacity(1 << 16, f),
        m,
        o,
        sink,
    ))
}

fn lint(input: &str, verbose: bool) -> Result<(), String> {
    use kinepost::cl::{Event, Reader};
    use kinepost::diag::Severity;
    let mut counts: std::collections::BTreeMap<String, u64> = Default::default();
    let (mut records, mut errors, mut warnings) = (0u64, 0u64, 0u64);
    for ev in Reader::new(open_input(input)?) {
        match ev.map_err(|e| e.to_string())? {
            Event::Statement(s) => {
                records += 1;
                let name = format!("{:?}", s.record);
                let key = name.split([' ', '(', '{']).next().unwrap_or("").to_string();
                *counts.entry(key).or_default() += 1;
            }
            Event::Diagnostic(d) => {
                match d.severity {
                    Severity::Error => errors += 1,
                    Severity::Warning => warnings += 1,
                    Severity::Info => {}
                }
                if verbose || d.severity == Severity::Error {
                    eprintln!("{input}: {d}");
                }
            }
        }
    }
    say!(
        "{}",
        json!({"records": records, "errors": errors, "warnings": warnings, "by_record": counts})
    );
    if errors > 0 {
        Err(format!("{errors} bad records"))
    } else {
        Ok(())
    }
}

/// A duration option given in `unit` seconds, within [min, max] units: a clear error for
/// anything else (NaN and negatives would panic in `Duration`, and clamping hides a typo).
fn seconds(flag: &str, v: f64, min: f64, max: f64, unit: f64) -> Result<std::time::Duration, String> {
    if v.is_finite() && (min..=max).contains(&v) {
        Ok(std::time::Duration::from_secs_f64(v * unit))
    } else {
        Err(format!("--{flag}: expected a number from {min} to {max}, got {v}"))
    }
}

/// The user's data directory (XDG), else `./data` where there is no home.
fn default_data_dir() -> PathBuf {
    let xdg = std::env::var_os("XDG_DATA_HOME").filter(|d| !d.is_empty()).map(PathBuf::from);
    let home = std::env::var_os("HOME").filter(|d| !d.is_empty()).map(|h| PathBuf::from(h).join(".local/share"));
    xdg.or(home).map_or_else(|| PathBuf::from("data"), |d| d.join("kinepost"))
}

fn serve(cli: &Cli, a: &ServeArgs) -> Result<(), String> {
    if a.admin_token.as_deref().is_some_and(|t| !t.is_empty() && t.trim().is_empty()) {
        return Err("KINEPOST_ADMIN_TOKEN is only whitespace: give a real token, or none to keep profile writes off".into());
    }
    let filter =
        tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    // Colours only for a terminal: a log file kept the escape codes.
    let ansi = std::io::IsTerminal::is_terminal(&std::io::stderr());
    let builder = tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr).with_ansi(ansi);
    match a.log_format.as_str() {
        "json" => builder.json().init(),
        "text" => builder.init(),
        other => return Err(format!("--log-format {other:?}: expected text or json")),
    }
    let cfg = kinepost::http::Config {
        bind: a.bind.clone(),
        machines: cli.machines.clone().unwrap_or_else(machines::default_dir),
        dialects: cli.dialects.clone().unwrap_or_else(machines::dialects::default_dir),
        data_dir: a.data_dir.clone().unwrap_or_else(default_data_dir),
        max_upload: a.max_upload,
        request_timeout: std::time::Duration::from_secs(a.request_timeout),
        max_streams: a.max_streams.max(1),
        header_timeout: seconds("header-timeout", a.header_timeout, 0.1, 3600.0, 1.0)?,
        idle_timeout: seconds("idle-timeout", a.idle_timeout, 0.1, 86400.0, 1.0)?,
        write_timeout: seconds("write-timeout", a.write_timeout, 0.0, 86400.0, 1.0)?,
        max_downloads_per_client: a.max_downloads_per_client,
        max_connections: a.max_connections.max(1),
        min_upload_rate: a.min_upload_rate,
        upload_rate_window: seconds("upload-rate-window", a.upload_rate_window, 0.1, 3600.0, 1.0)?,
        cors_origins: a.cors_origins.clone(),
        log_json: a.log_format == "json",
        workers: a
            .workers
            .unwrap_or_else(|| std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1))
            .max(1),
        max_queued: a.max_queued,
        max_jobs_per_client: a.max_jobs_per_client,
        job_retention: seconds("job-retention-hours", a.job_retention_hours, 0.0, 1e6, 3600.0)?,
        admin_token: a.admin_token.clone().filter(|t| !t.is_empty()),
        database_url: a.database_url.clone().filter(|u| !u.is_empty()),
        spool_dir: a.spool_dir.clone(),
        job_lease: seconds("job-lease-secs", a.job_lease_secs, 1.0, 86400.0, 1.0)?,
        shutdown_grace: seconds("shutdown-grace", a.shutdown_grace, 0.0, 86400.0, 1.0)?,
        job_max_attempts: match a.job_max_attempts {
            1..=100 => a.job_max_attempts,
            n => return Err(format!("--job-max-attempts {n}: expected 1 to 100")),
        },
        job_retry_backoff: seconds("job-retry-secs", a.job_retry_secs, 0.0, 300.0, 1.0)?,
        post_budget: a.budget.budget()?,
        post_threads: kinepost::post::threads(Some(a.post_threads)).map_err(|e| format!("--post-{e}"))?,
        job_threads: match a.job_threads {
            0 => 0,
            n => kinepost::post::threads(Some(n)).map_err(|e| format!("--job-{e}"))?,
        },
    };
    let rt = tokio::runtime::Runtime::new().map_err(|e| e.to_string())?;
    let r = rt.block_on(kinepost::http::serve(cfg));
    // Dropping the runtime would wait for every blocking task (a job mid-run) to end; the queue
    // is durable, so what still runs resumes on the next start.
    rt.shutdown_timeout(std::time::Duration::from_secs(2));
    r
}

fn run(cli: Cli) -> Result<(), Failure> {
    if let Command::Lint { input, verbose } = &cli.command {
        return Ok(lint(input, *verbose)?);
    }
    if let Command::Serve(a) = &cli.command {
        return Ok(serve(&cli, a)?);
    }
    let lib = library(&cli)?;
    match cli.command {
        Command::Lint { .. } | Command::Serve(_) => unreachable!("handled above"),
        Command::Generate {
            machine,
            points,
            seed,
            tool_length,
        } => {
            let p = lib.get(&machine).map_err(|e| e.to_string())?;
            let out = std::io::stdout().lock();
            let mut w = std::io::BufWriter::with_capacity(1 << 16, out);
            kinepost::testgen::write_path(
                &p.machine,
                points,
                seed,
                tool_length.unwrap_or(p.machine.default_tool_length),
                &mut w,
            )
            .and_then(|_| std::io::Write::flush(&mut w))
            .map_err(|e| e.to_string().into())
        }
        Command::Verify {
            machine,
            cl,
            nc,
            mode,
            setup,
            tolerance,
            cl_units,
            tool_table,
        } => {
            use kinepost::post::verify;
            let p = lib.get(&machine).map_err(|e| e.to_string())?;
            let m = &p.machine;
            let tool_table = match &tool_table {
                Some(f) => Some(std::sync::Arc::new(
                    machines::tools::load_tool_table(f).map_err(|e| e.to_string())?,
                )),
                None => lib.tools(&machine),
            };
            let o = verify::VerifyOptions {
                mode: mode.into(),
                setup: setup.setup(m)?,
                tolerance: tolerance.unwrap_or(if m.units == Units::Mm { 0.01 } else { 0.0004 }),
                angle_tolerance_deg: 0.01,
                cl_units: cl_units.map(Units::from),
                cl_tool_length: setup.tool_length.is_none(),
                tool_table,
            };
            let rep = verify::verify(open_input(&cl)?, open_input(&nc)?, m, &o).map_err(|e| e.to_string())?;
            say!("{}", serde_json::to_string_pretty(&rep).map_err(|e| e.to_string())?);
            if rep.ok {
                Ok(())
            } else {
                Err(Failure::Written(format!(
                    "{} of {} CL points matched, {} blocks off their CL segment",
                    rep.matched, rep.cl_points, rep.off_segment_blocks
                )))
            }
        }
        Command::Post(a) => {
            let machine = a.settings.machine.as_deref().unwrap_or_default();
            let p = lib.get(machine).map_err(|e| e.to_string())?;
            let standing = lib.tools(machine).map(|t| (t, "THE MACHINE'S TOOL TABLE".to_string()));
            post_cmd(&p, standing, &lib.dialects, &a)
        }
        Command::Dialects { json } => {
            for d in lib.dialects.iter() {
                let events: Vec<&str> = kinepost::nc::templates::EVENTS.iter().copied().filter(|e| d.templates.has(e)).collect();
                if json {
                    say!("{}", json!({"id": d.name, "title": d.title, "templates": events, "notes": d.notes}));
                } else {
                    say!("{:<16} {:<34} {}", d.name, d.title, if events.is_empty() { String::new() } else { format!("templates: {}", events.join(", ")) });
                }
            }
            Ok(())
        }
        Command::Machines { action: Some(a), .. } => {
            let dir = cli.machines.clone().unwrap_or_else(machines::default_dir);
            Ok(machines_cmd(&lib, &dir, &a)?)
        }
        Command::Machines { json, action: None } => {
            for p in lib.iter() {
                let m = &p.machine;
                if json {
                    let v = json!({"id": m.id, "name": m.name, "kinematics": m.kinematics_kind(),
                        "controller": m.controller, "units": m.units.as_str()});
                    say!("{v}");
                } else {
                    say!(
                        "{:<22} {:<14} {:<11} {:<5} {}",
                        m.id,
                        m.kinematics_kind(),
                        m.controller,
                        m.units.as_str(),
                        m.name
                    );
                }
            }
            Ok(())
        }
        Command::Fk { machine, setup, words } => {
            let p = lib.get(&machine).map_err(|e| e.to_string())?;
            let m = &p.machine;
            let setup = setup.setup(m)?;
            let joints = parse_words(m, &words)?;
            let pose = kinematics::fk(m, &joints, &setup);
            say!("{}", json!({"tip": pose.tip.as_slice(), "axis": pose.axis.as_slice()}));
            Ok(())
        }
        Command::Ik {
            machine,
            setup,
            units,
            pose,
        } => {
            let p = lib.get(&machine).map_err(|e| e.to_string())?;
            let m = &p.machine;
            let setup = setup.setup(m)?;
            let f = units.map_or(1.0, |u| Units::from(u).factor_to(m.units));
            let pose = Pose {
                tip: Vec3::new(pose[0], pose[1], pose[2]) * f,
                axis: Vec3::new(pose[3], pose[4], pose[5]),
            };
            let sols = kinematics::ik(m, &pose, &setup, &IkOptions::default())
                .map_err(|e| format!("{machine}: pose unreachable: {e}"))?;
            let list: Vec<Value> = sols.iter().map(|s| solution_json(m, s)).collect();
            say!("{}", json!({ "solutions": list }));
            Ok(())
        }
    }
}

fn post_cmd(
    p: &machines::Profile,
    standing: Option<(std::sync::Arc<machines::tools::ToolTable>, String)>,
    dialects: &machines::dialects::Dialects,
    a: &PostArgs,
) -> Result<(), Failure> {
    let m = &p.machine;
    use kinepost::post::{self, Sink};
    use std::io::Write;
    let mut settings = a.settings.clone();
    if a.canned_cycles {
        settings.cycles = Some("canned".into());
    }
    if a.tilted_planes {
        settings.planes = Some("tilted".into());
    }
    if let Some(f) = &a.tool_table {
        // Read and checked here, so that an error names the file.
        machines::tools::load_tool_table(f).map_err(|e| e.to_string())?;
        settings.tool_table = Some(machines::read_text(f).map_err(|e| format!("{}: {e}", f.display()))?);
    }
    let mut o = settings.profile_options_with(p, standing, &|id| dialects.get(id)).map_err(|e| e.to_string())?;
    o.threads = post::threads(Some(a.threads))?;
    o.budget = a.budget.budget()?;
    o.header.push(format!("DATE {} UTC", utc_now()));
    o.header.push(format!(
        "SOURCE {}",
        std::path::Path::new(&a.input)
            .file_name()
            .and_then(|f| f.to_str())
            .unwrap_or("-")
    ));
    if o.setup_offsets && a.input != "-" {
        // Input that is no CL is refused by the post itself, with its line.
        o.header.extend(post::setups::header_lines(open_input(&a.input)?, m, &o).unwrap_or_default());
    }
    let out: Box<dyn Write> = match &a.output {
        Some(p) => Box::new(std::fs::File::create(p).map_err(|e| format!("{}: {e}", p.display()))?),
        None => Box::new(std::io::stdout().lock()),
    };
    let diag: Option<Box<dyn Write>> = match &a.diagnostics {
        Some(p) => Some(Box::new(
            std::fs::File::create(p).map_err(|e| format!("{}: {e}", p.display()))?,
        )),
        None => None,
    };
    let mut sink = kinepost::output::FileSink::new(out, diag);
    sink.echo_warnings = true;
    let res = post_input(&a.input, m, &o, &mut sink)?;
    // Input that is no CL is refused before the program begins: there is nothing to mark.
    if let Err(e) = &res
        && !matches!(e, post::Error::NotCl(_))
    {
        // Cut short: the file says so where the machinist reads it.
        let _ = sink.line(&o.dialect.comment_line(&format!("KINEPOST: NOT FIT TO RUN, CUT SHORT: {e}")), None);
    }
    sink.flush().map_err(|e| e.to_string())?;
    let s = res.map_err(|e| e.to_string())?;
    let rot: Vec<String> = m
        .rotaries
        .iter()
        .filter_map(|r| {
            s.axes.get(&r.name).map(|st| {
                format!(
                    "{} travel {:.1}° max step {:.1}°",
                    r.name,
                    st.travel.unwrap_or(0.0),
                    st.largest_step.unwrap_or(0.0)
                )
            })
        })
        .collect();
    if s.smoothed_blocks > 0 {
        eprintln!(
            "kinepost: singular tolerance {}°: {} blocks held the free rotary, {:.1}° of travel saved, largest deviation {:.4}°",
            settings.singular_tolerance.unwrap_or(0.0), s.smoothed_blocks, s.smoothing_travel_saved_deg, s.smoothing_max_deviation_deg
        );
    }
    eprintln!(
        "kinepost: {} CL points -> {} blocks ({} inserted); {}FK replay max {:.2e} {} / {:.2e}°; {} errors, {} warnings; est. {:.1} min",
        s.cl_points,
        s.blocks,
        s.inserted_blocks,
        // No rotary moved (or none on the machine): nothing to list.
        if rot.is_empty() {
            String::new()
        } else {
            format!("{}; ", rot.join(", "))
        },
        s.max_tip_deviation,
        m.units.as_str(),
        s.max_axis_deviation_deg,
        s.errors,
        s.warnings,
        s.cycle_time_s / 60.0
    );
    // Each tool's length and its source, where more than one length could have applied.
    if s.tools.len() > 1 || o.tool_table.is_some() {
        let t: Vec<String> = s
            .tools
            .iter()
            .map(|t| {
                let l = format!("{:.*}", if m.units == Units::Mm { 3 } else { 4 }, t.length);
                match t.tool {
                    Some(n) => format!("T{n} {l} ({})", t.from.as_str()),
                    None => format!("no tool {l} ({})", t.from.as_str()),
                }
            })
            .collect();
        eprintln!("kinepost: tool lengths: {}", t.join(", "));
    }
    if s.errors > 0 {
        return Err(Failure::Written(format!(
            "the program has {} error diagnostics: written, but not fit to run as it is",
            s.errors
        )));
    }
    Ok(())
}

fn parse_words(m: &kinematics::Machine, words: &[String]) -> Result<Joints, String> {
    let mut j = Joints::default();
    for w in words {
        let (name, val) = w
            .split_once('=')
            .ok_or_else(|| format!("{w:?}: expected AXIS=value, e.g. B=30"))?;
        let v: f64 = val.trim().parse().map_err(|_| format!("{w:?}: {val:?} is not a number"))?;
        if !v.is_finite() {
            return Err(format!("{w:?}: value must be finite"));
        }
        let name = name.trim().to_ascii_uppercase();
        match name.as_str() {
            "X" | "Y" | "Z" => {
                let i = (name.as_bytes()[0] - b'X') as usize;
                if m.linears[i].is_none() {
                    return Err(format!("{}: this machine has no {name} axis", m.id));
                }
                j.linear[i] = v;
            }
            _ => {
                let c = name.chars().next().filter(|_| name.len() == 1);
                let i = c
                    .and_then(|c| m.rotary_index(c))
                    .ok_or_else(|| format!("{}: no axis {name:?} (axes: {:?})", m.id, m.axis_names()))?;
                j.rotary[i] = v.to_radians();
            }
        }
    }
    Ok(j)
}
