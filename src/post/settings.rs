//! Post options: [`Settings`] as users give them, defined once for the CLI's flags, HTTP's
//! fields and the OpenAPI schema (the derives below are the one place the engine meets clap and
//! utoipa), validated in one place, [`Settings::options`], into the engine's [`Options`].

use crate::kinematics::{Machine, Units, Vec3};
pub use crate::machines::MAX_SPINDLE_SPEED;
use crate::machines::policy::{Prefer, Preselect, Retract, RotaryFeed, Smoothing, Unwind};
use crate::machines::tools::{ToolTable, parse_tool_table};
use crate::nc::Dialect;
use crate::text::quote;
use serde::Serialize;
use std::sync::Arc;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// No TCP on the controller: X Y Z are the machine's linear joints.
    Joint,
    /// The controller's tool-centre-point control: X Y Z are the tip in the part frame.
    Tcp,
}

#[derive(Clone, Debug)]
pub struct Options {
    pub mode: Mode,
    pub dialect: Arc<Dialect>,
    /// Profile units; overrides the CL file's, the tool table's and the profile's default.
    pub tool_length: Option<f64>,
    /// Lengths per tool number (the job's table, else the machine's): `post::tools` weighs them.
    pub tool_table: Option<Arc<ToolTable>>,
    /// How the program's header names that table.
    pub tool_table_label: String,
    pub work_offset: Vec3,
    /// Chord tolerance (profile units): linearization, arcs, and the self-verification bound.
    pub tolerance: f64,
    pub sequence_numbers: bool,
    pub program_number: u32,
    pub strict: bool,
    pub cl_units: Option<Units>,
    /// Largest rotary change in one feed block before it is subdivided (radians).
    pub max_rotary_step: f64,
    /// Retract distance along the tool axis for unwinds and repositions (profile units).
    pub clearance: f64,
    /// Where positioning retracts to (`Retract::resolve`).
    pub retract: Retract,
    /// The side of one rotary the planner keeps to where both branches can cut.
    pub prefer: Option<Prefer>,
    /// How a feed move with rotaries says its speed (`RotaryFeed`).
    pub rotary_feed: RotaryFeed,
    /// Where a bounded rotary may unwind (`Unwind`).
    pub unwind: Unwind,
    /// Which tool is readied while another cuts (`Preselect`).
    pub preselect: Preselect,
    /// Which smoothing word each operation gets (`Smoothing`).
    pub smoothing: Smoothing,
    /// Cone (radians) around a singular direction within which blocks are marked `singular`.
    pub singular_cone: f64,
    /// Orientation tolerance (radians) the free rotary may use near a singular direction: 0 is
    /// exact (the default); e.g. 0.5° for a ball-end tool holds the rotary still where the tool
    /// axis passes within that angle of the singular direction.
    pub singular_tolerance: f64,
    /// Per rotary (chain order): the words that lock and unlock it, if the machine clamps it.
    pub clamps: [Option<(String, String)>; 3],
    /// Header comment lines (source file name, date …) the caller wants in the program.
    pub header: Vec<String>,
    /// Drilling cycles (CL `CYCLE/`) as the control's canned cycles where the hole runs along
    /// the machine's Z (joint mode); else, and by default, expanded into moves.
    pub canned_cycles: bool,
    /// Fixed-axis (3+2) runs in a tilted working plane (G68.2, G254, CYCLE800, PLANE SPATIAL)
    /// with their motion in plane coordinates (joint mode); else, and by default, 5-axis
    /// positioning.
    pub tilted_planes: bool,
    /// The work coordinate system the program selects (`G54`…): its origin must be where the
    /// X Y Z words are measured from (joint mode: the profile's origin; TCP: the part's).
    /// `None`: the dialect's first (none on a control without one); `Some("none")`: the program
    /// selects none and runs in whatever the control has active.
    pub work_coordinates: Option<String>,
    /// Each distinct MCS of the program (NX `MSYS`) in the next work offset, its X Y Z words
    /// measured from it; else, and by default, every operation taken into the first's frame.
    pub setup_offsets: bool,
    /// Spindle speed (RPM, clockwise) for a tool whose CL starts none before its first move (NX's
    /// CLSF listings carry no SPINDL: its post takes the speed from the operation). `None`: the
    /// CL's own, and a cut with none is a `spindle_stopped` warning.
    pub spindle_speed: Option<f64>,
    /// The machine's spindle speeds in RPM (the profile's `[spindle]`): an S outside them is an
    /// error where the CL asks for it.
    pub spindle_range: (f64, f64),
    /// What the run may cost: set by whoever runs the engine for others (the server, the CLI's
    /// flags), never by a request.
    pub budget: Budget,
    /// The machine's bodies to check every block against (`collide`); none: collisions are
    /// not checked (switched off, or the profile gives no bodies).
    pub geometry: Option<Arc<crate::collide::Geometry>>,
    /// Bodies closer than this (profile units) are a `near_collision` warning.
    pub collision_clearance: f64,
    /// The job's stock and fixtures: boxes in W (the CL's frame), the CL's units.
    pub stock: Vec<crate::collide::Solid>,
    pub fixtures: Vec<crate::collide::Solid>,
    /// Threads one post runs on: 1, or 2 (the CL read and planned beside the emitting). The
    /// output is the same either way; the caller chooses what its load wants (`threads`).
    pub threads: usize,
}

/// What one post may cost, whatever its input: blocks written per CL byte read beyond a floor
/// every program gets, and seconds. A few bytes of helix at a fine tolerance once streamed
/// 460 MB of NC, and 170 bytes on a three-rotary machine took three minutes of CPU.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Budget {
    /// Blocks any program may write, however short its CL.
    pub floor_blocks: u64,
    /// Blocks more per CL byte read; `u64::MAX`: no bound.
    pub blocks_per_byte: u64,
    /// Seconds a run may take; infinite: no bound.
    pub seconds: f64,
}

impl Default for Budget {
    fn default() -> Self {
        // A dense 5-axis CL writes about 0.1 block a byte; one arc record of a few dozen bytes
        // linearized at the finest tolerance, a few thousand blocks: the floor covers that.
        Budget {
            floor_blocks: 100_000,
            blocks_per_byte: 8,
            seconds: 3600.0,
        }
    }
}

impl Budget {
    /// From flags; 0 for either means no bound.
    pub fn new(blocks_per_byte: u64, seconds: f64) -> Result<Budget, String> {
        if !(seconds.is_finite() && seconds >= 0.0) {
            return Err(format!("a post's time bound must be a number of seconds, 0 for none, not {seconds}"));
        }
        Ok(Budget {
            blocks_per_byte: if blocks_per_byte == 0 { u64::MAX } else { blocks_per_byte },
            seconds: if seconds == 0.0 { f64::INFINITY } else { seconds },
            ..Budget::default()
        })
    }

    /// Why a run that wrote `blocks` from `bytes` of CL in `secs` must stop, if it must.
    pub fn exceeded(&self, blocks: u64, bytes: u64, secs: f64) -> Option<String> {
        let most = self.floor_blocks.saturating_add(self.blocks_per_byte.saturating_mul(bytes));
        if blocks > most {
            return Some(format!(
                "output bound: {blocks} blocks from {bytes} bytes of CL, beyond {} and {} a byte; a coarser tolerance writes fewer",
                self.floor_blocks, self.blocks_per_byte
            ));
        }
        (secs > self.seconds).then(|| format!("time bound: the post ran over {} s", self.seconds))
    }
}

impl Options {
    pub fn new(m: &Machine) -> Options {
        let mm = m.units == Units::Mm;
        Options {
            mode: Mode::Joint,
            dialect: crate::nc::dialect(&m.controller).unwrap_or_else(|| crate::nc::builtins()[0].clone()),
            tool_length: None,
            tool_table: None,
            tool_table_label: String::new(),
            work_offset: Vec3::zeros(),
            tolerance: if mm { 0.01 } else { 0.0004 },
            sequence_numbers: false,
            program_number: 1000,
            strict: false,
            cl_units: None,
            max_rotary_step: 10f64.to_radians(),
            clearance: if mm { 50.0 } else { 2.0 },
            retract: Retract::MachineZ,
            prefer: None,
            rotary_feed: RotaryFeed::InverseTime,
            unwind: Unwind::RetractInCut,
            preselect: Preselect::Next,
            smoothing: Smoothing::Auto,
            singular_cone: 2f64.to_radians(),
            singular_tolerance: 0.0,
            clamps: Default::default(),
            spindle_range: (1.0, MAX_SPINDLE_SPEED),
            header: Vec::new(),
            canned_cycles: false,
            tilted_planes: false,
            work_coordinates: None,
            setup_offsets: false,
            spindle_speed: None,
            budget: Budget::default(),
            geometry: None,
            collision_clearance: if mm { 2.0 } else { 0.08 },
            stock: Vec::new(),
            fixtures: Vec::new(),
            threads: 1,
        }
    }

    /// The work coordinate word the program writes, if any.
    pub fn wcs_word(&self) -> Option<&str> {
        match self.work_coordinates.as_deref() {
            None => self.dialect.work_coordinates.first().map(String::as_str),
            Some("none") => None,
            Some(w) => Some(w),
        }
    }
}

/// The threads a post runs on, from a setting (1 where absent): 1 or 2, the two halves of the
/// pipeline (`post::pipe`); more would have nothing to run.
pub fn threads(n: Option<u32>) -> Result<usize, String> {
    match n {
        None | Some(1) => Ok(1),
        Some(2) => Ok(2),
        Some(n) => Err(format!("threads {n}: expected 1 or 2")),
    }
}

/// The post options as users give them, defined once: the CLI's flags (`--feed-mode`), the HTTP
/// query and form fields (`feed_mode=`), the OpenAPI schema and the page's fields all come from
/// this struct and its doc comments. Plain values, validated in one place, [`Settings::options`],
/// into [`Options`]; so its error names the field ([`SettingError`]).
///
/// What each edge does its own way stays out: the CL input, the output files, the threads (the
/// CLI's flag, the server's configuration), a job's versions (`jobs`), and the CLI's
/// `--tool-table`, a file, which it reads into `tool_table`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, serde::Deserialize, clap::Args, utoipa::ToSchema, utoipa::IntoParams)]
#[serde(deny_unknown_fields)]
#[schema(as = PostParams)]
#[into_params(parameter_in = Query)]
pub struct Settings {
    /// Machine profile id (required).
    #[arg(long, required = true)]
    pub machine: Option<String>,
    /// NC dialect; default: the profile's controller.
    #[arg(long)]
    pub dialect: Option<String>,
    /// `joint` (default: no TCP on the control, X Y Z are the machine's linear joints) or `tcp`
    /// (X Y Z are the tip, the control does the rest).
    #[arg(long)]
    pub mode: Option<String>,
    /// Tool length (gauge line to tip), profile units, one for every tool (a single-tool job);
    /// default per tool: the tool table's, else the CL file's, else the profile's.
    #[arg(long, allow_hyphen_values = true)]
    pub tool_length: Option<f64>,
    /// The job's own tool table, as TOML text (`units = "mm"`, `[[tool]] number = 3, length =
    /// 112.5 …`): each tool's length; it replaces the machine's (`/v1/machines/{id}/tools`,
    /// `machines/<id>.tools.toml`) for this job. The CLI's `--tool-table` names a file.
    #[arg(skip)]
    pub tool_table: Option<String>,
    /// Work offset `x,y,z` in profile units: the part origin in the machine frame at home.
    #[arg(long, allow_hyphen_values = true)]
    pub work_offset: Option<String>,
    /// Chord tolerance in profile units (default 0.01 mm / 0.0004 in, at most 1 mm / 0.04 in):
    /// also the bound of the FK replay's tip check.
    #[arg(long, allow_hyphen_values = true)]
    pub tolerance: Option<f64>,
    /// N numbers on blocks.
    #[arg(long, num_args = 0, default_missing_value = "true")]
    #[serde(default, deserialize_with = "flag")]
    pub sequence_numbers: Option<bool>,
    /// Program number (default 1000): 1 to 9999 on fanuc (`O` and four digits), 1 to 99999 on
    /// haas; any on the others, which name the program.
    #[arg(long, allow_hyphen_values = true)]
    pub program_number: Option<u32>,
    /// Stop at the first error (bad record, unreachable pose, limit, collision) instead of
    /// reporting it and going on.
    #[arg(long, num_args = 0, default_missing_value = "true")]
    #[serde(default, deserialize_with = "flag")]
    pub strict: Option<bool>,
    /// Degrees of orientation the free rotary may use near a singular direction (default 0:
    /// exact): it is held while the tool axis stays within them of the CL's (e.g. 0.5 for a
    /// ball-end tool).
    #[arg(long, allow_hyphen_values = true)]
    pub singular_tolerance: Option<f64>,
    /// Units of the CL when the file does not say: `mm` or `inch`.
    #[arg(long)]
    pub cl_units: Option<String>,
    /// Drilling cycles: `expand` (default: moves; taps and bores that stop the spindle are
    /// cycles even so) or `canned` (G81–G89, CYCLE81–89, CYCL DEF 200–207 where the hole runs
    /// along the machine's Z in joint mode; elsewhere still expanded).
    #[arg(long)]
    pub cycles: Option<String>,
    /// 3+2 work: `positioning` (default: 5-axis positioning, machine coordinates) or `tilted` (a
    /// tilted working plane per fixed-axis run, G68.2/G53.1, G254, CYCLE800, PLANE SPATIAL, with
    /// its motion in plane coordinates; joint mode).
    #[arg(long)]
    pub planes: Option<String>,
    /// Work coordinate system the program selects: `G54` (default) to `G59` (siemens: `G57`), or
    /// `none` (the control's active one). Its origin must be where X Y Z are measured from (joint
    /// mode: the profile's origin; TCP: the part's). heidenhain: none only (the TNC's preset is
    /// chosen on the control).
    #[arg(long)]
    pub work_coordinates: Option<String>,
    /// Programs of several setups (NX `MSYS` per operation): `transform` (default: every
    /// operation's points taken into the first's MCS) or `work-offsets` (each distinct MCS in the
    /// next work offset, G55 …; the program lists where to set each).
    #[arg(long)]
    pub setups: Option<String>,
    /// Spindle speed (RPM, clockwise, 1 to 200000) for a tool the CL starts no spindle for before
    /// its first move (NX CLSF listings carry no SPINDL); the CL's own SPINDL and SPINDL/OFF win.
    #[arg(long, allow_hyphen_values = true)]
    pub spindle_speed: Option<f64>,
    /// Where positioning retracts to before the rotaries turn, at a tool change and at the end:
    /// `machine-z` (joint mode's default: the top of Z travel), `axis:D` (D along the tool axis;
    /// TCP mode's default is the clearance) or `plane:Z` (along the tool axis up to z = Z in the
    /// part frame); the profile's `[policy] retract` where absent.
    #[arg(long, allow_hyphen_values = true)]
    pub retract: Option<String>,
    /// A rotary's side the planner keeps to where both IK branches can cut a run: `B-`, `A+` (a
    /// preference, never a branch change inside a cut); and the angle the program starts nearest
    /// (`C=180`), items separated by commas; the profile's `[policy] prefer` where absent.
    #[arg(long, allow_hyphen_values = true)]
    pub prefer: Option<String>,
    /// How a feed move that turns a rotary writes F: `inverse-time` (G93, the default where the
    /// control has it), `dpm` (LinuxCNC's and Haas's per-minute rule: the linear axes' feed, or
    /// degrees per minute when only rotaries move) or `combined` (along the machine axes, units
    /// and degrees); the profile's `[policy] feed_mode` where absent.
    #[arg(long)]
    pub feed_mode: Option<String>,
    /// Where a bounded rotary may unwind: `retract` (the default: in the cut too, retracting
    /// along the tool axis) or `rapids` (one inside a cut is an error); the profile's `[policy]
    /// unwind` where absent.
    #[arg(long)]
    pub unwind: Option<String>,
    /// Which tool is readied while another cuts: `next` (default: right after each tool change,
    /// the next tool the CL loads; a streamed post, whose CL is read once, readies where the CL
    /// says `SELCTL`), `cl` (where the CL says `SELCTL`) or `off`.
    #[arg(long)]
    pub preselect: Option<String>,
    /// The smoothing word of each operation: `auto` (default: once the CL says `INTOL`/`OUTTOL`,
    /// each operation's level from its type, else its tolerance), `off`, `rough` or `finish`; the
    /// profile's `[policy] smoothing`, else the dialect's `[smoothing] default`, where absent.
    #[arg(long)]
    pub smoothing: Option<String>,
    /// The collision check against the profile's bodies: `on` (default: every block, where the
    /// profile gives bodies) or `off`.
    #[arg(long)]
    pub collisions: Option<String>,
    /// Bodies closer than this (profile units; default 2 mm / 0.08 in) are a `near_collision`.
    #[arg(long)]
    pub collision_clearance: Option<f64>,
    /// The stock: a box `x0,y0,z0,x1,y1,z1` in the CL's frame and units.
    #[arg(long, allow_hyphen_values = true)]
    pub stock: Option<String>,
    /// Fixtures: boxes as the stock's, separated by `;`.
    #[arg(long, allow_hyphen_values = true)]
    pub fixtures: Option<String>,
}

/// A yes-or-no setting: a bool (JSON, a job's record), or the text a query or form sends
/// (`true`, `1`, `on`, `yes`; `false`, `0`, `off`, `no` or nothing).
fn flag<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<bool>, D::Error> {
    struct Flag;
    impl serde::de::Visitor<'_> for Flag {
        type Value = Option<bool>;
        fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
            f.write_str("true or false")
        }
        fn visit_bool<E: serde::de::Error>(self, v: bool) -> Result<Option<bool>, E> {
            Ok(Some(v))
        }
        fn visit_unit<E: serde::de::Error>(self) -> Result<Option<bool>, E> {
            Ok(None)
        }
        fn visit_none<E: serde::de::Error>(self) -> Result<Option<bool>, E> {
            Ok(None)
        }
        fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<Option<bool>, E> {
            match v.trim() {
                "true" | "1" | "on" | "yes" => Ok(Some(true)),
                "false" | "0" | "off" | "no" | "" => Ok(Some(false)),
                _ => Err(E::invalid_value(serde::de::Unexpected::Str(v), &self)),
            }
        }
    }
    d.deserialize_any(Flag)
}

/// A setting refused: the field it came in (`feed_mode`, as HTTP names it; the CLI's flag is
/// the same with dashes) and why, the message naming it too.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{message}")]
pub struct SettingError {
    pub field: &'static str,
    pub message: String,
}

/// Where an edge reports errors as text (the CLI, a job's `error`): the message, which names the
/// field too.
impl From<SettingError> for String {
    fn from(e: SettingError) -> String {
        e.message
    }
}

impl SettingError {
    /// `Err` of `field` for a parser's message.
    fn of(field: &'static str) -> impl Fn(String) -> SettingError {
        move |message| SettingError { field, message }
    }
}

impl Settings {
    /// Options for a loaded profile: [`Settings::options`] plus what the profile adds beyond
    /// its kinematics (rotary clamp words, its `[policy]`) and the machine's standing tool table
    /// (`label` names it in the header), which the job's own replaces.
    pub fn profile_options(
        &self,
        p: &crate::machines::Profile,
        standing: Option<(Arc<ToolTable>, String)>,
    ) -> Result<Options, SettingError> {
        self.profile_options_with(p, standing, &crate::nc::dialect)
    }

    /// [`Settings::profile_options`] with the dialects `dialects` finds by id (the service's
    /// current ones, a job's recorded version, a `--dialects` directory's).
    pub fn profile_options_with(
        &self,
        p: &crate::machines::Profile,
        standing: Option<(Arc<ToolTable>, String)>,
        dialects: &dyn Fn(&str) -> Option<Arc<Dialect>>,
    ) -> Result<Options, SettingError> {
        let mut o = self.options_with(&p.machine, dialects)?;
        o.clamps = p.clamps();
        for (i, r) in p.machine.rotaries.iter().enumerate().take(3) {
            if let Some([lock, unlock]) = o.dialect.clamps.get(&r.name.to_string()) {
                o.clamps[i] = Some((lock.clone(), unlock.clone()));
            }
        }
        // The profile's motion policies (parsed when it loaded), where the job gives none.
        let policy = &p.policy;
        o.retract = retract(self.retract.as_deref(), policy.retract, o.mode, o.clearance)?;
        if let (None, Some(f)) = (&self.feed_mode, policy.feed_mode) {
            o.rotary_feed = f;
        }
        if let (None, Some(u)) = (&self.unwind, policy.unwind) {
            o.unwind = u;
        }
        if let (None, Some(s)) = (self.smoothing.as_deref().filter(|s| !s.trim().is_empty()), policy.smoothing) {
            o.smoothing = s;
        }
        if o.prefer.is_none() {
            o.prefer = policy.prefer;
        }
        o.spindle_range = p.spindle_range();
        if self.collisions.as_deref() != Some("off") {
            let g = p.geometry();
            o.geometry = (!g.bodies.is_empty()).then(|| Arc::new(g));
        }
        if let Some(s) = o.spindle_speed
            && !(o.spindle_range.0..=o.spindle_range.1).contains(&s)
        {
            let (lo, hi) = o.spindle_range;
            return Err(SettingError::of("spindle_speed")(format!("spindle_speed {s}: {}'s spindle turns from {lo} to {hi} RPM", p.doc.id)));
        }
        if o.tool_table.is_none()
            && let Some((t, label)) = standing
        {
            o.tool_table = Some(t);
            o.tool_table_label = label;
        }
        Ok(o)
    }

    /// Validated options for machine `m`; the error names the setting.
    pub fn options(&self, m: &Machine) -> Result<Options, SettingError> {
        self.options_with(m, &crate::nc::dialect)
    }

    /// [`Settings::options`] with the dialects `dialects` finds by id.
    pub fn options_with(&self, m: &Machine, dialects: &dyn Fn(&str) -> Option<Arc<Dialect>>) -> Result<Options, SettingError> {
        let mut o = Options::new(m);
        let name = self.dialect.as_deref().filter(|d| !d.is_empty()).unwrap_or(&m.controller);
        o.dialect = match dialects(name) {
            Some(d) => d,
            None if self.dialect.is_none() => o.dialect,
            None => {
                return Err(SettingError::of("dialect")(format!(
                    "dialect {}: no such dialect (the built-ins are {}; GET /v1/dialects lists a service's)",
                    quote(name),
                    crate::nc::DIALECTS.join(", ")
                )));
            }
        };
        o.mode = match self.mode.as_deref() {
            None | Some("joint") => Mode::Joint,
            Some("tcp") => Mode::Tcp,
            Some(x) => return Err(SettingError::of("mode")(format!("mode {}: expected joint or tcp", quote(x)))),
        };
        o.retract = retract(self.retract.as_deref(), None, o.mode, o.clearance)?;
        if let Some(f) = given(&self.feed_mode) {
            o.rotary_feed = RotaryFeed::parse(f).map_err(SettingError::of("feed_mode"))?;
        }
        if let Some(p) = given(&self.preselect) {
            o.preselect = Preselect::parse(p).map_err(SettingError::of("preselect"))?;
        }
        if let Some(s) = given(&self.smoothing) {
            o.smoothing = Smoothing::parse(s).map_err(SettingError::of("smoothing"))?;
        } else if let Some(s) = o.dialect.smoothing.default.as_deref() {
            // The dialect's file was checked when it was read; a bad default is its own error.
            o.smoothing = Smoothing::parse(s).map_err(SettingError::of("dialect"))?;
        }
        if let Some(u) = given(&self.unwind) {
            o.unwind = Unwind::parse(u).map_err(SettingError::of("unwind"))?;
        }
        if let Some(p) = given(&self.prefer) {
            o.prefer = Some(Prefer::parse(p, m).map_err(SettingError::of("prefer"))?);
        }
        self.tool_options(&mut o, m)?;
        o.sequence_numbers = self.sequence_numbers.unwrap_or(false);
        o.program_number = self.program_number.unwrap_or(1000);
        let numbers = o.dialect.program_numbers();
        if !numbers.contains(&o.program_number) {
            return Err(SettingError::of("program_number")(format!(
                "program_number {}: {} takes {} to {}",
                o.program_number,
                o.dialect.name,
                numbers.start(),
                numbers.end()
            )));
        }
        o.strict = self.strict.unwrap_or(false);
        if let Some(t) = self.singular_tolerance {
            if !(t.is_finite() && (0.0..=10.0).contains(&t)) {
                return Err(SettingError::of("singular_tolerance")("singular_tolerance must be between 0 and 10 degrees".into()));
            }
            o.singular_tolerance = t.to_radians();
        }
        o.cl_units = match self.cl_units.as_deref() {
            None => None,
            Some("mm") => Some(Units::Mm),
            Some("inch") => Some(Units::Inch),
            Some(u) => return Err(SettingError::of("cl_units")(format!("cl_units {}: expected mm or inch", quote(u)))),
        };
        self.program_options(&mut o)?;
        if let Some(s) = self.spindle_speed {
            if !(s.is_finite() && (1.0..=MAX_SPINDLE_SPEED).contains(&s)) {
                return Err(SettingError::of("spindle_speed")(format!("spindle_speed must be from 1 to {MAX_SPINDLE_SPEED} RPM")));
            }
            o.spindle_speed = Some(s);
        }
        self.collision_options(&mut o)?;
        Ok(o)
    }

    /// The tool and the part: tool length and table, work offset, tolerance.
    fn tool_options(&self, o: &mut Options, m: &Machine) -> Result<(), SettingError> {
        if let Some(l) = self.tool_length {
            if !(l >= 0.0 && crate::kinematics::coordinate_ok(l)) {
                return Err(SettingError::of("tool_length")(format!(
                    "tool_length must be a length from 0 to {:e}",
                    crate::kinematics::MAX_COORD
                )));
            }
            o.tool_length = Some(l);
        }
        if let Some(text) = self.tool_table.as_deref().filter(|t| !t.trim().is_empty()) {
            let t = parse_tool_table(text, "tool_table").map_err(|e| SettingError::of("tool_table")(e.to_string()))?;
            o.tool_table = Some(Arc::new(t));
            o.tool_table_label = "THE JOB'S TOOL TABLE".into();
        }
        if let Some(w) = &self.work_offset {
            o.work_offset = parse_triple(w).map_err(|e| SettingError::of("work_offset")(format!("work_offset: {e}")))?;
        }
        if let Some(t) = self.tolerance {
            let bad = SettingError::of("tolerance");
            // It is also the FK replay's bound: a huge one would switch the self-verification off.
            let (max, unit) = if m.units == Units::Mm { (1.0, "mm") } else { (0.04, "in") };
            if !(t.is_finite() && t > 0.0 && t <= max) {
                return Err(bad(format!("tolerance must be a positive number up to {max} {unit}")));
            }
            // Finer than the X Y Z words can say, every block's rounding alone would be an
            // FK-replay error: two units of the word's last digit is the least that works.
            let least = 2.0 / 10f64.powi(crate::nc::Formats::for_dialect(&o.dialect, m.units).linear as i32);
            if t < least * (1.0 - 1e-9) {
                return Err(bad(format!(
                    "tolerance {} {unit} is finer than the X Y Z words can hold; the smallest that works is {least} {unit}",
                    short(t)
                )));
            }
            o.tolerance = t;
        }
        Ok(())
    }

    /// What the program is written as: canned cycles, tilted planes, the work coordinates and
    /// the setups' offsets.
    fn program_options(&self, o: &mut Options) -> Result<(), SettingError> {
        o.canned_cycles = match self.cycles.as_deref() {
            None | Some("expand") => false,
            Some("canned") => true,
            Some(x) => return Err(SettingError::of("cycles")(format!("cycles {}: expected expand or canned", quote(x)))),
        };
        o.tilted_planes = match self.planes.as_deref() {
            None | Some("positioning") => false,
            Some("tilted") => true,
            Some(x) => return Err(SettingError::of("planes")(format!("planes {}: expected positioning or tilted", quote(x)))),
        };
        if let Some(w) = self.work_coordinates.as_deref().map(str::trim).filter(|w| !w.is_empty()) {
            let bad = SettingError::of("work_coordinates");
            let known = o.dialect.work_coordinates.clone();
            let w = w.to_ascii_uppercase();
            if w == "NONE" {
                o.work_coordinates = Some("none".into());
            } else if known.contains(&w) {
                o.work_coordinates = Some(w);
            } else if known.is_empty() {
                return Err(bad(format!(
                    "work_coordinates {}: {} selects none (its datum is the control's preset); expected none",
                    quote(&w),
                    o.dialect.name
                )));
            } else {
                return Err(bad(format!(
                    "work_coordinates {}: {} takes {} or none",
                    quote(&w),
                    o.dialect.name,
                    known.join(", ")
                )));
            }
        }
        o.setup_offsets = match self.setups.as_deref() {
            None | Some("transform") => false,
            Some("work-offsets") => true,
            Some(x) => return Err(SettingError::of("setups")(format!("setups {}: expected transform or work-offsets", quote(x)))),
        };
        if o.setup_offsets {
            setups_allowed(o).map_err(SettingError::of("setups"))?;
        }
        Ok(())
    }

    /// The collision check's settings: on or off, the clearance, the stock and fixtures.
    fn collision_options(&self, o: &mut Options) -> Result<(), SettingError> {
        match self.collisions.as_deref().map(str::trim) {
            None | Some("") | Some("on") | Some("off") => {}
            Some(x) => return Err(SettingError::of("collisions")(format!("collisions {}: expected on or off", quote(x)))),
        }
        if let Some(c) = self.collision_clearance {
            let bad = SettingError::of("collision_clearance");
            if !(c.is_finite() && c >= 0.0 && crate::kinematics::coordinate_ok(c)) {
                return Err(bad("collision_clearance must be a length of 0 or more".into()));
            }
            // Samples are kept within the clearance: a 1e-9 one asked the most of every move.
            if c > 0.0 && c < MIN_CLEARANCE {
                return Err(bad(format!("collision_clearance must be 0 (none) or at least {MIN_CLEARANCE}")));
            }
            o.collision_clearance = c;
        }
        if let Some(s) = self.stock.as_deref().filter(|s| !s.trim().is_empty()) {
            o.stock = vec![parse_box(s).map_err(|e| SettingError::of("stock")(format!("stock: {e}")))?];
        }
        if let Some(f) = self.fixtures.as_deref().filter(|s| !s.trim().is_empty()) {
            let bad = SettingError::of("fixtures");
            o.fixtures = f
                .split(';')
                .filter(|b| !b.trim().is_empty())
                .map(|b| parse_box(b).map_err(|e| bad(format!("fixtures: {e}"))))
                .collect::<Result<_, _>>()?;
            if o.fixtures.len() > 16 {
                return Err(bad("fixtures: at most 16 boxes".into()));
            }
        }
        Ok(())
    }
}

/// A text setting that says something (an empty form field is none).
fn given(v: &Option<String>) -> Option<&str> {
    v.as_deref().filter(|v| !v.trim().is_empty())
}

/// Where positioning retracts to: the job's, else the profile's, else the mode's own (the top of
/// Z in joint mode; `clearance` along the tool axis in TCP mode, where X Y Z are the tip). A job
/// that asks for the top of Z in TCP mode is refused; a profile's default yields to the mode.
fn retract(job: Option<&str>, profile: Option<Retract>, mode: Mode, clearance: f64) -> Result<Retract, SettingError> {
    let bad = SettingError::of("retract");
    let by_mode = match mode {
        Mode::Joint => Retract::MachineZ,
        Mode::Tcp => Retract::Axis(clearance),
    };
    match (job.map(Retract::parse).transpose().map_err(&bad)?, profile) {
        (Some(Retract::MachineZ), _) if mode == Mode::Tcp => Err(bad(
            "retract machine-z: in TCP mode X Y Z are the tip, not the machine's Z; use axis:D or plane:Z".into(),
        )),
        (Some(r), _) => Ok(r),
        (None, Some(Retract::MachineZ)) => Ok(by_mode),
        (None, Some(r)) => Ok(r),
        (None, None) => Ok(by_mode),
    }
}

/// A number as an error quotes it: as written where that is short, else in exponent form (1e-300
/// written out is 301 digits; an error quotes at most 80 characters).
fn short(v: f64) -> String {
    let s = v.to_string();
    if s.len() <= 24 { s } else { format!("{v:e}") }
}

/// The least clearance, and the least side of a stock or fixture box (samples are kept within
/// both; any less only multiplies the check's samples).
const MIN_CLEARANCE: f64 = 0.001;
/// The farthest a stock or fixture box may reach from the CL's origin (100 m, or 100 000 in):
/// a ±1e8 one swung its corners through metres a degree.
const MAX_BOX: f64 = 1e5;

/// `x0,y0,z0,x1,y1,z1`: a box by two opposite corners, its sides at least [`MIN_CLEARANCE`], within
/// ±[`MAX_BOX`].
pub fn parse_box(s: &str) -> Result<crate::collide::Solid, String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|p| p.trim().parse::<f64>().map_err(|_| format!("{} is not a number", quote(p))))
        .collect::<Result<_, _>>()?;
    let [x0, y0, z0, x1, y1, z1] = v.as_slice() else {
        return Err(format!("expected six numbers x0,y0,z0,x1,y1,z1, got {}", quote(s)));
    };
    let (a, b) = (Vec3::new(*x0, *y0, *z0), Vec3::new(*x1, *y1, *z1));
    let solid = crate::collide::Solid::Box {
        min: a.inf(&b),
        max: a.sup(&b),
    };
    solid.check()?;
    if v.iter().any(|c| c.abs() > MAX_BOX) {
        return Err(format!("every coordinate within ±{MAX_BOX}: nothing larger stands on a machine tool"));
    }
    if (b - a).abs().min() < MIN_CLEARANCE {
        return Err(format!("each side at least {MIN_CLEARANCE} long"));
    }
    Ok(solid)
}

/// `setups=work-offsets` needs offsets to select, and words measured from them.
fn setups_allowed(o: &Options) -> Result<(), String> {
    if o.dialect.work_coordinates.is_empty() || o.work_coordinates.as_deref() == Some("none") {
        return Err(format!(
            "setups work-offsets: the program selects no work offset ({}, work_coordinates {}): use setups=transform",
            o.dialect.name,
            o.work_coordinates.as_deref().unwrap_or("default")
        ));
    }
    if o.tilted_planes {
        return Err("setups work-offsets: not with planes=tilted (a plane's origin is in the first offset's words): use setups=transform".into());
    }
    Ok(())
}

/// `x,y,z`: three finite coordinates (a work offset, a point on the command line).
pub fn parse_triple(s: &str) -> Result<Vec3, String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|p| p.trim().parse::<f64>().map_err(|_| format!("{} is not a number", quote(p))))
        .collect::<Result<_, _>>()?;
    match v.as_slice() {
        [x, y, z] if v.iter().all(|c| crate::kinematics::coordinate_ok(*c)) => Ok(Vec3::new(*x, *y, *z)),
        _ => Err(format!(
            "expected three numbers x,y,z within ±{:e}, got {}",
            crate::kinematics::MAX_COORD,
            quote(s)
        )),
    }
}
