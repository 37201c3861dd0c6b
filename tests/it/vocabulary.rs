//! The CL vocabulary: every word kinepost knows, placed in the middle of a path, changes the NC
//! or is told at its line; only the informational list is read past in silence, and that list
//! is the one printed in docs/cl-vocabulary.md.

use crate::common;

use common::machine;

use kinepost::cl::vocabulary::{Treatment, VOCABULARY};
use kinepost::diag::{Diagnostic, Severity};
use kinepost::post::{self, BlockInfo, Options, Sink};

#[derive(Default)]
struct Collect {
    nc: Vec<String>,
    diags: Vec<Diagnostic>,
}

impl Sink for Collect {
    fn line(&mut self, text: &str, b: Option<&BlockInfo>) -> Result<(), kinepost::post::Stop> {
        // The date is the run's, not the program's.
        if !text.contains("DATE ") {
            self.nc.push(text.to_string());
        }
        self.diags.extend(b.iter().flat_map(|b| b.diagnostics.iter().cloned()));
        Ok(())
    }
    fn diagnostic(&mut self, d: &Diagnostic) -> Result<(), kinepost::post::Stop> {
        self.diags.push(d.clone());
        Ok(())
    }
}

/// The line the record under test stands on.
const LINE: u32 = 9;

/// A tilted 5-axis path on a head machine (so that a tool length changes the words), with
/// `mid` at line 9.
fn path(mid: &str) -> String {
    format!(
        "UNITS/MM\nMSYS/0,0,0,1,0,0,0,1,0\nLOADTL/1\nSPINDL/1000,CLW\nFEDRAT/100,MMPM\n\
         TLAXIS/0.2,0,0.9797959\nGOTO/0,0,10\nGOTO/5,0,10\n{mid}\nGOTO/10,0,10\nGOTO/15,5,10\nEND\n"
    )
}

fn post(cl: &str) -> Collect {
    let m = machine("dmg-dmc75v");
    let mut o = Options::new(&m);
    o.dialect = kinepost::nc::dialect("fanuc").unwrap();
    let mut sink = Collect::default();
    post::post(cl.as_bytes(), &m, &o, &mut sink).unwrap();
    sink
}

#[test]
fn every_word_changes_the_nc_or_is_told_and_only_the_informational_ones_are_silent() {
    let mut failures = Vec::new();
    for w in VOCABULARY {
        // A sample's later statements are its context: in the program without it too.
        let rest = w.sample.split_once('\n').map_or("", |(_, r)| r);
        let (with, without) = (post(&path(w.sample)), post(&path(rest)));
        let at_line: Vec<_> = with.diags.iter().filter(|d| d.line == Some(LINE)).collect();
        let changed = with.nc != without.nc;
        let ok = match w.treatment {
            Treatment::Honoured => changed || at_line.iter().any(|d| d.severity >= Severity::Warning),
            Treatment::Informational(_) => !changed && at_line.is_empty(),
            Treatment::Told(sev, _) => at_line.iter().any(|d| d.severity == sev && d.message.starts_with(w.word)),
        };
        if !ok {
            failures.push(format!("{} ({:?}): changed {changed}, told {at_line:?}", w.sample, w.treatment));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// The docs' table is the vocabulary's (`KINEPOST_UPDATE_DOCS=1` writes it).
#[test]
fn the_documented_vocabulary_is_the_one_in_the_code() {
    let mut doc = String::from(
        "# The CL vocabulary\n\n\
         Every major word kinepost knows, and what it does with it (generated from\n\
         `src/cl/vocabulary.rs` by `tests/it/vocabulary.rs`: `KINEPOST_UPDATE_DOCS=1 cargo test --test it vocabulary::`).\n\
         A word not listed here is unknown: a warning naming its line, and the record is not used.\n\
         A word told again (unknown, or told below) is told by one record a program, at the end of the\n\
         input, naming its first line and its count.\n\
         SOLIDWORKS CAM's vendor records (`CSI_…`) are informational: tool and path parameters for its own posts.\n",
    );
    for (title, pick) in [("Honoured: acted on", 0), ("Informational: read past in silence", 1), ("Told: not acted on, a diagnostic at its line", 2)] {
        doc.push_str(&format!("\n## {title}\n\n| word | example | {} |\n|---|---|---|\n", if pick == 2 { "severity: why" } else { "why" }));
        for w in VOCABULARY {
            let (class, why) = match w.treatment {
                Treatment::Honoured => (0, String::new()),
                Treatment::Informational(r) => (1, r.to_string()),
                Treatment::Told(s, r) => (2, format!("{}: {r}", if s == Severity::Error { "error" } else { "warning" })),
            };
            if class == pick {
                doc.push_str(&format!("| `{}` | `{}` | {why} |\n", w.word, w.sample.replace('\n', "` then `")));
            }
        }
    }
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/docs/cl-vocabulary.md");
    if std::env::var("KINEPOST_UPDATE_DOCS").is_ok() {
        std::fs::write(path, &doc).unwrap();
    }
    let checked_in = std::fs::read_to_string(path).expect("docs/cl-vocabulary.md (KINEPOST_UPDATE_DOCS=1 writes it)");
    assert_eq!(checked_in, doc, "docs/cl-vocabulary.md is stale: run with KINEPOST_UPDATE_DOCS=1");
}
