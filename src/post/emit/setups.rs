//! `setups=work-offsets`: an operation in another MCS selects its work offset, and its X Y Z
//! words are measured from it (the formatter's shift); the program says where to set each. By
//! default (`setups=transform`) the change is only a comment: the points come taken into the
//! first MCS.

use super::Emitter;
use crate::diag::{Code, Diagnostic, Severity};
use crate::kinematics::Vec3;
use crate::post::setups::{Refused, offset_text};
use crate::post::{Error, Sink};
use crate::post::Stop;

impl<S: Sink + ?Sized> Emitter<'_, S> {
    /// The operation from `line` on is in an MCS at `shift` from the first (`turned`: not
    /// parallel to it): its offset is selected, or, where none can hold it, the first's with an
    /// error (its points are in the first's frame already: the cut is right, the offset not).
    pub(super) fn setup_change(&mut self, shift: Vec3, turned: bool, line: u32, taken: &str) -> Result<(), Error> {
        let Some(offsets) = self.frames.offsets() else {
            let c = self.f.comment(taken).to_string();
            return Ok(self.out(&c)?);
        };
        let picked = offsets.pick(shift, turned);
        // Refused: the first offset, the points taken into its frame.
        let i = picked.unwrap_or(0);
        let (first, code, s) = (offsets.first().to_string(), offsets.code(i).to_string(), offsets.shift(i));
        if let Err(why) = picked {
            let name = self.o.dialect.name.clone();
            let msg = match why {
                Refused::Turned => format!(
                    "setups=work-offsets: this operation's MCS is turned against the first, and a work offset on {name} holds no rotation: its points are written in {first}, taken into the first MCS"
                ),
                Refused::Full => format!(
                    "setups=work-offsets: every work offset of {name} is in use: this operation's points are written in {first}, taken into the first MCS"
                ),
            };
            self.note(Diagnostic::new(Code::CoordinateSystem, Severity::Error, Some(line), msg))?;
            let c = self.f.comment(taken).to_string();
            self.out(&c)?;
        }
        if !self.frames.select_offset(i) {
            return Ok(());
        }
        self.f.set_shift(s.into());
        let l = self.f.words(&code).to_string();
        self.out(&l)?;
        if i > 0 {
            let c = self.f.comment(&offset_text(&code, &first, s, self.f.fmt.linear as usize)).to_string();
            self.out(&c)?;
        }
        Ok(())
    }

    /// Before the program's end: each offset after the first, and where to set it.
    pub(super) fn list_work_offsets(&mut self) -> Result<(), Stop> {
        let Some(offsets) = self.frames.offsets() else {
            return Ok(());
        };
        let lines: Vec<String> =
            offsets.listing().map(|(code, s)| offset_text(code, offsets.first(), s, self.f.fmt.linear as usize)).collect();
        for l in lines {
            let c = self.f.comment(&l).to_string();
            self.out(&c)?;
        }
        Ok(())
    }
}
