//! A dialect's templates at the program's events: the variables they see, and their lines
//! written as blocks. An event with a template writes it in place of the dialect's own words
//! (tool change, TCP on and off) or beside them (program start and end, operations, the first
//! move of a tool, tilted planes).

use super::Emitter;
use crate::diag::{Code, Diagnostic, Severity};
use crate::nc::templates::Vars;
use crate::post::Sink;
use crate::post::Stop;

impl<S: Sink + ?Sized> Emitter<'_, S> {
    /// The variables as the program stands: the tool in the spindle, its length and (from the
    /// tool table) diameter, the tool readied next, the spindle speed, the work offset …
    fn template_vars(&self) -> Vars {
        let mut v = Vars::default();
        let diameter = self
            .tool
            .number()
            .and_then(|t| self.o.tool_table.as_ref()?.get(t)?.diameter);
        v.set_opt("tool", self.tool.number())
            .set("length", self.tool.setup().tool_length)
            .set_opt("diameter", diameter)
            .set_opt("next_tool", self.tool.next())
            .set_opt("spindle_speed", self.spindle.rpm().map(|s| s.round() as i64))
            .set("work_offset", self.o.wcs_word().unwrap_or("").to_string())
            .set("program_number", self.o.program_number)
            .set("machine", self.m.id.clone())
            .set("date", crate::text::utc_now())
            .set("units", self.m.units.as_str())
            // The CL's text: it may not close the template's comment or start a block.
            .set_opt("operation", self.tool.operation().map(crate::nc::comment_safe))
            .set("tolerance", self.o.tolerance)
            .set("dialect", self.o.dialect.name.clone());
        v
    }

    /// Writes the dialect's template for `event` (its variables as now, then `set`'s), each
    /// line a block. `Ok(false)`: the dialect has none. A render that fails is an error at CL
    /// `line` and writes nothing.
    pub(super) fn template_with(&mut self, event: &str, line: Option<u32>, set: impl FnOnce(&mut Vars)) -> Result<bool, Stop> {
        let d = self.o.dialect.clone();
        if !d.templates.has(event) {
            return Ok(false);
        }
        let mut vars = self.template_vars();
        set(&mut vars);
        match d.templates.render(event, &vars) {
            Some(Ok(lines)) => {
                for l in lines {
                    let w = self.f.words(&l).to_string();
                    self.out(&w)?;
                }
            }
            Some(Err(e)) => {
                self.note(Diagnostic::new(Code::Template, Severity::Error, line, format!("dialect {}: {e}: nothing written", d.name)))?;
            }
            None => return Ok(false),
        }
        Ok(true)
    }

    /// The lines of `event`'s template, not yet written (the footer places them).
    pub(super) fn rendered(&mut self, event: &str) -> Result<Vec<String>, Stop> {
        let d = self.o.dialect.clone();
        match d.templates.render(event, &self.template_vars()) {
            Some(Ok(lines)) => Ok(lines),
            Some(Err(e)) => {
                self.note(Diagnostic::new(Code::Template, Severity::Error, None, format!("dialect {}: {e}: nothing written", d.name)))?;
                Ok(Vec::new())
            }
            None => Ok(Vec::new()),
        }
    }

    pub(super) fn template(&mut self, event: &str, line: Option<u32>) -> Result<bool, Stop> {
        self.template_with(event, line, |_| {})
    }
}
