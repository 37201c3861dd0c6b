//! What the edges write besides NC text: the NDJSON records (one definition, used by the CLI,
//! HTTP and jobs alike), the files a run writes, the preview, and the JSON of
//! an IK solution.
//! The engine knows none of it: it pushes blocks into a [`crate::post::Sink`].

pub mod model;
pub mod ndjson;
pub mod preview;

pub use ndjson::{ErrorBody, FileSink, Header, Record};

use crate::kinematics;
use serde_json::{Map, Value, json};

pub use crate::text::utc_now;

/// One solution as the CLI and the API show it: axis words, branch, flags. Rotary words are those
/// of the actual angle in (−180°, 180°]; they are never wrapped themselves, because angle-error
/// compensation is not periodic (a word of 183.26° may be the one that stands at 179.41°).
pub fn solution_json(m: &kinematics::Machine, s: &kinematics::Solution) -> Value {
    let mut o = Map::new();
    for (i, l) in m.linears.iter().enumerate() {
        if l.is_some() {
            o.insert(kinematics::LINEAR_NAMES[i].to_string(), json!(s.joints.linear[i]));
        }
    }
    for (i, r) in m.rotaries.iter().enumerate() {
        o.insert(r.name.to_string(), json!(s.joints.rotary[i].to_degrees()));
    }
    o.insert("branch".into(), json!(s.branch));
    if m.rotaries.len() == 3 {
        o.insert("root".into(), json!(s.root));
    }
    o.insert("within_limits".into(), json!(kinematics::reachable_within_limits(m, s)));
    o.insert("singular".into(), json!(s.singular.is_some()));
    if let Some(ri) = s.singular {
        o.insert("free_axis".into(), json!(m.rotaries[ri].name.to_string()));
    }
    Value::Object(o)
}
