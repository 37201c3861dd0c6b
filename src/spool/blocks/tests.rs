use super::*;
use crate::diag::{Code, Severity};
use crate::output::FileSink;
use crate::post::{Sink, Summary};
use proptest::prelude::*;

fn block(n: u64, source_line: Option<u32>, joints: [Option<f64>; 6], diagnostics: Vec<Diagnostic>) -> BlockInfo {
    BlockInfo {
        n,
        source_line,
        joints: AxisWords(joints),
        diagnostics,
        rapid: false,
        tip: [0.0; 3],
        axis: [0.0, 0.0, 1.0],
        time_s: 0.0,
    }
}

/// One program into the CLI's files (NC, NDJSON) and into NC and a block store, the store's
/// NDJSON rebuilt: `(cli ndjson, rebuilt)`.
fn both(lines: &[(String, Option<BlockInfo>)], notes: &[(usize, Diagnostic)]) -> (Vec<u8>, Vec<u8>) {
    let mut cli = FileSink::new(Vec::new(), Some(Vec::new()));
    let mut store = BlockWriter::new(Vec::new()).unwrap();
    let mut nc = Vec::new();
    for (i, (text, b)) in lines.iter().enumerate() {
        for (_, d) in notes.iter().filter(|(at, _)| *at == i) {
            cli.diagnostic(d).unwrap();
            store.record(&Record::Diagnostic { diagnostic: d }).unwrap();
        }
        cli.line(text, b.as_ref()).unwrap();
        store.line(text, b.as_ref()).unwrap();
        nc.extend_from_slice(text.as_bytes());
        nc.push(b'\n');
    }
    let s = Summary {
        blocks: lines.len() as u64,
        ..Summary::default()
    };
    cli.summary(&s).unwrap();
    store.record(&Record::Summary { summary: &s }).unwrap();
    let (_, nd) = cli.into_inner().unwrap();
    let store = store.into_inner();
    let mut out = Vec::new();
    Ndjson::new(Some(&store[..]), Some(&nc[..]), None)
        .unwrap()
        .read_to_end(&mut out)
        .unwrap();
    (nd.unwrap(), out)
}

fn value() -> impl Strategy<Value = f64> {
    prop_oneof![
        4 => -1000.0..1000.0f64,
        1 => Just(0.0),
        1 => Just(-0.0),
        1 => prop::num::f64::ANY,
        1 => (-100i64..100).prop_map(|k| k as f64 * 0.001),
    ]
}

proptest! {
    /// Any blocks, joints (any bits), numbering, CL lines, other lines and diagnostics: the
    /// same bytes as the CLI's NDJSON.
    #[test]
    fn the_rebuilt_ndjson_is_the_clis(
        rows in prop::collection::vec((
            prop::array::uniform6(prop::option::weighted(0.9, value())),
            0u8..16,
            0u32..5000,
        ), 1..300),
    ) {
        let mut lines = Vec::new();
        let mut n = 0;
        let mut notes = Vec::new();
        let mut last = 0u32;
        for (i, (joints, pick, line)) in rows.iter().enumerate() {
            let text = format!("G1 X{i} \"quoted\" é");
            match pick {
                0 => lines.push((format!("(COMMENT {i})"), None)),
                1 => {
                    n += 3;
                    lines.push((text, Some(block(n, None, *joints, vec![]))));
                }
                2 => {
                    n += 1;
                    let d = Diagnostic::new(Code::Unwind, Severity::Warning, Some(*line), "turned");
                    lines.push((text, Some(block(n, Some(*line), *joints, vec![d]))));
                }
                3 => notes.push((lines.len(), Diagnostic::new(Code::Unwind, Severity::Info, None, format!("note {i}")))),
                4 => {
                    n += 1;
                    lines.push((format!("G1 X{i}\nY1"), Some(block(n, Some(*line), *joints, vec![]))));
                }
                5..=9 => {
                    // The CL line after the last block's, or the same.
                    n += 1;
                    last = last.wrapping_add((pick & 1) as u32);
                    lines.push((text, Some(block(n, Some(last), *joints, vec![]))));
                }
                _ => {
                    n += 1;
                    last = *line;
                    lines.push((text, Some(block(n, Some(*line), *joints, vec![]))));
                }
            }
        }
        let (cli, rebuilt) = both(&lines, &notes);
        prop_assert_eq!(String::from_utf8(cli).unwrap(), String::from_utf8(rebuilt).unwrap());
    }
}

#[test]
fn a_smooth_path_costs_a_few_bytes_an_axis() {
    let lines: Vec<_> = (0..10_000u32)
        .map(|i| {
            let t = i as f64 * 0.001;
            let j = [
                Some(100.0 * t.sin()),
                Some(50.0 * t.cos()),
                Some(-20.0 + t),
                None,
                Some(30.0 * t.sin()),
                Some(7.0 * t),
            ];
            (format!("X{t:.3}"), Some(block(i as u64 + 1, Some(i + 10), j, vec![])))
        })
        .collect();
    let mut store = BlockWriter::new(Vec::new()).unwrap();
    for (t, b) in &lines {
        store.line(t, b.as_ref()).unwrap();
    }
    let per_block = store.into_inner().len() as f64 / 10_000.0;
    assert!(per_block < 24.0, "{per_block} bytes a block");
    let (cli, rebuilt) = both(&lines, &[]);
    assert_eq!(cli, rebuilt);
}

/// A store the first format wrote (a job of the version before, `tests/data/job_v1`) is
/// rebuilt into the NDJSON served then: its length and FNV-1a hash, taken from that server.
#[test]
fn a_version_1_store_is_still_read() {
    let data = |f: &str| std::fs::read(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/job_v1/").to_string() + f).unwrap();
    let (store, nc) = (data("job.blocks"), data("job.nc"));
    assert_eq!(&store[..8], MAGIC_V1);
    let mut out = Vec::new();
    Ndjson::new(Some(&store[..]), Some(&nc[..]), None)
        .unwrap()
        .read_to_end(&mut out)
        .unwrap();
    let fnv = out.iter().fold(0xcbf29ce484222325u64, |h, &b| (h ^ b as u64).wrapping_mul(0x100000001b3));
    assert_eq!((out.len(), fnv), (245_905, 0xe0290fdd74dcd032));
}

/// The same job's blocks in this format: a fraction of the first's size, the same NDJSON.
#[test]
fn version_2_is_smaller_and_the_same() {
    let lib = crate::machines::Library::load_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/machines").as_ref()).unwrap();
    let p = lib.get("spinner-u5-620").unwrap();
    let mut cl = Vec::new();
    crate::testgen::write_path(&p.machine, 20_000, 5, p.machine.default_tool_length, &mut cl).unwrap();
    let opts = crate::post::Settings::default().profile_options(&p, None).unwrap();
    struct Both(FileSink<Vec<u8>, Vec<u8>>, BlockWriter<Vec<u8>>, Vec<u8>, u64);
    impl Sink for Both {
        fn line(&mut self, text: &str, b: Option<&BlockInfo>) -> Result<(), crate::post::Stop> {
            self.2.extend_from_slice(text.as_bytes());
            self.2.push(b'\n');
            self.3 += b.is_some() as u64;
            self.0.line(text, b)?;
            Ok(self.1.line(text, b)?)
        }
        fn diagnostic(&mut self, d: &Diagnostic) -> Result<(), crate::post::Stop> {
            self.0.diagnostic(d)?;
            Ok(self.1.record(&Record::Diagnostic { diagnostic: d })?)
        }
        fn summary(&mut self, s: &Summary) -> Result<(), crate::post::Stop> {
            self.0.summary(s)?;
            Ok(self.1.record(&Record::Summary { summary: s })?)
        }
    }
    let mut both = Both(FileSink::new(Vec::new(), Some(Vec::new())), BlockWriter::new(Vec::new()).unwrap(), Vec::new(), 0);
    crate::post::post(&cl[..], &p.machine, &opts, &mut both).unwrap();
    let (_, nd) = both.0.into_inner().unwrap();
    let store = both.1.into_inner();
    let mut out = Vec::new();
    Ndjson::new(Some(&store[..]), Some(&both.2[..]), None)
        .unwrap()
        .read_to_end(&mut out)
        .unwrap();
    assert!(out == nd.unwrap());
    let per_block = store.len() as f64 / both.3 as f64;
    eprintln!("{per_block:.2} bytes a block");
    assert!(per_block < 26.0, "{per_block:.2} bytes a block");
}

/// Cut anywhere, a failed job's stream ends with its error after the last whole record; a
/// succeeded job's ends in an error, never silently short.
#[test]
fn a_store_cut_short_ends_with_the_error_or_fails() {
    let lines: Vec<_> = (0..50u32)
        .map(|i| {
            (
                format!("X{i}"),
                Some(block(
                    i as u64 + 1,
                    Some(i + 1),
                    [Some(i as f64 / 3.0), None, None, None, None, None],
                    vec![],
                )),
            )
        })
        .collect();
    let (cli, _) = both(&lines, &[]);
    let mut store = BlockWriter::new(Vec::new()).unwrap();
    let mut nc = Vec::new();
    for (t, b) in &lines {
        store.line(t, b.as_ref()).unwrap();
        nc.extend_from_slice(format!("{t}\n").as_bytes());
    }
    let store = store.into_inner();
    let end = b"{\"type\":\"error\"}\n".to_vec();
    for cut in [MAGIC.len() + 1, store.len() / 2, store.len() - 1] {
        let mut out = Vec::new();
        Ndjson::new(Some(&store[..cut]), Some(&nc[..]), Some(end.clone()))
            .unwrap()
            .read_to_end(&mut out)
            .unwrap();
        let text = String::from_utf8(out).unwrap();
        assert!(
            text.ends_with("\n{\"type\":\"error\"}\n") || text == "{\"type\":\"error\"}\n",
            "{text}"
        );
        assert!(String::from_utf8_lossy(&cli).starts_with(text.trim_end_matches("{\"type\":\"error\"}\n")));
        let mut out = Vec::new();
        let r = Ndjson::new(Some(&store[..cut]), Some(&nc[..]), None)
            .unwrap()
            .read_to_end(&mut out);
        assert!(r.is_err());
    }
    // The NC gone short: the same.
    let mut out = Vec::new();
    Ndjson::new(Some(&store[..]), Some(&nc[..nc.len() / 2]), Some(end.clone()))
        .unwrap()
        .read_to_end(&mut out)
        .unwrap();
    assert!(out.ends_with(&end));
}
