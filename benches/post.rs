//! End to end on a generated 5-axis file: read, IK, plan, linearize, format, write (to a null
//! sink), one core. `cargo bench --bench post [-- POINTS MACHINE]` runs TCP, then joint mode, then
//! joint on two threads (`Options::threads`), and prints points per second and peak RSS (VmHWM),
//! which must not grow with the input. The yardsticks below are beside the one-thread joint run.
//!
//! Then the same file through three yardsticks, measured in the same minute (this VM's speed
//! varies by a third from day to day and by half within an hour, ratios measured together vary
//! less):
//! - the floor: a loop that only splits lines, parses the six numbers of each GOTO and writes
//!   five words, tuned (SIMD line splitting, fast_float2, itoa);
//! - the plain floor: the same written plainly (`read_line`, `str::parse`, integer words). It does
//!   about 6.5-7.7 M lines/s here, the rate the issue gives its floor "here" (a tuned floor is
//!   1.5-1.8x that), so the 2 M points/s target is 3.25x the plain floor;
//! - the essentials: the tuned floor plus what no correct postprocessor can skip (IK, a solution,
//!   the words' FK replay), a lower bound for the engine without planning, linearization, feed,
//!   diagnostics and statistics.

use kinepost::machines::Library;
use kinepost::post::{self, Mode, Options, TextSink};
use std::io::Write;

#[path = "floors/mod.rs"]
mod floors;
use floors::{floor, gotos, plain_floor};
use std::time::Instant;

/// `X Y Z B C` words of `v`, each rounded to `scale` (10^decimals), into `o`: returns the
/// integers written.
fn words(o: &mut Vec<u8>, v: &[f64; 5], scale: [u64; 5]) -> [i64; 5] {
    o.clear();
    let mut out = [0; 5];
    for k in 0..5 {
        let r = (v[k] * scale[k] as f64).round() as i64;
        out[k] = r;
        o.push(b"XYZBC"[k]);
        if r < 0 {
            o.push(b'-');
        }
        let a = r.unsigned_abs();
        o.extend_from_slice(itoa::Buffer::new().format(a / scale[k]).as_bytes());
        o.push(b'.');
        // The fraction's digits, zero-padded: those of scale + fraction after its leading 1.
        o.extend_from_slice(&itoa::Buffer::new().format(scale[k] + a % scale[k]).as_bytes()[1..]);
        o.push(b' ');
    }
    o.push(b'\n');
    out
}

/// The least a correct postprocessor does per point, as a lower bound for the engine: the floor's
/// parsing and writing, plus the tool axis normalised, every IK solution, the one nearest the
/// last taken (rotaries the short way), its words rounded and replayed through FK. No planning
/// window, linearization check, feed, diagnostics or statistics. Returns the largest replay
/// deviation (mm), so that none of it is optimised away.
fn essentials(path: &std::path::Path, m: &kinepost::kinematics::Machine, tool_length: f64) -> f64 {
    use kinepost::kinematics::{IkOptions, Pose, Setup, Solutions, Vec3, fk, ik_into};
    let setup = Setup::new(tool_length, Vec3::zeros());
    let opt = IkOptions::default();
    let mut sols = Solutions::new();
    let mut w = std::io::BufWriter::with_capacity(1 << 16, std::io::sink());
    let mut o: Vec<u8> = Vec::with_capacity(128);
    let mut last = [0.0f64; 3];
    let mut worst = 0.0f64;
    gotos(path, |v| {
        let axis = Vec3::new(v[3], v[4], v[5]);
        let pose = Pose {
            tip: Vec3::new(v[0], v[1], v[2]),
            axis: axis / axis.norm(),
        };
        if ik_into(m, &pose, &setup, &opt, &mut sols).is_err() {
            return;
        }
        let step = |s: &kinepost::kinematics::Solution| -> f64 {
            (0..3)
                .map(|i| kinepost::kinematics::wrap(s.joints.rotary[i] - last[i]).abs())
                .sum()
        };
        let Some(s) = sols.iter().min_by(|a, b| step(a).total_cmp(&step(b))) else {
            return;
        };
        let mut j = s.joints;
        last = j.rotary;
        let scale = [1000, 1000, 1000, 10_000, 10_000];
        let r = words(
            &mut o,
            &[
                j.linear[0],
                j.linear[1],
                j.linear[2],
                j.rotary[0].to_degrees(),
                j.rotary[1].to_degrees(),
            ],
            scale,
        );
        w.write_all(&o).unwrap();
        for k in 0..3 {
            j.linear[k] = r[k] as f64 / scale[k] as f64;
        }
        for k in 0..2 {
            j.rotary[k] = (r[k + 3] as f64 / scale[k + 3] as f64).to_radians();
        }
        worst = worst.max((fk(m, &j, &setup).tip - pose.tip).norm());
    });
    worst
}

fn peak_rss_kb() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse().ok())
        })
        .unwrap_or(0)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).filter(|a| !a.starts_with("--")).collect();
    let points: usize = args.first().and_then(|a| a.parse().ok()).unwrap_or(1_000_000);
    let id = args.get(1).cloned().unwrap_or_else(|| "spinner-u5-620".into());
    let lib = Library::load_dir(std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/machines"))).unwrap();
    let m = lib.get(&id).unwrap().machine.clone();
    let path = std::env::temp_dir().join(format!("kinepost-bench-{id}-{points}.cls"));
    if !path.exists() {
        let mut f = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
        kinepost::testgen::write_path(&m, points, 1, m.default_tool_length, &mut f).unwrap();
    }
    let bytes = std::fs::metadata(&path).unwrap().len();
    let rss0 = peak_rss_kb();
    let mut joint_s = 0.0;
    for (mode, threads) in [(Mode::Tcp, 1), (Mode::Joint, 1), (Mode::Joint, 2)] {
        let mut o = Options::new(&m);
        o.mode = mode;
        o.threads = threads;
        let input = std::io::BufReader::with_capacity(1 << 16, std::fs::File::open(&path).unwrap());
        let mut sink = TextSink(std::io::BufWriter::with_capacity(1 << 16, std::io::sink()));
        let t = Instant::now();
        let s = post::post(input, &m, &o, &mut sink).unwrap();
        let dt = t.elapsed().as_secs_f64();
        println!(
            "{id} {mode:?}, {threads} thread(s): {} CL points ({:.1} MB) -> {} blocks in {dt:.3} s: {:.3} M points/s; peak RSS {} kB (before: {rss0} kB); FK replay max {:.1e}",
            s.cl_points,
            bytes as f64 / 1e6,
            s.blocks,
            s.cl_points as f64 / dt / 1e6,
            peak_rss_kb(),
            s.max_tip_deviation
        );
        if (mode, threads) == (Mode::Joint, 1) {
            joint_s = dt;
        }
    }
    let (n, dt) = timed(|| floor(&path, std::io::sink()));
    println!(
        "floor (parse six numbers, write five words): {n} lines in {dt:.3} s: {:.3} M lines/s; kinepost joint takes {:.2}x the floor (2 M/s on the issue's 6.5 M/s floor: 3.25x)",
        n as f64 / dt / 1e6,
        joint_s / dt
    );
    let (n, dp) = timed(|| plain_floor(&path, std::io::sink()));
    println!(
        "plain floor (read_line, str::parse, integer words): {n} lines in {dp:.3} s: {:.3} M lines/s; kinepost joint takes {:.2}x it",
        n as f64 / dp / 1e6,
        joint_s / dp
    );
    let (worst, de) = timed(|| essentials(&path, &m, m.default_tool_length));
    println!(
        "essentials (floor + IK, nearest solution, FK replay of the words): {de:.3} s: {:.2}x the floor; kinepost joint takes {:.2}x the essentials (replay max {worst:.1e} mm)",
        de / dt,
        joint_s / de
    );
}

/// What `f` returns and the seconds it took.
fn timed<T>(f: impl FnOnce() -> T) -> (T, f64) {
    let t = Instant::now();
    let v = f();
    (v, t.elapsed().as_secs_f64())
}
