//! The floor as a whole process, to time beside `kinepost post` from outside (start-up and
//! writing included): `floor FILE [plain|tuned] > /dev/null` turns each GOTO line of FILE into
//! five words on stdout and prints the lines converted on stderr. `plain` (the default):
//! `read_line`, `str::parse`, integer words, the floor; `tuned`: SIMD line splitting,
//! fast_float2, itoa. Not part of the binary (`cargo build --release --example floor`).

#[path = "../benches/floors/mod.rs"]
mod floors;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(path) = args.first() else {
        eprintln!("usage: floor FILE [plain|tuned]");
        std::process::exit(2);
    };
    let out = std::io::stdout().lock();
    let n = match args.get(1).map(String::as_str) {
        None | Some("plain") => floors::plain_floor(path.as_ref(), out),
        Some("tuned") => floors::floor(path.as_ref(), out),
        Some(x) => {
            eprintln!("floor: {x}: expected plain or tuned");
            std::process::exit(2);
        }
    };
    eprintln!("floor: {n} lines");
}
