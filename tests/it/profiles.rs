//! Profile loading: what a shop gets told when a profile is wrong.

use kinepost::machines::{self, Library, parse_profile};

const GOOD: &str = r#"
id = "t"
name = "test"
units = "mm"
controller = "fanuc"

[[linear]]
name = "X"
min = -100.0
max = 100.0

[[linear]]
name = "Y"
min = -100.0
max = 100.0

[[linear]]
name = "Z"
min = -100.0
max = 100.0

[[rotary]]
name = "B"
on = "table"
axis = [0.0, -1.0, 0.0]
pivot = [0.0, 0.0, 0.0]
min = -90.0
max = 90.0

[[rotary]]
name = "C"
on = "table"
axis = [0.0, 0.0, -1.0]
pivot = [0.0, 0.0, 0.0]

[tool]
default_length = 50.0
"#;

/// The error text for GOOD with `from` replaced by `to` (exactly once).
fn err(from: &str, to: &str) -> String {
    assert_eq!(GOOD.matches(from).count(), 1, "{from:?} must occur once");
    let text = GOOD.replacen(from, to, 1);
    match parse_profile(&text, "machines/t.toml", Some("t")) {
        Ok(_) => panic!("accepted: {to}"),
        Err(e) => e.to_string(),
    }
}

fn says(msg: &str, parts: &[&str]) {
    for p in parts {
        assert!(msg.contains(p), "{msg:?} should mention {p:?}");
    }
}

#[test]
fn a_good_profile_loads() {
    let p = parse_profile(GOOD, "machines/t.toml", Some("t")).unwrap();
    assert_eq!(p.machine.rotaries.len(), 2);
    assert_eq!(p.machine.default_tool_length, 50.0);
    assert_eq!(p.machine.kinematics_kind(), "table-table");
}

#[test]
fn unknown_keys_are_rejected_by_name() {
    says(
        &err("controller = \"fanuc\"", "controller = \"fanuc\"\ncolour = \"red\""),
        &["machines/t.toml", "colour"],
    );
    says(
        &err(
            "on = \"table\"\naxis = [0.0, -1.0, 0.0]",
            "on = \"table\"\naxiz = [0.0, -1.0, 0.0]",
        ),
        &["axiz"],
    );
}

#[test]
fn zero_or_non_finite_axes_are_rejected() {
    says(
        &err("axis = [0.0, -1.0, 0.0]", "axis = [0.0, 0.0, 0.0]"),
        &["rotary[0] (B).axis", "non-zero"],
    );
    says(
        &err("axis = [0.0, -1.0, 0.0]", "axis = [nan, -1.0, 0.0]"),
        &["rotary[0] (B).axis", "finite"],
    );
    says(
        &err("pivot = [0.0, 0.0, 0.0]\nmin = -90.0", "pivot = [inf, 0.0, 0.0]\nmin = -90.0"),
        &["rotary[0] (B).pivot", "finite"],
    );
}

#[test]
fn limits_must_be_ordered_and_paired() {
    says(
        &err("min = -90.0\nmax = 90.0", "min = 90.0\nmax = 90.0"),
        &["rotary[0] (B).min/max", "less than"],
    );
    says(
        &err(
            "min = -100.0\nmax = 100.0\n\n[[linear]]\nname = \"Y\"",
            "min = 100.0\nmax = -100.0\n\n[[linear]]\nname = \"Y\"",
        ),
        &["linear.X", "less than"],
    );
    says(&err("min = -90.0\nmax = 90.0", "min = -90.0"), &["rotary[0].min/max", "both"]);
    // ±1e12° made IK list windings for minutes.
    says(
        &err("min = -90.0\nmax = 90.0", "min = -1e12\nmax = 1e12"),
        &["rotary[0] (B).min/max", "99999.999"],
    );
}

#[test]
fn axis_names_must_be_valid_and_unique() {
    says(&err("name = \"B\"", "name = \"Q\""), &["rotary[0].name", "A, B or C"]);
    says(&err("name = \"B\"", "name = \"C\""), &["rotary[1].name", "duplicate"]);
    says(&err("name = \"Y\"", "name = \"X\""), &["linear[1].name", "duplicate"]);
    says(&err("name = \"Z\"", "name = \"W\""), &["linear[2].name", "X, Y or Z"]);
}

#[test]
fn id_must_equal_the_file_stem_and_be_well_formed() {
    says(&err("id = \"t\"", "id = \"other\""), &["id", "file name"]);
    let bad = GOOD.replacen("id = \"t\"", "id = \"Bad_Id\"", 1);
    says(
        &parse_profile(&bad, "x.toml", None).unwrap_err().to_string(),
        &["id", "[a-z0-9-]{1,64}"],
    );
}

#[test]
fn chains_the_solver_cannot_handle_are_rejected() {
    // Two rotaries about the same line cannot orient a tool.
    says(
        &err("axis = [0.0, -1.0, 0.0]", "axis = [0.0, 0.0, 1.0]"),
        &["rotary", "orient"],
    );
    // No X and only two rotaries: the tip's x cannot be placed.
    let no_x = GOOD.replacen("[[linear]]\nname = \"X\"\nmin = -100.0\nmax = 100.0\n", "", 1);
    says(
        &parse_profile(&no_x, "machines/t.toml", Some("t")).unwrap_err().to_string(),
        &["rotary", "supported chains"],
    );
    // A C table on the bed carrying an A trunnion is fine; a C table innermost on its own trunnion axis along z is not.
    says(
        &err(
            "axis = [0.0, -1.0, 0.0]\npivot = [0.0, 0.0, 0.0]",
            "axis = [0.0, 0.0, 1.0]\npivot = [5.0, 0.0, 0.0]",
        ),
        &["rotary"],
    );
}

#[test]
fn bad_units_and_angle_errors_are_rejected() {
    says(&err("units = \"mm\"", "units = \"cm\""), &["units", "mm", "inch"]);
    let ae = "max = 90.0\n\n[rotary.angle_error]\ncoefficients = [0.0, -1.5]\nrange = [0.0, 40.0]\n\n[[rotary]]";
    says(&err("max = 90.0\n\n[[rotary]]", ae), &["angle_error", "increase"]);
}

#[test]
fn a_directory_with_one_bad_profile_fails_to_load_naming_it() {
    let dir = std::env::temp_dir().join(format!("kinepost-profiles-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("t.toml"), GOOD).unwrap();
    assert_eq!(Library::load_dir(&dir).unwrap().len(), 1);
    std::fs::write(dir.join("u.toml"), GOOD).unwrap(); // id "t" in u.toml
    let e = Library::load_dir(&dir).unwrap_err().to_string();
    std::fs::remove_dir_all(&dir).ok();
    says(&e, &["u.toml", "id", "file name"]);
}

#[test]
fn shipped_profiles_load_and_an_unknown_id_is_named() {
    let lib = Library::load_dir(&machines::default_dir()).unwrap();
    assert_eq!(lib.len(), 11);
    assert!(lib.get("no-such").unwrap_err().to_string().contains("no-such"));
}

/// A controller kinepost has no dialect for posted Fanuc without a word; a clamp "word" with a
/// space (`M10 M30`) put a program end at every clamp. Both are refused, naming the key; a
/// speed or acceleration must be positive.
#[test]
fn unknown_controllers_multi_word_clamps_and_bad_speeds_are_rejected() {
    says(
        &err("controller = \"fanuc\"", "controller = \"fanucc\""),
        &["controller", "fanucc"],
    );
    // An id is a name, not a payload (a 1 MB one was accepted).
    let long = "x".repeat(65);
    let text = GOOD.replacen("id = \"t\"", &format!("id = \"{long}\""), 1);
    says(
        &parse_profile(&text, "machines/x.toml", None).unwrap_err().to_string(),
        &["id", "{1,64}"],
    );
    let clamp = |words: &str| {
        err(
            "min = -90.0\nmax = 90.0\n",
            &format!("min = -90.0\nmax = 90.0\nclamp = {words}\n"),
        )
    };
    says(&clamp(r#"["M10 M30", "M11"]"#), &["rotary[0].clamp", "one word each"]);
    says(&clamp(r#"["M10", ""]"#), &["rotary[0].clamp"]);
    says(&clamp(r#"["M10", "(M11)"]"#), &["rotary[0].clamp"]);
    let ok = GOOD.replacen(
        "min = -90.0\nmax = 90.0\n",
        "min = -90.0\nmax = 90.0\nclamp = [\"M10\", \"M11\"]\n",
        1,
    );
    assert!(parse_profile(&ok, "machines/t.toml", Some("t")).is_ok());
    says(
        &err("min = -90.0\nmax = 90.0\n", "min = -90.0\nmax = 90.0\nmax_accel = -1.0\n"),
        &["max_accel"],
    );
}
