//! Dialects as data: the built-ins are the files of `dialects/`, a shop's own `extends` one and
//! says what differs (words, number formats, block numbers, templates for the program's events),
//! from the CLI (`--dialects DIR --dialect NAME`) and over the API with versions. Bad templates
//! are refused with their line; a template that runs away is stopped.

use crate::common;

use common::Fetch;
use serde_json::Value;
use std::path::Path;
use std::process::Command;
use std::time::Duration;

const TOKEN: &str = "post-admin";
const MACHINE: &str = "fryer-5x-45";

/// The issue's shop dialect: Fanuc with a tool change that first sends Z home.
const SHOP: &str = r#"id = "shop"
extends = "fanuc"
title = "Fanuc, our tool change"

[templates]
tool_change = """
G91 G28 Z0.
G90
T{{ tool }} M6
"""
program_start = "(MACHINE {{ machine }} PROGRAM {{ program_number }})"
first_move = "{% if next_tool is not none %}T{{ next_tool }}{% endif %}"
"#;

/// Two tools on the fryer (A/C head-head), a short 5-axis cut each.
fn two_tools() -> String {
    let cut = |x0: f64| -> String {
        (0..12)
            .map(|i| {
                let t = i as f64 / 11.0;
                let (a, c) = ((10.0 + 15.0 * t).to_radians(), (90.0 * t).to_radians());
                format!(
                    "GOTO/{:.4},{:.4},-9,{:.6},{:.6},{:.6}\n",
                    x0 + 2.0 * t,
                    1.0 - t,
                    a.sin() * c.cos(),
                    a.sin() * c.sin(),
                    a.cos()
                )
            })
            .collect()
    };
    format!(
        "UNITS/INCHES\nLOADTL/1\nSPINDL/RPM,6000,CLW\nFEDRAT/20\n{}LOADTL/2\nSELCTL/3\nSPINDL/RPM,6000,CLW\nFEDRAT/20\n{}FINI\n",
        cut(0.0),
        cut(4.0)
    )
}

fn kinepost(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_kinepost")).args(args).output().unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn scratch(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("kinepost-dialects-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn the_built_in_files_are_the_dialects() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("dialects");
    for id in kinepost::nc::DIALECTS {
        let text = std::fs::read_to_string(dir.join(format!("{id}.toml"))).unwrap();
        let d = kinepost::machines::dialects::parse(&text, id, Some(id)).unwrap();
        let built = kinepost::nc::dialect(id).unwrap();
        assert_eq!((d.name.as_str(), d.title.as_str()), (built.name.as_str(), built.title.as_str()));
        assert_eq!(format!("{d:?}"), format!("{built:?}"), "{id}: the file and the built-in differ");
    }
}

#[test]
fn a_shop_dialect_from_the_cli_writes_its_tool_change_and_verifies() {
    let dir = scratch("cli");
    std::fs::write(dir.join("shop.toml"), SHOP).unwrap();
    let cl = dir.join("two.cls");
    std::fs::write(&cl, two_tools()).unwrap();
    let nc = dir.join("two.nc");
    let (code, out, err) = kinepost(&[
        "post", "--machine", MACHINE, "--dialects", dir.to_str().unwrap(), "--dialect", "shop", "--output",
        nc.to_str().unwrap(), cl.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{out}{err}");
    let text = std::fs::read_to_string(&nc).unwrap();
    for tool in [1, 2] {
        assert!(text.contains(&format!("G91 G28 Z0.\nG90\nT{tool} M6\n")), "tool {tool}:\n{text}");
    }
    assert!(!text.contains("\nT1 M6\nG43"), "the built-in tool change is replaced:\n{text}");
    assert!(text.contains("(MACHINE FRYER-5X-45 PROGRAM 1000)") || text.contains("(MACHINE fryer-5x-45 PROGRAM 1000)"), "{text}");
    // The first move of tool 2 readies tool 3 (SELCTL/3 came before it).
    assert!(text.lines().any(|l| l == "T3"), "{text}");
    let (code, out, err) = kinepost(&["verify", "--machine", MACHINE, "--cl", cl.to_str().unwrap(), "--nc", nc.to_str().unwrap()]);
    assert_eq!(code, 0, "the program still reaches every CL point: {out}{err}");
    // Listed beside the built-ins.
    let (code, out, _) = kinepost(&["dialects", "--dialects", dir.to_str().unwrap()]);
    assert_eq!(code, 0);
    assert!(out.contains("shop") && out.contains("templates: program_start, tool_change, first_move"), "{out}");
    let _ = std::fs::remove_dir_all(&dir);
}

fn refused(text: &str) -> String {
    kinepost::machines::dialects::parse(text, "bad.toml", None).unwrap_err().to_string()
}

#[test]
fn bad_templates_and_keys_are_refused_with_their_line() {
    let e = refused(&SHOP.replace("T{{ tool }} M6", "T{{ tool }} M6 {% if %}"));
    assert!(e.contains("templates.tool_change: line 3") && e.contains("syntax"), "{e}");
    let e = refused(&SHOP.replace("G90\nT{{ tool }}", "G90\nT{{ toool }}"));
    assert!(e.contains("templates.tool_change: line 3: unknown variable \"toool\""), "{e}");
    let e = refused(&SHOP.replace("T{{ tool }} M6", "T{{ tool | nosuchfilter }} M6"));
    assert!(e.contains("templates.tool_change: line 3") && e.contains("unknown filter"), "{e}");
    let e = refused(&SHOP.replace("G90\n", "{% for i in range(90000) %}{% for j in range(90000) %}{% endfor %}{% endfor %}G90\n"));
    assert!(e.contains("templates.tool_change") && e.contains("fuel"), "a runaway template: {e}");
    let e = refused(&SHOP.replace("tool_change = ", "tool_swap = "));
    assert!(e.contains("templates.tool_swap: no such event"), "{e}");
    let e = refused(&SHOP.replace("extends = \"fanuc\"", "extends = \"fanucc\""));
    assert!(e.contains("extends: no dialect \"fanucc\""), "{e}");
    let e = refused(&format!("{SHOP}\n[sequence]\nstart = 1\nstep = 0\n"));
    assert!(e.contains("sequence.step"), "{e}");
    let e = refused(&SHOP.replace("title =", "titel ="));
    assert!(e.contains("unknown field `titel`"), "{e}");
    let e = refused("id = \"x\"\ntitle = \"no parent, nothing else\"\n");
    assert!(e.contains("missing field"), "{e}");
}

/// Posts `cl` on `machine` in `dialect` (a value, not a file) through the engine.
fn post_with(dialect: &str, cl: &str) -> (String, kinepost::post::Summary, Vec<kinepost::diag::Diagnostic>) {
    let lib = common::library();
    let p = lib.get(MACHINE).unwrap();
    let d = std::sync::Arc::new(kinepost::machines::dialects::parse(dialect, "test.toml", None).unwrap());
    let mut o = kinepost::post::Options::new(&p.machine);
    o.dialect = d;
    o.sequence_numbers = true;
    let mut sink = common::collect::Collect::default();
    let s = kinepost::post::post(cl.as_bytes(), &p.machine, &o, &mut sink).unwrap();
    (sink.nc, s, sink.diags)
}

#[test]
fn number_formats_block_numbers_blending_and_line_length_are_the_dialects() {
    let d = r#"id = "plain"
extends = "fanuc"
title = "no zeros"
blend = "G64 P{tol}"
line_length = 24
[format]
trailing_zeros = false
leading_zero = false
[sequence]
start = 100
step = 10
width = 5
"#;
    let (nc, s, diags) = post_with(d, &two_tools());
    assert!(nc.contains("N00100 G20\n"), "{nc}");
    assert!(nc.contains(" G64 P.0004\n"), "the blending word with the job's tolerance:\n{nc}");
    let words: Vec<&str> = nc.lines().filter(|l| !l.contains('(')).flat_map(|l| l.split(' ')).collect();
    assert!(words.iter().any(|w| w.starts_with('X') && w.ends_with('.')), "a whole number ends in its point:\n{nc}");
    for w in words.iter().filter(|w| w.len() > 1 && "XYZABCF".contains(&w[..1]) && w.contains('.')) {
        assert!(!w.ends_with('0') && !w[1..].trim_start_matches('-').starts_with("0."), "{w} in\n{nc}");
    }
    // Lines over 24 characters are errors at their CL line, the program says so.
    assert!(s.errors > 0 && diags.iter().any(|d| d.code == kinepost::diag::Code::LineTooLong), "{diags:?}");
    // Every word is still the same number: the blocks replay to their CL points (FK replay).
    assert!(!diags.iter().any(|d| d.code == kinepost::diag::Code::VerifyDeviation), "{diags:?}");

    let (nc, ..) = post_with(&d.replace("line_length = 24\n", "").replace("[format]", "[format]\nmodal = false"), &two_tools());
    let moves: Vec<&str> = nc.lines().filter(|l| l.contains(" G1 ") || l.contains(" X")).collect();
    assert!(moves.len() > 20 && moves.iter().all(|l| l.contains(" X") && l.contains(" Y") && l.contains(" Z") && l.contains(" A") && l.contains(" C")), "{nc}");
}

#[test]
fn a_runaway_template_is_stopped_and_told() {
    // Tool 1 (the trial render's) passes; tool 2 loops past the fuel a render may spend.
    let d = SHOP.replace("G90\n", "{% if tool == 2 %}{% for i in range(90000) %}{% for j in range(90000) %}{% endfor %}{% endfor %}{% endif %}G90\n");
    let (nc, s, diags) = post_with(&d, &two_tools());
    assert!(s.errors > 0, "{nc}");
    let t: Vec<_> = diags.iter().filter(|d| d.code == kinepost::diag::Code::Template).collect();
    assert!(!t.is_empty() && t[0].message.contains("templates.tool_change"), "{diags:?}");
    assert!(nc.contains("ERROR"), "the program says so in its text:\n{nc}");
}

#[tokio::test]
async fn dialects_over_the_api_are_versioned_and_a_job_keeps_its_version() {
    let mut cfg = common::cfg();
    cfg.admin_token = Some(TOKEN.into());
    cfg.workers = 1;
    round_trip(common::server(cfg).await).await;
}

#[tokio::test]
#[ignore = "needs PostgreSQL: KINEPOST_TEST_DATABASE_URL=postgres://… cargo test -- --ignored"]
async fn dialects_over_the_api_on_postgres() {
    let Some((url, admin, name)) = common::postgres("dialects").await else {
        assert!(std::env::var("KINEPOST_REQUIRE_POSTGRES").is_err(), "KINEPOST_REQUIRE_POSTGRES is set but KINEPOST_TEST_DATABASE_URL is not");
        eprintln!("SKIPPED: set KINEPOST_TEST_DATABASE_URL=postgres://… to run on PostgreSQL");
        return;
    };
    let mut cfg = common::cfg();
    cfg.admin_token = Some(TOKEN.into());
    cfg.workers = 1;
    cfg.database_url = Some(url);
    round_trip(common::server(cfg).await).await;
    common::drop_postgres(&admin, &name).await;
}

async fn round_trip(base: String) {
    let c = reqwest::Client::new();
    let url = format!("{base}/v1/dialects/shop");
    let auth = format!("Bearer {TOKEN}");
    let put = |body: String| {
        c.put(&url)
            .header("authorization", &auth)
            .header("content-type", "application/toml")
            .body(body)
            .send()
    };
    assert_eq!(c.get(&url).status_ok().await, 404);
    let r = c.put(&url).header("content-type", "application/toml").body(SHOP).send().await.unwrap();
    assert_eq!(r.status(), 401);
    let r = put(SHOP.into()).await.unwrap();
    assert_eq!(r.status(), 201);
    assert_eq!(r.headers()["etag"], "\"shop-dialect-v1\"");
    let d: Value = r.json().await.unwrap();
    assert_eq!(d["templates"], serde_json::json!(["program_start", "tool_change", "first_move"]), "{d}");
    let r = c.get(&url).header("accept", "application/toml").send().await.unwrap();
    assert_eq!(r.text().await.unwrap(), SHOP);
    let list = common::get_json(&c, &format!("{base}/v1/dialects")).await;
    let ids: Vec<&str> = list.as_array().unwrap().iter().filter_map(|d| d["name"].as_str()).collect();
    assert_eq!(ids, ["fanuc", "haas", "siemens", "heidenhain", "linuxcnc", "linuxcnc-switchkins", "shop"]);

    // A bad template: 422 naming the event and its line; nothing written.
    let r = put(SHOP.replace("T{{ tool }} M6", "T{{ tool | nosuchfilter }} M6")).await.unwrap();
    assert_eq!(r.status(), 422);
    let p: Value = r.json().await.unwrap();
    assert_eq!(p["title"], "Invalid dialect");
    assert!(p["detail"].as_str().unwrap().contains("templates.tool_change: line 3"), "{p}");

    // Posts use it; a job records version 1 and keeps it when version 2 comes.
    let nc = c
        .post(format!("{base}/v1/post?machine={MACHINE}&dialect=shop"))
        .header("content-type", "text/plain")
        .body(two_tools())
        .text_ok()
        .await;
    assert!(nc.contains("G91 G28 Z0.\nG90\nT2 M6"), "{nc}");
    let job: Value = c
        .post(format!("{base}/v1/jobs?machine={MACHINE}&dialect=shop"))
        .header("content-type", "text/plain")
        .body(two_tools())
        .json_ok()
        .await;
    assert_eq!(job["dialect_version"], 1, "{job}");
    let r = put(SHOP.replace("G91 G28 Z0.", "G53 G0 Z0.")).await.unwrap();
    assert_eq!(r.status(), 200);
    let id = job["id"].as_str().unwrap();
    common::wait_job(&c, &base, id, "succeeded", Duration::from_secs(60)).await;
    let nc = c.get(format!("{base}/v1/jobs/{id}/nc")).text_ok().await;
    assert!(nc.contains("G91 G28 Z0.") && !nc.contains("G53 G0 Z0."), "the job ran with version 1:\n{nc}");
    let vs = common::get_json(&c, &format!("{url}/versions")).await;
    assert_eq!(vs["current"], 2, "{vs}");
    assert_eq!(c.get(format!("{url}/versions/1")).text_ok().await, SHOP);
    let r = c.delete(&url).header("authorization", &auth).send().await.unwrap();
    assert_eq!(r.status(), 204);
    let r = c
        .post(format!("{base}/v1/post?machine={MACHINE}&dialect=shop"))
        .header("content-type", "text/plain")
        .body(two_tools())
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 400, "a deleted dialect is no longer there to post with");
}

#[test]
fn a_dialect_names_its_clamp_words_and_its_block_delete() {
    let lib = common::library();
    let p = lib.get("haas-umc750").unwrap();
    let d = r#"id = "haas-shop"
extends = "haas"
title = "Haas, our clamps"
block_delete = "/1"
[clamps]
C = ["M82", "M83"]
"#;
    let d = std::sync::Arc::new(kinepost::machines::dialects::parse(d, "t.toml", None).unwrap());
    let s = kinepost::post::Settings { dialect: Some("haas-shop".into()), ..Default::default() };
    let o = s.profile_options_with(&p, None, &|id| (id == "haas-shop").then(|| d.clone())).unwrap();
    let mut cl = String::from("UNITS/INCHES\nLOADTL/1\nSPINDL/RPM,3000,CLW\nFEDRAT/20\n");
    for (k, (b, c)) in [(0.0f64, 0.0f64), (20.0, 40.0), (20.0, 40.0), (30.0, 90.0)].iter().enumerate() {
        let (b, c) = (b.to_radians(), c.to_radians());
        if k == 2 {
            cl.push_str("OPSKIP/ON\n");
        }
        cl.push_str(&format!("GOTO/{},0,1,{:.7},{:.7},{:.7}\n", k, b.sin() * c.cos(), b.sin() * c.sin(), b.cos()));
        if k == 2 {
            cl.push_str("OPSKIP/OFF\n");
        }
    }
    cl.push_str("FINI\n");
    let mut sink = common::collect::Collect::default();
    kinepost::post::post(cl.as_bytes(), &p.machine, &o, &mut sink).unwrap();
    assert!(sink.nc.contains("M82") || sink.nc.contains("M83"), "the dialect's C clamp words:\n{}", sink.nc);
    assert!(!sink.nc.contains("M10") && !sink.nc.contains("M11"), "not the profile's:\n{}", sink.nc);
    assert!(sink.nc.contains("M12") || sink.nc.contains("M13"), "B keeps the profile's:\n{}", sink.nc);
    assert!(sink.nc.lines().any(|l| l.starts_with("/1G")), "the block delete:\n{}", sink.nc);
}

/// Issue 51, 4: the CL's text reached NC through a template variable: an operation named
/// `FACE) M30 G0 Z-500 (` wrote `(OP FACE) M30 G0 Z-500 ()`, and a carriage return in a name
/// reached the NC raw. Now the name is made safe as every comment is: no delimiter, no control
/// character, and every block is one the template wrote.
#[test]
fn cl_text_in_a_template_variable_cannot_close_its_comment_or_split_a_block() {
    let d = format!("{SHOP}operation_start = \"(OP {{{{ operation }}}})\"\n");
    let cl = "UNITS/MM\nLOADTL/1\nSPINDL/RPM,6000,CLW\nFEDRAT/500\nTOOL PATH/FACE) M30 G0 Z-500 (,TOOL,T1\nGOTO/1,2,3\nEND-OF-PATH\nTOOL PATH/RO\rUGH\nG0 Z-400,TOOL,T1\nGOTO/4,5,6\nFINI\n";
    let (nc, s, diags) = post_with(&d, cl);
    assert_eq!(s.errors, 0, "{diags:?}\n{nc}");
    let ops: Vec<&str> = nc.lines().filter(|l| l.contains("(OP ")).collect();
    assert_eq!(ops.len(), 2, "{nc}");
    for l in &ops {
        let inner = l.split_once("(OP ").unwrap().1;
        assert_eq!(inner.matches(')').count(), 1, "the name closed the comment: {l}");
        assert!(inner.ends_with(')'), "{l}");
    }
    assert!(!nc.contains('\r'), "a carriage return reached the NC:\n{nc:?}");
    assert!(!nc.lines().any(|l| l.trim_start_matches(|c: char| c == 'N' || c.is_ascii_digit()).trim_start().starts_with("G0 Z-400")), "{nc}");
    let ends = nc.lines().filter(|l| l.split('(').next().unwrap().contains("M30")).count();
    assert_eq!(ends, 1, "one program end:\n{nc}");
}

/// Issue 51, 4 and 10: the trial render when a dialect is read uses the longest values and the
/// output bounds: a template that always writes 200 lines, or a carriage return within a line,
/// is refused there (it passed, and every post using it then failed).
#[test]
fn the_trial_render_holds_a_template_to_the_output_bounds() {
    let e = refused(&SHOP.replace("G90\n", "{% for i in range(200) %}G90\n{% endfor %}"));
    assert!(e.contains("templates.tool_change") && e.contains("more than 64 lines"), "{e}");
    let e = refused(&SHOP.replace("G90\n", "G90 {{ \"\\r\" }}M30\n"));
    assert!(e.contains("templates.tool_change") && e.contains("U+000D"), "{e}");
    // The longest operation name (120 characters) repeated past the byte bound.
    let e = refused(&format!("{SHOP}operation_start = \"{{% for i in range(70) %}}(OP {{{{ operation }}}}){{% endfor %}}\"\n"));
    assert!(e.contains("templates.operation_start") && e.contains("8192 bytes"), "{e}");
}

/// Issue 51, 6 and 9: a dialect's keys had no bounds: `[sequence] width = 300000000` was taken
/// (a 2 KB CL then streamed 13.5 GB), and its words were not held as a profile's: clamps
/// `"M10 M30"` and a multi-line `safe_start` or `spindle_cw` were stored and then written as
/// `M30` and `G0 Z-500` blocks. Each is refused now, naming the key.
#[test]
fn a_dialects_keys_are_bounded_and_its_words_are_words() {
    let e = refused(&format!("{SHOP}\n[sequence]\nstart = 1\nstep = 1\nwidth = 300000000\n"));
    assert!(e.contains("sequence.width") && e.contains("at most 9"), "{e}");
    let e = refused(&format!("{SHOP}\n[clamps]\nC = [\"M10 M30\", \"M11\"]\n"));
    assert!(e.contains("clamps.C") && e.contains("one NC word"), "{e}");
    let e = refused(&SHOP.replace("title =", "safe_start = \"\"\"G90\nG0 Z-500\"\"\"\ntitle ="));
    assert!(e.contains("safe_start") && e.contains("one line"), "{e}");
    let e = refused(&SHOP.replace("title =", "spindle_cw = \"M3\\rM30\"\ntitle ="));
    assert!(e.contains("spindle_cw") && e.contains("one line"), "{e}");
    // What a shop writes is still taken.
    kinepost::machines::dialects::parse(&format!("{SHOP}\n[clamps]\nC = [\"M10\", \"M11\"]\n[sequence]\nstart = 1\nstep = 1\nwidth = 5\n"), "ok.toml", None).unwrap();
}

/// `smoothing` where the job says none: the profile's `[policy] smoothing`, else the dialect's
/// `[smoothing] default`; a dialect that extends one replaces its levels key by key. Bad values
/// are refused naming the key.
#[test]
fn smoothing_defaults_from_the_profile_and_the_dialect() {
    use kinepost::post::{Settings, Smoothing};
    let shop = r#"id = "smooth"
extends = "haas"
title = "Haas, finish with high-speed look-ahead"
[smoothing]
default = "finish"
finish = ["G187 P3 E{tol}", "G103 P1"]
"#;
    let d = std::sync::Arc::new(kinepost::machines::dialects::parse(shop, "smooth.toml", None).unwrap());
    assert_eq!(d.smoothing.rough, ["G187 P1 E{tol}"], "the parent's rough level kept");
    let lib = common::library();
    let p = lib.get(MACHINE).unwrap();
    let find = |id: &str| (id == "smooth").then(|| d.clone()).or_else(|| kinepost::nc::dialect(id));
    let with = |s: Settings, p: &kinepost::machines::Profile| s.profile_options_with(p, None, &find).map(|o| o.smoothing);
    let job = |v: Option<&str>| Settings { dialect: Some("smooth".into()), smoothing: v.map(Into::into), ..Default::default() };
    assert_eq!(with(job(None), &p), Ok(Smoothing::Finish), "the dialect's default");
    assert_eq!(with(job(Some("off")), &p), Ok(Smoothing::Off), "the job's over the dialect's");
    let mut policed = (*p).clone();
    policed.policy.smoothing = Some(Smoothing::Rough);
    assert_eq!(with(job(None), &policed), Ok(Smoothing::Rough), "the profile's over the dialect's");
    assert_eq!(with(job(Some("auto")), &policed), Ok(Smoothing::Auto), "the job's over the profile's");
    let e = with(job(Some("medium")), &p).unwrap_err();
    assert!(e.field == "smoothing" && e.message.contains("smoothing \"medium\""), "{e}");
    // From the first feed move, the two finish lines at the job's tolerance (the CL says none).
    let mut o = kinepost::post::Options::new(&p.machine);
    o.dialect = d.clone();
    o.smoothing = Smoothing::Finish;
    let mut sink = common::collect::Collect::default();
    kinepost::post::post(two_tools().as_bytes(), &p.machine, &o, &mut sink).unwrap();
    assert!(sink.nc.contains("\nG187 P3 E0.0004\nG103 P1\n"), "{}", sink.nc);
    let refused = |t: &str| kinepost::machines::dialects::parse(t, "smooth.toml", None).unwrap_err().to_string();
    let e = refused(&shop.replace("\"finish\"\n", "\"smooth\"\n"));
    assert!(e.contains("smoothing.default") && e.contains("\"smooth\""), "{e}");
    let e = refused(&shop.replace("\"G103 P1\"]", "\"a\", \"b\", \"c\", \"d\"]"));
    assert!(e.contains("smoothing: at most 4 lines"), "{e}");
    let e = refused(&shop.replace("\"G103 P1\"]", "\"G103\\nP1\"]"));
    assert!(e.contains("smoothing:") && e.contains("one line"), "{e}");
}
