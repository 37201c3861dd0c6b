//! End to end on a generated 5-axis file: read, IK, plan, linearize, format, write (to a null
//! sink), one core. `cargo bench --bench post [-- POINTS MACHINE]` runs TCP, then joint mode, and
//! prints points per second and peak RSS (VmHWM), which must not grow with the input.
//!
//! Then the same file through the floor: a loop that only splits lines, parses the six numbers of
//! each GOTO and writes five words (what the issue calls the floor to approach). This VM's speed
//! varies by a third from day to day and by half within an hour; kinepost's time over the
//! floor's, measured in the same minute, varies less (4.5–5.8× over five runs in one hour while
//! kinepost's own time ranged 1.06–1.63 s), so that ratio is the figure to compare across days
//! (2 M/s against the 6.5 M/s floor is 3.25×).

use kinepost::machines::Library;
use kinepost::post::{self, Mode, Options, TextSink};
use std::io::{Read, Write};
use std::time::Instant;

/// The floor: GOTO lines to `X Y Z B C` words, nothing else. Returns the lines converted.
fn floor(path: &std::path::Path) -> u64 {
    let mut f = std::fs::File::open(path).unwrap();
    let mut w = std::io::BufWriter::with_capacity(1 << 16, std::io::sink());
    let mut buf = vec![0u8; 1 << 16];
    let (mut have, mut n) = (0usize, 0u64);
    let mut o: Vec<u8> = Vec::with_capacity(128);
    loop {
        let got = f.read(&mut buf[have..]).unwrap();
        if got == 0 {
            break;
        }
        have += got;
        let mut start = 0;
        while let Some(e) = memchr::memchr(b'\n', &buf[start..have]) {
            let line = &buf[start..start + e];
            start += e + 1;
            let Some(mut rest) = line.strip_prefix(b"GOTO/") else {
                continue;
            };
            let mut v = [0.0f64; 6];
            for x in v.iter_mut() {
                let (y, used) = fast_float2::parse_partial::<f64, _>(rest).unwrap_or((0.0, 0));
                *x = y;
                rest = &rest[(used + 1).min(rest.len())..];
            }
            o.clear();
            for (k, x) in v.iter().take(5).enumerate() {
                o.push(b"XYZBC"[k]);
                let r = (x * 1000.0).round() as i64;
                if r < 0 {
                    o.push(b'-');
                }
                let a = r.unsigned_abs();
                o.extend_from_slice(itoa::Buffer::new().format(a / 1000).as_bytes());
                let f = a % 1000;
                o.extend_from_slice(&[
                    b'.',
                    b'0' + (f / 100) as u8,
                    b'0' + (f / 10 % 10) as u8,
                    b'0' + (f % 10) as u8,
                    b' ',
                ]);
            }
            o.push(b'\n');
            w.write_all(&o).unwrap();
            n += 1;
        }
        buf.copy_within(start..have, 0);
        have -= start;
    }
    n
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
    for mode in [Mode::Tcp, Mode::Joint] {
        let mut o = Options::new(&m);
        o.mode = mode;
        let input = std::io::BufReader::with_capacity(1 << 16, std::fs::File::open(&path).unwrap());
        let mut sink = TextSink(std::io::BufWriter::with_capacity(1 << 16, std::io::sink()));
        let t = Instant::now();
        let s = post::post(input, &m, &o, &mut sink).unwrap();
        let dt = t.elapsed().as_secs_f64();
        println!(
            "{id} {mode:?}: {} CL points ({:.1} MB) -> {} blocks in {dt:.3} s: {:.3} M points/s; peak RSS {} kB (before: {rss0} kB); FK replay max {:.1e}",
            s.cl_points,
            bytes as f64 / 1e6,
            s.blocks,
            s.cl_points as f64 / dt / 1e6,
            peak_rss_kb(),
            s.max_tip_deviation
        );
        joint_s = dt;
    }
    let t = Instant::now();
    let n = floor(&path);
    let dt = t.elapsed().as_secs_f64();
    println!(
        "floor (parse six numbers, write five words): {n} lines in {dt:.3} s: {:.3} M lines/s; kinepost joint takes {:.2}x the floor (2 M/s on the issue's 6.5 M/s floor: 3.25x)",
        n as f64 / dt / 1e6,
        joint_s / dt
    );
}
