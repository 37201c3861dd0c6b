//! Hostile input: no panic, no hang, no unbounded allocation, whatever the bytes. The stable
//! stand-in for fuzzing (cargo-fuzz needs nightly): proptest over arbitrary and mutated inputs,
//! plus the specific monsters.

use crate::common;

use kinepost::cl::{Event, Reader};
use kinepost::diag::{Code, Severity};
use kinepost::machines::parse_profile;
use kinepost::post::{self, Options, Sink};
use proptest::prelude::*;

struct Null(usize);
impl Sink for Null {
    fn line(&mut self, t: &str, _: Option<&post::BlockInfo>) -> Result<(), kinepost::post::Stop> {
        self.0 += t.len();
        Ok(())
    }
}

fn read_all(bytes: &[u8]) -> (usize, Vec<kinepost::diag::Diagnostic>) {
    let mut n = 0;
    let mut d = Vec::new();
    for ev in Reader::new(bytes) {
        match ev.unwrap() {
            Event::Statement(_) => n += 1,
            Event::Diagnostic(x) => d.push(x),
        }
    }
    (n, d)
}

fn post_all(machine: &str, bytes: &[u8]) -> post::Summary {
    let lib = common::library();
    let m = lib.get(machine).unwrap().machine.clone();
    post::post(bytes, &m, &Options::new(&m), &mut Null(0)).unwrap()
}

const SEED: &str = include_str!("../data/nx_clsf_mech491_contour_chamfer_inch_5ax.cls");

proptest! {
    #![proptest_config(ProptestConfig::with_cases(std::env::var("KINEPOST_PROPTEST_SCALE").ok().and_then(|s| s.parse::<u32>().ok()).unwrap_or(1) * 300))]

    #[test]
    fn the_reader_survives_any_bytes(bytes in prop::collection::vec(any::<u8>(), 0..4000)) {
        let _ = read_all(&bytes);
    }

    #[test]
    fn the_engine_survives_mutated_real_files(cut in 0usize..18000, len in 0usize..200, junk in prop::collection::vec(any::<u8>(), 0..64), machine in prop::sample::select(vec!["haas-umc750", "dmu-nutating-45", "propeller-3r2l", "vmc-3axis"])) {
        let mut b = SEED.as_bytes()[..SEED.len().min(3000)].to_vec();
        let at = cut % b.len().max(1);
        let end = (at + len).min(b.len());
        b.splice(at..end, junk);
        let lib = common::library();
        let m = lib.get(machine).unwrap().machine.clone();
        // Junk at the start can make it no CL at all (a UTF-16 mark): refused, not a panic.
        match post::post(&b[..], &m, &Options::new(&m), &mut Null(0)) {
            Ok(_) | Err(post::Error::NotCl(_)) => {}
            Err(e) => panic!("{e}"),
        }
    }

    #[test]
    fn the_engine_survives_hostile_numbers(v in prop::collection::vec(prop::sample::select(vec!["1e999", "-1e999", "NaN", "inf", "1e308", "-0", "0", ".", "-", "1e-320", "123456789012345678901234567890", "7"]), 6)) {
        let cl = format!("UNITS/MM\nFEDRAT/{},MMPM\nGOTO/{},{},{},{},{},{}\nGOTO/1,2,3\n", v[0], v[0], v[1], v[2], v[3], v[4], v[5]);
        let _ = post_all("spinner-u5-620", cl.as_bytes());
    }

    #[test]
    fn the_profile_loader_survives_mutated_profiles(cut in 0usize..900, len in 0usize..40, junk in "[ -~\n]{0,40}") {
        let text = include_str!("../../machines/htm50200-horizontal.toml");
        let mut s = text.to_string();
        let at = cut.min(s.len());
        let end = (at + len).min(s.len());
        if s.is_char_boundary(at) && s.is_char_boundary(end) {
            s.replace_range(at..end, &junk);
        }
        let _ = parse_profile(&s, "fuzz.toml", None);
    }
}

#[test]
fn monsters() {
    // A 10 MB line: reported and skipped; the next record still read.
    let mut big = vec![b'G'; 10 << 20];
    big.extend_from_slice(b"\nGOTO/1,2,3\n");
    let (n, d) = read_all(&big);
    assert_eq!(n, 1);
    assert!(d.iter().any(|x| x.code == Code::LineTooLong && x.line == Some(1)));
    // A deep continuation chain: 200 000 lines of `$`; bounded, then reported.
    let chain = "GOTO/1,$\n".repeat(200_000) + "2,3\n";
    let (_, d) = read_all(chain.as_bytes());
    assert!(
        d.iter().any(|x| x.code == Code::LineTooLong),
        "an endless statement is cut, not accumulated"
    );
    // Truncated UTF-8 and binary garbage: warnings and errors, never a panic.
    let (_, d) = read_all(b"GOTO/1,2,\xe2\x82\n\x00\x01\x02\xff\xfe\nGOTO/1,2,3\n");
    assert!(d.iter().any(|x| x.code == Code::InvalidUtf8));
    // 1e999 is not a coordinate.
    let s = post_all("vmc-3axis", b"UNITS/MM\nGOTO/1e999,0,0\nGOTO/1,2,3\n");
    assert_eq!((s.cl_points, s.errors), (1, 1));
    // A zero tool axis is an error; an unnormalized one a warning; a GOTO before any units a warning.
    let mut sink = Null(0);
    let lib = common::library();
    let m = lib.get("spinner-u5-620").unwrap().machine.clone();
    let s = post::post(&b"GOTO/1,2,3,0,0,0\nGOTO/1,2,3,0,0,2\n"[..], &m, &Options::new(&m), &mut sink).unwrap();
    assert_eq!(s.counts.get("bad_record"), Some(&1));
    assert_eq!(s.counts.get("axis_normalized"), Some(&1));
    assert_eq!(s.counts.get("units_assumed"), Some(&1));
    assert!(s.warnings >= 2 && s.errors == 1);
    let _ = Severity::Info;
}
