//! The collision check (issue 31): a profile's bodies, the tool and the stock, checked at every
//! block and between blocks. Per machine kind, a CL made to crash is found at its block naming
//! both bodies; a clean CL shows nothing; `collisions=off` checks nothing; strict refuses.

use crate::common;

use common::collect::Collect;
use kinepost::diag::{Code, Diagnostic, Severity};
use kinepost::machines::{Profile, parse_profile};
use kinepost::post::{self, Settings, Summary};

fn shipped_file(id: &str) -> String {
    std::fs::read_to_string(format!("{}/machines/{id}.toml", env!("CARGO_MANIFEST_DIR"))).unwrap()
}

/// A shipped profile's text without its geometry (the file ends with it).
fn shipped(id: &str) -> String {
    let text = shipped_file(id);
    let cut = text.find("\n# Geometry for the collision check").or_else(|| text.find("\n[[body]]"));
    text[..cut.unwrap_or(text.len())].to_string()
}

/// A shipped profile's kinematics with `bodies` (TOML `[[body]]` entries) in place of its own.
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
    run_with(p, text, &settings.profile_options(p, None).unwrap())
}

fn run_with(p: &Profile, text: &str, o: &post::Options) -> (Collect, Result<Summary, post::Error>) {
    let mut sink = Collect::default();
    let r = post::post(text.as_bytes(), &p.machine, o, &mut sink);
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
    // The rapid out of the plunge starts 5 mm in the table: its way out overlaps too.
    assert_hit(&c, lines[3], "cutter", "table");
    for (i, l) in lines.iter().enumerate() {
        if ![2, 3, 5].contains(&i) {
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

/// A rapid that grazes the stock's corner with the cutter's side, 0.5 mm deep over 4.4 mm of its
/// 40: samples half the cutter apart (5 mm) could fall either side of it. Kept within the
/// clearance (2 mm), one lands in it.
#[test]
fn a_shallow_gouge_between_samples_is_found() {
    let p = profile("spinner-u5-620", SPINNER);
    let r = kinepost::collide::ToolShape::default_for(100.0, true).diameter / 2.0;
    let (corner, out, along) = ([-50.0, 50.0], [-0.5f64.sqrt(), 0.5f64.sqrt()], [0.5f64.sqrt(), 0.5f64.sqrt()]);
    // The cutter's axis passes r − 0.5 from the corner, outside the stock.
    let q = [corner[0] + (r - 0.5) * out[0], corner[1] + (r - 0.5) * out[1]];
    let pt = |s: f64| at([q[0] + s * along[0], q[1] + s * along[1], 30.0], UP);
    let (text, lines) = cl("MM", 100.0, &[(true, pt(-22.5)), (true, pt(17.5))]);
    let (c, s) = run(&p, &text, Settings { stock: Some("-50,-50,0,50,50,40".into()), ..Default::default() });
    s.unwrap();
    assert_hit(&c, lines[1], "cutter", "stock");
}

/// With TCP the control keeps the tip where it is while a feed turns C 60° (in one block: no
/// rotary step limit); the joints' straight line would pull it 26.8 mm toward C's axis halfway,
/// 200 mm from it. A fixture 15 mm inside the tip is clear on the path the control takes, and
/// hit on the joints' line (joint mode, where the joints do move straight, linearizes the turn).
#[test]
fn a_tcp_move_is_checked_along_the_path_the_control_takes() {
    let p = profile("spinner-u5-620", SPINNER);
    let axis = |deg: f64| {
        let (t, c) = (20f64.to_radians(), deg.to_radians());
        [t.sin() * c.cos(), t.sin() * c.sin(), t.cos()]
    };
    let tip = [200.0, 0.0, 30.0];
    let (text, _) = cl("MM", 100.0, &[(true, at(tip, axis(0.0))), (false, at(tip, axis(60.0)))]);
    for mode in ["tcp", "joint"] {
        let settings = Settings { fixtures: Some("150,-20,0,180,20,40".into()), mode: Some(mode.into()), ..Default::default() };
        let mut o = settings.profile_options(&p, None).unwrap();
        o.max_rotary_step = std::f64::consts::PI;
        let (c, s) = run_with(&p, &text, &o);
        s.unwrap();
        assert_clean(&c, mode);
    }
}

/// A G2/G3 block is checked along its arc, not its chord: a half circle of radius 40 passes
/// through a clamp standing where the chord (through the centre) does not go.
#[test]
fn an_arc_is_checked_along_the_arc() {
    let p = profile("spinner-u5-620", SPINNER);
    let text = "PARTNO/ARC\nUNITS/MM\nLOADTL/1,LENGTH,100\nSPINDL/6000,RPM,CLW\nFEDRAT/500,MMPM\nRAPID\nGOTO/40,0,50,0,0,1\nGOTO/40,0,10,0,0,1\nCIRCLE/0,0,10,0,0,1,40\nGOTO/-40,0,10,0,0,1\nGOTO/-40,0,50,0,0,1\nSPINDL/OFF\nFINI\n";
    let clamp = Settings { fixtures: Some("-5,33,0,5,47,30".into()), ..Default::default() };
    let (c, s) = run(&p, text, clamp);
    s.unwrap();
    assert!(c.nc.contains("G3"), "written as an arc: {}", c.nc);
    assert_hit(&c, 10, "cutter", "fixture 1");
    // Without the clamp, nothing.
    let (c, _) = run(&p, text, Settings::default());
    assert_clean(&c, "no clamp");
}

/// On the way between blocks a touching pair may be told by its last measure: off by at most the
/// spacing or a quarter of that measure (a third of the distance), and the same pairs told,
/// colliding or near, as a fresh check finds at every sample. A move
/// through the table, down into it and out again past the clearance (2 mm), the table tilting on
/// the way; a plunge 40 mm deep, the depth growing as fast as the tool moves; then straight down
/// in steps of 0.3 mm, the holder coming within the clearance and into the table (a bound that
/// moves across 0 must not be told).
#[test]
fn on_the_way_an_overlap_may_be_told_by_its_last_measure() {
    use kinepost::collide::{Axes, Hit, Solid, ToolShape, World};
    use kinepost::kinematics::{Setup, Vec3, controlled_point};
    let p = profile("spinner-u5-620", SPINNER);
    let (m, g) = (&p.machine, p.geometry());
    let stock = [Solid::Box { min: [-40.0, -40.0, 0.0].into(), max: [40.0, 40.0, 30.0].into() }];
    let len = 100.0;
    let tool = ToolShape::default_for(len, true);
    let setup = Setup::new(len, Vec3::zeros());
    let spacing = 2.0;
    let world = || {
        let mut w = World::new(m, &g, &stock, &[], spacing, 1e-3);
        w.set_tool(tool);
        w
    };
    let mut along = world();
    let (mut bounded, mut overlaps) = (0, 0);
    let through = (0..=800).map(|k| {
        let t = k as f64 / 800.0;
        let depth = 1.0 - (2.0 * t - 1.0).abs();
        let tip = Vec3::new(-250.0 + 500.0 * t, -60.0 + 120.0 * t, 50.0 - 130.0 * depth);
        (tip, [(20.0 * t).to_radians(), (45.0 * t).to_radians(), 0.0])
    });
    let plunge = (0..=80).map(|k| (Vec3::new(-100.0, 0.0, -5.0 - 0.5 * k as f64), [0.0; 3]));
    // The holder's end is 60 mm above the tip.
    let down = (0..=30).map(|k| (Vec3::new(100.0, 0.0, -55.0 - 0.3 * k as f64), [0.0; 3]));
    for (k, (tip, actual)) in through.chain(plunge).chain(down).enumerate() {
        let lin: [f64; 3] = controlled_point(m, &actual, &tip, &setup).into();
        let (mut told, mut exact): (Vec<Hit>, Vec<Hit>) = (Vec::new(), Vec::new());
        let at = Axes { linear: lin, actual };
        along.check_on_the_way(m, &setup, &at, true, &mut told);
        world().check_at(m, &setup, &at, true, &mut exact);
        let pairs = |v: &[Hit]| v.iter().map(|h| (h.a.clone(), h.b.clone(), h.dist < 0.0)).collect::<Vec<_>>();
        assert_eq!(pairs(&told), pairs(&exact), "sample {k}");
        for (a, b) in told.iter().zip(&exact) {
            let off = (a.dist - b.dist).abs();
            assert!(off <= spacing.max(b.dist.abs() / 3.0) + 1e-9, "sample {k}: {a:?} against {b:?}");
            bounded += usize::from(off > 1e-9);
            overlaps += usize::from(b.dist < 0.0);
        }
    }
    // Deep enough for long that many overlaps are told by an earlier measure.
    assert!(overlaps > 200 && bounded * 5 > overlaps, "{bounded} of {overlaps} told by an earlier measure");
}

/// A hole written as a canned cycle is checked as the control drills it: a bottom 5 mm into the
/// table, and the move across to the next hole of the same cycle at its return level (35 mm)
/// through a clamp 40 mm tall standing between them. Each on its hole's one cycle block; the
/// same holes expanded into moves find the same.
#[test]
fn a_canned_cycle_is_checked_down_the_hole_and_across_to_the_next() {
    let p = profile("spinner-u5-620", SPINNER);
    let holes = |top: f64| {
        format!(
            "PARTNO/HOLES\nUNITS/MM\nLOADTL/1,LENGTH,100\nSPINDL/6000,RPM,CLW\nFEDRAT/500,MMPM\nRAPID\nGOTO/-60,0,60,0,0,1\nCYCLE/DRILL,FEDTO,5,MMPM,200,RAPTO,3,RTRCTO,{}\nGOTO/-60,0,{top},0,0,1\nGOTO/60,0,{top},0,0,1\nCYCLE/OFF\nSPINDL/OFF\nFINI\n",
            35.0 - top
        )
    };
    let clamp = || Settings { fixtures: Some("-10,-20,0,10,20,40".into()), ..Default::default() };
    for cycles in ["canned", "expand"] {
        let with = |s: Settings| Settings { cycles: Some(cycles.into()), ..s };
        // Into the table (the holes' tops on it), nothing in between.
        let (c, s) = run(&p, &holes(0.0), with(Settings::default()));
        s.unwrap();
        assert_hit(&c, 9, "cutter", "table");
        if cycles == "canned" {
            assert!(c.nc.contains("G81"), "{}", c.nc);
            // Down, and back out of it: one diagnostic for the pair, the deepest.
            let table = hits(&c, Code::Collision).into_iter().filter(|d| d.line == Some(9) && d.message.contains("cutter and table")).count();
            assert_eq!(table, 1, "{:#?}", c.diags);
        }
        // 10 mm above the table: clear, until the clamp stands between the holes.
        let (c, s) = run(&p, &holes(10.0), with(Settings::default()));
        s.unwrap();
        assert_clean(&c, cycles);
        let (c, s) = run(&p, &holes(10.0), with(clamp()));
        s.unwrap();
        assert_hit(&c, 10, "cutter", "fixture 1");
        assert!(!hits(&c, Code::Collision).iter().any(|d| d.line == Some(9)), "{cycles}: {:#?}", hits(&c, Code::Collision));
    }
    // The holder (Ø40, 60 mm above the tip) comes 1 mm over a clamp at R and 1 mm into its side
    // at the bottom: the cycle's block tells the pair once, as the collision it is.
    let side = Settings { cycles: Some("canned".into()), fixtures: Some("-41,-20,0,-30,20,72".into()), ..Default::default() };
    let (c, s) = run(&p, &holes(10.0), side);
    s.unwrap();
    let told: Vec<_> = c.diags.iter().filter(|d| d.line == Some(9) && d.message.contains("holder and fixture 1")).collect();
    assert!(told.len() == 1 && told[0].code == Code::Collision, "{told:#?}");
}

/// A tool of length 0 (the gauge point at the spindle nose) has no cutter or holder to check:
/// the spindle's own bodies are checked, at the spacing they need (the housing starts 5 mm
/// above the gauge point: 10 mm into the table).
#[test]
fn a_tool_of_no_length_leaves_the_spindle_nose_checked() {
    let p = profile("spinner-u5-620", SPINNER);
    let (text, lines) = cl("MM", 0.0, &[(true, at([0.0, 0.0, 100.0], UP)), (true, at([150.0, 0.0, 100.0], tilted(30.0))), (false, at([0.0, 0.0, -15.0], UP))]);
    let (c, s) = run(&p, &text, Settings::default());
    s.unwrap();
    assert!(hits(&c, Code::CollisionCoarse).is_empty(), "{:#?}", hits(&c, Code::CollisionCoarse));
    assert_hit(&c, lines[2], "spindle housing", "table");
    assert!(!c.diags.iter().any(|d| d.message.contains("cutter") || d.message.contains("holder")), "{:#?}", c.diags);
}

/// A rapid that tilts the table with the cutter just over a stock 0.01 mm thick would need more
/// samples than one block takes: the block says its check was coarser than the step.
#[test]
fn a_move_with_too_few_samples_for_its_motion_says_so() {
    let p = profile("spinner-u5-620", SPINNER);
    let (text, lines) = cl("MM", 100.0, &[(true, at([0.0, 0.0, 5.0], UP)), (true, at([30.0, 0.0, 5.0], tilted(60.0)))]);
    let sheet = Settings {
        stock: Some("-50,-50,0,50,50,0.01".into()),
        ..Default::default()
    };
    let (c, s) = run(&p, &text, sheet);
    s.unwrap();
    let coarse = hits(&c, Code::CollisionCoarse);
    assert!(
        coarse.iter().any(|d| d.line == Some(lines[1]) && d.severity == Severity::Warning && d.message.contains("0.005 mm")),
        "{:#?}",
        c.diags
    );
    // A stock of ordinary thickness under the same moves: enough samples, nothing to tell.
    let (c, _) = run(&p, &text, Settings { stock: Some("-50,-50,0,50,50,4".into()), ..Default::default() });
    assert!(hits(&c, Code::CollisionCoarse).is_empty(), "{:#?}", c.diags);
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


// The shipped profiles' own geometry (machines/*.toml).

fn shipped_profile(id: &str) -> Profile {
    parse_profile(&shipped_file(id), id, None).unwrap()
}

fn assert_clean(c: &Collect, what: &str) {
    let found: Vec<_> = c.diags.iter().filter(|d| matches!(d.code, Code::Collision | Code::NearCollision)).collect();
    assert!(found.is_empty(), "{what}: {} collisions or near ones, first {:#?}", found.len(), &found[..found.len().min(3)]);
}

/// Every shipped profile carries its machine's bodies, and the generated paths (the tool leaning
/// at most 55°, the tip above the table) post without a collision or a near one, joint and TCP.
#[test]
fn every_shipped_profile_has_geometry_and_its_generated_path_is_clear() {
    for p in common::library().iter() {
        let m = &p.machine;
        assert!(p.geometry().bodies.len() >= 3, "{}: no geometry", m.id);
        let n = if m.rotaries.len() == 3 { 150 } else { 600 };
        let mut cl = Vec::new();
        kinepost::testgen::write_path(m, n, 5, m.default_tool_length, &mut cl).unwrap();
        let text = String::from_utf8(cl).unwrap();
        for mode in ["joint", "tcp"] {
            let s = Settings { mode: Some(mode.into()), ..Default::default() };
            let (c, sum) = run(p, &text, s);
            let sum = sum.unwrap();
            assert_clean(&c, &format!("{} {mode}", m.id));
            assert_eq!(sum.errors, 0, "{} {mode}: {:?}", m.id, sum.counts);
        }
    }
}

/// Where a profile has a rotary table, its top face is W's default origin: a plunge 1 mm (0.04 in)
/// below z = 0 at the table's centre is the cutter in the table, 5 mm (0.2 in) above is clear.
/// The exceptions turn the part about a horizontal axis through the origin: no table top there.
#[test]
fn the_table_top_is_w_origin_on_every_rotary_table_profile() {
    let turning = ["htm50200-horizontal", "vmc-4axis-a"];
    let mut checked = 0;
    for p in common::library().iter() {
        let m = &p.machine;
        if !m.rotaries.iter().any(|r| r.mount == kinepost::kinematics::Mount::Table) || turning.contains(&m.id.as_str()) {
            continue;
        }
        let (units, k) = if m.units == kinepost::kinematics::Units::Mm { ("MM", 1.0) } else { ("INCHES", 0.04) };
        let len = m.default_tool_length;
        let (text, lines) = cl(units, len, &[(true, at([0.0, 0.0, 100.0 * k], UP)), (false, at([0.0, 0.0, 5.0 * k], UP)), (false, at([0.0, 0.0, -k], UP))]);
        let (c, s) = run(p, &text, Settings::default());
        s.unwrap();
        let hit = |l: u32| hits(&c, Code::Collision).into_iter().filter(move |d| d.line == Some(l)).collect::<Vec<_>>();
        assert!(hit(lines[1]).is_empty(), "{}: 5 above the table top {:#?}", m.id, hit(lines[1]));
        let below = hit(lines[2]);
        assert!(
            below.iter().any(|d| d.message.starts_with("cutter and table") || d.message.starts_with("cutter and platter")),
            "{}: 1 below the table top {below:#?}",
            m.id
        );
        checked += 1;
    }
    assert_eq!(checked, 7, "the rotary-table profiles checked");
}

/// Crashes per machine kind on the shipped geometry, each found at its block naming the bodies.
#[test]
fn the_shipped_geometry_catches_each_kinds_crash() {
    let side = [-1.0, 0.0, 0.0];
    let cases: [(&str, &str, f64, Vec<(bool, [f64; 6])>, &str, &str); 5] = [
        // Head-table: the swivel head swung level, 30 mm above the table.
        ("dmg-dmc75v", "MM", 100.0, vec![(true, at([0.0, 0.0, 300.0], UP)), (true, at([0.0, 0.0, 300.0], side)), (false, at([0.0, 0.0, 30.0], side))], "b head", "table"),
        // Head-head: the tool plunged into the fixed table (its top at z = -18 in).
        ("fryer-5x-45", "INCHES", 3.0, vec![(true, at([0.0, 0.0, -10.0], UP)), (false, at([0.0, 0.0, -18.5], UP))], "cutter", "table"),
        // Table-table: the holder into the table tilted 85°.
        ("spinner-u5-620", "MM", 100.0, vec![(true, at([0.0, 0.0, 100.0], tilted(85.0))), (false, at([0.0, 0.0, 6.0], tilted(85.0)))], "holder", "table"),
        // A 4th axis: the tool into its faceplate.
        ("vmc-4axis-a", "MM", 100.0, vec![(true, at([-315.0, 0.0, 200.0], UP)), (false, at([-315.0, 0.0, 50.0], UP))], "cutter", "faceplate"),
        // The turning axis: the tool into the faceplate at X's end.
        ("htm50200-horizontal", "MM", 100.0, vec![(true, at([-1900.0, -1600.0, 50.0], UP)), (false, at([-2000.0, -1600.0, -100.0], UP))], "cutter", "faceplate"),
    ];
    for (id, units, len, pts, a, b) in cases {
        let p = shipped_profile(id);
        let (text, lines) = cl(units, len, &pts);
        let (c, s) = run(&p, &text, Settings::default());
        s.unwrap();
        assert!(!hits(&c, Code::Collision).iter().any(|d| d.line == Some(lines[0])), "{id}: the start collides");
        assert_hit(&c, *lines.last().unwrap(), a, b);
    }
}

/// The cutter is the CL's where the tool table says nothing: `TLDATA/MILL,50,…` is a Ø50 cutter,
/// which touches a fixture the default Ø10 passes 10 mm from.
#[test]
fn the_cutter_is_the_cls_tldata() {
    let p = shipped_profile("spinner-u5-620");
    let base = "PARTNO/T\nUNITS/MM\nLOADTL/1,LENGTH,100\nSPINDL/6000,RPM,CLW\nFEDRAT/500,MMPM\nRAPID\nGOTO/0,0,100,0,0,1\nGOTO/0,0,20,0,0,1\nSPINDL/OFF\nFINI\n";
    let fixture = Settings { fixtures: Some("10,-50,0,60,50,50".into()), ..Default::default() };
    let (c, s) = run(&p, base, fixture.clone());
    s.unwrap();
    assert!(hits(&c, Code::Collision).is_empty(), "the default Ø10 cutter: {:#?}", hits(&c, Code::Collision));
    let wide = base.replace("LOADTL/1,LENGTH,100\n", "TLDATA/MILL,50.0000,5.0000,100.0000,0.0000,0.0000\nLOADTL/1,LENGTH,100\n");
    let (c, s) = run(&p, &wide, fixture);
    s.unwrap();
    assert!(hits(&c, Code::Collision).iter().any(|d| d.message.starts_with("cutter and fixture")), "{:#?}", c.diags);
}

/// The stock is in the CL's units: a CL in inches on a mm machine gives its stock in inches.
#[test]
fn the_stock_is_in_the_cls_units() {
    let p = shipped_profile("spinner-u5-620");
    let text = "PARTNO/T\nUNITS/INCHES\nLOADTL/1,LENGTH,4\nSPINDL/6000,RPM,CLW\nFEDRAT/20,IPM\nRAPID\nGOTO/0,0,4,0,0,1\nRAPID\nGOTO/0,0,1,0,0,1\nSPINDL/OFF\nFINI\n";
    let stock = |s: &str| Settings { stock: Some(s.into()), ..Default::default() };
    // 2 in high: the rapid to 1 in is inside it; read as mm it would be 2 mm high and clear.
    let (c, s) = run(&p, text, stock("-2,-2,0,2,2,2"));
    s.unwrap();
    assert!(hits(&c, Code::Collision).iter().any(|d| d.message.starts_with("cutter and stock")), "{:#?}", c.diags);
    let (c, s) = run(&p, text, stock("-2,-2,0,2,2,0.5"));
    s.unwrap();
    assert!(hits(&c, Code::Collision).is_empty(), "{:#?}", hits(&c, Code::Collision));
}

/// The corpus files with a stock that fits them (their feed moves' extent, up to below their
/// lowest rapid) post on shipped machines without a collision or a near one. Each sits where a
/// shop would set it: the Creo files cut below their z = 0 (the part's top), so their stock
/// reaches down to the table 30 mm below; NX's project2 lays the tool flat 0.5 in above its z = 0,
/// so the inch parts stand on a 3 in riser (no stock below their z = 0); its holder, flat, passes
/// within the box of its own feed moves (it cuts walls from the side), so no box is its stock.
#[test]
fn the_corpus_with_fitting_stock_is_clear() {
    // (file, machine, work offset's z: the part's z = 0 above the table top, the stock's floor)
    let cases = [
        ("nx_clsf_mech491_variable_axis_inch_5ax.cls", "haas-umc750", 3.0, 0.0),
        ("nx_clsf_mech491_contour_chamfer_inch_5ax.cls", "haas-umc750", 3.0, 0.0),
        ("nx_clsf_mech491_project2_inch_5ax.cls", "haas-umc750", 3.0, 0.0),
        ("nx_clsf_mech491_simple_mill_plane_mm.cls", "spinner-u5-620", 0.0, 0.0),
        ("nx_clsf_mech491_simple_mill_plane_zig_mm.cls", "mikron-ucp710", 0.0, 0.0),
        ("creo8_ncl_schruppen_roughing_mm.ncl", "spinner-u5-620", 30.0, -30.0),
        ("creo8_ncl_profilfraesen_profile_mm.ncl", "dmg-dmc75v", 30.0, -30.0),
        ("creo8_ncl_bohren_drill_mm.ncl", "vmc-3axis", 30.0, -30.0),
    ];
    for (file, id, lift, floor) in cases {
        let text = std::fs::read_to_string(format!("{}/tests/data/{file}", env!("CARGO_MANIFEST_DIR"))).unwrap();
        let stock = if file.contains("project2") { String::new() } else { fitting_stock(&text, floor) };
        let p = shipped_profile(id);
        // The 3-axis machine's table top is at z = -150: the part sits on it.
        let table = if id == "vmc-3axis" { -150.0 } else { 0.0 };
        for mode in ["joint", "tcp"] {
            if mode == "tcp" && p.machine.rotaries.is_empty() {
                continue;
            }
            let s = Settings {
                mode: Some(mode.into()),
                stock: Some(stock.clone()),
                work_offset: Some(format!("0,0,{}", table + lift)),
                ..Default::default()
            };
            let (c, sum) = run(&p, &text, s);
            sum.unwrap_or_else(|e| panic!("{file} on {id} {mode}: {e}"));
            assert_clean(&c, &format!("{file} on {id} {mode} with stock {stock}"));
        }
    }
}

/// The box of a CL's feed moves, from `floor` (the table top, in the CL's frame) up to just below
/// its lowest rapid point, as `x0,y0,z0,x1,y1,z1`.
fn fitting_stock(text: &str, floor: f64) -> String {
    let (mut lo, mut hi, mut rapid_low, mut rapid) = ([f64::MAX; 3], [f64::MIN; 3], f64::MAX, false);
    for line in text.lines() {
        let l = line.trim().to_ascii_uppercase().replace(' ', "");
        if l.starts_with("RAPID") {
            rapid = true;
        } else if let Some(rest) = l.strip_prefix("GOTO/") {
            let v: Vec<f64> = rest.split(',').take(3).filter_map(|s| s.parse().ok()).collect();
            if v.len() == 3 {
                if rapid {
                    rapid_low = rapid_low.min(v[2]);
                } else {
                    for i in 0..3 {
                        lo[i] = lo[i].min(v[i]);
                        hi[i] = hi[i].max(v[i]);
                    }
                }
            }
            rapid = false;
        }
    }
    let top = (rapid_low - 0.5).min(hi[2]).max(floor + 0.5);
    // A drilled row has no width: the stock is a little wider than the holes' centres.
    let pad = |i: usize| 0.02 * (hi[i] - lo[i]) + 0.01;
    format!("{},{},{floor},{},{},{top}", lo[0] - pad(0), lo[1] - pad(1), hi[0] + pad(0), hi[1] + pad(1))
}

// Triangle-mesh bodies: STL files beside the profile.

/// A directory with `files` written into it (each test its own).
fn mesh_dir(test: &str, files: &[(&str, Vec<u8>)]) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("kinepost-mesh-{test}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    for (name, bytes) in files {
        std::fs::write(dir.join(name), bytes).unwrap();
    }
    dir
}

/// SPINNER with its table cylinder swapped for a mesh `file` of the same size (a box).
fn spinner_mesh(file: &str) -> String {
    let table = "cylinder = { from = [0.0, 0.0, -60.0], to = [0.0, 0.0, 0.0], radius = 300.0 }";
    assert!(SPINNER.contains(table));
    format!("{}\n{}", shipped("spinner-u5-620"), SPINNER.replace(table, &format!("mesh = {file:?}")).replace("name = \"table\"", "name = \"table mesh\""))
}

fn table_stl() -> Vec<[[f64; 3]; 3]> {
    common::stl::box_triangles([-300.0, -300.0, -60.0], [300.0, 300.0, 0.0])
}

#[test]
fn a_mesh_on_the_table_rotary_is_checked_binary_and_ascii() {
    let dir = mesh_dir(
        "crash",
        &[("table.stl", common::stl::binary(&table_stl())), ("table-ascii.stl", common::stl::ascii(&table_stl()).into_bytes())],
    );
    for file in ["table.stl", "table-ascii.stl"] {
        let p = kinepost::machines::parse_profile_in(&spinner_mesh(file), "spinner-mesh", None, Some(&dir)).unwrap();
        let g = p.geometry();
        assert!(matches!(&g.bodies[0].solid, kinepost::collide::Solid::Mesh(m) if m.triangles().len() == 12), "{file}");
        let (text, lines) = cl(
            "MM",
            100.0,
            &[
                (true, at([0.0, 0.0, 100.0], UP)),
                (false, at([100.0, 50.0, 20.0], UP)),
                (false, at([100.0, 50.0, -5.0], UP)),
                (true, at([100.0, 50.0, 100.0], UP)),
                (true, at([0.0, 0.0, 100.0], tilted(85.0))),
                (false, at([0.0, 0.0, 6.0], tilted(85.0))),
            ],
        );
        let (c, s) = run(&p, &text, Settings::default());
        s.unwrap();
        assert_hit(&c, lines[2], "cutter", "table mesh");
        assert_hit(&c, lines[5], "holder", "table mesh");
        assert_hit(&c, lines[3], "cutter", "table mesh");
        for (i, l) in lines.iter().enumerate() {
            if ![2, 3, 5].contains(&i) {
                assert!(hits(&c, Code::Collision).iter().all(|d| d.line != Some(*l)), "{file}: line {l}: {:#?}", hits(&c, Code::Collision));
            }
        }
        // A clear path: tilted 30°, the tip above the table, the C table turning.
        let (text, _) = cl(
            "MM",
            100.0,
            &[
                (true, at([0.0, 0.0, 150.0], UP)),
                (false, at([50.0, 0.0, 20.0], tilted(30.0))),
                (false, at([0.0, 50.0, 20.0], [0.0, 0.5, 0.75f64.sqrt()])),
                (false, at([-50.0, 0.0, 20.0], [-0.5, 0.0, 0.75f64.sqrt()])),
                (true, at([0.0, 0.0, 150.0], UP)),
            ],
        );
        let (c, s) = run(&p, &text, Settings::default());
        s.unwrap();
        assert_clean(&c, file);
    }
}

#[test]
fn bad_meshes_are_refused_naming_the_key() {
    let mut nan = table_stl();
    nan[3][1][2] = f64::NAN;
    let mut big = common::stl::binary(&table_stl());
    big.resize(17 << 20, 0);
    let many: Vec<_> = (0..200_001).map(|i| [[i as f64, 0.0, 0.0], [i as f64, 1.0, 0.0], [i as f64, 0.0, 1.0]]).collect();
    let dir = mesh_dir(
        "bad",
        &[
            ("nan.stl", common::stl::binary(&nan)),
            ("big.stl", big),
            ("many.stl", common::stl::binary(&many)),
            ("junk.stl", b"not an stl".to_vec()),
            ("point.stl", common::stl::binary(&[[[1.0, 2.0, 3.0]; 3]])),
            ("far.stl", common::stl::binary(&[[[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1e30, 0.0]]])),
            ("table.stl", common::stl::binary(&table_stl())),
        ],
    );
    let bad = |file: &str, dir: Option<&std::path::Path>| {
        kinepost::machines::parse_profile_in(&spinner_mesh(file), "spinner-mesh", None, dir).unwrap_err().to_string()
    };
    for (file, why) in [
        ("nan.stl", "finite"),
        ("big.stl", "larger than"),
        ("many.stl", "more than 200000 triangles"),
        ("junk.stl", "STL"),
        ("point.stl", "one point"),
        ("far.stl", "within"),
        ("gone.stl", "gone.stl"),
        ("../table.stl", "beside the profile"),
        ("sub/table.stl", "beside the profile"),
        ("/etc/passwd", "beside the profile"),
    ] {
        let e = bad(file, Some(&dir));
        assert!(e.contains("body[0].mesh") && e.contains(why), "{file}: {e}");
    }
    // No directory (a profile parsed on its own): meshes come from the library's directory only.
    let e = bad("table.stl", None);
    assert!(e.contains("body[0].mesh") && e.contains("directory only"), "{e}");
    // Two shapes in one body.
    let two = spinner_mesh("table.stl").replace("mesh = \"table.stl\"", "mesh = \"table.stl\"\nbox = [0.0, 0.0, 0.0, 1.0, 1.0, 1.0]");
    let e = kinepost::machines::parse_profile_in(&two, "two", None, Some(&dir)).unwrap_err().to_string();
    assert!(e.contains("body[0]") && e.contains("one shape"), "{e}");
    // The library reads a profile's meshes beside it.
    std::fs::write(dir.join("spinner-u5-620.toml"), spinner_mesh("table.stl")).unwrap();
    for f in ["nan.stl", "big.stl", "many.stl", "junk.stl", "point.stl", "far.stl"] {
        std::fs::remove_file(dir.join(f)).unwrap();
    }
    let lib = kinepost::machines::Library::load_dir(&dir).unwrap();
    assert_eq!(lib.get("spinner-u5-620").unwrap().geometry().bodies.len(), 5);
    let _ = std::fs::remove_dir_all(&dir);
}

/// A closed mesh wound outward is a solid: a cutter wholly inside it, touching no triangle, is a
/// hit; an open one (two triangles gone) is a surface, and the same cutter is not.
#[test]
fn a_closed_mesh_is_a_solid_an_open_one_a_surface() {
    use kinepost::collide::{Axes, Hit, Solid, ToolShape, World};
    let open: Vec<_> = table_stl()[2..].to_vec();
    let inward: Vec<_> = table_stl().into_iter().map(|[a, b, c]| [a, c, b]).collect();
    let dir = mesh_dir(
        "solid",
        &[
            ("closed.stl", common::stl::binary(&table_stl())),
            ("open.stl", common::stl::binary(&open)),
            ("inward.stl", common::stl::ascii(&inward).into_bytes()),
        ],
    );
    let tool = ToolShape { length: 10.0, diameter: 10.0, corner_radius: 0.0, holder_diameter: 0.0, holder_length: 0.0 };
    for (file, solid) in [("closed.stl", true), ("open.stl", false), ("inward.stl", false)] {
        let text = format!("{}\n[[body]]\nname = \"table mesh\"\non = \"C\"\nmesh = {file:?}\n", shipped("spinner-u5-620"));
        let p = kinepost::machines::parse_profile_in(&text, "t", None, Some(&dir)).unwrap();
        let g = p.geometry();
        assert!(matches!(&g.bodies[0].solid, Solid::Mesh(m) if m.is_solid() == solid), "{file}");
        let mut w = World::new(&p.machine, &g, &[], &[], 2.0, 0.01);
        w.set_tool(tool);
        let setup = kinepost::kinematics::Setup::new(tool.length, kinepost::kinematics::Vec3::zeros());
        let at = |w: &mut World, z: f64| {
            let mut out: Vec<Hit> = Vec::new();
            w.check_at(&p.machine, &setup, &Axes { linear: [100.0, 50.0, z], actual: [0.0; 3] }, false, &mut out);
            out
        };
        // The cutter spans z −25 … −15 (the table −60 … 0): wholly inside.
        let deep = at(&mut w, -25.0);
        assert_eq!(deep.len(), usize::from(solid), "{file}: {deep:?}");
        if solid {
            assert!(deep[0].a == "cutter" && deep[0].b == "table mesh" && deep[0].dist <= -15.0, "{deep:?}");
        }
        // Through the top face: a hit either way; above it: none.
        assert!(at(&mut w, -5.0).iter().any(|h| h.b == "table mesh"), "{file}");
        assert!(at(&mut w, 20.0).is_empty(), "{file}");
    }
}

/// Mesh against mesh (a head housing on the spindle into the table): parry answers it triangle
/// against triangle; a housing wholly inside the closed table is found too.
#[test]
fn a_mesh_against_a_mesh() {
    use kinepost::collide::{Axes, Hit, ToolShape, World};
    let head = common::stl::box_triangles([-50.0, -50.0, 5.0], [50.0, 50.0, 40.0]);
    let dir = mesh_dir("mm", &[("table.stl", common::stl::binary(&table_stl())), ("head.stl", common::stl::binary(&head))]);
    let bodies = "[[body]]\nname = \"table mesh\"\non = \"C\"\nmesh = \"table.stl\"\n[[body]]\nname = \"head mesh\"\non = \"spindle\"\nmesh = \"head.stl\"\n";
    let p = kinepost::machines::parse_profile_in(&format!("{}\n{bodies}", shipped("spinner-u5-620")), "t", None, Some(&dir)).unwrap();
    let g = p.geometry();
    let mut w = World::new(&p.machine, &g, &[], &[], 2.0, 0.01);
    w.set_tool(ToolShape { length: 10.0, diameter: 10.0, corner_radius: 0.0, holder_diameter: 0.0, holder_length: 0.0 });
    let setup = kinepost::kinematics::Setup::new(10.0, kinepost::kinematics::Vec3::zeros());
    let mut at = |z: f64| {
        let mut out: Vec<Hit> = Vec::new();
        w.check_at(&p.machine, &setup, &Axes { linear: [100.0, 50.0, z], actual: [0.0; 3] }, false, &mut out);
        out.into_iter().filter(|h| h.a == "head mesh").collect::<Vec<_>>()
    };
    // The housing spans z + 15 … z + 50 (spindle at z + 10).
    let through = at(-30.0);
    assert!(through.len() == 1 && through[0].b == "table mesh" && through[0].dist < 0.0, "{through:?}");
    let wholly = at(-57.0);
    assert!(wholly.len() == 1 && wholly[0].dist < 0.0, "wholly inside: {wholly:?}");
    assert!(at(-14.0).iter().all(|h| h.dist > 0.0), "a near miss at most");
    assert!(at(0.0).is_empty());
}

/// The check skips a pair while the distance it last measured, less how far anything can have
/// moved since, is still beyond what is told. That bound must never skip a hit: on random walks
/// of every shipped machine's joints (small steps and jumps, near and into the table), the hits
/// at each step equal those of a check that remembers nothing.
#[test]
fn skipping_pairs_that_cannot_have_closed_in_misses_nothing() {
    let mut s: u64 = 0x2545F4914F6CDD1D;
    let mut rnd = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    let (mut steps, mut hits, mut whole) = (0, 0, 0);
    for p in common::library().iter() {
        let (h, w) = walk_compare(p, 3000, &mut rnd);
        (hits, whole) = (hits + h, whole + w);
        steps += 3000;
    }
    // A head rotary before a table one in the chain's numbering (dmg-dmc75v's B listed first).
    let text = shipped_file("dmg-dmc75v");
    let (c, b) = (text.find("[[rotary]]\nname = \"C\"").unwrap(), text.find("[[rotary]]\nname = \"B\"").unwrap());
    let end = b + text[b..].find("\n\n").unwrap() + 1;
    let swapped = format!("{}{}{}{}", &text[..c], &text[b..end], &text[c..b], &text[end..]).replace("\"dmg-dmc75v\"", "\"dmg-b-first\"");
    let p = parse_profile(&swapped, "dmg-b-first", None).unwrap();
    assert_eq!(p.machine.rotaries[0].name, 'B');
    let (h, w) = walk_compare(&p, 3000, &mut rnd);
    (hits, whole, steps) = (hits + h, whole + w, steps + 3000);
    assert!(hits > 1000, "the walks touched something only {hits} times in {steps} steps");
    assert!(whole > steps / 20, "only {whole} of {steps} moves were taken whole");
    // Mesh bodies too: a closed table (a solid: wholly inside is a hit) and a head housing.
    let head = common::stl::box_triangles([-120.0, -120.0, 5.0], [120.0, 120.0, 200.0]);
    let dir = mesh_dir("walk", &[("table.stl", common::stl::binary(&table_stl())), ("head.stl", common::stl::binary(&head))]);
    let bodies = "[[body]]\nname = \"table mesh\"\non = \"C\"\nmesh = \"table.stl\"\n[[body]]\nname = \"head mesh\"\non = \"spindle\"\nmesh = \"head.stl\"\n";
    let p = kinepost::machines::parse_profile_in(&format!("{}\n{bodies}", shipped("spinner-u5-620")), "t", None, Some(&dir)).unwrap();
    assert!(walk_compare(&p, 3000, &mut rnd).0 > 100, "the mesh walk touched too little");
}

/// One table rotary turning alone swings the stock's corner into a cutter standing 3 mm off its
/// edge: the pairs it moves must be asked again even though no linear moved (the bounds are
/// kept per set of joints that move a pair).
#[test]
fn a_rotary_turning_alone_is_counted_for_the_pairs_it_moves() {
    use kinepost::collide::{Axes, Solid, ToolShape, World};
    let p = shipped_profile("spinner-u5-620");
    let (m, g) = (&p.machine, p.geometry());
    let stock = [Solid::Box { min: [-40.0, -40.0, 0.0].into(), max: [40.0, 40.0, 30.0].into() }];
    let len = m.default_tool_length;
    let tool = ToolShape::default_for(len, true);
    let setup = kinepost::kinematics::Setup::new(len, kinepost::kinematics::Vec3::zeros());
    let tip = [40.0 + 0.5 * tool.diameter + 3.0, 0.0, 10.0];
    let deg = std::f64::consts::PI / 180.0;
    // B (index 0) and C (index 1), each alone from 0, in steps of a quarter degree.
    for (i, end) in [(1, -50.0f64), (0, 10.0)] {
        let mut remembering = World::new(m, &g, &stock, &[], 2.0, 1e-3);
        remembering.set_tool(tool);
        let mut touched = 0;
        for k in 0..=(4.0 * end).abs() as usize {
            let mut rot = [0.0; 3];
            rot[i] = end.signum() * 0.25 * k as f64 * deg;
            let (mut a, mut b) = (Vec::new(), Vec::new());
            let at = Axes { linear: tip, actual: rot };
            remembering.check_at(m, &setup, &at, true, &mut a);
            let mut fresh = World::new(m, &g, &stock, &[], 2.0, 1e-3);
            fresh.set_tool(tool);
            fresh.check_at(m, &setup, &at, true, &mut b);
            let names = |v: &[kinepost::collide::Hit]| v.iter().map(|h| format!("{}-{}", h.a, h.b)).collect::<Vec<_>>();
            assert_eq!(names(&a), names(&b), "rotary {i} at {:.2}°", rot[i] / deg);
            touched += b.iter().filter(|h| h.a == "cutter" && h.b == "stock").count();
        }
        assert!(touched > 0, "rotary {i} to {end}° never swung the stock into the cutter");
    }
}

/// The samples along a move keep every point of the stock within half its smallest size of where
/// it stood at the sample before, wherever the work offset puts it: the table turns a part far
/// off its axes while the tool stands near the machine's zero. The stock is the only body and no
/// clearance is asked, so half its smallest size is the step the samples are counted by.
#[test]
fn the_samples_follow_a_part_the_work_offset_puts_far_off_the_axes() {
    use kinepost::collide::{Axes, Coarse, Geometry, Solid, World};
    use kinepost::kinematics::{Setup, Vec3, controlled_point};
    let p = shipped_profile("spinner-u5-620");
    let m = &p.machine;
    let (min, max) = (Vec3::new(-40.0, -40.0, 0.0), Vec3::new(40.0, 40.0, 30.0));
    let mut world = World::new(m, &Geometry::default(), &[Solid::Box { min, max }], &[], 0.0, 1e-3);
    let half = 15.0;
    let len = m.default_tool_length;
    let deg = std::f64::consts::PI / 180.0;
    let lin = [0.0; 3];
    let mut worst: f64 = 0.0;
    for wo in [Vec3::zeros(), Vec3::new(1000.0, 0.0, 0.0), Vec3::new(300.0, -700.0, 50.0)] {
        let setup = Setup::new(len, wo);
        // (B, C) actual angles at the move's ends.
        for (a, b) in [([0.0, 0.0], [0.0, 90.0]), ([0.0, 0.0], [30.0, -45.0]), ([-20.0, 170.0], [15.0, 10.0])] {
            let (from, to) = ([a[0] * deg, a[1] * deg, 0.0], [b[0] * deg, b[1] * deg, 0.0]);
            let (n, coarse) = world.samples(m, &setup, &Axes { linear: lin, actual: from }, &Axes { linear: lin, actual: to }, 0.0);
            assert_eq!(coarse, None, "{n} samples");
            let at = |t: f64| std::array::from_fn::<f64, 3, _>(|i| from[i] + (to[i] - from[i]) * t);
            for corner in 0..8 {
                let c = Vec3::new(
                    if corner & 1 == 0 { min.x } else { max.x },
                    if corner & 2 == 0 { min.y } else { max.y },
                    if corner & 4 == 0 { min.z } else { max.z },
                );
                for k in 0..n {
                    let here = controlled_point(m, &at(k as f64 / n as f64), &c, &setup);
                    for sub in 1..=8 {
                        let t = (k as f64 + sub as f64 / 8.0) / n as f64;
                        let d = (controlled_point(m, &at(t), &c, &setup) - here).norm();
                        worst = worst.max(d / half);
                        assert!(d <= half, "work offset {wo:?}, ({a:?}) to ({b:?}): corner {c:?} moves {d:.2} mm between {n} samples");
                    }
                }
            }
        }
    }
    // The bound is not so loose that the check would pass whatever it counted.
    assert!(worst > 0.2, "the stock moved at most {worst} of a step between samples");
    // A sheet 0.01 mm thick turned half a turn would need more samples than one block takes:
    // the samples stop at the most, and say how far apart they are.
    let sheet = [Solid::Box { min, max: Vec3::new(40.0, 40.0, 0.01) }];
    let mut world = World::new(m, &Geometry::default(), &sheet, &[], 2.0, 1e-3);
    let (from, to) = ([0.0; 3], [0.0, std::f64::consts::PI, 0.0]);
    let setup = Setup::new(len, Vec3::new(500.0, 0.0, 0.0));
    let (n, coarse) = world.samples(m, &setup, &Axes { linear: lin, actual: from }, &Axes { linear: lin, actual: to }, 0.0);
    assert_eq!(n, kinepost::collide::MAX_SAMPLES);
    let Coarse { apart, step } = coarse.expect("too few samples for the motion are told");
    assert!((step - 0.005).abs() < 1e-12 && apart > step, "{apart} {step}");
}

/// A random walk of `p`'s joints (small steps, and a jump now and then), checked by one World
/// that remembers and by a fresh one at every step: the same hits. A third World takes each
/// move whole where its bounds allow (`move_clear`): where it does, a fresh World finds nothing
/// at the move's end or at points along it. Returns how many hits, and how many moves were taken
/// whole.
fn walk_compare(p: &Profile, n: usize, rnd: &mut impl FnMut() -> f64) -> (usize, usize) {
    use kinepost::collide::{Axes, ToolShape, World};
    let mut hits = 0;
    let m = &p.machine;
    let g = p.geometry();
    let stock = [kinepost::collide::Solid::Box { min: [-40.0, -40.0, 0.0].into(), max: [40.0, 40.0, 30.0].into() }];
    let len = m.default_tool_length;
    let tool = ToolShape::default_for(len, m.units == kinepost::kinematics::Units::Mm);
    let setup = kinepost::kinematics::Setup::new(len, kinepost::kinematics::Vec3::zeros());
    let mut remembering = World::new(m, &g, &stock, &[], 2.0, 1e-3);
    remembering.set_tool(tool);
    let mut whole = World::new(m, &g, &stock, &[], 2.0, 1e-3);
    whole.set_tool(tool);
    let fresh_hits = |lin: &[f64; 3], rot: &[f64; 3], stock_now: bool| {
        let mut fresh = World::new(m, &g, &stock, &[], 2.0, 1e-3);
        fresh.set_tool(tool);
        let mut out = Vec::new();
        fresh.check_at(m, &setup, &Axes { linear: *lin, actual: *rot }, stock_now, &mut out);
        out
    };
    let mut taken_whole = 0;
    let (mut lin, mut rot) = ([0.0f64; 3], [0.0f64; 3]);
    for i in 0..3 {
        if let Some(l) = &m.linears[i] {
            lin[i] = 0.5 * (l.min + l.max);
        }
    }
    for k in 0..n {
        let jump = k % 97 == 0;
        let (lin0, rot0) = (lin, rot);
        // Two steps in three move one joint alone: a pair that joint does not move need not be
        // asked again, and one it does must be.
        let alone = (k % 3 != 2).then_some((k / 3 + k % 3) % (3 + m.rotaries.len()));
        let moves = |j: usize| alone.is_none_or(|a| a == j);
        for i in 0..3 {
            if let Some(l) = m.linears[i].as_ref().filter(|_| moves(i)) {
                let step = if jump { l.max - l.min } else { 0.02 * (l.max - l.min) };
                lin[i] = (lin[i] + step * (rnd() - 0.5)).clamp(l.min, l.max);
            }
        }
        for (i, r) in rot.iter_mut().enumerate().take(m.rotaries.len()) {
            if moves(3 + i) {
                *r += if jump { 3.0 } else { 0.05 } * (rnd() - 0.5);
            }
        }
        let stock_now = k % 3 == 0;
        let (mut a, mut b) = (Vec::new(), Vec::new());
        let (at, at0) = (Axes { linear: lin, actual: rot }, Axes { linear: lin0, actual: rot0 });
        remembering.check_at(m, &setup, &at, stock_now, &mut a);
        let mut fresh = World::new(m, &g, &stock, &[], 2.0, 1e-3);
        fresh.set_tool(tool);
        fresh.check_at(m, &setup, &at, stock_now, &mut b);
        // A move that does not start where the last check left the joints is never taken whole.
        let elsewhere = Axes { linear: [lin0[0] + 1.0, lin0[1], lin0[2]], actual: rot0 };
        assert!(!whole.move_clear(m, &setup, Some(&elsewhere), &at, stock_now, 0.0));
        let from = (k % 7 != 3).then_some(&at0);
        if whole.move_clear(m, &setup, from, &at, stock_now, 0.0) {
            taken_whole += 1;
            for t in [0.25, 0.5, 0.75, 1.0] {
                let along = |p: &[f64; 3], q: &[f64; 3]| std::array::from_fn::<f64, 3, _>(|i| p[i] + (q[i] - p[i]) * t);
                let seen = fresh_hits(&along(&lin0, &lin), &along(&rot0, &rot), stock_now);
                assert!(seen.is_empty(), "{} step {k}: taken whole, yet {seen:?} at {t} of the way", m.id);
            }
        } else {
            whole.check_at(m, &setup, &at, stock_now, &mut Vec::new());
        }
        let key = |h: &kinepost::collide::Hit| (h.a.clone(), h.b.clone(), (h.dist * 1e9).round() as i64);
        let (ka, kb): (Vec<_>, Vec<_>) = (a.iter().map(key).collect(), b.iter().map(key).collect());
        assert_eq!(ka, kb, "{} step {k}: joints {lin:?} {rot:?}", m.id);
        hits += b.len();
    }
    (hits, taken_whole)
}

/// Issue 51, 5 and 2: the time bound was looked at every 256 output records, so a collision check
/// that wrote nothing for minutes ran on (`--max-post-seconds 5` stopped at 19.7 s); a stock of
/// ±1e8 on a six-point path takes minutes of samples. Now the bound is looked at between the
/// check's samples: the post stops within a second of it, with the `over_budget` reason.
#[test]
fn the_time_bound_holds_inside_a_long_collision_check() {
    let lib = common::library();
    let p = lib.get("spinner-u5-620").unwrap().clone();
    let cl = String::from_utf8(common::generated("spinner-u5-620", 6, 1)).unwrap();
    // Options refuse such a stock now (below); the engine's bound holds whatever it is given.
    let mut o = Settings::default().profile_options(&p, None).unwrap();
    o.stock = vec![kinepost::collide::Solid::Box {
        min: kinepost::kinematics::Vec3::repeat(-1e8),
        max: kinepost::kinematics::Vec3::repeat(1e8),
    }];
    o.budget = post::Budget::new(0, 1.0).unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    let t0 = std::time::Instant::now();
    std::thread::spawn(move || {
        let r = run_with(&p, &cl, &o).1;
        let _ = tx.send(r.map(|_| ()).map_err(|e| e.to_string()));
    });
    let r = rx
        .recv_timeout(std::time::Duration::from_secs(20))
        .expect("the post stops near its 1 s bound");
    let took = t0.elapsed();
    let e = r.expect_err("over its time");
    assert!(e.contains("1 s"), "{e}");
    assert!(took < std::time::Duration::from_secs(2), "stopped after {took:?}");
}

/// Issue 51, 2: job options multiplied the check's cost with nothing said: a ±1e8 stock (34.7 s
/// for a 298-byte CL, 0.01 s without), a clearance of 1e-9 (39×), a 1e-6 mm fixture (40×). Now
/// what no machine tool holds is refused naming the bound, and what is left costs at most the
/// post's allowance of samples (`MAX_SAMPLES` once, 256 a move on average), the moves past it
/// told `collision_coarse`.
#[test]
fn options_that_multiply_the_checks_cost_are_refused_or_bounded() {
    let lib = common::library();
    let p = lib.get("spinner-u5-620").unwrap().clone();
    for (s, want) in [
        (Settings { stock: Some("-1e8,-1e8,-1e8,1e8,1e8,1e8".into()), ..Default::default() }, "within ±100000"),
        (Settings { fixtures: Some("0,0,0,1e-6,1,1".into()), ..Default::default() }, "at least 0.001"),
        (Settings { collision_clearance: Some(1e-9), ..Default::default() }, "0 (none) or at least 0.001"),
    ] {
        let e = s.profile_options(&p, None).map(|_| ()).expect_err("refused");
        assert!(e.message.contains(want), "{e}");
    }
    // The smallest fixture taken: every move of the path would want thousands of samples.
    let cl = String::from_utf8(common::generated("spinner-u5-620", 6, 1)).unwrap();
    let o = Settings { fixtures: Some("0,0,0,0.001,0.001,0.001".into()), ..Default::default() }
        .profile_options(&p, None)
        .unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let (c, r) = run_with(&p, &cl, &o);
        let _ = tx.send((hits(&c, Code::CollisionCoarse).len(), r.is_ok()));
    });
    let (coarse, ok) = rx.recv_timeout(std::time::Duration::from_secs(15)).expect("the check's cost is bounded");
    assert!(ok);
    assert!(coarse > 100, "the moves past the allowance are told coarse: {coarse}");
}

/// Issue 51, 7: the 1 000 000-triangle bound counted files, not bodies: 64 bodies naming one
/// 200 000-triangle file passed (12.8 M triangles for the check), and the refusal for six
/// different files said "more than 0 triangles". Counted per body now, the refusal naming them.
#[test]
fn the_triangle_bound_counts_bodies_and_names_the_count() {
    let many: Vec<_> = (0..200_000).map(|i| [[i as f64 * 1e-3, 0.0, 0.0], [i as f64 * 1e-3, 1.0, 0.0], [i as f64 * 1e-3, 0.0, 1.0]]).collect();
    let dir = mesh_dir("count", &[("many.stl", common::stl::binary(&many)), ("table.stl", common::stl::binary(&table_stl()))]);
    let bodies = |files: &[&str]| -> String {
        let mut p = shipped("spinner-u5-620");
        for (i, f) in files.iter().enumerate() {
            p.push_str(&format!("\n[[body]]\nname = \"part {i}\"\non = \"C\"\nmesh = {f:?}\n"));
        }
        p
    };
    let parse = |text: String| kinepost::machines::parse_profile_in(&text, "spinner-mesh", None, Some(&dir)).map(|_| ());
    parse(bodies(&["many.stl"; 5])).expect("five bodies: 1 000 000 triangles");
    let e = parse(bodies(&["many.stl"; 6])).unwrap_err().to_string();
    assert!(e.contains("1200000 triangles (1000000 in the bodies before this one, 200000 in it)"), "{e}");
    let e = parse(bodies(&["many.stl", "many.stl", "many.stl", "many.stl", "many.stl", "table.stl"])).unwrap_err().to_string();
    assert!(e.contains("1000012 triangles") && !e.contains("more than 0"), "{e}");
}

/// Issue 51, 10: `tolerance=1e-300` quoted a 391-character number in its error (errors quote at
/// most 80); an `MSYS` origin of 1e300 and a body radius of 1e300 were taken.
#[test]
fn huge_and_tiny_numbers_are_refused_and_quoted_short() {
    let p = shipped_profile("spinner-u5-620");
    let e = Settings { tolerance: Some(1e-300), ..Default::default() }.profile_options(&p, None).err().unwrap().message;
    assert!(e.len() <= 160 && e.contains("1e-300"), "{} characters: {e}", e.len());
    let (c, s) = run(&p, "UNITS/MM\nMSYS/1e300,0,0,1,0,0,0,1,0\nGOTO/0,0,100,0,0,1\nFINI\n", Settings::default());
    s.unwrap();
    assert!(c.diags.iter().any(|d| d.message.contains("MSYS: its origin must be within")), "{:?}", c.diags);
    let big = shipped_file("spinner-u5-620").replacen("radius = 250.0", "radius = 1e300", 1);
    assert!(big.contains("radius = 1e300"));
    let e = parse_profile(&big, "big", None).map(|_| ()).expect_err("refused").to_string();
    assert!(e.contains("radius"), "{e}");
}
