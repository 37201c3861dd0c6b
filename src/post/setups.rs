//! `setups=work-offsets`: each distinct MCS of a program (NX `MSYS`) gets the next work offset
//! of the dialect, its origin measured from the first's; the program then says where to set it.
//! The one rule both the emitter and `verify` follow.

use super::source::{Item, ProgEvent, Source};
use super::Options;
use crate::kinematics::{Machine, Vec3};
use std::io::BufRead;

/// Origins closer than this (profile units) are the same offset.
const SAME: f64 = 1e-6;

/// The work offsets a program has used, the first (the program's own) at zero.
#[derive(Clone, Debug)]
pub struct WorkOffsets {
    /// The dialect's codes from the program's first on (`G54`, `G55` …).
    codes: Vec<String>,
    shifts: Vec<Vec3>,
}

/// Why an MCS keeps the first offset.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Refused {
    /// Turned against the first: a work offset holds no rotation here.
    Turned,
    /// Every code the dialect has is in use.
    Full,
}

impl WorkOffsets {
    /// `first`: the code the program selects; the rest follow it in `codes`.
    pub fn new(codes: &[String], first: &str) -> WorkOffsets {
        let at = codes.iter().position(|c| c == first).unwrap_or(0);
        WorkOffsets {
            codes: codes[at..].to_vec(),
            shifts: vec![Vec3::zeros()],
        }
    }

    /// The offset (index) for an MCS at `shift` from the first, a new one if it is new.
    pub fn pick(&mut self, shift: Vec3, turned: bool) -> Result<usize, Refused> {
        if turned {
            return Err(Refused::Turned);
        }
        if let Some(i) = self.shifts.iter().position(|s| (s - shift).amax() < SAME) {
            return Ok(i);
        }
        if self.shifts.len() >= self.codes.len() {
            return Err(Refused::Full);
        }
        self.shifts.push(shift);
        Ok(self.shifts.len() - 1)
    }

    pub fn code(&self, i: usize) -> &str {
        &self.codes[i]
    }

    pub fn shift(&self, i: usize) -> Vec3 {
        self.shifts[i]
    }

    /// The index of `code`, if the program has used it.
    pub fn index_of(&self, code: &str) -> Option<usize> {
        self.codes.iter().position(|c| c == code).filter(|i| *i < self.shifts.len())
    }

    /// Each offset after the first with its origin from the first: what the operator sets.
    pub fn listing(&self) -> impl Iterator<Item = (&str, Vec3)> + '_ {
        self.shifts.iter().enumerate().skip(1).map(|(i, s)| (self.codes[i].as_str(), *s))
    }

    pub fn first(&self) -> &str {
        &self.codes[0]
    }
}

/// `G55 = G54 + X100.000 Y0.000 Z0.000`: where the operator sets an offset.
pub(crate) fn offset_text(code: &str, first: &str, s: Vec3, dec: usize) -> String {
    format!("WORK OFFSET {code} = {first} + X{:.dec$} Y{:.dec$} Z{:.dec$}", s.x, s.y, s.z)
}

/// The header lines that list the offsets a program of several setups will select: a first
/// pass over a CL that can be read twice (a file, a job's spool). A CL read once lists each
/// where it is selected, and before its end.
pub fn header_lines<R: BufRead>(cl: R, m: &Machine, o: &Options) -> Result<Vec<String>, super::source::Error> {
    let first = o.wcs_word().unwrap_or("");
    let mut offsets = WorkOffsets::new(&o.dialect.work_coordinates, first);
    let mut src = Source::new(cl, m.units, o.cl_units, false)?;
    while let Some(item) = src.next_item()? {
        if let Item::Event(ProgEvent::Setup { shift, turned, .. }) = item {
            let _ = offsets.pick(shift, turned);
        }
    }
    let dec = crate::nc::Formats::for_dialect(&o.dialect, m.units).linear as usize;
    Ok(offsets.listing().map(|(code, s)| offset_text(code, offsets.first(), s, dec)).collect())
}
