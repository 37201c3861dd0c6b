//! The collision check (issue 31): a profile's bodies, the tool and the stock, checked at every
//! block and between blocks. Per machine kind, a CL made to crash is found at its block naming
//! both bodies; a clean CL shows nothing; `collisions=off` checks nothing; strict refuses.

mod common;

use common::collect::Collect;
use kinepost::diag::{Code, Diagnostic, Severity};
use kinepost::machines::{Profile, parse_profile};
use kinepost::post::{self, Settings, Summary};

fn shipped(id: &str) -> String {
    std::fs::read_to_string(format!("{}/machines/{id}.toml", env!("CARGO_MANIFEST_DIR"))).unwrap()
}

/// A shipped profile's kinematics with `bodies` (TOML `[[body]]` entries) added.
fn profile(id: &str, bodies: &str) -> Profile {
    parse_profile(&format!("{}\n{bodies}", shipped(id)), id, None).unwrap()
}

const SPINNER: &str = r#"
[[body]]
name = "table"
on = "C"
cylinder = { from = [0.0, 0.0, -60.0], to = [0.0, 0.0, 0.0], radius = 300.0 }
[[body]]
name = "cradle"
on = "B"
box = [-320.0, -340.0, -160.0, 320.0, 340.0, -80.0]
[[body]]
name = "base"
on = "bed"
box = [-700.0, -700.0, -900.0, 700.0, 700.0, -460.0]
[[body]]
name = "spindle housing"
on = "spindle"
cylinder = { from = [0.0, 0.0, 5.0], to = [0.0, 0.0, 300.0], radius = 90.0 }
[[body]]
name = "ram"
on = "ram"
box = [-160.0, -160.0, 300.0, 160.0, 400.0, 900.0]
"#;

/// A CL: header, then points `(rapid, x y z i j k)`; returns the text and each point's line.
fn cl(units: &str, length: f64, pts: &[(bool, [f64; 6])]) -> (String, Vec<u32>) {
    let mut s = format!("PARTNO/COLLIDE\nUNITS/{units}\nLOADTL/1,LENGTH,{length}\nSPINDL/6000,RPM,CLW\nFEDRAT/500,{}\n", if units == "MM" { "MMPM" } else { "IPM" });
    let mut lines = Vec::new();
    let mut line = 5;
    for (rapid, p) in pts {
        if *rapid {
            s.push_str("RAPID\n");
            line += 1;
        }
        s.push_str(&format!("GOTO/{},{},{},{},{},{}\n", p[0], p[1], p[2], p[3], p[4], p[5]));
        line += 1;
        lines.push(line);
    }
    s.push_str("SPINDL/OFF\nFINI\n");
    (s, lines)
}

fn run(p: &Profile, text: &str, settings: Settings) -> (Collect, Result<Summary, post::Error>) {
    let o = settings.profile_options(p, None).unwrap();
    let mut sink = Collect::default();
    let r = post::post(text.as_bytes(), &p.machine, &o, &mut sink);
    (sink, r)
}

fn hits(c: &Collect, code: Code) -> Vec<&Diagnostic> {
    c.diags.iter().filter(|d| d.code == code).collect()
}

/// A collision on `line` naming both bodies.
fn assert_hit(c: &Collect, line: u32, a: &str, b: &str) {
    let found = hits(c, Code::Collision)
        .into_iter()
        .any(|d| d.line == Some(line) && d.message.contains(a) && d.message.contains(b) && d.severity == Severity::Error);
    assert!(found, "no collision of {a} and {b} at line {line}: {:#?}", hits(c, Code::Collision));
}

fn tilted(deg: f64) -> [f64; 3] {
    let t = deg.to_radians();
    [t.sin(), 0.0, t.cos()]
}

fn at(p: [f64; 3], a: [f64; 3]) -> [f64; 6] {
    [p[0], p[1], p[2], a[0], a[1], a[2]]
}

const UP: [f64; 3] = [0.0, 0.0, 1.0];

#[test]
fn table_table_plunge_into_the_table_and_holder_into_the_tilted_table() {
    let p = profile("spinner-u5-620", SPINNER);
    let (text, lines) = cl(
        "MM",
        100.0,
        &[
            (true, at([0.0, 0.0, 100.0], UP)),
            (false, at([0.0, 0.0, 20.0], UP)),
            (false, at([0.0, 0.0, -5.0], UP)),
            (true, at([0.0, 0.0, 100.0], UP)),
            (true, at([0.0, 0.0, 100.0], tilted(85.0))),
            (false, at([0.0, 0.0, 6.0], tilted(85.0))),
        ],
    );
    let (c, s) = run(&p, &text, Settings::default());
    let s = s.unwrap();
    assert_hit(&c, lines[2], "cutter", "table");
    assert_hit(&c, lines[5], "holder", "table");
    for (i, l) in lines.iter().enumerate() {
        if i != 2 && i != 5 {
            assert!(
                !hits(&c, Code::Collision).iter().any(|d| d.line == Some(*l)),
                "a collision at line {l}: {:#?}",
                hits(&c, Code::Collision)
            );
        }
    }
    assert!(s.counts.get("collision").copied().unwrap_or(0) >= 2, "{:?}", s.counts);
}

#[test]
fn rapid_through_the_stock_is_a_collision_a_cut_is_not() {
    let p = profile("spinner-u5-620", SPINNER);
    let (text, lines) = cl(
        "MM",
        100.0,
        &[
            (true, at([0.0, 0.0, 100.0], UP)),
            (false, at([0.0, 0.0, 30.0], UP)),
            (true, at([0.0, 0.0, 100.0], UP)),
            (true, at([20.0, 0.0, 20.0], UP)),
        ],
    );
    let stock = Settings {
        stock: Some("-50,-50,0,50,50,40".into()),
        ..Default::default()
    };
    let (c, s) = run(&p, &text, stock);
    s.unwrap();
    assert_hit(&c, lines[3], "cutter", "stock");
    // The retract from the cut leaves along what it cut: only the rapid into the stock (and the
    // approach kinepost inserts before it) is a collision.
    let all = hits(&c, Code::Collision);
    assert!(all.iter().all(|d| d.line == Some(lines[3])), "{all:#?}");
}

#[test]
fn a_clean_program_with_its_stock_shows_nothing_and_off_checks_nothing() {
    let p = profile("spinner-u5-620", SPINNER);
    let mut pts = vec![(true, at([-60.0, -60.0, 80.0], UP))];
    for k in 0..40 {
        let x = -40.0 + 2.0 * k as f64;
        pts.push((false, at([x, (k as f64 * 0.3).sin() * 30.0, 40.0], tilted(k as f64))));
    }
    let (text, _) = cl("MM", 100.0, &pts);
    let with_stock = Settings {
        stock: Some("-50,-50,0,50,50,40".into()),
        ..Default::default()
    };
    let (c, s) = run(&p, &text, with_stock);
    s.unwrap();
    assert!(hits(&c, Code::Collision).is_empty(), "{:#?}", hits(&c, Code::Collision));
    assert!(hits(&c, Code::NearCollision).is_empty(), "{:#?}", hits(&c, Code::NearCollision));

    let (crash, _) = cl("MM", 100.0, &[(true, at([0.0, 0.0, 100.0], UP)), (false, at([0.0, 0.0, -5.0], UP))]);
    let off = Settings {
        collisions: Some("off".into()),
        ..Default::default()
    };
    let (c, s) = run(&p, &crash, off);
    s.unwrap();
    assert!(hits(&c, Code::Collision).is_empty());
    let strict = Settings {
        strict: Some(true),
        ..Default::default()
    };
    let (_, s) = run(&p, &crash, strict);
    assert!(s.is_err(), "strict mode posted a collision");
}

#[test]
fn a_near_miss_is_a_warning() {
    let p = profile("spinner-u5-620", SPINNER);
    // The holder's rim passes 1 mm above the table top: within the 2 mm clearance.
    let t = 80f64.to_radians();
    let z = 1.0 + 20.0 * t.sin() - 60.0 * t.cos();
    let (text, lines) = cl("MM", 100.0, &[(true, at([0.0, 0.0, 100.0], tilted(80.0))), (false, at([0.0, 0.0, z.max(6.0)], tilted(80.0)))]);
    let (c, s) = run(&p, &text, Settings::default());
    s.unwrap();
    let near = hits(&c, Code::NearCollision);
    assert!(
        near.iter().any(|d| d.line == Some(lines[1]) && d.message.contains("holder") && d.severity == Severity::Warning),
        "{near:#?} {:#?}",
        hits(&c, Code::Collision)
    );
}

#[test]
fn head_head_swings_the_spindle_head_into_the_table() {
    let p = profile(
        "fryer-5x-45",
        r#"
[[body]]
name = "table"
on = "table"
box = [-20.0, -10.0, -2.0, 20.0, 10.0, 0.0]
[[body]]
name = "a fork"
on = "A"
box = [-2.5, -1.0, 4.0, 2.5, 1.0, 6.0]
[[body]]
name = "spindle housing"
on = "spindle"
cylinder = { from = [0.0, 0.0, 0.3], to = [0.0, 0.0, 4.0], radius = 1.5 }
[[body]]
name = "c head"
on = "C"
box = [-3.0, -3.0, 7.0, 3.0, 3.0, 12.0]
"#,
    );
    let side = [0.0, -1.0, 0.0];
    let (text, lines) = cl(
        "INCHES",
        3.0,
        &[(true, at([0.0, 0.0, 6.0], UP)), (false, at([0.0, 0.0, 2.0], UP)), (true, at([0.0, 0.0, 6.0], side)), (false, at([0.0, 0.0, 0.5], side))],
    );
    let (c, s) = run(&p, &text, Settings::default());
    s.unwrap();
    assert_hit(&c, lines[3], "spindle housing", "table");
    assert!(!hits(&c, Code::Collision).iter().any(|d| d.line == Some(lines[1])));
}

#[test]
fn head_table_swings_the_head_into_the_table() {
    let p = profile(
        "dmg-dmc75v",
        r#"
[[body]]
name = "table"
on = "C"
cylinder = { from = [0.0, 0.0, -80.0], to = [0.0, 0.0, 0.0], radius = 300.0 }
[[body]]
name = "b head"
on = "B"
box = [-90.0, -120.0, 100.0, 90.0, 120.0, 220.0]
[[body]]
name = "spindle housing"
on = "spindle"
cylinder = { from = [0.0, 0.0, 5.0], to = [0.0, 0.0, 100.0], radius = 70.0 }
"#,
    );
    let (text, lines) = cl(
        "MM",
        100.0,
        &[(true, at([0.0, 0.0, 200.0], UP)), (false, at([0.0, 0.0, 30.0], UP)), (true, at([0.0, 0.0, 200.0], [-1.0, 0.0, 0.0])), (false, at([0.0, 0.0, 30.0], [-1.0, 0.0, 0.0]))],
    );
    let (c, s) = run(&p, &text, Settings::default());
    s.unwrap();
    assert_hit(&c, lines[3], "spindle housing", "table");
    assert!(!hits(&c, Code::Collision).iter().any(|d| d.line == Some(lines[1])));
}

#[test]
fn nutating_plunge_into_the_table() {
    let p = profile(
        "dmu-nutating-45",
        r#"
[[body]]
name = "table"
on = "C"
cylinder = { from = [0.0, 0.0, -40.0], to = [0.0, 0.0, 0.0], radius = 200.0 }
[[body]]
name = "nutating body"
on = "B"
cylinder = { from = [0.0, 0.0, -200.0], to = [0.0, 0.0, -60.0], radius = 150.0 }
"#,
    );
    let (text, lines) = cl("MM", 100.0, &[(true, at([0.0, 0.0, 100.0], UP)), (false, at([0.0, 0.0, 10.0], UP)), (false, at([0.0, 0.0, -8.0], UP))]);
    let (c, s) = run(&p, &text, Settings::default());
    s.unwrap();
    assert_hit(&c, lines[2], "cutter", "table");
    assert!(!hits(&c, Code::Collision).iter().any(|d| d.line == Some(lines[1])));
}

#[test]
fn three_rotary_plunge_into_the_table() {
    let p = profile(
        "propeller-3r2l",
        r#"
[[body]]
name = "table"
on = "C"
cylinder = { from = [0.0, 0.0, -100.0], to = [0.0, 0.0, 0.0], radius = 400.0 }
[[body]]
name = "b head"
on = "B"
cylinder = { from = [-80.0, 0.0, 150.0], to = [80.0, 0.0, 150.0], radius = 60.0 }
"#,
    );
    let (text, lines) = cl("MM", 100.0, &[(true, at([0.0, 0.0, 300.0], UP)), (false, at([0.0, 0.0, 50.0], UP)), (false, at([0.0, 0.0, -10.0], UP))]);
    let (c, s) = run(&p, &text, Settings::default());
    s.unwrap();
    assert_hit(&c, lines[2], "cutter", "table");
    assert!(!hits(&c, Code::Collision).iter().any(|d| d.line == Some(lines[1])));
}

#[test]
fn bad_bodies_and_settings_are_refused_naming_the_key() {
    let id = "spinner-u5-620";
    let bad = |b: &str| parse_profile(&format!("{}\n{b}", shipped(id)), id, None).unwrap_err().to_string();
    assert!(bad("[[body]]\nname = \"t\"\non = \"Q\"\nbox = [0.0,0.0,0.0,1.0,1.0,1.0]\n").contains("body[0].on"));
    assert!(bad("[[body]]\nname = \"t\"\non = \"bed\"\nbox = [0.0,0.0,0.0,-1.0,1.0,1.0]\n").contains("body[0].box"));
    assert!(bad("[[body]]\nname = \"t\"\non = \"bed\"\n").contains("body[0]"));
    let p = profile(id, SPINNER);
    for s in [
        Settings { collisions: Some("maybe".into()), ..Default::default() },
        Settings { stock: Some("1,2,3".into()), ..Default::default() },
        Settings { collision_clearance: Some(-1.0), ..Default::default() },
    ] {
        assert!(s.profile_options(&p, None).is_err());
    }
}

