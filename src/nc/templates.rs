//! A dialect's templates for the program's events (`[templates]` in its file): MiniJinja, with
//! no loader (no file or network access), a fuel bound on every render and a bound on what it
//! writes. Every variable a template names is checked when the dialect is read, so a typo is
//! refused with its line there, not found mid-program.

use minijinja::{Environment, UndefinedBehavior, Value};
use std::collections::BTreeMap;

/// The events a template can be written for, in the order the file format lists them.
pub const EVENTS: [&str; 10] = [
    "program_start",
    "program_end",
    "operation_start",
    "operation_end",
    "tool_change",
    "first_move",
    "tcp_on",
    "tcp_off",
    "plane_on",
    "plane_off",
];

/// What a template may name. A value the program does not know at the event is `none`.
pub const VARIABLES: [&str; 13] = [
    "tool",
    "length",
    "diameter",
    "next_tool",
    "spindle_speed",
    "work_offset",
    "program_number",
    "machine",
    "date",
    "units",
    "operation",
    "tolerance",
    "dialect",
];

/// MiniJinja's own functions a template may call.
const FUNCTIONS: [&str; 3] = ["range", "dict", "namespace"];

/// Instructions one render may spend: a loop over a big range runs out, a real template never.
const FUEL: u64 = 100_000;
/// Lines and bytes one event may write.
const MAX_LINES: usize = 64;
const MAX_BYTES: usize = 8 * 1024;

/// A dialect's compiled templates.
#[derive(Clone, Default)]
pub struct Templates {
    env: Option<Environment<'static>>,
    has: [bool; EVENTS.len()],
}

impl std::fmt::Debug for Templates {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let names: Vec<&str> = EVENTS.iter().zip(self.has).filter(|(_, h)| *h).map(|(e, _)| *e).collect();
        f.debug_struct("Templates").field("events", &names).finish()
    }
}

fn environment() -> Environment<'static> {
    let mut env = Environment::new();
    env.set_undefined_behavior(UndefinedBehavior::Strict);
    env.set_fuel(Some(FUEL));
    env
}

impl Templates {
    /// Compiles `sources` (event → template text). The error names the event, the line within
    /// the template and what is wrong: an unknown event, a syntax error, an unknown variable.
    pub fn compile(sources: &BTreeMap<String, String>) -> Result<Templates, String> {
        let mut env = environment();
        let mut has = [false; EVENTS.len()];
        for (event, text) in sources {
            let Some(i) = EVENTS.iter().position(|e| e == event) else {
                return Err(format!("templates.{event}: no such event (events: {})", EVENTS.join(", ")));
            };
            if text.len() > MAX_BYTES {
                return Err(format!("templates.{event}: longer than {MAX_BYTES} bytes"));
            }
            env.add_template_owned(event.clone(), text.clone()).map_err(|e| template_error(event, &e))?;
            let t = env.get_template(event).map_err(|e| template_error(event, &e))?;
            let mut unknown: Vec<String> = t
                .undeclared_variables(false)
                .into_iter()
                .filter(|v| !VARIABLES.contains(&v.as_str()) && !FUNCTIONS.contains(&v.as_str()))
                .collect();
            unknown.sort();
            if let Some(v) = unknown.first() {
                let line = text.lines().position(|l| l.contains(v.as_str())).map_or(1, |n| n + 1);
                return Err(format!(
                    "templates.{event}: line {line}: unknown variable {v:?} (variables: {})",
                    VARIABLES.join(", ")
                ));
            }
            // A trial with every variable set finds what only rendering can: an unknown filter
            // or test, a filter on the wrong kind of value, a loop that runs out of fuel, output
            // over its bounds or a line split where the template does not say; with plausible
            // values and with the longest and largest each may have.
            for vars in [Vars::sample(), Vars::worst()] {
                let text = t.render(Value::from_object(vars.0)).map_err(|e| template_error(event, &e))?;
                lines(event, &text)?;
            }
            has[i] = true;
        }
        let env = has.iter().any(|h| *h).then_some(env);
        Ok(Templates { env, has })
    }

    pub fn has(&self, event: &str) -> bool {
        EVENTS.iter().position(|e| *e == event).is_some_and(|i| self.has[i])
    }

    /// The event's lines (each one a block), or `None` when the dialect has no template for it.
    /// A render that fails (a filter on the wrong kind, out of fuel, too much output) is an error
    /// naming the event and the line.
    pub fn render(&self, event: &str, vars: &Vars) -> Option<Result<Vec<String>, String>> {
        if !self.has(event) {
            return None;
        }
        let env = self.env.as_ref()?;
        let t = match env.get_template(event) {
            Ok(t) => t,
            Err(e) => return Some(Err(template_error(event, &e))),
        };
        Some(match t.render(Value::from_object(vars.0.clone())) {
            Ok(text) => lines(event, &text),
            Err(e) => Err(template_error(event, &e)),
        })
    }
}

/// A render's text as blocks, within the bounds: a line break (the template's own) ends a
/// block; any other control character (a lone carriage return) is refused, so that nothing
/// starts a block the template did not write as a line.
fn lines(event: &str, text: &str) -> Result<Vec<String>, String> {
    if text.len() > MAX_BYTES {
        return Err(format!("templates.{event}: wrote more than {MAX_BYTES} bytes"));
    }
    let mut out = Vec::new();
    for l in text.split('\n').map(|l| l.strip_suffix('\r').unwrap_or(l)) {
        if let Some(c) = l.chars().find(|c| c.is_control() && *c != '\t') {
            return Err(format!(
                "templates.{event}: wrote the control character U+{:04X} within a line",
                c as u32
            ));
        }
        let l = l.trim();
        if !l.is_empty() {
            out.push(l.to_string());
        }
    }
    if out.len() > MAX_LINES {
        return Err(format!("templates.{event}: wrote more than {MAX_LINES} lines"));
    }
    Ok(out)
}

fn template_error(event: &str, e: &minijinja::Error) -> String {
    let detail = e.detail().map(|d| format!(": {d}")).unwrap_or_default();
    match e.line() {
        Some(l) => format!("templates.{event}: line {l}: {}{detail}", e.kind()),
        None => format!("templates.{event}: {}{detail}", e.kind()),
    }
}

/// The variables of one event. Every name of [`VARIABLES`] is present (`none` where unknown),
/// so a template may test `{% if next_tool is not none %}`.
#[derive(Clone, Debug)]
pub struct Vars(BTreeMap<String, Value>);

impl Default for Vars {
    fn default() -> Self {
        Vars(VARIABLES.iter().map(|v| (v.to_string(), Value::from(()))).collect())
    }
}

impl Vars {
    /// Every variable with a plausible value: the trial render when a dialect is read.
    fn sample() -> Vars {
        let mut v = Vars::default();
        v.set("tool", 1)
            .set("length", 100.0)
            .set("diameter", 10.0)
            .set("next_tool", 2)
            .set("spindle_speed", 6000)
            .set("work_offset", "G54")
            .set("program_number", 1000)
            .set("machine", "machine")
            .set("date", "2026-01-01 00:00")
            .set("units", "mm")
            .set("operation", "OPERATION")
            .set("tolerance", 0.01)
            .set("dialect", "dialect");
        v
    }

    /// Every variable at the longest or largest it may be: an operation's name of 120
    /// characters (what reaches a template of the CL's), ids of 64, numbers at their bounds.
    fn worst() -> Vars {
        let long = |n: usize| "W".repeat(n);
        let mut v = Vars::default();
        v.set("tool", i64::from(u32::MAX))
            .set("length", -99_999.999)
            .set("diameter", 99_999.999)
            .set("next_tool", i64::from(u32::MAX))
            .set("spindle_speed", 999_999)
            .set("work_offset", "G54.1 P300")
            .set("program_number", 99_999_999)
            .set("machine", long(64))
            .set("date", "2026-12-31 23:59")
            .set("units", "inch")
            .set("operation", long(120))
            .set("tolerance", 1e-6)
            .set("dialect", long(64));
        v
    }

    pub fn set(&mut self, name: &'static str, v: impl Into<Value>) -> &mut Self {
        debug_assert!(VARIABLES.contains(&name), "{name} is no template variable");
        self.0.insert(name.to_string(), v.into());
        self
    }

    pub fn set_opt<T: Into<Value>>(&mut self, name: &'static str, v: Option<T>) -> &mut Self {
        if let Some(v) = v {
            self.set(name, v);
        }
        self
    }
}
