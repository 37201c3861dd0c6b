//! The floors: what a program that only turns GOTO lines into words costs, the yardstick the
//! post is measured beside (shared by `benches/post.rs`, in process, and `examples/floor.rs`, a
//! whole process beside `kinepost post`).
#![allow(dead_code)] // each user takes part of it

use std::io::{Read, Write};

/// Every GOTO line's six numbers, parsed the tuned way (SIMD line splitting, fast_float2).
pub fn gotos(path: &std::path::Path, mut each: impl FnMut([f64; 6])) {
    let mut f = std::fs::File::open(path).unwrap();
    let mut buf = vec![0u8; 1 << 16];
    let mut have = 0usize;
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
            each(v);
        }
        buf.copy_within(start..have, 0);
        have -= start;
    }
}

/// `.fff ` for a fraction `f` < 1000 (both floors' words).
#[inline(always)]
pub fn point3(f: u64) -> [u8; 5] {
    [
        b'.',
        b'0' + (f / 100) as u8,
        b'0' + (f / 10 % 10) as u8,
        b'0' + (f % 10) as u8,
        b' ',
    ]
}

/// The floor: GOTO lines to `X Y Z B C` words, nothing else. Returns the lines converted. (Its
/// words are written as they were when this yardstick was first measured: 3 decimals each, the
/// divisions by constants.)
pub fn floor(path: &std::path::Path, out: impl Write) -> u64 {
    let mut w = std::io::BufWriter::with_capacity(1 << 16, out);
    let mut o: Vec<u8> = Vec::with_capacity(128);
    let mut n = 0u64;
    gotos(path, |v| {
        o.clear();
        for (k, x) in v.iter().take(5).enumerate() {
            o.push(b"XYZBC"[k]);
            let r = (x * 1000.0).round() as i64;
            if r < 0 {
                o.push(b'-');
            }
            let a = r.unsigned_abs();
            o.extend_from_slice(itoa::Buffer::new().format(a / 1000).as_bytes());
            o.extend_from_slice(&point3(a % 1000));
        }
        o.push(b'\n');
        w.write_all(&o).unwrap();
        n += 1;
    });
    n
}

/// The floor written plainly: `read_line`, `str::parse` for the six numbers and the words by
/// integer formatting (no SIMD parsing, no `format!`): 6.2-7.7 M lines/s on this VM, the rate the
/// issue gives its floor "here".
pub fn plain_floor(path: &std::path::Path, out: impl Write) -> u64 {
    use std::io::BufRead;
    let mut r = std::io::BufReader::with_capacity(1 << 16, std::fs::File::open(path).unwrap());
    let mut w = std::io::BufWriter::with_capacity(1 << 16, out);
    let (mut line, mut n) = (String::new(), 0u64);
    let mut ib = itoa::Buffer::new();
    loop {
        line.clear();
        if r.read_line(&mut line).unwrap() == 0 {
            break;
        }
        let Some(rest) = line.trim_end().strip_prefix("GOTO/") else {
            continue;
        };
        let mut v = [0.0f64; 6];
        for (x, s) in v.iter_mut().zip(rest.split(',')) {
            *x = s.trim().parse().unwrap_or(0.0);
        }
        for (k, x) in v.iter().take(5).enumerate() {
            let r = (x * 1000.0).round() as i64;
            w.write_all(&[b"XYZBC"[k]]).unwrap();
            if r < 0 {
                w.write_all(b"-").unwrap();
            }
            let a = r.unsigned_abs();
            w.write_all(ib.format(a / 1000).as_bytes()).unwrap();
            w.write_all(&point3(a % 1000)).unwrap();
        }
        w.write_all(b"\n").unwrap();
        n += 1;
    }
    n
}

