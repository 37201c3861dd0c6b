//! The APT/CLDATA vocabulary kinepost knows (ISO 4343's post-processor words and what NX, Creo,
//! CATIA, SOLIDWORKS CAM / CAMWorks and Fusion write), and what it does with each word: honours
//! it, knows it to be informational, or tells it at its line. A word on none of these lists is
//! unknown: a warning at its line.

use crate::diag::Severity;

/// What kinepost does with a major word.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Treatment {
    /// Acted on: it changes the NC (or, if it cannot be, says so at its line).
    Honoured,
    /// Cannot change what the machine does: read past in silence, for this reason.
    Informational(&'static str),
    /// Could change what the machine does, and kinepost does not act on it: a diagnostic of
    /// this severity at its line, saying why.
    Told(Severity, &'static str),
}

/// One word of the vocabulary, with a statement that uses it (what the tests place mid-path).
#[derive(Clone, Copy, Debug)]
pub struct Word {
    pub word: &'static str,
    pub sample: &'static str,
    pub treatment: Treatment,
}

const fn honoured(word: &'static str, sample: &'static str) -> Word {
    Word { word, sample, treatment: Treatment::Honoured }
}

const fn info(word: &'static str, sample: &'static str, why: &'static str) -> Word {
    Word { word, sample, treatment: Treatment::Informational(why) }
}

const fn told(word: &'static str, sample: &'static str, sev: Severity, why: &'static str) -> Word {
    Word { word, sample, treatment: Treatment::Told(sev, why) }
}

use Severity::{Error, Warning};

pub const VOCABULARY: &[Word] = &[
    honoured("GOTO", "GOTO/5,5,20"),
    honoured("GODLTA", "GODLTA/0,0,5"),
    honoured("FROM", "FROM/5,5,40"),
    honoured("RAPID", "RAPID"),
    honoured("GOHOME", "GOHOME"),
    honoured("FEDRAT", "FEDRAT/250,MMPM"),
    honoured("SPINDL", "SPINDL/3000,RPM,CCLW"),
    honoured("COOLNT", "COOLNT/MIST"),
    honoured("LOADTL", "LOADTL/7"),
    honoured("LOAD", "LOAD/TOOL,7"),
    honoured("TLDATA", "TLDATA/MILL,10,0,150,0,0"),
    honoured("CUTTER", "CUTTER/10\nSPINDL/200,SMM,CLW"),
    honoured("TOOLNO", "TOOLNO/7,TURN\nCUTTER/10\nSPINDL/200,SMM,CLW"),
    honoured("MODE", "MODE/TURN"),
    honoured("TURRET", "TURRET/7\nCUTTER/10\nSPINDL/200,SMM,CLW"),
    honoured("TLAXIS", "TLAXIS/0,0.2,0.9797959"),
    honoured("MULTAX", "MULTAX/OFF"),
    honoured("ROTABL", "ROTABL/90,CAXIS"),
    honoured("CIRCLE", "CIRCLE/7.5,0,10,0,0,1,2.5"),
    honoured("MOVARC", "MOVARC/7.5,0,10,0,0,1,2.5,ANGLE,180"),
    honoured("GOFWD", "TLON,GOFWD/(CIRCLE/5,5,10,5),ON,(LINE/0,5,10,10,5,10)"),
    honoured("GOBACK", "GOBACK/(CIRCLE/5,5,10,5),ON,(LINE/0,5,10,10,5,10)"),
    honoured("GOLFT", "GOLFT/(CIRCLE/10,0,10,5),ON,(LINE/10,-10,10,10,10,10)"),
    honoured("GORGT", "GORGT/(CIRCLE/10,0,10,5),ON,(LINE/10,-10,10,10,10,10)"),
    honoured("TLON", "TLON,GOFWD/(CIRCLE/5,5,10,5),TANTO,(CIRCLE/5,15,10,5)"),
    honoured("TLLFT", "CUTTER/2\nTLLFT,GOFWD/(CIRCLE/5,5,10,6),ON,(LINE/0,5,10,10,5,10)"),
    honoured("TLRGT", "CUTTER/2\nTLRGT,GOFWD/(CIRCLE/5,5,10,4),PAST,(PLANE/0,1,0,4)"),
    honoured("INDIRV", "INDIRV/0,1,0\nTLON,GOFWD/(CIRCLE/10,0,10,5),ON,(LINE/10,-10,10,10,10,10)"),
    honoured("INDIRP", "INDIRP/5,10,10\nTLON,GOFWD/(CIRCLE/10,0,10,5),ON,(LINE/10,-10,10,10,10,10)"),
    honoured("CYCLE", "CYCLE/DRILL,5,MMPM,100,3"),
    honoured("UNITS", "UNITS/INCHES"),
    honoured("UNIT", "UNIT/INCHES"),
    honoured("DELAY", "DELAY/2"),
    honoured("DWELL", "DWELL/2"),
    honoured("STOP", "STOP"),
    honoured("OPSTOP", "OPSTOP"),
    honoured("OPSKIP", "OPSKIP/ON"),
    honoured("AUXFUN", "AUXFUN/8"),
    honoured("PREFUN", "PREFUN/64"),
    honoured("SELCTL", "SELCTL/9"),
    honoured("SELECT", "SELECT/TOOL,9"),
    honoured("CUTCOM", "CUTCOM/LEFT"),
    honoured("CLEARP", "CLEARP/XYPLAN,60\nRETRCT"),
    honoured("CLRSRF", "CLRSRF/XYPLAN,60\nRETRCT"),
    honoured("RETRCT", "RETRCT"),
    honoured("MSYS", "MSYS/10,0,0,1,0,0,0,1,0"),
    honoured("TOOL PATH", "TOOL PATH/FINISH,TOOL,BALL"),
    honoured("INTOL", "INTOL/0.01"),
    honoured("OUTTOL", "OUTTOL/0.01"),
    honoured("PARTNO", "PARTNO/BRACKET"),
    honoured("PPRINT", "PPRINT/CHECK THE CLAMPS"),
    honoured("INSERT", "INSERT/CHECK THE CLAMPS"),
    honoured("FINI", "FINI"),
    honoured("END", "END"),
    // Informational: the reason is the whole case for silence.
    info("END-OF-PATH", "END-OF-PATH", "an operation's end: what follows says what happens next"),
    info("PAINT", "PAINT/COLOR,4", "NX's display of the path: colour, speed, tool drawing"),
    info("CSYS", "CSYS/1,0,0,0,0,1,0,0,0,0,1,0", "SOLIDWORKS CAM's setup frame: its GOTOs are already in the part frame"),
    info("TRNTYP", "TRNTYP/WORLD,0,0,0", "SOLIDWORKS CAM's note of the frame type before each CSYS"),
    info("BOX", "BOX/0,0,0,100,100,50", "CAMWorks' stock box: geometry for a simulator"),
    info("MACHIN", "MACHIN/UNCX01,1", "names the post the CAM meant: the job's machine profile decides"),
    info("OPFEATSTART", "OPFEATSTART/1", "CAMWorks' feature bounds"),
    info("OPFEATEND", "OPFEATEND/1", "CAMWorks' feature bounds"),
    info("OPERATION", "OPERATION/END", "operation bounds (Fusion)"),
    info("TPRINT", "TPRINT/T1 BALL 10", "a tool listing line for the post's printout"),
    info("SYN", "SYN/'TLAXIS','$$*TLAXIS'", "a synonym for the APT processor"),
    info("PPFUN", "PPFUN/15,1,OFF", "switches of CATIA's ICAM post, not of this one"),
    info("REWIND", "REWIND", "tape rewind: the program end is written anyway"),
    info("DISPLY", "DISPLY/ON", "the post listing's display"),
    info("MFGNO", "MFGNO/4", "Creo's manufacturing number"),
    info("FEATNO", "FEATNO/638", "Creo's feature number"),
    info("AUTOPS", "AUTOPS", "an APT processor switch"),
    info("CYCLE_DEF", "CYCLE_DEF/1", "a cycle's definition for a listing; CYCLE itself is honoured"),
    info("SET", "SET/1", "a CAM-side setting"),
    info("OPTIONS", "OPTIONS/1", "a CAM-side setting"),
    info("TECHNO", "TECHNO/1", "the CAM's technology listing"),
    info("SEQNO", "SEQNO/10,INCR,10", "sequence numbers are the job's option"),
    info("MOVE_ATTRIB", "MOVE_ATTRIB/LINK", "SOLIDWORKS CAM's tag of a link move: the moves are in the CL"),
    info("LINTOL", "LINTOL/0.01", "a tolerance the CAM applied: the job's tolerance governs the post"),
    info("TOLER", "TOLER/0.01", "a tolerance the CAM applied to the path already"),
    info("THICK", "THICK/0.5", "stock left: already in the path"),
    info("MCHTOL", "MCHTOL/0.01", "cornering tolerance of a listing"),
    info("ARCSLP", "ARCSLP/ON", "how arcs are output: the job's dialect decides"),
    info("PITCH", "PITCH/1.5", "a thread's pitch for a listing: cycles carry their own"),
    info("LEADER", "LEADER/10", "tape leader"),
    info("LETTER", "LETTER/1", "letters punched on tape"),
    info("TMARK", "TMARK", "a tape mark"),
    info("ISN", "ISN/12", "the APT source's line number"),
    info("PLOT", "PLOT/ON", "plotter output"),
    info("OVPLOT", "OVPLOT/ON", "plotter output"),
    info("PLABEL", "PLABEL/ON", "plotter output"),
    info("PPLOT", "PPLOT/ON", "plotter output"),
    info("DELETE", "DELETE/10", "tape delete codes"),
    info("REMARK", "REMARK/ROUGH THE POCKET", "Creo's remark for the listing: PPRINT is what reaches the NC"),
    info("PPWORD", "PPWORD/SPINDL,1", "Creo's declaration of a post word for the APT processor"),
    info("KNOT", "KNOT/0,0,0,0,1,1,1,1", "NX's NURBS knot vector: part of the NURBS record, which is told"),
    info("CNTRL", "CNTRL/0,0,5,1", "NX's NURBS control point: part of the NURBS record, which is told"),
    info("CAMERA", "CAMERA/1,0,0,0,0,0,1", "a view for the CAM's display"),
    // Told: could change the machine; not acted on.
    told("ORIGIN", "ORIGIN/100,0,0", Warning, "the origin of the output: NX writes it as information, an ISO post would shift the words by it; not applied (set the job's work_offset or the control's work offset)"),
    told("TRANS", "TRANS/100,0,0", Error, "a shift of the output words a post would apply: not applied (set the job's work_offset or the control's work offset)"),
    told("ROTATE", "ROTATE/CAXIS,ATANGLE,90", Error, "NX's table index: not applied; the path after it is taken as written"),
    told("ROTHED", "ROTHED/AAXIS,30", Error, "a head index: not applied; the path after it is taken as written"),
    told("NURBS", "NURBS/1", Error, "NURBS motion is not posted: the path it describes is missing (post with linear output)"),
    told("POSTN", "POSTN/IN,X,10", Error, "a direct axis position: not applied"),
    told("THREAD", "THREAD/1.5", Error, "threading motion: not written"),
    told("COUPLE", "COUPLE/1", Error, "a rotary coupled to linear motion: not written"),
    told("TRACUT", "TRACUT/1", Error, "an APT transform left for the post: not applied"),
    told("INDEX", "INDEX/1", Error, "an APT repeat left for the post: not applied"),
    told("COPY", "COPY/1", Error, "an APT repeat left for the post: not applied"),
    told("HEAD", "HEAD/1", Warning, "a head or turret selection: a mill has one spindle here"),
    told("SWITCH", "SWITCH/3", Warning, "a CAM-specific switch: not applied"),
    told("CLAMP", "CLAMP/ON", Warning, "a clamp word: the profile's clamp words are written around positioning"),
    told("AIR", "AIR/ON", Warning, "air blast: not written (AUXFUN passes the M code)"),
    told("SAFETY", "SAFETY/ON", Warning, "a safety setting of another post: not applied"),
    told("RESET", "RESET", Warning, "a post reset: not applied"),
    told("CHECK", "CHECK/1", Warning, "a probing or check request: not written"),
    told("REVERS", "REVERS", Warning, "a direction reversal: not applied"),
];

/// `word`'s entry, if kinepost knows it.
pub fn word(major: &str) -> Option<&'static Word> {
    VOCABULARY.iter().find(|w| w.word == major)
}
