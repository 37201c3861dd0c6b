//! End to end on a generated 5-axis file: read, IK, plan, linearize, format, write (to a null
//! sink), one core. `cargo bench --bench post [-- POINTS MACHINE MODE]`. Prints points per second
//! and peak RSS (VmHWM), which must not grow with the input.

use kinepost::machines::Library;
use kinepost::post::{self, Mode, Options, TextSink};
use std::time::Instant;

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
    }
}
