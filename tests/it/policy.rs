//! Motion policies: where positioning retracts to (`retract`), a profile default that a job
//! overrides, validated where options are made.

use crate::common;

use common::collect::Collect;
use kinepost::machines::parse_profile;
use kinepost::post::{self, Mode, Retract, Settings};

/// A cut, two rapids that each turn the rotaries, a tool change, a cut: every kind of
/// repositioning the emitter makes.
fn program() -> String {
    let (s, c) = (30f64.to_radians().sin(), 30f64.to_radians().cos());
    format!(
        "UNITS/MM\nLOADTL/1\nSPINDL/3000\nFEDRAT/500,MMPM\nGOTO/0,0,10,0,0,1\nGOTO/10,0,10,0,0,1\n\
         RAPID\nGOTO/20,5,60,{s},0,{c}\nRAPID\nGOTO/20,5,60,0,{s},{c}\nGOTO/25,5,40,0,{s},{c}\n\
         LOADTL/2\nSPINDL/3000\nRAPID\nGOTO/0,0,30,0,0,1\nGOTO/5,0,20,0,0,1\nFINI\n"
    )
}

fn post_with(id: &str, s: Settings) -> Collect {
    common::post_with(id, &s, program().as_bytes()).0
}

fn with_retract(mode: &str, retract: &str) -> Settings {
    Settings {
        mode: Some(mode.into()),
        retract: Some(retract.into()),
        ..Default::default()
    }
}

#[test]
fn retract_to_a_plane_keeps_every_repositioning_under_it() {
    for mode in ["joint", "tcp"] {
        let sink = post_with("spinner-u5-620", with_retract(mode, "plane:100"));
        let top = sink.blocks.iter().map(|b| b.tip[2]).fold(f64::MIN, f64::max);
        assert!(top <= 100.0 + 1e-3, "{mode}: a block at z = {top}:\n{}", sink.nc);
        // The plane is where it turns: retracts reach it, not only stay under it.
        let at_plane = sink
            .blocks
            .iter()
            .zip(&sink.texts)
            .filter(|(b, t)| t.contains("RETRACT") && (b.tip[2] - 100.0).abs() < 1e-3)
            .count();
        assert!(at_plane >= 2, "{mode}: {at_plane} retracts at the plane:\n{}", sink.nc);
        assert!(!sink.nc.contains("RETRACT Z"), "{mode}: no climb to the top of Z");
    }
}

#[test]
fn retract_along_the_axis_lifts_by_its_distance() {
    let sink = post_with("spinner-u5-620", with_retract("joint", "axis:25"));
    assert!(!sink.nc.contains("RETRACT Z"), "{}", sink.nc);
    let lifts: Vec<f64> = sink
        .blocks
        .windows(2)
        .zip(sink.texts.iter().skip(1))
        .filter(|(_, t)| t.contains("(RETRACT)"))
        .map(|(w, _)| (0..3).map(|i| (w[1].tip[i] - w[0].tip[i]).powi(2)).sum::<f64>().sqrt())
        .collect();
    assert!(!lifts.is_empty() && lifts.iter().all(|d| (d - 25.0).abs() < 1e-3), "{lifts:?}\n{}", sink.nc);
}

#[test]
fn the_default_is_the_modes_own_and_the_top_of_z_in_joint_mode() {
    let sink = post_with("spinner-u5-620", Settings::default());
    assert!(sink.nc.contains("RETRACT Z"), "{}", sink.nc);
    let lib = common::library();
    let p = lib.get("spinner-u5-620").unwrap();
    let tcp = Settings {
        mode: Some("tcp".into()),
        ..Default::default()
    };
    let o = tcp.profile_options(&p, None).unwrap();
    assert_eq!(o.retract, Retract::Axis(o.clearance));
}

#[test]
fn a_profile_states_its_default_and_a_job_overrides_it() {
    let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/machines/spinner-u5-620.toml")).unwrap();
    let shop = format!("{text}\n[policy]\nretract = \"plane:120\"\n");
    let p = parse_profile(&shop, "shop.toml", None).unwrap();
    let o = Settings::default().profile_options(&p, None).unwrap();
    assert_eq!(o.retract, Retract::Plane(120.0));
    let o = with_retract("joint", "machine-z").profile_options(&p, None).unwrap();
    assert_eq!(o.retract, Retract::MachineZ);
    // A profile's machine-z yields to TCP mode; a job's is refused there.
    let mz = parse_profile(&format!("{text}\n[policy]\nretract = \"machine-z\"\n"), "mz.toml", None).unwrap();
    let tcp = Settings {
        mode: Some("tcp".into()),
        ..Default::default()
    };
    assert!(matches!(tcp.profile_options(&mz, None).unwrap().retract, Retract::Axis(_)));
    let e = with_retract("tcp", "machine-z").profile_options(&mz, None).unwrap_err();
    assert!(e.field == "retract" && e.message.contains("TCP"), "{e}");
    let bad = parse_profile(&format!("{text}\n[policy]\nretract = \"up\"\n"), "bad.toml", None).unwrap_err();
    assert!(bad.to_string().contains("policy.retract"), "{bad}");
}

/// A profile's `[policy]` is parsed when it loads, every key: a bad value is refused there,
/// naming the file and the key, not blamed later on a post's parameter the client never sent.
#[test]
fn a_bad_policy_value_is_refused_at_load_naming_the_file_and_key() {
    let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/machines/spinner-u5-620.toml")).unwrap();
    for (key, bad) in [("retract", "up"), ("prefer", "A-"), ("feed_mode", "fast"), ("unwind", "never"), ("smoothing", "medium")] {
        let shop = format!("{text}\n[policy]\n{key} = \"{bad}\"\n");
        let e = parse_profile(&shop, "shop.toml", None).unwrap_err();
        let msg = e.to_string();
        assert!(msg.starts_with("shop.toml: ") && msg.contains(&format!("policy.{key}")) && msg.contains(bad), "{key}: {msg}");
        assert!(matches!(e, kinepost::machines::Error::Invalid { key: ref k, .. } if *k == format!("policy.{key}")), "{key}: {e:?}");
    }
    // Each good value loads typed, and a post without the setting takes it.
    let shop = format!("{text}\n[policy]\nretract = \"axis:30\"\nprefer = \"B-\"\nfeed_mode = \"dpm\"\nunwind = \"rapids\"\nsmoothing = \"off\"\n");
    let p = parse_profile(&shop, "shop.toml", None).unwrap();
    assert_eq!(p.policy.feed_mode, Some(post::RotaryFeed::DegreesPerMinute));
    assert_eq!(p.policy.unwind, Some(post::Unwind::AtRapids));
    let o = Settings::default().profile_options(&p, None).unwrap();
    assert_eq!(o.retract, Retract::Axis(30.0));
    assert_eq!((o.prefer.unwrap().rotary, o.prefer.unwrap().sign), (0, -1.0));
    assert_eq!((o.rotary_feed, o.unwind, o.smoothing), (post::RotaryFeed::DegreesPerMinute, post::Unwind::AtRapids, post::Smoothing::Off));
    // The job's own wins over each.
    let job = Settings {
        feed_mode: Some("combined".into()),
        unwind: Some("retract".into()),
        smoothing: Some("rough".into()),
        ..Default::default()
    };
    let o = job.profile_options(&p, None).unwrap();
    assert_eq!((o.rotary_feed, o.unwind, o.smoothing), (post::RotaryFeed::Combined, post::Unwind::RetractInCut, post::Smoothing::Rough));
}

#[test]
fn bad_retracts_are_refused_naming_the_setting() {
    let lib = common::library();
    let m = &lib.get("spinner-u5-620").unwrap().machine;
    for bad in ["up", "axis:", "axis:-5", "axis:0", "plane:x", "plane:NaN", "plane:1e300", "machine-z:1"] {
        let e = with_retract("joint", bad).options(m).unwrap_err();
        assert!(e.field == "retract" && e.message.starts_with("retract"), "{bad}: {e}");
    }
    for (good, want) in [("machine-z", Retract::MachineZ), ("axis:5", Retract::Axis(5.0)), ("plane:-20", Retract::Plane(-20.0))] {
        assert_eq!(with_retract("joint", good).options(m).unwrap().retract, want);
    }
    assert_eq!(Settings::default().options(m).unwrap().mode, Mode::Joint);
}

/// A tilted run both trunnion branches can cut (B = ±20° with C half a turn apart): `prefer`
/// decides the side, every B word of it, and the path is the same either way.
#[test]
fn prefer_keeps_a_rotary_on_the_side_asked_for() {
    let tilt = 20f64.to_radians();
    let mut cl = String::from("UNITS/MM\nLOADTL/1\nSPINDL/3000\nFEDRAT/800,MMPM\n");
    for k in 0..=60 {
        let az = (k as f64 * 1.5).to_radians();
        let (i, j, kk) = (tilt.sin() * az.cos(), tilt.sin() * az.sin(), tilt.cos());
        cl.push_str(&format!("GOTO/{:.3},{:.3},20,{i:.7},{j:.7},{kk:.7}\n", 30.0 * az.cos(), 30.0 * az.sin()));
    }
    cl.push_str("FINI\n");
    let lib = common::library();
    let p = lib.get("spinner-u5-620").unwrap();
    for (side, sign) in [("B-", -1.0), ("B+", 1.0)] {
        let s = Settings {
            prefer: Some(side.into()),
            ..Default::default()
        };
        let o = s.profile_options(&p, None).unwrap();
        let mut sink = Collect::default();
        let sum = post::post(cl.as_bytes(), &p.machine, &o, &mut sink).unwrap();
        assert_eq!(sum.errors, 0, "{side}: {:?}", sink.diags);
        let bs: Vec<f64> = sink.blocks.iter().filter_map(|b| b.joints.0[4]).collect();
        assert!(bs.len() > 30, "{side}: {} B words", bs.len());
        assert!(bs.iter().all(|b| b * sign >= -1e-9), "{side}: {bs:?}");
        assert!(bs.iter().any(|b| b * sign > 19.0), "{side}: tilted to its side: {bs:?}");
    }
    // A starting angle: the unbounded C table starts on the winding nearest it; with a side.
    for (start, near) in [("C=360", 360.0), ("B+, C=-720", -720.0), ("C=0", 0.0)] {
        let s = Settings {
            prefer: Some(start.into()),
            ..Default::default()
        };
        let o = s.profile_options(&p, None).unwrap();
        let mut sink = Collect::default();
        post::post(cl.as_bytes(), &p.machine, &o, &mut sink).unwrap();
        let c0 = sink.blocks.iter().find_map(|b| b.joints.0[5]).unwrap();
        assert!((c0 - near).abs() <= 180.0, "{start}: C starts at {c0}");
    }
    // A rotary the machine lacks, or no sign: refused naming the setting.
    for bad in ["A-", "B", "B*", "BB-", "B-, B+", "C=x", "C=1e9"] {
        let s = Settings {
            prefer: Some(bad.into()),
            ..Default::default()
        };
        assert_eq!(s.profile_options(&p, None).unwrap_err().field, "prefer", "{bad}");
    }
}

/// A 5-axis cut on spinner-u5-620 whose tool axis swings as it goes, in LinuxCNC's dialect.
fn swing() -> String {
    let mut cl = String::from("UNITS/MM\nLOADTL/1\nSPINDL/3000\nFEDRAT/800,MMPM\n");
    for k in 0..=40 {
        let t = k as f64 / 40.0;
        let (tilt, az) = ((10.0 + 20.0 * t).to_radians(), (60.0 * t).to_radians());
        let (i, j, kk) = (tilt.sin() * az.cos(), tilt.sin() * az.sin(), tilt.cos());
        cl.push_str(&format!("GOTO/{:.3},{:.3},20,{i:.7},{j:.7},{kk:.7}\n", 20.0 * t, 5.0 * t));
    }
    // The tool turning about a tip on the table's axis at a fixed tilt: only C moves.
    for k in 0..=10 {
        let az = (60.0 + 3.0 * k as f64).to_radians();
        let tilt = 30f64.to_radians();
        cl.push_str(&format!("GOTO/0,0,20,{:.7},{:.7},{:.7}\n", tilt.sin() * az.cos(), tilt.sin() * az.sin(), tilt.cos()));
    }
    cl.push_str("FINI\n");
    cl
}

/// The F word of a block's text.
fn f_word(text: &str) -> Option<f64> {
    text.split(' ').find_map(|w| w.strip_prefix('F')?.parse().ok())
}

#[test]
fn feed_mode_dpm_writes_no_inverse_time_and_keeps_each_blocks_time() {
    let lib = common::library();
    let p = lib.get("spinner-u5-620").unwrap();
    let run = |mode: Option<&str>| {
        let s = Settings {
            dialect: Some("linuxcnc".into()),
            feed_mode: mode.map(str::to_string),
            ..Default::default()
        };
        let o = s.profile_options(&p, None).unwrap();
        let mut sink = Collect::default();
        let sum = post::post(swing().as_bytes(), &p.machine, &o, &mut sink).unwrap();
        assert_eq!(sum.errors, 0, "{mode:?}: {:?}", sink.diags);
        (sink, sum)
    };
    let (g93, sum93) = run(None);
    assert!(g93.nc.contains("G93"), "inverse time by default:\n{}", g93.nc);
    for (mode, rule) in [("dpm", "dpm"), ("combined", "combined")] {
        let (sink, sum) = run(Some(mode));
        assert!(!sink.nc.contains("G93"), "{mode}:\n{}", sink.nc);
        // The same motion in the same time: each block's F over the path the control reads it
        // along gives the block's time.
        assert!((sum.cycle_time_s - sum93.cycle_time_s).abs() < 1e-6 * sum93.cycle_time_s.max(1.0), "{mode}");
        let mut checked = (0, 0);
        let mut prev: Option<&kinepost::post::BlockInfo> = None;
        let mut f_modal = None;
        for (b, t) in sink.blocks.iter().zip(&sink.texts) {
            f_modal = f_word(t).or(f_modal);
            if let (Some(a), false, Some(f)) = (prev, b.rapid, f_modal) {
                let d = |i: usize| b.joints.0[i].unwrap_or(0.0) - a.joints.0[i].unwrap_or(0.0);
                let lin = (d(0).powi(2) + d(1).powi(2) + d(2).powi(2)).sqrt();
                let rot = (d(3).powi(2) + d(4).powi(2) + d(5).powi(2)).sqrt();
                let path = match rule {
                    "dpm" if lin > 5e-4 => lin,
                    "dpm" => rot,
                    _ => (lin * lin + rot * rot).sqrt(),
                };
                if rot > 1e-3 && b.time_s > 1e-3 {
                    let want = path / (b.time_s / 60.0);
                    assert!((f - want).abs() <= 0.06 + 2e-3 * want, "{mode}: F{f} where {want:.2} gives the block's time: {t}");
                    if lin > 5e-4 { checked.0 += 1 } else { checked.1 += 1 }
                }
            }
            prev = Some(b);
        }
        assert!(checked.0 > 20 && checked.1 >= 5, "{mode}: {checked:?} blocks checked (with and without linear motion)");
    }
    let s = Settings {
        feed_mode: Some("per-tooth".into()),
        ..Default::default()
    };
    assert_eq!(s.profile_options(&p, None).unwrap_err().field, "feed_mode");
}
