//! Reads NC back into motion blocks, for `kinepost verify`: word address (Fanuc-like; Siemens
//! 840D's `TRAORI`, `MCALL` cycles and `CYCLE800`) and Heidenhain conversational (from its
//! `BEGIN PGM`): modal axis values after each block, motion kind, units, TCP state. Streaming,
//! one line at a time.

use crate::kinematics::Units;

/// The work coordinate systems a program may select (G54–G59), in order.
pub const WCS_CODES: [&str; 6] = ["G54", "G55", "G56", "G57", "G58", "G59"];

#[derive(Clone, Debug, PartialEq)]
pub struct NcBlock {
    pub line: u32,
    pub rapid: bool,
    /// X Y Z A B C after this block (modal), in the program's units and degrees; None until set.
    pub axes: [Option<f64>; 6],
    pub units: Units,
    pub tcp: bool,
    /// The tilted working plane the block's X Y Z are in, if any.
    pub plane: Option<Plane>,
    /// The work coordinate system in force (`G54` … `G59`), once the program selects one.
    pub wcs: Option<&'static str>,
    pub comment: String,
}

/// A tilted working plane as a program sets it: X Y Z of a block in it are `origin + F · xyz`
/// in the untilted program coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plane {
    pub origin: [f64; 3],
    /// `F`; `None`: a dynamic work offset (Haas G254), whose frame the rotaries make.
    pub frame: Option<nalgebra::Matrix3<f64>>,
}

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("NC line {line}: {problem}")]
    Unsupported { line: u32, problem: String },
    #[error("reading NC: {0}")]
    Io(#[from] std::io::Error),
}

/// An ISO canned drilling cycle in force (G81–G89 until G80 or another motion word).
#[derive(Clone, Copy, Debug)]
struct Cycle {
    /// Z of the hole's bottom and of the R plane, and the level before the cycle began (G98
    /// returns there, G99 to R).
    bottom: Option<f64>,
    r: Option<f64>,
    initial: Option<f64>,
}

pub struct NcReader<R> {
    input: R,
    /// Blocks one line expanded into (a canned cycle's moves), handed out in order.
    pending: std::collections::VecDeque<NcBlock>,
    cycle: Option<Cycle>,
    /// G98 (true, the default) or G99.
    return_initial: bool,
    line: u32,
    buf: String,
    axes: [Option<f64>; 6],
    rapid: bool,
    units: Units,
    tcp: bool,
    plane: Option<Plane>,
    wcs: Option<&'static str>,
    incremental: bool,
    /// A `%` after program text ends the tape: what follows is not part of the program.
    percents: u32,
    content: bool,
    /// A Heidenhain conversational program (it began with `BEGIN PGM`).
    conversational: bool,
    /// Heidenhain `CYCL DEF 200`: the Q parameters read so far while its `~` lines go on, and
    /// the cycle it defines, which each `M99` block then drills.
    cycl_def: Option<Vec<(u32, f64)>>,
    cycl: Option<Cycle>,
}

impl<R: std::io::BufRead> NcReader<R> {
    pub fn new(input: R, default_units: Units) -> Self {
        NcReader {
            input,
            pending: std::collections::VecDeque::new(),
            cycle: None,
            return_initial: true,
            line: 0,
            buf: String::new(),
            axes: [None; 6],
            rapid: true,
            units: default_units,
            tcp: false,
            plane: None,
            wcs: None,
            incremental: false,
            percents: 0,
            content: false,
            conversational: false,
            cycl_def: None,
            cycl: None,
        }
    }

    /// The next motion block, skipping everything else.
    pub fn next_block(&mut self) -> Result<Option<NcBlock>, Error> {
        loop {
            if let Some(b) = self.pending.pop_front() {
                return Ok(Some(b));
            }
            self.buf.clear();
            if self.input.read_line(&mut self.buf)? == 0 {
                return Ok(None);
            }
            self.line += 1;
            let raw = std::mem::take(&mut self.buf);
            let r = self.parse_line(&raw);
            self.buf = raw;
            match r {
                Ok(Some(b)) => self.pending.push_back(b),
                Ok(None) => {}
                // Text before the program (a tape's leader, an NX listing header before the
                // first `%`) is not part of it.
                Err(_) if !self.content && self.percents == 0 => {}
                Err(e) => return Err(e),
            }
        }
    }

    /// Siemens `CYCLE800(_FR,_TC,_ST,_MODE,_X0,_Y0,_Z0,_A,_B,_C,_X1,_Y1,_Z1,_DIR …)`, axis by
    /// axis X Y' Z'' (mode 57) with reference point and zero point; `CYCLE800()` resets.
    fn cycle800(&mut self, args: &str) -> Result<(), Error> {
        if args.trim().is_empty() {
            self.plane = None;
            return Ok(());
        }
        let f: Vec<&str> = args.split(',').map(str::trim).collect();
        let num = |k: usize| -> Result<f64, Error> {
            match f.get(k).copied().unwrap_or("") {
                "" => Ok(0.0),
                s => s
                    .parse::<f64>()
                    .map_err(|_| self.unsupported(format!("CYCLE800 argument {} is not a number: {s:?}", k + 1))),
            }
        };
        if num(3)? != 57.0 {
            return Err(self.unsupported("CYCLE800 modes other than 57 (axis by axis X Y Z) are not read".into()));
        }
        let frame = super::plane::from_xyz([num(7)?, num(8)?, num(9)?].map(f64::to_radians));
        let (x0, x1) = (
            nalgebra::Vector3::new(num(4)?, num(5)?, num(6)?),
            nalgebra::Vector3::new(num(10)?, num(11)?, num(12)?),
        );
        let o = x0 + frame * x1;
        self.plane = Some(Plane {
            origin: [o.x, o.y, o.z],
            frame: Some(frame),
        });
        Ok(())
    }

    /// Siemens' modal call `MCALL CYCLE81…89|840(RTP, RFP, SDIS, DP …)`: every positioning block
    /// after it drills as ISO G81 with R at RFP + SDIS, the bottom at DP and the return to RTP;
    /// a bare `MCALL` ends it. Pecks, dwells, taps and bores do not move the tip elsewhere (a
    /// fine bore's lift-off aside, a fraction of a millimetre).
    fn mcall(&mut self, call: &str) -> Result<(), Error> {
        if call.is_empty() {
            self.cycle = None;
            return Ok(());
        }
        let upper = call.to_ascii_uppercase();
        let args = [
            "CYCLE81(",
            "CYCLE82(",
            "CYCLE83(",
            "CYCLE84(",
            "CYCLE840(",
            "CYCLE85(",
            "CYCLE86(",
            "CYCLE89(",
        ]
        .iter()
        .find_map(|c| upper.strip_prefix(c))
        .ok_or_else(|| self.unsupported(format!("MCALL {call}: only CYCLE81 to 86, 89 and 840 are read")))?;
        let args: Vec<&str> = args.strip_suffix(')').unwrap_or(args).split(',').map(str::trim).collect();
        let arg = |k: usize, name: &str| {
            args.get(k)
                .and_then(|a| a.parse::<f64>().ok())
                .ok_or_else(|| self.unsupported(format!("MCALL {call}: {name} (argument {}) is not a number", k + 1)))
        };
        let (rtp, rfp, sdis, dp) = (arg(0, "RTP")?, arg(1, "RFP")?, arg(2, "SDIS")?, arg(3, "DP")?);
        self.return_initial = true;
        self.cycle = Some(Cycle {
            bottom: Some(dp),
            r: Some(rfp + sdis),
            initial: Some(rtp),
        });
        Ok(())
    }

    /// One Heidenhain line (its number already stripped): `L` and `C` blocks (`FMAX` is rapid for
    /// its block, an `F` feed), `CYCL DEF 200` with its `~`-continued Q parameters and the `M99`
    /// that drills it, `PLANE SPATIAL` / `PLANE RESET`, `FUNCTION TCPM` / `FUNCTION RESET TCPM`,
    /// `BEGIN PGM … MM|INCH` / `END PGM`; the rest (`TOOL CALL`, `CC`, M words) moves nothing.
    fn conversational_line(&mut self, line: &str) -> Result<Option<NcBlock>, Error> {
        let continued = line.trim_end().ends_with('~');
        let (code, comment) = match line.split_once(';') {
            Some((c, k)) => (c, k.trim_end_matches([' ', '~', '\r', '\n'])),
            None => (line, ""),
        };
        let code = code.trim().trim_end_matches('~').trim_end().to_ascii_uppercase();
        let words: Vec<&str> = code.split_whitespace().collect();
        if self.cycl_def.is_some() {
            return self.cycl_def_line(&words, continued).map(|_| None);
        }
        match words.as_slice() {
            ["BEGIN", "PGM", .., u] => self.units = if *u == "INCH" { Units::Inch } else { Units::Mm },
            ["END", "PGM", ..] => self.percents = u32::MAX, // what follows is no part of the program
            ["FUNCTION", "TCPM", ..] => self.tcp = true,
            ["FUNCTION", "RESET", "TCPM", ..] => self.tcp = false,
            ["PLANE", rest @ ..] => self.plane_words(rest)?,
            ["CYCL", "DEF", rest @ ..] => self.cycl_def_start(rest, continued)?,
            [polar @ ("LP" | "CP" | "RND" | "CHF"), ..] => {
                return Err(self.unsupported(format!("{polar}: polar moves, roundings and chamfers are not read")));
            }
            ["L" | "C" | "CR" | "CT", rest @ ..] => return self.conversational_move(rest, comment),
            _ => {}
        }
        Ok(None)
    }

    /// Heidenhain `PLANE SPATIAL SPA… SPB… SPC…` and `PLANE RESET` (the words after `PLANE`).
    fn plane_words(&mut self, words: &[&str]) -> Result<(), Error> {
        match words {
            ["RESET", ..] => self.plane = None,
            ["SPATIAL", rest @ ..] => {
                let mut a = [0.0; 3];
                for (k, name) in ["SPA", "SPB", "SPC"].iter().enumerate() {
                    let w = rest
                        .iter()
                        .find(|w| w.starts_with(name))
                        .ok_or_else(|| self.unsupported(format!("PLANE SPATIAL without {name}")))?;
                    a[k] = self.number(w, 3)?.to_radians();
                }
                self.plane = Some(Plane {
                    origin: [0.0; 3],
                    frame: Some(super::plane::from_spatial(a)),
                });
            }
            [other, ..] => {
                return Err(self.unsupported(format!("PLANE {other}: only PLANE SPATIAL and PLANE RESET are read")));
            }
            [] => {}
        }
        Ok(())
    }

    /// `CYCL DEF n` (the words after `CYCL DEF`): 200 opens a definition whose Q parameters
    /// follow on `~`-continued lines; 9 (a dwell) moves nothing.
    fn cycl_def_start(&mut self, words: &[&str], continued: bool) -> Result<(), Error> {
        match words {
            ["200" | "201" | "202" | "203" | "206" | "207", ..] => {
                self.cycl_def = Some(Vec::new());
                if !continued {
                    return Err(self.unsupported("CYCL DEF 200 without its Q parameters".into()));
                }
            }
            ["9.0" | "9.1", ..] => {}
            [other, ..] => {
                return Err(self.unsupported(format!("CYCL DEF {other}: only cycles 200 to 203, 206 and 207 are read")));
            }
            [] => {}
        }
        Ok(())
    }

    /// A line of an open `CYCL DEF 200`: its `Qn=v` words; the last line (not `~`-continued)
    /// closes the definition into the cycle that `M99` drills.
    fn cycl_def_line(&mut self, words: &[&str], continued: bool) -> Result<(), Error> {
        if let Some(def) = self.cycl_def.as_mut() {
            def.extend(words.iter().filter_map(|w| q_parameter(w)));
        }
        if continued {
            return Ok(());
        }
        let def = self.cycl_def.take().unwrap_or_default();
        let q = |n: u32| def.iter().rev().find(|(k, _)| *k == n).map(|(_, v)| *v);
        let (Some(clear), Some(depth), Some(surface)) = (q(200), q(201), q(203)) else {
            return Err(self.unsupported("CYCL DEF 200 without Q200, Q201 and Q203".into()));
        };
        // Down to Q203 + Q201 from the set-up clearance, back to the 2nd one.
        let second = q(204).unwrap_or(0.0).max(clear);
        self.cycl = Some(Cycle {
            bottom: Some(surface + depth),
            r: Some(surface + clear),
            initial: Some(surface + second),
        });
        Ok(())
    }

    /// An `L`/`C`/`CR`/`CT` block (the words after it): absolute X Y Z A B C words; with `M99`,
    /// the defined cycle drilled where it ends.
    fn conversational_move(&mut self, words: &[&str], comment: &str) -> Result<Option<NcBlock>, Error> {
        let mut vals: [Option<f64>; 6] = [None; 6];
        let (mut rapid, mut call) = (false, false);
        for w in words {
            match *w {
                "FMAX" => rapid = true,
                "M99" => call = true,
                _ if w.starts_with('I') && w.get(1..2).is_some_and(|c| "XYZABC".contains(c)) => {
                    return Err(self.unsupported(format!("{w}: incremental positions are not supported")));
                }
                _ => {
                    if let Some(k) = w.get(..1).and_then(|c| "XYZABC".find(c))
                        && w.len() > 1
                        && (w.as_bytes()[1] == b'+' || w.as_bytes()[1] == b'-' || w.as_bytes()[1].is_ascii_digit())
                    {
                        vals[k] = Some(self.number(w, 1)?);
                    }
                }
            }
        }
        if vals.iter().all(|v| v.is_none()) && !call {
            return Ok(None);
        }
        self.set_axes(&vals);
        let (Some(c), true) = (self.cycl, call) else {
            return Ok(Some(self.block(rapid, comment)));
        };
        // Over the hole, then as G81 with G98.
        if let (Some(bottom), Some(r), Some(back)) = (c.bottom, c.r, c.initial) {
            self.drill(r, bottom, back, comment);
        }
        Ok(None)
    }

    /// The number after the first `at` bytes of a conversational word.
    fn number(&self, w: &str, at: usize) -> Result<f64, Error> {
        w[at..]
            .parse::<f64>()
            .map_err(|_| self.unsupported(format!("{w}: not a number after {}", &w[..at])))
    }

    fn unsupported(&self, problem: String) -> Error {
        Error::Unsupported {
            line: self.line,
            problem,
        }
    }

    fn parse_line(&mut self, raw: &str) -> Result<Option<NcBlock>, Error> {
        if let Some(r) = self.statement_line(raw) {
            return r;
        }
        let (code, comment) = split_comment(raw);
        let code = code.trim();
        if self.outside_program(code) {
            return Ok(None);
        }
        let words = self.words(code)?;
        // The line parsed: from here on the program has begun.
        self.content = true;
        self.apply(words, &comment)
    }

    /// The lines that are no word address: Siemens' `CYCLE800(…)` (its parentheses are
    /// arguments, not a comment) and `MCALL`, and every line of a Heidenhain conversational
    /// program. `None` for the others.
    fn statement_line(&mut self, raw: &str) -> Option<Result<Option<NcBlock>, Error>> {
        let bare = raw.trim_start();
        let bare = match bare.strip_prefix(['N', 'n']) {
            Some(r) if r.starts_with(|c: char| c.is_ascii_digit()) => {
                r.trim_start_matches(|c: char| c.is_ascii_digit()).trim_start()
            }
            _ => bare,
        };
        if bare.get(..9).is_some_and(|h| h.eq_ignore_ascii_case("CYCLE800(")) {
            let args = bare[9..].split(';').next().unwrap_or("").trim_end();
            self.content = true;
            return Some(self.cycle800(args.strip_suffix(')').unwrap_or(args)).map(|_| None));
        }
        // Heidenhain's conversational language is no word address (its `L X+… C+…` read as
        // words failed at "C without a value"): its own reader from `BEGIN PGM` on.
        let unnumbered = bare.trim_start_matches(|c: char| c.is_ascii_digit()).trim_start();
        if !self.content && unnumbered.get(..9).is_some_and(|h| h.eq_ignore_ascii_case("BEGIN PGM")) {
            self.conversational = true;
        }
        if self.conversational {
            self.content = true;
            return Some(self.conversational_line(unnumbered));
        }
        if bare.get(..5).is_some_and(|h| h.eq_ignore_ascii_case("MCALL")) {
            let call = bare[5..].split(';').next().unwrap_or("").trim();
            self.content = true;
            return Some(self.mcall(call).map(|_| None));
        }
        None
    }

    /// Whether a line's code (comment stripped) is outside the program proper: `%` marks
    /// (the second ends the tape), anything after the end, empty lines and `O` numbers.
    fn outside_program(&mut self, code: &str) -> bool {
        if code.starts_with('%') {
            self.percents += 1;
            if self.content {
                self.percents = u32::MAX;
            }
            return true;
        }
        self.percents == u32::MAX || code.is_empty() || code.starts_with('O')
    }

    /// Reads a block's words (upper-case, comment stripped). G words and Siemens' `TRAORI` /
    /// `TRAFOOF` set the modal state as they come; the rest is returned.
    fn words(&mut self, code: &str) -> Result<Words, Error> {
        let mut w = Words::default();
        let b = code.as_bytes();
        let mut i = 0;
        while i < b.len() {
            let c = b[i] as char;
            if !c.is_ascii_alphabetic() {
                i += 1;
                continue;
            }
            if let Some((len, on)) = transformation(code, i) {
                self.tcp = on;
                i += len;
                continue;
            }
            // Siemens' 3D cutter compensation on and off: the path stays the words'.
            if let Some(kw) = ["CUT3DC", "CUT2D"].into_iter().find(|kw| code[i..].starts_with(kw)) {
                i += kw.len();
                continue;
            }
            let end = value_end(b, i + 1);
            let num = code[i + 1..end].replace(' ', "");
            i = end;
            if num.is_empty() {
                if matches!(c, 'X' | 'Y' | 'Z' | 'A' | 'B' | 'C') {
                    return Err(self.unsupported(format!("{c} without a value (macro expressions are not supported)")));
                }
                continue;
            }
            let Ok(v) = num.parse::<f64>() else { continue };
            match c {
                'G' => self.g_word(v, &mut w),
                'X' => w.vals[0] = Some(v),
                'Y' => w.vals[1] = Some(v),
                'Z' => w.vals[2] = Some(v),
                'A' => w.vals[3] = Some(v),
                'B' => w.vals[4] = Some(v),
                'C' => w.vals[5] = Some(v),
                'R' => w.r = Some(v),
                'I' => w.ijk[0] = Some(v),
                'J' => w.ijk[1] = Some(v),
                'K' => w.ijk[2] = Some(v),
                _ => {}
            }
        }
        Ok(w)
    }

    /// One G word: the modal groups verify follows (motion, cycles and their return level, units,
    /// absolute/incremental, TCP, tilted planes) change the state; the block kinds that move
    /// nothing kinepost checks (machine coordinates, settings, a plane definition) mark `w`.
    fn g_word(&mut self, v: f64, w: &mut Words) {
        // Keyed by ten times the number: G2 is 20, G20 is 200, G43.4 is 434.
        match (v * 10.0).round() as i64 {
            0 => {
                self.rapid = true;
                self.cycle = None;
            }
            10 | 20 | 30 => {
                self.rapid = false;
                self.cycle = None;
            }
            800 => self.cycle = None,
            980 => self.return_initial = true,
            990 => self.return_initial = false,
            // Drilling cycles whose motion is rapid to R, feed to Z, back out: the tap,
            // bore and fine-bore variants differ only in spindle and retract feed.
            730 | 740 | 760 | 810 | 820 | 830 | 840 | 850 | 860 | 890 => w.starts_cycle = true,
            // LinuxCNC's rigid tap: from where the tool is to Z and back.
            331 => w.sync_tap = true,
            200 => self.units = Units::Inch,
            210 => self.units = Units::Mm,
            900 => self.incremental = false,
            910 => self.incremental = true,
            434 | 435 | 2340 => self.tcp = true,
            490 => self.tcp = false,
            280 | 300 | 530 => w.machine_coords = true,
            540 | 550 | 560 | 570 | 580 | 590 => {
                self.wcs = Some(WCS_CODES[((v * 10.0).round() as usize - 540) / 10]);
            }
            682 => w.plane_def = true,
            690 | 2550 => self.plane = None,
            2540 => {
                self.plane = Some(Plane {
                    origin: [0.0; 3],
                    frame: None,
                })
            }
            40 | 100 | 520 | 920 => w.setting = true,
            _ => {}
        }
    }

    /// What a parsed word-address block does: start a canned cycle, define a tilted plane, drill
    /// a hole of the cycle in force, or move.
    fn apply(&mut self, w: Words, comment: &str) -> Result<Option<NcBlock>, Error> {
        if w.starts_cycle {
            let initial = match self.cycle {
                Some(c) => c.initial,
                None => self.axes[2],
            };
            self.cycle = Some(Cycle {
                bottom: None,
                r: None,
                initial,
            });
        }
        if w.plane_def {
            // G68.2 X Y Z (origin) I J K (Euler Z X' Z'', degrees).
            let a = w.ijk.map(|v| v.unwrap_or(0.0).to_radians());
            self.plane = Some(Plane {
                origin: [0, 1, 2].map(|k| w.vals[k].unwrap_or(0.0)),
                frame: Some(super::plane::from_zxz(a)),
            });
            return Ok(None);
        }
        if w.vals.iter().all(|v| v.is_none()) || w.setting {
            return Ok(None);
        }
        if w.machine_coords {
            // G28/G30/G53: positions in machine coordinates or via a reference point.
            for (k, v) in w.vals.iter().enumerate() {
                if v.is_some() {
                    self.axes[k] = None;
                }
            }
            return Ok(None);
        }
        if self.incremental {
            return Err(self.unsupported("G91 incremental motion is not supported".into()));
        }
        if self.cycle.is_some() {
            return self.cycle_hole(&w, comment).map(|_| None);
        }
        if w.sync_tap {
            let (Some(from), Some(bottom)) = (self.axes[2], w.vals[2]) else {
                return Err(self.unsupported("G33.1 without Z, or from an unknown Z".into()));
            };
            self.drill(from, bottom, from, comment);
            return Ok(None);
        }
        self.set_axes(&w.vals);
        Ok(Some(self.block(self.rapid, comment)))
    }

    /// A block while a canned cycle is in force: its Z and R words set the cycle's levels, and
    /// it drills at its X Y (and rotaries).
    fn cycle_hole(&mut self, w: &Words, comment: &str) -> Result<(), Error> {
        let Some(c) = self.cycle.as_mut() else { return Ok(()) };
        c.bottom = w.vals[2].or(c.bottom);
        c.r = w.r.or(c.r);
        let c = *c;
        let (Some(bottom), Some(r)) = (c.bottom, c.r) else {
            return Err(self.unsupported("canned cycle without Z or R".into()));
        };
        for k in [0, 1, 3, 4, 5] {
            if w.vals[k].is_some() {
                self.axes[k] = w.vals[k];
            }
        }
        let back = if self.return_initial { c.initial.unwrap_or(r) } else { r };
        self.drill(r, bottom, back, comment);
        Ok(())
    }

    /// The axis words a block gives; the others keep their values.
    fn set_axes(&mut self, vals: &[Option<f64>; 6]) {
        for (k, v) in vals.iter().enumerate() {
            if v.is_some() {
                self.axes[k] = *v;
            }
        }
    }

    /// A block to where the axes now stand, in the program's state.
    fn block(&self, rapid: bool, comment: &str) -> NcBlock {
        NcBlock {
            line: self.line,
            rapid,
            axes: self.axes,
            units: self.units,
            tcp: self.tcp,
            plane: self.plane,
            wcs: self.wcs,
            comment: comment.trim().to_string(),
        }
    }

    /// The moves a drilling cycle makes at the X Y the axes stand at: rapid there (at the height
    /// it was called from) and to `r`, feed to `bottom`, rapid back to `back`.
    fn drill(&mut self, r: f64, bottom: f64, back: f64, comment: &str) {
        for (z, rapid) in [(self.axes[2].unwrap_or(back), true), (r, true), (bottom, false), (back, true)] {
            self.axes[2] = Some(z);
            self.pending.push_back(self.block(rapid, comment));
        }
    }
}

/// A word-address block's words beyond the modal state they set.
#[derive(Default)]
struct Words {
    /// X Y Z A B C.
    vals: [Option<f64>; 6],
    /// G28, G30, G53: positions in machine coordinates or via a reference point.
    machine_coords: bool,
    /// G4, G10, G52, G92: a dwell or a setting, no motion.
    setting: bool,
    r: Option<f64>,
    ijk: [Option<f64>; 3],
    /// G68.2: a tilted plane defined by X Y Z and I J K.
    plane_def: bool,
    /// A drilling cycle begins (G73, G74, G76, G81–G86, G89).
    starts_cycle: bool,
    /// G33.1: a rigid tap from the current Z to the block's and back.
    sync_tap: bool,
}

/// Splits a word-address line at its comments: the code, upper-case, up to a `;` outside
/// parentheses, and the text inside them.
fn split_comment(raw: &str) -> (String, String) {
    let mut comment = String::new();
    let mut code = String::with_capacity(raw.len());
    let mut depth = 0;
    for c in raw.chars() {
        match c {
            '(' => depth += 1,
            ')' if depth > 0 => depth -= 1,
            ';' if depth == 0 => break,
            _ if depth > 0 => comment.push(c),
            _ => code.push(c.to_ascii_uppercase()),
        }
    }
    (code, comment)
}

/// Siemens' transformation on and off at byte `i` of `code`: words, not addresses (T R A …).
/// Its length and whether it turns TCP on.
fn transformation(code: &str, i: usize) -> Option<(usize, bool)> {
    let b = code.as_bytes();
    [("TRAORI", true), ("TRAFOOF", false)]
        .into_iter()
        .find(|(kw, _)| code[i..].starts_with(kw) && !b.get(i + kw.len()).is_some_and(u8::is_ascii_alphabetic))
        .map(|(kw, on)| (kw.len(), on))
}

/// Where the value of an address starting at `start` ends: digits, sign, point and blanks, up
/// to a blank that separates it from the next address.
fn value_end(b: &[u8], start: usize) -> usize {
    let mut j = start;
    while j < b.len() && (b[j].is_ascii_digit() || matches!(b[j], b'.' | b'-' | b'+' | b' ')) {
        if b[j] == b' ' && j > start && b[j - 1] != b' ' && j + 1 < b.len() && b[j + 1].is_ascii_alphabetic() {
            break;
        }
        j += 1;
    }
    j
}

/// A Heidenhain `Qn=v` word.
fn q_parameter(w: &str) -> Option<(u32, f64)> {
    let (q, v) = w.strip_prefix('Q')?.split_once('=')?;
    Some((q.parse::<u32>().ok()?, v.parse::<f64>().ok()?))
}
