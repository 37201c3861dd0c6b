//! Motion policies: how the shop wants the machine to move where the CL does not say. A
//! profile's `[policy]` is parsed into these at load, every key, so a bad value is refused with
//! the file and the key (not blamed on a post's parameter later); a job may override each, its
//! text parsed by the same functions.

use crate::kinematics::Machine;

/// Where positioning takes the tool before the rotaries turn, at a tool change and at the
/// program's end.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Retract {
    /// Machine Z to the top of its travel (joint mode): the farthest from the part there is.
    MachineZ,
    /// This far along the tool axis (or less where the travel ends first).
    Axis(f64),
    /// Along the tool axis up to the plane z = this in the part frame: a fixture or a second
    /// part above the work stays clear of a rotary turning under it, and no time is spent
    /// climbing higher.
    Plane(f64),
}

impl Retract {
    /// `machine-z`, `axis:D` or `plane:Z` (the machine's units); the error says what is wrong.
    pub fn parse(text: &str) -> Result<Retract, String> {
        let number = |v: &str| {
            v.trim()
                .parse::<f64>()
                .ok()
                .filter(|x| crate::kinematics::coordinate_ok(*x))
                .ok_or_else(|| format!("retract {text:?}: {v:?} is not a number"))
        };
        match text.trim().split_once(':') {
            None if text.trim() == "machine-z" => Ok(Retract::MachineZ),
            Some(("axis", d)) => match number(d)? {
                d if d > 0.0 => Ok(Retract::Axis(d)),
                _ => Err(format!("retract {text:?}: the distance along the tool axis must be positive")),
            },
            Some(("plane", z)) => Ok(Retract::Plane(number(z)?)),
            _ => Err(format!("retract {text:?}: expected machine-z, axis:D or plane:Z")),
        }
    }
}

/// One rotary's side where both IK branches can cut a run (`B-`, `A+`): a trunnion tilted away
/// from the operator, a head kept on the side its cable likes. A preference, never a reason to
/// change branch inside a cut (`plan::PREFER_PENALTY`). And the angles the program starts
/// nearest (`C=180`: the winding of an unbounded table, the side of a tilt), where the first
/// point leaves a choice.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Prefer {
    /// The rotary's index in chain order.
    pub rotary: usize,
    /// +1 or −1; 0: no side preferred.
    pub sign: f64,
    /// Radians, per rotary in chain order: where the first point's angles are sought.
    pub start: [Option<f64>; 3],
}

impl Prefer {
    /// Items separated by commas: a rotary of `m` and a sign (`B-`, `A+`; one at most), a rotary
    /// and the angle the program starts nearest (`C=180`, degrees).
    pub fn parse(text: &str, m: &Machine) -> Result<Prefer, String> {
        let mut p = Prefer { rotary: 0, sign: 0.0, start: [None; 3] };
        for item in text.split(',').map(str::trim).filter(|i| !i.is_empty()) {
            let mut chars = item.chars();
            let name = chars.next().unwrap_or(' ');
            let rotary = m
                .rotary_index(name.to_ascii_uppercase())
                .ok_or_else(|| format!("prefer {item:?}: {} has no rotary {name}", m.id))?;
            match chars.as_str() {
                "+" | "-" if p.sign != 0.0 => return Err(format!("prefer {text:?}: one side at most")),
                "+" => (p.rotary, p.sign) = (rotary, 1.0),
                "-" => (p.rotary, p.sign) = (rotary, -1.0),
                rest => match rest.strip_prefix('=').map(|v| v.trim().parse::<f64>()) {
                    Some(Ok(a)) if a.is_finite() && a.abs() <= 36_000.0 => p.start[rotary] = Some(a.to_radians()),
                    _ => {
                        return Err(format!(
                            "prefer {item:?}: expected a rotary and a sign (B-, A+) or a starting angle in degrees (C=180)"
                        ));
                    }
                },
            }
        }
        Ok(p)
    }
}

/// How a feed move that turns a rotary says its speed (`feed_mode`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum RotaryFeed {
    /// `G93` inverse time: F is 1 / the block's minutes (the default where the control has it;
    /// elsewhere the combined feed).
    #[default]
    InverseTime,
    /// Feed per minute as LinuxCNC and Haas read it (NIST RS274): the linear axes' path when
    /// they move, the rotaries' degrees per minute when only rotaries move.
    DegreesPerMinute,
    /// Feed per minute along the machine axes' combined path, units and degrees alike (a Fanuc
    /// in `G94`, a TNC).
    Combined,
}

impl RotaryFeed {
    /// `inverse-time`, `dpm` or `combined`.
    pub fn parse(text: &str) -> Result<RotaryFeed, String> {
        match text.trim() {
            "inverse-time" => Ok(RotaryFeed::InverseTime),
            "dpm" => Ok(RotaryFeed::DegreesPerMinute),
            "combined" => Ok(RotaryFeed::Combined),
            t => Err(format!("feed_mode {t:?}: expected inverse-time, dpm or combined")),
        }
    }
}

/// Where a bounded rotary may unwind (`unwind`): the planner puts every unwind it can at a
/// repositioning move of the CL; this says what to make of one it cannot.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Unwind {
    /// Inside a cut too, as a retract along the tool axis, a turn and a re-approach (a warning).
    #[default]
    RetractInCut,
    /// Only at rapids: one inside a cut is still written as the retract (the part stays safe) but
    /// is an error, so the program is not run as is.
    AtRapids,
}

impl Unwind {
    /// `retract` or `rapids`.
    pub fn parse(text: &str) -> Result<Unwind, String> {
        match text.trim() {
            "retract" => Ok(Unwind::RetractInCut),
            "rapids" => Ok(Unwind::AtRapids),
            t => Err(format!("unwind {t:?}: expected retract (in the cut too) or rapids (only at rapids)")),
        }
    }
}

/// Which tool is readied in the magazine while another cuts (`preselect`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Preselect {
    /// Right after each tool change, the next tool the CL loads (as a shop's post does); where
    /// the CL cannot be read twice (a stream), as the CL says.
    #[default]
    Next,
    /// Where the CL says `SELCTL`.
    Cl,
    /// Never (`SELCTL` told as not written).
    Off,
}

impl Preselect {
    /// `next`, `cl` or `off`.
    pub fn parse(text: &str) -> Result<Preselect, String> {
        match text.trim() {
            "next" => Ok(Preselect::Next),
            "cl" => Ok(Preselect::Cl),
            "off" => Ok(Preselect::Off),
            t => Err(format!(
                "preselect {t:?}: expected next (the next tool after each change), cl (where the CL says SELCTL) or off"
            )),
        }
    }
}

/// Which smoothing word an operation gets (`smoothing`): the dialect's `[smoothing]` lines.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Smoothing {
    /// Once the CL says `INTOL`/`OUTTOL`: each operation's level from its type where its name
    /// says (`ROUGH`, `SEMI`, `FINISH`), else from its tolerance; a CL that says none is posted
    /// as without smoothing.
    #[default]
    Auto,
    /// None: the dialect's `blend` after the safe start only, as before smoothing existed.
    Off,
    /// Every operation the rough level, at its tolerance (else the job's).
    Rough,
    /// Every operation the finish level, at its tolerance (else the job's).
    Finish,
}

impl Smoothing {
    /// `auto`, `off`, `rough` or `finish`.
    pub fn parse(text: &str) -> Result<Smoothing, String> {
        match text.trim() {
            "auto" => Ok(Smoothing::Auto),
            "off" => Ok(Smoothing::Off),
            "rough" => Ok(Smoothing::Rough),
            "finish" => Ok(Smoothing::Finish),
            t => Err(format!(
                "smoothing {t:?}: expected auto (each operation's from its INTOL/OUTTOL and type), off, rough or finish"
            )),
        }
    }
}

/// A profile's `[policy]`, every key parsed when the profile loads: what a post takes where the
/// job says nothing.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Policy {
    pub retract: Option<Retract>,
    pub prefer: Option<Prefer>,
    pub feed_mode: Option<RotaryFeed>,
    pub unwind: Option<Unwind>,
    pub smoothing: Option<Smoothing>,
}

impl Policy {
    /// Each key of `doc` parsed for machine `m`; the error names the key (`policy.unwind`).
    pub fn parse(doc: &super::PolicyDoc, m: &Machine) -> Result<Policy, (String, String)> {
        fn key<T>(name: &str, text: &Option<String>, parse: impl FnOnce(&str) -> Result<T, String>) -> Result<Option<T>, (String, String)> {
            text.as_deref().map(parse).transpose().map_err(|e| (format!("policy.{name}"), e))
        }
        Ok(Policy {
            retract: key("retract", &doc.retract, Retract::parse)?,
            prefer: key("prefer", &doc.prefer, |t| Prefer::parse(t, m))?,
            feed_mode: key("feed_mode", &doc.feed_mode, RotaryFeed::parse)?,
            unwind: key("unwind", &doc.unwind, Unwind::parse)?,
            smoothing: key("smoothing", &doc.smoothing, Smoothing::parse)?,
        })
    }
}
