//! The Formatter's canned hole cycles: each hole kind as the control's own cycle runs it
//! (ISO G73 G74 G76 G81–G86 G89 and rigid tapping, Sinumerik CYCLE81–89 and CYCLE840,
//! Heidenhain CYCL DEF 200–207). What a control cannot write is said by [`Formatter::cannot`]
//! before any word is written: the engine makes that an error, never a different motion.

use super::{FeedMode, Formats, Formatter, number, round_to, write_fixed};

/// Canned cycle families.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
pub enum Cycles {
    /// `G98/G99 G81|G82|G83|G73|G84|G74|G85|G86|G89|G76 X Y Z R [Q] [P] F`, modal until `G80`;
    /// dwell `P` in milliseconds (Fanuc) or seconds (Haas, LinuxCNC).
    Iso {
        dwell_ms: bool,
        /// How the control taps with the spindle synchronised to Z.
        #[serde(default)]
        taps: IsoTaps,
        /// `G76` is a fine bore (orient, shift, rapid out); on LinuxCNC it is threading.
        #[serde(default = "yes")]
        fine_bore: bool,
        /// `G86` wants its `P` word even with no dwell (LinuxCNC's interpreter refuses it without).
        #[serde(default)]
        g86_dwell: bool,
    },
    /// `MCALL CYCLE81…89(RTP, RFP, SDIS, DP …)`, called by each positioning block until a bare
    /// `MCALL`.
    Siemens,
    /// `CYCL DEF 200…207` with Q parameters, called by `M99` on a positioning block.
    Heidenhain,
}

fn yes() -> bool {
    true
}

/// Rigid (synchronised) tapping on an ISO control.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Deserialize)]
pub enum IsoTaps {
    /// Fanuc: `M29 S…` before `G84`/`G74` makes it rigid; without it, a floating holder's tap.
    #[default]
    #[serde(rename = "m29")]
    M29,
    /// Haas: `G84`/`G74` are rigid as written (a floating holder follows as well).
    #[serde(rename = "g84")]
    G84,
    /// LinuxCNC: `G84`/`G74` are floating-holder cycles; rigid is `G33.1 Z K` from R.
    #[serde(rename = "g33.1")]
    G33_1,
}

impl Cycles {
    pub fn describe(self) -> &'static str {
        match self {
            Cycles::Iso { dwell_ms: true, .. } => {
                "G73, G74, G76, G81–G89 as the control has them, G98/G99 R plane, G80 cancels; dwell P in ms"
            }
            Cycles::Iso { dwell_ms: false, .. } => {
                "G73, G74, G76, G81–G89 as the control has them, G98/G99 R plane, G80 cancels; dwell P in seconds"
            }
            Cycles::Siemens => "MCALL CYCLE81/82/83/84/840/85/86/89, bare MCALL cancels",
            Cycles::Heidenhain => "CYCL DEF 200/201/202/203/206/207, called with M99",
        }
    }
}

/// Which canned cycle a hole takes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CannedKind {
    Drill,
    /// Dwell at the bottom.
    Spot,
    /// Full-retract pecking.
    Peck,
    /// Pecking with a short retract that breaks the chip.
    ChipBreak,
    /// Tapping: feed in, the spindle reversed at the bottom, feed out. `rigid`: the spindle
    /// synchronised with Z; `left`: a left-hand thread (the spindle turning CCW on the way in).
    Tap {
        rigid: bool,
        left: bool,
    },
    /// Feed in, feed out (a dwell at the bottom where given): boring, reaming.
    Bore,
    /// Feed in, the spindle stopped at the bottom, rapid out.
    BoreStop,
    /// Feed in, the spindle oriented at the bottom, the bar shifted off the wall, rapid out.
    FineBore,
}

impl CannedKind {
    /// Comes out of the hole at the feed (else at rapid).
    pub fn feeds_out(self) -> bool {
        matches!(self, CannedKind::Tap { .. } | CannedKind::Bore)
    }
}

/// One hole as a canned cycle, in joint words (the hole runs along the machine's Z): position,
/// and the Z levels of the top (surface), the R plane, the bottom and the start level the tool
/// waits at and returns to (G98's initial level, Siemens' RTP, Heidenhain's 2nd set-up
/// clearance).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Canned {
    pub kind: CannedKind,
    pub x: Option<f64>,
    pub y: Option<f64>,
    pub z_top: f64,
    pub z_r: f64,
    pub z_bottom: f64,
    pub z_start: f64,
    /// Per minute (a tap's: the pitch times the speed).
    pub feed: f64,
    pub peck: f64,
    /// Seconds.
    pub dwell: f64,
    /// A tap's pitch (always positive: `kind` says the hand) and the spindle speed it turns at.
    pub pitch: f64,
    pub rpm: f64,
    /// A fine bore's shift off the wall at the bottom.
    pub shift: f64,
}

impl Canned {
    /// The same cycle started from (`x`, `y`) at level `z_start`: every Z level moves with it.
    pub fn start_at(&mut self, x: Option<f64>, y: Option<f64>, z_start: f64) {
        let shift = z_start - self.z_start;
        for z in [&mut self.z_top, &mut self.z_r, &mut self.z_bottom, &mut self.z_start] {
            *z += shift;
        }
        (self.x, self.y) = (x, y);
    }

    /// The cycle's positions and levels measured from `origin` (a work offset's).
    fn measured_from(&self, origin: [f64; 3]) -> Canned {
        let [sx, sy, sz] = origin;
        Canned {
            x: self.x.map(|x| x - sx),
            y: self.y.map(|y| y - sy),
            z_top: self.z_top - sz,
            z_r: self.z_r - sz,
            z_bottom: self.z_bottom - sz,
            z_start: self.z_start - sz,
            ..*self
        }
    }

    /// Same cycle as written (levels, feed, peck, dwell …): a next hole needs only its position.
    pub fn same_cycle(&self, o: &Canned, f: &Formats) -> bool {
        let l = |a: f64, b: f64| round_to(a, f.linear) == round_to(b, f.linear);
        self.kind == o.kind
            && l(self.z_top, o.z_top)
            && l(self.z_r, o.z_r)
            && l(self.z_bottom, o.z_bottom)
            && l(self.z_start, o.z_start)
            && l(self.peck, o.peck)
            && l(self.shift, o.shift)
            && round_to(self.pitch, 6) == round_to(o.pitch, 6)
            && round_to(self.rpm, 0) == round_to(o.rpm, 0)
            && round_to(self.feed, f.feed) == round_to(o.feed, f.feed)
            && round_to(self.dwell, 3) == round_to(o.dwell, 3)
    }
}

/// The lines of one hole and which of them is the cycle's call (the block that drills it).
pub struct CycleLines {
    pub lines: Vec<String>,
    pub call: usize,
}

impl Formatter {
    /// Why this control cannot write a hole of `kind` as its cycle, if it cannot.
    pub fn cannot(&self, kind: CannedKind) -> Option<&'static str> {
        match (self.d.cycles, kind) {
            (Cycles::Iso { fine_bore: false, .. }, CannedKind::FineBore) => {
                Some("this control has no fine boring cycle (its G76 is threading)")
            }
            _ => None,
        }
    }

    /// Whether a hole of `kind` leaves a modal cycle on that the next hole can call.
    pub fn modal_cycle(&self, kind: CannedKind) -> bool {
        !matches!(
            (self.d.cycles, kind),
            (
                Cycles::Iso {
                    taps: IsoTaps::G33_1,
                    ..
                },
                CannedKind::Tap { rigid: true, .. }
            )
        )
    }

    /// X and Y of a hole: always both on the block that starts a cycle (it is the call), else
    /// what changed.
    fn hole_xy(&mut self, c: &Canned, force: bool) {
        let conv = self.conversational();
        for (i, v) in [(0, c.x), (1, c.y)] {
            let Some(v) = v else { continue };
            let r = round_to(v, self.fmt.linear);
            if force || self.axes[i] != Some(r) {
                self.axes[i] = Some(r);
                number::write_word(&mut self.buf, super::AXIS_ADDRESSES[i], conv, r, self.fmt.linear);
            }
        }
    }

    /// The lines of one hole as a canned cycle (the tool already waits above it at `z_start`).
    /// `modal`: the previous hole's cycle is still on with the same levels, feed, peck and
    /// dwell, so only the position is written (it calls the cycle).
    pub fn canned(&mut self, c: &Canned, modal: bool) -> CycleLines {
        let c = &c.measured_from([self.shift[0], self.shift[1], self.shift[2]]);
        let mut out = CycleLines {
            lines: Vec::new(),
            call: 0,
        };
        match self.d.cycles {
            Cycles::Iso {
                taps: IsoTaps::G33_1, ..
            } if matches!(c.kind, CannedKind::Tap { rigid: true, .. }) => {
                self.g33_1(c, &mut out.lines);
                out.call = 1;
                return out;
            }
            Cycles::Iso {
                dwell_ms,
                taps,
                g86_dwell,
                ..
            } => self.iso(c, modal, dwell_ms, taps, g86_dwell, &mut out.lines),
            Cycles::Siemens => self.siemens(c, modal, &mut out.lines),
            Cycles::Heidenhain => self.heidenhain(c, modal, &mut out.lines),
        }
        while self.buf.ends_with(' ') {
            self.buf.pop();
        }
        out.call = out.lines.len();
        out.lines.push(self.buf.clone());
        out
    }

    /// The feed's words (`G94` where another mode is on, `F`), each hole's cycle starting with
    /// them; `None` where the feed in force is this one.
    fn cycle_feed(&mut self, feed: f64, always: bool) -> String {
        let mut f = String::new();
        if let Some(d) = self.switch_feed_mode(FeedMode::PerMinute) {
            f.push_str(d.feed_mode_word(FeedMode::PerMinute));
            f.push(' ');
        }
        let feed_r = round_to(feed, self.fmt.feed);
        if always || self.feed != Some(feed_r) {
            f.push('F');
            write_fixed(&mut f, feed_r, self.fmt.feed);
            self.feed = Some(feed_r);
        }
        f
    }

    /// Fanuc, Haas, LinuxCNC: `G98|G99 G8x X Y Z R [Q] [P] F` (rigid taps after `M29 S`).
    fn iso(&mut self, c: &Canned, modal: bool, dwell_ms: bool, taps: IsoTaps, g86_dwell: bool, out: &mut Vec<String>) {
        let lin = self.fmt.linear;
        if !modal && taps == IsoTaps::M29 && matches!(c.kind, CannedKind::Tap { rigid: true, .. }) {
            // Fanuc's rigid tapping mode: the speed on the M29 block, the G84 next.
            let s = format!("M29 S{}", round_to(c.rpm, 0));
            out.push(self.words(&s).to_string());
        }
        self.start();
        if !modal {
            let mode = self.switch_feed_mode(FeedMode::PerMinute);
            if let Some(d) = mode {
                self.buf.push_str(d.feed_mode_word(FeedMode::PerMinute));
                self.buf.push(' ');
            }
            // G98 returns to the level the cycle started from, G99 to the R plane.
            let g98 = round_to(c.z_start, lin) > round_to(c.z_r, lin);
            self.buf.push_str(if g98 { "G98 " } else { "G99 " });
            self.buf.push_str(match c.kind {
                CannedKind::Drill => "G81 ",
                CannedKind::Spot => "G82 ",
                CannedKind::Peck => "G83 ",
                CannedKind::ChipBreak => "G73 ",
                CannedKind::Tap { left: false, .. } => "G84 ",
                CannedKind::Tap { left: true, .. } => "G74 ",
                CannedKind::Bore if c.dwell > 0.0 => "G89 ",
                CannedKind::Bore => "G85 ",
                CannedKind::BoreStop => "G86 ",
                CannedKind::FineBore => "G76 ",
            });
        }
        self.hole_xy(c, !modal);
        if modal {
            self.motion = None;
            return;
        }
        self.buf.push('Z');
        self.number(c.z_bottom, lin, false);
        self.buf.push_str(" R");
        self.number(c.z_r, lin, false);
        if matches!(c.kind, CannedKind::Peck | CannedKind::ChipBreak) {
            self.buf.push_str(" Q");
            self.number(c.peck, lin, false);
        }
        if c.kind == CannedKind::FineBore {
            self.buf.push_str(" Q");
            self.number(c.shift, lin, false);
        }
        let dwell_word = match c.kind {
            CannedKind::Spot => true,
            CannedKind::BoreStop => g86_dwell || c.dwell > 0.0,
            CannedKind::Drill | CannedKind::Peck | CannedKind::ChipBreak => false,
            _ => c.dwell > 0.0,
        };
        if dwell_word {
            self.buf.push_str(" P");
            self.seconds(c.dwell, dwell_ms);
        }
        let f = self.cycle_feed(c.feed, true);
        self.buf.push(' ');
        self.buf.push_str(&f);
        self.motion = None;
    }

    /// LinuxCNC's rigid tap: `G0 Z` R, `G33.1 Z K` (the spindle synchronised, reversed at the
    /// bottom and back to R), `G0 Z` start. Not modal: each hole is whole.
    fn g33_1(&mut self, c: &Canned, out: &mut Vec<String>) {
        let lin = self.fmt.linear;
        self.start();
        self.buf.push_str("G0 Z");
        self.number(c.z_r, lin, false);
        out.push(self.buf.clone());
        self.start();
        self.buf.push_str("G33.1 Z");
        self.number(c.z_bottom, lin, false);
        self.buf.push_str(" K");
        self.number(c.pitch, lin.max(4), false);
        out.push(self.buf.clone());
        self.start();
        self.buf.push_str("G0 Z");
        self.number(c.z_start, lin, false);
        out.push(self.buf.clone());
        self.axes[2] = Some(round_to(c.z_start, lin));
        self.motion = Some(super::Motion::Rapid);
    }

    /// Sinumerik: the feed, then `MCALL CYCLE8x(RTP, RFP, SDIS, DP, DPR …)` and the hole's
    /// position, which calls it.
    fn siemens(&mut self, c: &Canned, modal: bool, out: &mut Vec<String>) {
        if !modal {
            let f = self.cycle_feed(c.feed, false);
            if !f.is_empty() {
                out.push(self.words(f.trim_end()).to_string());
            }
            let lin = self.fmt.linear;
            let n = |v: f64, dec: u32| {
                let mut s = String::new();
                write_fixed(&mut s, round_to(v, dec), dec);
                s
            };
            // RTP, RFP, SDIS, DP (absolute); DPR left empty: given, it would win.
            let mut args = vec![
                n(c.z_start, lin),
                n(c.z_top, lin),
                n(c.z_r - c.z_top, lin),
                n(c.z_bottom, lin),
            ];
            let dtb = n(c.dwell, 3);
            let (name, more): (&str, Vec<String>) = match c.kind {
                CannedKind::Drill => ("CYCLE81", vec![]),
                CannedKind::Spot => ("CYCLE82", vec![String::new(), dtb]),
                // FDEP (first depth, absolute), FDPR empty, DAM (each next peck), DTB, DTS,
                // FRF 1, VARI: 1 full retract between pecks (G83), 0 chip breaking (G73).
                CannedKind::Peck | CannedKind::ChipBreak => {
                    let vari = if c.kind == CannedKind::Peck { "1" } else { "0" };
                    let more = [String::new(), n(c.z_top - c.peck, lin), String::new(), n(c.peck, lin)];
                    (
                        "CYCLE83",
                        more.into_iter().chain(["0", "0", "1", vari].map(String::from)).collect(),
                    )
                }
                // DPR, DTB, SDAC (the spindle's direction after), MPIT, PIT (signed: the hand),
                // POSS, SST (tapping speed), SST1 (retract speed).
                CannedKind::Tap { rigid: true, left } => {
                    let pit = if left { -c.pitch } else { c.pitch };
                    let (sdac, s) = (if left { "4" } else { "3" }, n(c.rpm, 0));
                    let more = [
                        String::new(),
                        dtb,
                        sdac.into(),
                        String::new(),
                        n(pit, 4),
                        "0".into(),
                        s.clone(),
                        s,
                    ];
                    ("CYCLE84", more.into())
                }
                // DPR, DTB, SDR (direction out), SDAC (after), ENC 1: no encoder, the feed F.
                CannedKind::Tap { rigid: false, left } => {
                    let (sdr, sdac) = if left { ("3", "4") } else { ("4", "3") };
                    ("CYCLE840", vec![String::new(), dtb, sdr.into(), sdac.into(), "1".into()])
                }
                // DPR, DTB, FFR (feed in), RFF (feed out).
                CannedKind::Bore if c.dwell <= 0.0 => {
                    let f = n(c.feed, self.fmt.feed);
                    ("CYCLE85", vec![String::new(), dtb, f.clone(), f])
                }
                CannedKind::Bore => ("CYCLE89", vec![String::new(), dtb]),
                // DPR, DTB, SDIR 3, RPA (lift-off in X, signed), RPO, RPAP, POSS (orientation):
                // with no lift-off, the spindle stopped oriented and drawn straight out.
                CannedKind::BoreStop | CannedKind::FineBore => {
                    let rpa = if c.kind == CannedKind::FineBore { -c.shift } else { 0.0 };
                    let more = [
                        String::new(),
                        dtb,
                        "3".into(),
                        n(rpa, lin),
                        n(0.0, lin),
                        n(0.0, lin),
                        "0".into(),
                    ];
                    ("CYCLE86", more.into())
                }
            };
            args.extend(more);
            while args.last().is_some_and(String::is_empty) {
                args.pop();
            }
            self.start();
            self.buf.push_str("MCALL ");
            self.buf.push_str(name);
            self.buf.push('(');
            self.buf.push_str(&args.join(","));
            self.buf.push(')');
            out.push(self.buf.clone());
        }
        self.start();
        self.hole_xy(c, true);
        self.motion = None;
    }

    /// Heidenhain: `CYCL DEF n` with its Q parameters (`~`-continued), then `L X Y FMAX M99`.
    fn heidenhain(&mut self, c: &Canned, modal: bool, out: &mut Vec<String>) {
        if !modal {
            let (lin, fd) = (self.fmt.linear, self.fmt.feed);
            let depth = c.z_bottom - c.z_top;
            let (clear, top, second) = (c.z_r - c.z_top, c.z_top, c.z_start - c.z_top);
            type Q = (u32, f64, u32, &'static str);
            let setup: Q = (200, clear, lin, "SET-UP CLEARANCE");
            let dep: Q = (201, depth, lin, "DEPTH");
            let feed: Q = (206, c.feed, fd, "FEED RATE FOR PLNGNG");
            let surf: Q = (203, top, lin, "SURFACE COORDINATE");
            let sec: Q = (204, second, lin, "2ND SET-UP CLEARANCE");
            let dwell: Q = (211, c.dwell, 3, "DWELL TIME AT DEPTH");
            let (title, q): (&str, Vec<Q>) = match c.kind {
                CannedKind::Drill | CannedKind::Spot | CannedKind::Peck => {
                    let plunge = if c.kind == CannedKind::Peck { c.peck } else { -depth };
                    let dwell = if c.kind == CannedKind::Spot { c.dwell } else { 0.0 };
                    let q = vec![
                        setup,
                        dep,
                        feed,
                        (202, plunge, lin, "PLUNGING DEPTH"),
                        (210, 0.0, 0, "DWELL TIME AT TOP"),
                        surf,
                        sec,
                        (211, dwell, 3, "DWELL TIME AT DEPTH"),
                    ];
                    ("200 DRILLING", q)
                }
                // Chip breaking: 99 breaks (the most) before a full retract, 0.2 back each.
                CannedKind::ChipBreak => {
                    let q = vec![
                        setup,
                        dep,
                        feed,
                        (202, c.peck, lin, "PLUNGING DEPTH"),
                        (210, 0.0, 0, "DWELL TIME AT TOP"),
                        surf,
                        sec,
                        (212, 0.0, lin, "DECREMENT"),
                        (213, 99.0, 0, "NR OF BREAKS"),
                        (205, 0.0, lin, "MIN. PLUNGING DEPTH"),
                        dwell,
                        (208, 0.0, fd, "RETRACTION FEED RATE"),
                        (256, 0.2, lin, "DIST FOR CHIP BRKNG"),
                    ];
                    ("203 UNIVERSAL DRILLING", q)
                }
                // Floating holder: the hand is the spindle's (M4 turns a left-hand tap).
                CannedKind::Tap { rigid: false, .. } => ("206 TAPPING NEW", vec![setup, dep, feed, dwell, surf, sec]),
                // Rigid: the pitch's sign is the hand.
                CannedKind::Tap { rigid: true, left } => {
                    let pitch = if left { -c.pitch } else { c.pitch };
                    (
                        "207 RIGID TAPPING NEW",
                        vec![setup, dep, (239, pitch, 4, "THREAD PITCH"), surf, sec],
                    )
                }
                CannedKind::Bore => {
                    let out: Q = (208, c.feed, fd, "RETRACTION FEED RATE");
                    ("201 REAMING", vec![setup, dep, feed, dwell, out, surf, sec])
                }
                // Oriented at 0°, disengaged towards -X (Q214 1) for a fine bore, not at all
                // (0) where the CL only stops the spindle; out at the plunging feed (Q208 0).
                CannedKind::BoreStop | CannedKind::FineBore => {
                    let dir = if c.kind == CannedKind::FineBore { 1.0 } else { 0.0 };
                    let q = vec![
                        setup,
                        dep,
                        feed,
                        dwell,
                        (208, 0.0, fd, "RETRACTION FEED RATE"),
                        surf,
                        sec,
                        (214, dir, 0, "DISENGAGING DIRECTN"),
                        (336, 0.0, 3, "ANGLE OF SPINDLE"),
                    ];
                    ("202 BORING", q)
                }
            };
            self.start();
            self.buf.push_str("CYCL DEF ");
            self.buf.push_str(title);
            self.buf.push_str(" ~");
            out.push(self.buf.clone());
            for (k, (n, v, dec, name)) in q.iter().enumerate() {
                self.buf.clear();
                self.buf.push_str("  Q");
                self.buf.push_str(itoa::Buffer::new().format(*n));
                self.buf.push('=');
                self.number(*v, *dec, true);
                self.buf.push_str(" ;");
                self.buf.push_str(name);
                if k + 1 < q.len() {
                    self.buf.push_str(" ~");
                }
                out.push(self.buf.clone());
            }
        }
        self.start();
        self.buf.push_str("L ");
        self.hole_xy(c, true);
        self.buf.push_str("FMAX M99");
    }

    /// The line that switches a modal canned cycle off, if the control needs one.
    pub fn canned_off(&mut self) -> Option<String> {
        self.motion = None;
        match self.d.cycles {
            Cycles::Iso { .. } => Some(self.words("G80").to_string()),
            Cycles::Siemens => Some(self.words("MCALL").to_string()),
            Cycles::Heidenhain => None,
        }
    }
}
