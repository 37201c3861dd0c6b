//! The NDJSON a run writes beside its NC, one record per line, each defined once here: the
//! header, a block, a diagnostic, the summary, and the error that ends a failed run.

use crate::diag::Diagnostic;
use crate::post::{AxisWords, BlockInfo, Mode, Sink, Stop, Summary};
use serde::Serialize;
use std::io::Write;

/// One line of the NDJSON stream, tagged by `type`.
#[derive(Serialize)]
#[serde(tag = "type", rename_all = "lowercase")]
pub enum Record<'a> {
    Header(Header<'a>),
    /// A motion block: its text, CL line, axis words and diagnostics.
    Block {
        n: u64,
        nc: &'a str,
        source_line: Option<u32>,
        joints: &'a AxisWords,
        diagnostics: &'a [Diagnostic],
    },
    /// Any other line of the program (header, tool change, comment): its text only.
    #[serde(rename = "block")]
    Line {
        nc: &'a str,
    },
    Diagnostic {
        diagnostic: &'a Diagnostic,
    },
    Summary {
        summary: &'a Summary,
    },
    /// The run failed after output began: never a silent truncation.
    Error {
        error: ErrorBody,
    },
}

/// The settings a stream was posted with, first in it.
#[derive(Serialize)]
pub struct Header<'a> {
    pub machine: &'a str,
    pub units: &'a str,
    pub mode: Mode,
    pub dialect: &'a str,
    pub tolerance: f64,
}

/// Why a run failed, with the CL position and diagnostic code where an engine error has them.
#[derive(Clone, Debug, Serialize)]
pub struct ErrorBody {
    pub detail: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub line: Option<u32>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub column: Option<u32>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub code: Option<&'static str>,
}

impl ErrorBody {
    pub fn new(detail: impl Into<String>) -> Self {
        ErrorBody {
            detail: detail.into(),
            line: None,
            column: None,
            code: None,
        }
    }
}

impl<'a> Record<'a> {
    /// A program line: a block record with its details where it is a motion block.
    pub fn line(text: &'a str, b: Option<&'a BlockInfo>) -> Self {
        match b {
            Some(b) => Record::Block {
                n: b.n,
                nc: text,
                source_line: b.source_line,
                joints: &b.joints,
                diagnostics: &b.diagnostics,
            },
            None => Record::Line { nc: text },
        }
    }

    /// The record and its newline.
    pub fn write_to(&self, w: &mut impl Write) -> std::io::Result<()> {
        serde_json::to_writer(&mut *w, self)?;
        w.write_all(b"\n")
    }
}

/// NC text into one writer and, optionally, one NDJSON line per motion block, diagnostic and
/// the summary into another: the CLI's `--output`/`--diagnostics` and a job's spool files.
pub struct FileSink<W: Write, D: Write> {
    pub nc: std::io::BufWriter<W>,
    pub nd: Option<std::io::BufWriter<D>>,
    /// Print warnings and errors to stderr as they come (the CLI does; a job does not).
    pub echo_warnings: bool,
}

impl<W: Write, D: Write> FileSink<W, D> {
    pub fn new(nc: W, nd: Option<D>) -> Self {
        FileSink {
            nc: std::io::BufWriter::with_capacity(1 << 16, nc),
            nd: nd.map(|d| std::io::BufWriter::with_capacity(1 << 16, d)),
            echo_warnings: false,
        }
    }

    pub fn flush(&mut self) -> std::io::Result<()> {
        self.nc.flush()?;
        if let Some(nd) = self.nd.as_mut() {
            nd.flush()?;
        }
        Ok(())
    }

    /// Unwraps the writers, flushed (so the caller can fsync them).
    pub fn into_inner(self) -> std::io::Result<(W, Option<D>)> {
        let nc = self.nc.into_inner().map_err(|e| e.into_error())?;
        let nd = self.nd.map(|w| w.into_inner().map_err(|e| e.into_error())).transpose()?;
        Ok((nc, nd))
    }

    /// One line of the NDJSON (nothing without it).
    pub fn record(&mut self, r: &Record) -> std::io::Result<()> {
        match self.nd.as_mut() {
            Some(nd) => r.write_to(nd),
            None => Ok(()),
        }
    }
}

impl<W: Write, D: Write> Sink for FileSink<W, D> {
    fn line(&mut self, text: &str, b: Option<&BlockInfo>) -> Result<(), Stop> {
        self.nc.write_all(text.as_bytes())?;
        self.nc.write_all(b"\n")?;
        // Only motion blocks: the file's NDJSON has no records for the program's other lines.
        if let (true, Some(b)) = (self.nd.is_some(), b) {
            self.record(&Record::line(text, Some(b)))?;
        }
        Ok(())
    }
    fn diagnostic(&mut self, d: &Diagnostic) -> Result<(), Stop> {
        self.record(&Record::Diagnostic { diagnostic: d })?;
        if self.echo_warnings && d.severity >= crate::diag::Severity::Warning {
            eprintln!("kinepost: {d}");
        }
        Ok(())
    }
    fn summary(&mut self, s: &Summary) -> Result<(), Stop> {
        Ok(self.record(&Record::Summary { summary: s })?)
    }
}

impl ErrorBody {
    /// An engine error; a strict-mode stop names its CL line, column and code.
    pub fn from_engine(e: &crate::post::Error) -> Self {
        match e {
            crate::post::Error::Strict(d) => ErrorBody {
                detail: d.to_string(),
                line: d.line,
                column: d.column,
                code: Some(d.code.as_str()),
            },
            crate::post::Error::NotCl(d) => ErrorBody {
                detail: d.message.clone(),
                line: d.line,
                column: None,
                code: Some(d.code.as_str()),
            },
            crate::post::Error::Stop(Stop::Budget(why)) => ErrorBody {
                code: Some("over_budget"),
                ..ErrorBody::new(why.clone())
            },
            e => ErrorBody::new(e.to_string()),
        }
    }
}
