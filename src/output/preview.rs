//! A decimated picture of a program, for people: the path, the tool axis, every joint and every
//! block that deserves a look. Built block by block beside the NC (memory bounded by its caps, not
//! by the program), finished with one pass over the CL source to quote the lines it points at.

use super::model::{MachineModel, solid};
use crate::collide::{Geometry, Solid, ToolShape};
use crate::diag::{Code, Diagnostic, Severity};
use crate::kinematics::{Machine, Pose};
use crate::post::{BlockInfo, Mode, Summary};
use serde::Serialize;
use std::io::BufRead;

/// What a preview may hold. Decimation keeps every `stride`-th block, doubling the stride when
/// the path outgrows `max_points`; marked blocks are kept apart, up to `max_marks`.
#[derive(Clone, Copy, Debug)]
pub struct Caps {
    pub max_points: usize,
    pub max_marks: usize,
    pub max_notes: usize,
}

impl Default for Caps {
    fn default() -> Self {
        Caps {
            max_points: 10_000,
            max_marks: 5_000,
            max_notes: 1_000,
        }
    }
}

/// A plotted axis: the words of every point's `j`, in this order.
#[derive(Clone, Debug, Serialize, utoipa::ToSchema)]
pub struct PreviewAxis {
    pub name: char,
    /// `linear` (profile units) or `rotary` (degrees); in TCP mode X Y Z are the tip, not joints.
    pub kind: &'static str,
    /// The profile's travel; null for an unbounded rotary and for X Y Z in TCP mode.
    pub limits: Option<[f64; 2]>,
}

#[derive(Clone, Debug, Serialize, utoipa::ToSchema)]
pub struct PathPoint {
    /// Motion block number (1-based).
    pub n: u64,
    pub line: Option<u32>,
    pub rapid: bool,
    /// Seconds from the program start (cycle-time estimate) at the end of this block.
    pub t: f64,
    /// Tool tip and tool axis in the part frame.
    pub tip: [f64; 3],
    pub axis: [f64; 3],
    /// Axis words as written, in the order of `axes`.
    pub j: Vec<f64>,
}

/// A block worth a look: a warning or error, an unwind, a branch change.
#[derive(Clone, Debug, Serialize, utoipa::ToSchema)]
pub struct Mark {
    #[serde(flatten)]
    pub at: PathPoint,
    /// The NC block as written.
    pub nc: String,
    /// The CL source line it came from (truncated to 300 characters).
    pub cl: Option<String>,
    #[schema(value_type = Vec<Object>)]
    pub diagnostics: Vec<Diagnostic>,
    /// The bodies its `collision` and `near_collision` diagnostics name, and how deep or close.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub contacts: Vec<Contact>,
}

/// Two bodies that overlap (`collision`: `depth`) or come closer than the clearance
/// (`near_collision`: `distance`) at a block or on the way to it (profile units).
#[derive(Clone, Debug, Serialize, utoipa::ToSchema)]
pub struct Contact {
    /// `collision` or `near_collision`.
    pub code: String,
    pub a: String,
    pub b: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub depth: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub distance: Option<f64>,
}

/// The tool in the spindle from block `n` on: the length in force, the cutter and the holder as
/// the collision check sees them (profile units).
#[derive(Clone, Debug, Serialize, utoipa::ToSchema)]
pub struct PreviewTool {
    pub n: u64,
    pub length: f64,
    pub diameter: f64,
    pub corner_radius: f64,
    pub holder_diameter: f64,
    pub holder_length: f64,
}

/// A warning not attached to a block (the reader's, an unreachable pose's), with its CL line and,
/// for a pose that got no block, where the CL put it.
#[derive(Clone, Debug, Serialize, utoipa::ToSchema)]
pub struct Note {
    pub cl: Option<String>,
    pub tip: Option<[f64; 3]>,
    pub axis: Option<[f64; 3]>,
    #[schema(value_type = Object)]
    pub diagnostic: Diagnostic,
}

#[derive(Clone, Debug, Serialize, utoipa::ToSchema)]
pub struct Preview {
    /// The machine: its chain (each link's pose from the joints, as FK computes it) and bodies.
    pub machine: MachineModel,
    #[schema(value_type = String, example = "joint")]
    pub mode: Mode,
    pub units: &'static str,
    pub axes: Vec<PreviewAxis>,
    /// Motion blocks in the program; `points` holds every `stride`-th, the first, the last and
    /// every change between rapid and feed.
    pub blocks: u64,
    pub stride: u64,
    pub points: Vec<PathPoint>,
    pub marks: Vec<Mark>,
    /// Marked blocks beyond the cap (the summary counts them all).
    pub marks_dropped: u64,
    pub notes: Vec<Note>,
    pub notes_dropped: u64,
    pub cycle_time_s: f64,
    /// The work offset of the post (W's origin in M at home, profile units).
    pub work_offset: [f64; 3],
    /// The job's stock and fixtures: boxes `[x0, y0, z0, x1, y1, z1]` in W (profile units).
    pub stock: Vec<[f64; 6]>,
    pub fixtures: Vec<[f64; 6]>,
    /// Each tool as it comes into the spindle (at most 1000).
    pub tools: Vec<PreviewTool>,
}

/// What a block leaves for the preview before it is known whether it is kept.
#[derive(Clone, Copy)]
struct Last {
    n: u64,
    line: Option<u32>,
    rapid: bool,
    t: f64,
    tip: [f64; 3],
    axis: [f64; 3],
    joints: crate::post::AxisWords,
}

struct Kept {
    seq: u64,
    /// Kept whatever the stride: the first block and rapid/feed changes.
    pinned: bool,
    p: PathPoint,
}

pub struct PreviewBuilder {
    caps: Caps,
    /// (index into the 6 axis words, axis) in output order.
    axes: Vec<(usize, PreviewAxis)>,
    machine: MachineModel,
    work_offset: [f64; 3],
    stock: Vec<[f64; 6]>,
    fixtures: Vec<[f64; 6]>,
    tools: Vec<PreviewTool>,
    mode: Mode,
    units: &'static str,
    seq: u64,
    stride: u64,
    t: f64,
    kept: Vec<Kept>,
    last: Option<Last>,
    last_rapid: Option<bool>,
    /// Off once rapid/feed changes alone would fill the preview.
    pin_changes: bool,
    marks: Vec<Mark>,
    marks_dropped: u64,
    notes: Vec<Note>,
    notes_dropped: u64,
}

/// Rounded for display: shorter JSON, nothing a screen could show.
fn r(v: f64, q: f64) -> f64 {
    (v * q).round() / q
}

fn marks(d: &Diagnostic) -> bool {
    d.severity >= Severity::Warning || matches!(d.code, Code::Unwind | Code::BranchChange)
}

impl PreviewBuilder {
    pub fn new(m: &Machine, mode: Mode, caps: Caps) -> PreviewBuilder {
        let tcp = mode == Mode::Tcp;
        let mut axes = Vec::new();
        for (i, l) in m.linears.iter().enumerate() {
            if l.is_some() || tcp {
                axes.push((
                    i,
                    PreviewAxis {
                        name: crate::nc::AXIS_LETTERS[i],
                        kind: "linear",
                        limits: l.as_ref().filter(|_| !tcp).map(|l| [l.min, l.max]),
                    },
                ));
            }
        }
        for r in &m.rotaries {
            axes.push((
                r.slot(),
                PreviewAxis {
                    name: r.name,
                    kind: "rotary",
                    limits: r.limits.map(|(a, b)| [a.to_degrees(), b.to_degrees()]),
                },
            ));
        }
        axes.sort_by_key(|(k, _)| *k);
        PreviewBuilder {
            caps: Caps {
                max_points: caps.max_points.max(2),
                ..caps
            },
            axes,
            machine: MachineModel::new(m, &Geometry::default()),
            work_offset: [0.0; 3],
            stock: Vec::new(),
            fixtures: Vec::new(),
            tools: Vec::new(),
            mode,
            units: match m.units {
                crate::kinematics::Units::Mm => "mm",
                crate::kinematics::Units::Inch => "inch",
            },
            seq: 0,
            stride: 1,
            t: 0.0,
            kept: Vec::new(),
            last: None,
            last_rapid: None,
            pin_changes: true,
            marks: Vec::new(),
            marks_dropped: 0,
            notes: Vec::new(),
            notes_dropped: 0,
        }
    }

    /// The scene the program runs in: the machine's bodies (drawn whether or not they are
    /// checked), the work offset, the job's stock and fixtures.
    pub fn with_scene(mut self, m: &Machine, g: &Geometry, work_offset: [f64; 3], stock: &[Solid], fixtures: &[Solid]) -> Self {
        let boxes = |v: &[Solid]| v.iter().filter_map(|s| solid(s).0).collect();
        self.machine = MachineModel::new(m, g);
        self.work_offset = work_offset;
        self.stock = boxes(stock);
        self.fixtures = boxes(fixtures);
        self
    }

    /// A tool comes into the spindle (or its length changes) from block `n` on.
    pub fn tool(&mut self, n: u64, t: &ToolShape) {
        if self.tools.len() >= 1000 {
            return;
        }
        let tool = PreviewTool {
            n,
            length: t.length,
            diameter: t.diameter,
            corner_radius: t.corner_radius,
            holder_diameter: t.holder_diameter,
            holder_length: t.holder_length,
        };
        match self.tools.last_mut() {
            Some(last) if last.n == n => *last = tool,
            _ => self.tools.push(tool),
        }
    }

    /// The bodies a `collision` or `near_collision` names, as the check found them.
    fn contact(&self, d: &Diagnostic) -> Option<Contact> {
        let b = d.bodies.as_deref()?;
        let overlap = b.distance < 0.0;
        Some(Contact {
            code: d.code.as_str().into(),
            a: b.a.clone(),
            b: b.b.clone(),
            depth: overlap.then_some(-b.distance),
            distance: (!overlap).then_some(b.distance),
        })
    }

    /// A block's point for display: rounded, words in the order of `axes`.
    fn point(&self, b: &Last) -> PathPoint {
        PathPoint {
            n: b.n,
            line: b.line,
            rapid: b.rapid,
            t: r(b.t, 1e3),
            tip: b.tip.map(|v| r(v, 1e4)),
            axis: b.axis.map(|v| r(v, 1e6)),
            j: self.axes.iter().map(|(k, _)| r(b.joints.0[*k].unwrap_or(0.0), 1e4)).collect(),
        }
    }

    /// Called for every block: allocates only for the blocks it keeps.
    pub fn block(&mut self, nc: &str, b: &BlockInfo) {
        self.t += b.time_s;
        let raw = Last {
            n: b.n,
            line: b.source_line,
            rapid: b.rapid,
            t: self.t,
            tip: b.tip,
            axis: b.axis,
            joints: b.joints,
        };
        if b.diagnostics.iter().any(marks) {
            if self.marks.len() < self.caps.max_marks {
                self.marks.push(Mark {
                    at: self.point(&raw),
                    nc: nc.chars().take(300).collect(),
                    cl: None,
                    diagnostics: b.diagnostics.clone(),
                    contacts: b.diagnostics.iter().filter_map(|d| self.contact(d)).collect(),
                });
            } else {
                self.marks_dropped += 1;
            }
        }
        let pinned = self.last_rapid != Some(b.rapid) && self.pin_changes;
        self.last_rapid = Some(b.rapid);
        if pinned || self.seq % self.stride == 0 {
            self.kept.push(Kept {
                seq: self.seq,
                pinned,
                p: self.point(&raw),
            });
            if self.kept.len() > self.caps.max_points {
                self.thin();
            }
        }
        self.seq += 1;
        self.last = Some(raw);
    }

    /// Doubles the stride until the kept points fill half the cap. Rapid/feed changes stay
    /// unless they alone fill that half (a drilling program), when they thin like the rest.
    fn thin(&mut self) {
        let half = self.caps.max_points / 2;
        if self.pin_changes && self.kept.iter().filter(|k| k.pinned).count() > half / 2 {
            self.pin_changes = false;
            for k in &mut self.kept {
                k.pinned = false;
            }
        }
        while self.kept.len() > half && self.stride < 1 << 62 {
            self.stride *= 2;
            let s = self.stride;
            self.kept.retain(|k| k.pinned || k.seq % s == 0);
        }
    }

    pub fn note(&mut self, d: &Diagnostic, pose: Option<&Pose>) {
        if !marks(d) {
            return;
        }
        if self.notes.len() < self.caps.max_notes {
            self.notes.push(Note {
                cl: None,
                tip: pose.map(|p| <[f64; 3]>::from(p.tip).map(|v| r(v, 1e4))),
                axis: pose.map(|p| <[f64; 3]>::from(p.axis).map(|v| r(v, 1e6))),
                diagnostic: d.clone(),
            });
        } else {
            self.notes_dropped += 1;
        }
    }

    /// The preview, quoting the CL lines of its marks and notes from `source` (read once, up to
    /// the last line needed).
    pub fn finish(self, summary: Option<&Summary>, source: Option<&mut dyn BufRead>) -> Preview {
        let last = self.last.map(|l| self.point(&l));
        let mut points: Vec<PathPoint> = self.kept.into_iter().map(|k| k.p).collect();
        if let Some(last) = last
            && points.last().is_none_or(|p| p.n != last.n)
        {
            points.push(last);
        }
        let mut marks = self.marks;
        let mut notes = self.notes;
        if let Some(src) = source {
            let mut want: Vec<u32> = marks
                .iter()
                .filter_map(|m| m.at.line)
                .chain(notes.iter().filter_map(|n| n.diagnostic.line))
                .collect();
            want.sort_unstable();
            want.dedup();
            let text = quote_lines(src, &want);
            let find = |l: Option<u32>| l.and_then(|l| want.binary_search(&l).ok()).and_then(|i| text[i].clone());
            for m in &mut marks {
                m.cl = find(m.at.line);
            }
            for n in &mut notes {
                n.cl = find(n.diagnostic.line);
            }
        }
        Preview {
            machine: self.machine,
            mode: self.mode,
            units: self.units,
            axes: self.axes.into_iter().map(|(_, a)| a).collect(),
            blocks: self.seq,
            stride: self.stride,
            points,
            marks,
            marks_dropped: self.marks_dropped,
            notes,
            notes_dropped: self.notes_dropped,
            cycle_time_s: summary.map_or(r(self.t, 1e3), |s| s.cycle_time_s),
            work_offset: self.work_offset,
            stock: self.stock,
            fixtures: self.fixtures,
            tools: self.tools,
        }
    }
}

/// The text of the (sorted, distinct) 1-based lines `want`, each cut to 300 characters; a line
/// the source does not have (or cannot be read) is `None`. Never holds more than one cut line, however
/// long the source's lines are.
fn quote_lines(src: &mut dyn BufRead, want: &[u32]) -> Vec<Option<String>> {
    const CUT: usize = 1200;
    let mut out = vec![None; want.len()];
    let mut cur: Vec<u8> = Vec::new();
    let mut line = 1u32;
    let mut i = 0;
    while i < want.len() {
        if want[i] < line {
            i += 1;
            continue;
        }
        let buf = match src.fill_buf() {
            Ok([]) | Err(_) => break,
            Ok(b) => b,
        };
        // The lines before the next wanted one go by at memchr's pace: a job's CL is read
        // through once more for its marks, 10 M lines in a second by the byte, a tenth so.
        let mut at = 0;
        while line < want[i] {
            match memchr::memchr(b'\n', &buf[at..]) {
                Some(k) => {
                    at += k + 1;
                    line += 1;
                }
                None => {
                    at = buf.len();
                    break;
                }
            }
        }
        if line < want[i] {
            src.consume(at);
            continue;
        }
        let rest = &buf[at..];
        let (chunk, end) = match memchr::memchr(b'\n', rest) {
            Some(k) => (&rest[..k], Some(k + 1)),
            None => (rest, None),
        };
        if cur.len() < CUT {
            cur.extend_from_slice(&chunk[..chunk.len().min(CUT - cur.len())]);
        }
        let used = at + end.unwrap_or(rest.len());
        src.consume(used);
        if end.is_some() {
            out[i] = Some(cut(&cur));
            cur.clear();
            i += 1;
            line += 1;
        }
    }
    if i < want.len() && line == want[i] && !cur.is_empty() {
        out[i] = Some(cut(&cur));
    }
    out
}

fn cut(b: &[u8]) -> String {
    String::from_utf8_lossy(b).trim_end_matches('\r').chars().take(300).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::post::AxisWords;

    fn block(n: u64, rapid: bool, warn: bool) -> BlockInfo {
        BlockInfo {
            n,
            source_line: Some(n as u32),
            joints: AxisWords([Some(n as f64), Some(0.0), Some(0.0), None, Some(1.0), Some(2.0)]),
            diagnostics: if warn {
                vec![Diagnostic::new(Code::FeedClamped, Severity::Warning, Some(n as u32), "w")]
            } else {
                vec![Diagnostic::new(Code::Singular, Severity::Info, Some(n as u32), "i")]
            },
            rapid,
            tip: [n as f64, 0.0, 0.0],
            axis: [0.0, 0.0, 1.0],
            time_s: 0.5,
        }
    }

    fn machine() -> Machine {
        let lib = crate::machines::Library::load_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/machines").as_ref()).unwrap();
        lib.get("spinner-u5-620").unwrap().machine.clone()
    }

    #[test]
    fn decimation_is_bounded_keeps_ends_and_every_mark() {
        let caps = Caps {
            max_points: 1000,
            max_marks: 50,
            max_notes: 1,
        };
        // A drilling program: rapid and feed alternate every block, a warning every 997th.
        let mut b = PreviewBuilder::new(&machine(), Mode::Joint, caps);
        let total = 200_000;
        for n in 1..=total {
            b.block("G1", &block(n, n % 2 == 0, n % 997 == 0));
        }
        let p = b.finish(None, None);
        assert!(p.points.len() <= 1001 && p.points.len() >= 250, "{}", p.points.len());
        assert_eq!(p.points[0].n, 1);
        assert_eq!(p.points.last().unwrap().n, total);
        assert!(p.points.windows(2).all(|w| w[0].n < w[1].n));
        assert_eq!(p.marks.len(), 50);
        assert_eq!(p.marks_dropped, total / 997 - 50);
        assert!(p.marks.iter().all(|m| m.at.n % 997 == 0));
        assert_eq!(p.blocks, total);
        assert_eq!(p.points.last().unwrap().t, total as f64 * 0.5);
        let names: String = p.axes.iter().map(|a| a.name).collect();
        assert_eq!(names, "XYZBC");
        assert_eq!(p.points[5].j.len(), 5);

        // A path of long feed runs between rapids keeps every rapid/feed change.
        let mut b = PreviewBuilder::new(&machine(), Mode::Joint, caps);
        for n in 1..=100_000 {
            b.block("G1", &block(n, n % 5000 < 3, false));
        }
        let p = b.finish(None, None);
        for n in (5000..100_000).step_by(5000) {
            assert!(p.points.iter().any(|q| q.n == n as u64), "rapid start {n}");
            assert!(p.points.iter().any(|q| q.n == n as u64 + 3), "feed start {}", n + 3);
        }
    }

    #[test]
    fn quotes_wanted_lines_only_and_cuts_long_ones() {
        let long = "X".repeat(5000);
        let src = format!("a\r\nb\n{long}\nd\ne");
        let mut r = std::io::BufReader::with_capacity(7, src.as_bytes());
        let q = quote_lines(&mut r, &[2, 3, 5, 9]);
        assert_eq!(q[0].as_deref(), Some("b"));
        assert_eq!(q[1].as_ref().map(|s| s.len()), Some(300));
        assert_eq!(q[2].as_deref(), Some("e"));
        assert_eq!(q[3], None);
        let mut r = std::io::BufReader::new(src.as_bytes());
        assert_eq!(quote_lines(&mut r, &[1])[0].as_deref(), Some("a"));
    }
}
