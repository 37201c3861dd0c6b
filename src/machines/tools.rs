//! Tool tables: tool number → length (what joint mode on a head machine needs), and the
//! dimensions later work needs (diameter, corner radius, holder). One parser for the file beside
//! a profile (`machines/<id>.tools.toml`), the API's body and a job's own table.
//!
//! ```toml
//! units = "mm"            # or "inch": every length below
//! [[tool]]
//! number = 3
//! length = 112.5          # gauge line to tip
//! diameter = 10.0         # optional
//! corner_radius = 0.0     # optional, at most half the diameter
//! holder = { diameter = 40.0, length = 60.0 }   # optional
//! name = "10 mm flat end mill"                   # optional
//! ```

use super::Error;
use crate::kinematics::Units;
use crate::text::quote;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// Tools one table may hold: more pockets than any changer, few enough to read at every post.
pub const MAX_TOOLS: usize = 10_000;
/// The largest tool number: the largest `T` word of any dialect kinepost writes.
pub const MAX_TOOL_NUMBER: i64 = 99_999_999;
/// The largest length of any kind in a table, in mm (10 m): a typo's extra digits fail.
const MAX_LENGTH_MM: f64 = 10_000.0;
/// The largest name kept.
const MAX_NAME: usize = 200;

/// The TOML document of a tool table.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ToolTableDoc {
    pub units: String,
    #[serde(default)]
    pub tool: Vec<ToolEntryDoc>,
}

#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ToolEntryDoc {
    pub number: i64,
    pub length: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub diameter: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub corner_radius: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub holder: Option<HolderDoc>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
}

#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct HolderDoc {
    pub diameter: f64,
    pub length: f64,
}

/// One tool, in its table's units.
#[derive(Clone, Debug, PartialEq)]
pub struct Tool {
    pub number: u32,
    pub length: f64,
    pub diameter: Option<f64>,
    pub corner_radius: Option<f64>,
    /// Holder diameter and length (gauge line down), for collision checks to come.
    pub holder: Option<HolderDoc>,
    pub name: Option<String>,
}

/// A validated tool table.
#[derive(Clone, Debug, PartialEq)]
pub struct ToolTable {
    pub units: Units,
    tools: BTreeMap<u32, Tool>,
}

impl ToolTable {
    pub fn get(&self, number: u32) -> Option<&Tool> {
        self.tools.get(&number)
    }

    /// Tool `number`'s length in `units` (the profile's), if the table has it.
    pub fn length(&self, number: u32, units: Units) -> Option<f64> {
        self.get(number).map(|t| t.length * self.units.factor_to(units))
    }

    pub fn iter(&self) -> impl Iterator<Item = &Tool> {
        self.tools.values()
    }

    pub fn len(&self) -> usize {
        self.tools.len()
    }

    pub fn is_empty(&self) -> bool {
        self.tools.is_empty()
    }
}

/// Parses and validates a tool table; `file` names it in errors (a path, `request body`,
/// `tool_table`). Every error names the entry (`tool[2] (T7).length`) and what to fix.
pub fn parse_tool_table(text: &str, file: &str) -> Result<ToolTable, Error> {
    let invalid = |key: String, problem: String| Error::Invalid {
        file: file.into(),
        key,
        problem,
    };
    if text.len() as u64 > super::MAX_PROFILE_BYTES {
        return Err(invalid(
            String::new(),
            format!("larger than {} bytes: not a tool table", super::MAX_PROFILE_BYTES),
        ));
    }
    let doc: ToolTableDoc = toml::from_str(text).map_err(|e| Error::Parse {
        file: file.into(),
        message: super::one_line(&e),
    })?;
    let units = match doc.units.as_str() {
        "mm" => Units::Mm,
        "inch" => Units::Inch,
        other => {
            return Err(invalid(
                "units".into(),
                format!("{} must be \"mm\" or \"inch\"", quote(other)),
            ));
        }
    };
    if doc.tool.len() > MAX_TOOLS {
        return Err(invalid(
            "tool".into(),
            format!("{} tools: a table holds at most {MAX_TOOLS}", doc.tool.len()),
        ));
    }
    let max = MAX_LENGTH_MM * Units::Mm.factor_to(units);
    let mut tools = BTreeMap::new();
    for (i, t) in doc.tool.iter().enumerate() {
        let key = |k: &str| format!("tool[{i}] (T{}).{k}", t.number);
        if !(1..=MAX_TOOL_NUMBER).contains(&t.number) {
            return Err(invalid(
                format!("tool[{i}].number"),
                format!("{} must be a whole number from 1 to {MAX_TOOL_NUMBER}", t.number),
            ));
        }
        let length_ok = |v: f64, positive: bool| v.is_finite() && v <= max && if positive { v > 0.0 } else { v >= 0.0 };
        let bound = format!("at most {max} {}", units.as_str());
        if !length_ok(t.length, false) {
            return Err(invalid(
                key("length"),
                format!("{} must be a length from 0 to {bound}", t.length),
            ));
        }
        if let Some(d) = t.diameter.filter(|d| !length_ok(*d, true)) {
            return Err(invalid(key("diameter"), format!("{d} must be positive and {bound}")));
        }
        if let Some(r) = t.corner_radius {
            let half = t.diameter.map_or(max, |d| d / 2.0);
            if !(length_ok(r, false) && r <= half) {
                return Err(invalid(
                    key("corner_radius"),
                    format!("{r} must be from 0 to half the diameter ({half})"),
                ));
            }
        }
        if let Some(h) = &t.holder {
            for (k, v) in [("holder.diameter", h.diameter), ("holder.length", h.length)] {
                if !length_ok(v, true) {
                    return Err(invalid(key(k), format!("{v} must be positive and {bound}")));
                }
            }
        }
        if t.name.as_ref().is_some_and(|n| n.len() > MAX_NAME) {
            return Err(invalid(key("name"), format!("longer than {MAX_NAME} bytes")));
        }
        let number = t.number as u32;
        let tool = Tool {
            number,
            length: t.length,
            diameter: t.diameter,
            corner_radius: t.corner_radius,
            holder: t.holder,
            name: t.name.clone(),
        };
        if tools.insert(number, tool).is_some() {
            return Err(invalid(key("number"), format!("tool {number} is in the table twice")));
        }
    }
    Ok(ToolTable { units, tools })
}

/// The standing table's file beside profile `id` in `dir`.
pub fn table_path(dir: &std::path::Path, id: &str) -> std::path::PathBuf {
    dir.join(format!("{id}{TABLE_SUFFIX}"))
}

/// How a standing tool table's file name ends (`machines/<id>.tools.toml`).
pub const TABLE_SUFFIX: &str = ".tools.toml";

/// Reads a tool table file (at most [`super::MAX_PROFILE_BYTES`]).
pub fn load_tool_table(path: &std::path::Path) -> Result<ToolTable, Error> {
    let file = path.display().to_string();
    let text = super::read_text(path).map_err(|source| Error::Io {
        path: file.clone(),
        source,
    })?;
    parse_tool_table(&text, &file)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_table_reads_with_its_units() {
        let t = parse_tool_table(
            "units = \"inch\"\n[[tool]]\nnumber = 3\nlength = 4.5\ndiameter = 0.5\ncorner_radius = 0.25\nholder = { diameter = 1.5, length = 2 }\n",
            "t",
        )
        .unwrap();
        assert_eq!(t.len(), 1);
        assert!((t.length(3, Units::Mm).unwrap() - 114.3).abs() < 1e-9);
        assert_eq!(t.length(4, Units::Mm), None);
    }

    #[test]
    fn bad_entries_are_named() {
        let bad = [
            ("units = \"m\"", "units"),
            ("units = \"mm\"\n[[tool]]\nnumber = 0\nlength = 1", "tool[0].number"),
            ("units = \"mm\"\n[[tool]]\nnumber = 2\nlength = -1", "tool[0] (T2).length"),
            ("units = \"mm\"\n[[tool]]\nnumber = 2\nlength = nan", "tool[0] (T2).length"),
            ("units = \"mm\"\n[[tool]]\nnumber = 2\nlength = 1e9", "tool[0] (T2).length"),
            (
                "units = \"mm\"\n[[tool]]\nnumber = 2\nlength = 1\ndiameter = 0",
                "tool[0] (T2).diameter",
            ),
            (
                "units = \"mm\"\n[[tool]]\nnumber = 2\nlength = 1\ndiameter = 4\ncorner_radius = 3",
                "tool[0] (T2).corner_radius",
            ),
            (
                "units = \"mm\"\n[[tool]]\nnumber = 2\nlength = 1\nholder = { diameter = inf, length = 1 }",
                "tool[0] (T2).holder.diameter",
            ),
            (
                "units = \"mm\"\n[[tool]]\nnumber = 2\nlength = 1\n[[tool]]\nnumber = 2\nlength = 3",
                "tool[1] (T2).number",
            ),
        ];
        for (text, key) in bad {
            match parse_tool_table(text, "t") {
                Err(Error::Invalid { key: k, .. }) => assert_eq!(k, key, "{text}"),
                other => panic!("{text}: {other:?}"),
            }
        }
        assert!(matches!(
            parse_tool_table("units = \"mm\"\nbogus = 1", "t"),
            Err(Error::Parse { .. })
        ));
        let many: String = (1..=MAX_TOOLS + 1)
            .map(|n| format!("[[tool]]\nnumber = {n}\nlength = 1\n"))
            .collect();
        assert!(
            matches!(parse_tool_table(&format!("units = \"mm\"\n{many}"), "t"), Err(Error::Invalid { key, .. }) if key == "tool")
        );
    }
}
