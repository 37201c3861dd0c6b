//! `kinepost machines …`: the machine library offline (validate, fit an angle error, …).

use clap::Subcommand;
use super::parse_words;
use kinepost::kinematics::{Setup, Vec3};
use kinepost::machines::{self, Library};
use std::collections::BTreeMap;
use std::path::PathBuf;

/// Managing the machine library offline.
#[derive(Subcommand, Debug)]
pub enum MachinesCmd {
    /// Check profile files (and tool tables, `<id>.tools.toml`) with the loaders the service uses.
    Validate { files: Vec<PathBuf> },
    /// Validate a profile and copy it into the library directory.
    Add {
        file: PathBuf,
        /// Replace a profile of the same id.
        #[arg(long)]
        force: bool,
    },
    /// Fit a rotary's angle-error polynomial (degrees 2–5) from a CSV of `angle,error` (degrees),
    /// or of `angle,dz` with --pendulum (the HTM50200 paper's equation 10). Prints the fits and
    /// the proposed profile (TOML); apply it with `machines add --force`.
    FitAngleError {
        #[arg(long)]
        machine: String,
        /// The rotary: A, B or C.
        #[arg(long)]
        axis: String,
        #[arg(long)]
        input: PathBuf,
        #[arg(long)]
        pendulum: Option<f64>,
    },
    /// Fit pivot offsets from test cuts: a CSV whose header names the joint columns (X,Y,Z and
    /// the rotaries, degrees) and dx,dy,dz (measured tip deviation, part frame, profile units).
    Calibrate {
        #[arg(long)]
        machine: String,
        #[arg(long)]
        input: PathBuf,
        #[arg(long, allow_hyphen_values = true)]
        tool_length: Option<f64>,
    },
}

/// Rows of a CSV file with a header line, as name → number maps.
fn read_csv(path: &std::path::Path) -> Result<Vec<BTreeMap<String, f64>>, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut lines = text.lines().filter(|l| !l.trim().is_empty() && !l.starts_with('#'));
    let header: Vec<String> = lines
        .next()
        .ok_or("empty CSV")?
        .split(',')
        .map(|h| h.trim().to_string())
        .collect();
    let mut rows = Vec::new();
    for (n, l) in lines.enumerate() {
        let mut row = BTreeMap::new();
        for (h, v) in header.iter().zip(l.split(',')) {
            let x: f64 = v
                .trim()
                .parse()
                .map_err(|_| format!("{}: row {}: {h} = {v:?} is not a number", path.display(), n + 2))?;
            row.insert(h.clone(), x);
        }
        rows.push(row);
    }
    Ok(rows)
}

pub(super) fn machines_cmd(lib: &Library, dir: &std::path::Path, a: &MachinesCmd) -> Result<(), String> {
    match a {
        MachinesCmd::Validate { files } => {
            let mut bad = 0;
            for f in files {
                if f.to_string_lossy().ends_with(machines::tools::TABLE_SUFFIX) {
                    match machines::tools::load_tool_table(f) {
                        Ok(t) => say!("ok   {} (tool table, {} tools)", f.display(), t.len()),
                        Err(e) => {
                            bad += 1;
                            say!("FAIL {e}");
                        }
                    }
                    continue;
                }
                match machines::load_file(f) {
                    Ok(p) => say!("ok   {} ({}, {})", f.display(), p.machine.id, p.machine.kinematics_kind()),
                    Err(e) => {
                        bad += 1;
                        say!("FAIL {e}");
                    }
                }
            }
            if bad > 0 {
                Err(format!("{bad} invalid profile(s)"))
            } else {
                Ok(())
            }
        }
        MachinesCmd::Add { file, force } => {
            let text = machines::read_text(file).map_err(|e| format!("{}: {e}", file.display()))?;
            // As over the API: a mesh is a file of the library directory, not copied with it.
            let p = machines::parse_profile_in(&text, &file.display().to_string(), None, Some(dir)).map_err(|e| e.to_string())?;
            let dest = dir.join(format!("{}.toml", p.machine.id));
            if dest.exists() && !force {
                return Err(format!("{} exists: use --force to replace it", dest.display()));
            }
            std::fs::write(&dest, text).map_err(|e| format!("{}: {e}", dest.display()))?;
            say!("added {} as {}", p.machine.id, dest.display());
            Ok(())
        }
        MachinesCmd::FitAngleError {
            machine,
            axis,
            input,
            pendulum,
        } => {
            let p = lib.get(machine).map_err(|e| e.to_string())?;
            let idx = p
                .doc
                .rotary
                .iter()
                .position(|r| &r.name == axis)
                .ok_or_else(|| format!("{machine} has no rotary {axis:?}"))?;
            let mut samples = Vec::new();
            for row in read_csv(input)? {
                let t = *row.get("angle").ok_or("CSV needs an `angle` column")?;
                let d = match (row.get("error"), row.get("dz"), pendulum) {
                    (Some(e), _, _) => *e,
                    (None, Some(dz), Some(l)) => {
                        kinepost::calib::delta_from_vertical_error(t, *dz, *l).map_err(|e| e.to_string())?
                    }
                    _ => return Err("CSV needs an `error` column, or `dz` with --pendulum".into()),
                };
                samples.push((t, d));
            }
            let fits = kinepost::calib::fit_angle_error(&samples, 2..=5).map_err(|e| e.to_string())?;
            for f in &fits {
                eprintln!(
                    "degree {}: rms {:.3e}°, max {:.3e}°, coefficients {:?}",
                    f.degree, f.rms, f.max, f.coefficients
                );
            }
            let chosen = kinepost::calib::choose(&fits).ok_or("no fit")?;
            eprintln!("proposed: degree {}", chosen.degree);
            let range = samples
                .iter()
                .fold([f64::INFINITY, f64::NEG_INFINITY], |r, s| [r[0].min(s.0), r[1].max(s.0)]);
            let mut doc = p.doc.clone();
            doc.rotary[idx].angle_error = Some(machines::AngleErrorDoc {
                coefficients: chosen.coefficients.clone(),
                range,
            });
            print!("{}", toml::to_string(&doc).map_err(|e| e.to_string())?);
            Ok(())
        }
        MachinesCmd::Calibrate {
            machine,
            input,
            tool_length,
        } => {
            let p = lib.get(machine).map_err(|e| e.to_string())?;
            let m = &p.machine;
            let setup = Setup::new(tool_length.unwrap_or(m.default_tool_length), Vec3::zeros());
            let mut meas = Vec::new();
            for row in read_csv(input)? {
                let mut words = Vec::new();
                for (k, v) in &row {
                    if !matches!(k.as_str(), "dx" | "dy" | "dz") {
                        words.push(format!("{k}={v}"));
                    }
                }
                let joints = parse_words(m, &words)?;
                let d = |k: &str| row.get(k).copied().ok_or(format!("CSV needs a `{k}` column"));
                meas.push(kinepost::calib::Measurement {
                    joints,
                    deviation: Vec3::new(d("dx")?, d("dy")?, d("dz")?),
                });
            }
            let fit = kinepost::calib::fit_pivots(m, &setup, &meas).map_err(|e| e.to_string())?;
            eprintln!("rms {:.3e} -> {:.3e} {}", fit.rms_before, fit.rms, m.units.as_str());
            let mut doc = p.doc.clone();
            for (name, off) in &fit.offsets {
                eprintln!("{name} pivot offset {:.6} {:.6} {:.6}", off.x, off.y, off.z);
                if let Some(rd) = doc.rotary.iter_mut().find(|r| r.name == name.to_string()) {
                    for k in 0..3 {
                        rd.pivot[k] += off[k];
                    }
                }
            }
            print!("{}", toml::to_string(&doc).map_err(|e| e.to_string())?);
            Ok(())
        }
    }
}

