//! Per-machine computations for CAM plugins: FK, IK and reachability before posting, and the
//! calibration fits (test cuts → pivot offsets; measurements → angle-error polynomial). Fits
//! return a proposed profile; applying it is a separate, explicit step.

use super::AppState;
use super::error::{ApiError, ApiJson};
use super::refusals::MachineOpRefusals;
use crate::calib::{self, Measurement};
use crate::kinematics::{self, IkOptions, Joints, Machine, Pose, Setup, Units, Vec3};
use crate::machines::Profile;
use crate::text::quote;
use axum::Json;
use axum::extract::{Path, State};
use serde::{Deserialize, Serialize};
use serde_json::Value;
use std::collections::BTreeMap;
use std::sync::Arc;

/// Joint words by name (`X`, `Y`, `Z` in profile units; `A`, `B`, `C` in degrees).
type Words = BTreeMap<String, f64>;

#[derive(Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct FkRequest {
    pub joints: Words,
    pub tool_length: Option<f64>,
    #[schema(value_type = Option<Vec<f64>>, min_items = 3, max_items = 3)]
    pub work_offset: Option<[f64; 3]>,
}

#[derive(Serialize, utoipa::ToSchema)]
pub struct PoseDto {
    pub tip: [f64; 3],
    pub axis: [f64; 3],
}

#[derive(Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct PoseRequest {
    /// Tip point in the part frame.
    #[schema(value_type = Vec<f64>, min_items = 3, max_items = 3)]
    pub tip: [f64; 3],
    /// Tool axis (tip toward spindle).
    #[schema(value_type = Vec<f64>, min_items = 3, max_items = 3)]
    pub axis: [f64; 3],
    pub tool_length: Option<f64>,
    #[schema(value_type = Option<Vec<f64>>, min_items = 3, max_items = 3)]
    pub work_offset: Option<[f64; 3]>,
    /// Units of `tip` (default: the profile's).
    pub units: Option<String>,
}

#[derive(Serialize, utoipa::ToSchema)]
pub struct ReachDto {
    pub reachable: bool,
    /// Some solution has every axis within travel.
    pub within_limits: bool,
    pub solutions: usize,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    /// How far (degrees) the orientation misses what the rotaries can reach.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub miss_deg: Option<f64>,
}

#[derive(Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct AngleFitRequest {
    /// The rotary the measurements are of (`A`, `B` or `C`).
    pub axis: String,
    /// Measured (commanded angle, angle error) pairs, degrees.
    #[serde(default)]
    #[schema(value_type = Vec<Vec<f64>>)]
    pub samples: Vec<[f64; 2]>,
    /// Or (commanded angle, vertical tip error ΔZ) pairs with `pendulum` (the paper's eq. 10).
    #[serde(default)]
    #[schema(value_type = Vec<Vec<f64>>)]
    pub vertical: Vec<[f64; 2]>,
    pub pendulum: Option<f64>,
}

#[derive(Serialize, utoipa::ToSchema)]
pub struct FitDto {
    pub degree: usize,
    /// c0, c1, … of Δ(θ), degrees.
    pub coefficients: Vec<f64>,
    pub rms: f64,
    pub max: f64,
}

#[derive(Serialize, utoipa::ToSchema)]
pub struct AngleFitResponse {
    /// Degrees 2 to 5, each with its residuals (the paper compares them).
    pub fits: Vec<FitDto>,
    /// The proposal: the lowest degree whose RMS is within 10 % of the best.
    pub proposed: FitDto,
    pub range: [f64; 2],
    /// The profile with this angle error, as TOML: apply it explicitly.
    pub proposed_profile: String,
}

#[derive(Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct MeasurementDto {
    pub joints: Words,
    /// Where the tip landed minus where the profile says, part frame, profile units.
    #[schema(value_type = Vec<f64>, min_items = 3, max_items = 3)]
    pub deviation: [f64; 3],
}

#[derive(Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CalibrateRequest {
    pub measurements: Vec<MeasurementDto>,
    pub tool_length: Option<f64>,
}

#[derive(Serialize, utoipa::ToSchema)]
pub struct CalibrateResponse {
    /// Offset to add to each rotary's pivot, profile units.
    pub offsets: BTreeMap<String, [f64; 3]>,
    pub rms_before: f64,
    pub rms: f64,
    pub residuals: Vec<f64>,
    /// The profile with the fitted pivots, as TOML: apply it explicitly.
    pub proposed_profile: String,
}

fn profile(st: &AppState, id: &str) -> Result<Arc<Profile>, ApiError> {
    st.machines
        .get(id)
        .map(|c| c.item)
        .map_err(|_| ApiError::UnknownMachine(id.into()))
}

/// Every computation here runs on the blocking pool: a fit takes up to seconds with a full
/// request body, and IK on a profile it handles badly can take as long; on the runtime either
/// would stall the connections sharing its thread (health checks among them).
async fn off_runtime<T: Send + 'static>(f: impl FnOnce() -> T + Send + 'static) -> Result<T, ApiError> {
    tokio::task::spawn_blocking(f)
        .await
        .map_err(|e| ApiError::Internal(format!("computation: {e}")))
}

fn setup(m: &Machine, tool_length: Option<f64>, wo: Option<[f64; 3]>) -> Result<Setup, ApiError> {
    Setup::checked(m, tool_length, Vec3::from(wo.unwrap_or_default())).map_err(ApiError::BadParameter)
}

fn joints(m: &Machine, words: &Words) -> Result<Joints, ApiError> {
    let mut j = Joints::default();
    for (k, v) in words {
        if !kinematics::coordinate_ok(*v) {
            return Err(ApiError::BadParameter(format!(
                "joints.{} must be finite and within ±{:e}",
                quote(k),
                kinematics::MAX_COORD
            )));
        }
        match k.as_str() {
            "X" | "Y" | "Z" => {
                let i = (k.as_bytes()[0] - b'X') as usize;
                if m.linears[i].is_none() {
                    return Err(ApiError::BadParameter(format!("{} has no {k} axis", m.id)));
                }
                j.linear[i] = *v;
            }
            _ => {
                let i = k.chars().next().filter(|_| k.len() == 1).and_then(|c| m.rotary_index(c));
                let i = i.ok_or_else(|| ApiError::BadParameter(format!("{} has no axis {}", m.id, quote(k))))?;
                j.rotary[i] = v.to_radians();
            }
        }
    }
    Ok(j)
}

fn pose(m: &Machine, r: &PoseRequest) -> Result<Pose, ApiError> {
    let f = match r.units.as_deref() {
        None => 1.0,
        Some("mm") => Units::Mm.factor_to(m.units),
        Some("inch") => Units::Inch.factor_to(m.units),
        Some(u) => return Err(ApiError::BadParameter(format!("units {}: expected mm or inch", quote(u)))),
    };
    Ok(Pose {
        tip: Vec3::from(r.tip) * f,
        axis: Vec3::from(r.axis),
    })
}

/// Forward kinematics: axis words → tool pose in the part frame.
#[utoipa::path(post, path = "/v1/machines/{id}/fk", params(("id" = String, Path)), request_body = FkRequest,
    responses((status = 200, description = "Success", body = PoseDto), MachineOpRefusals), tag = "machines")]
pub async fn fk_route(
    State(st): State<Arc<AppState>>,
    Path(id): Path<String>,
    ApiJson(r): ApiJson<FkRequest>,
) -> Result<Json<PoseDto>, ApiError> {
    let p = profile(&st, &id)?;
    off_runtime(move || {
        let m = &p.machine;
        let p = kinematics::fk(m, &joints(m, &r.joints)?, &setup(m, r.tool_length, r.work_offset)?);
        Ok(Json(PoseDto {
            tip: p.tip.into(),
            axis: p.axis.into(),
        }))
    })
    .await?
}

/// Inverse kinematics: every joint solution of a pose, in limits or not.
#[utoipa::path(post, path = "/v1/machines/{id}/ik", params(("id" = String, Path)), request_body = PoseRequest,
    responses((status = 200, description = "{\"solutions\": [{axis words…, branch, within_limits, singular}]}", body = Object), MachineOpRefusals,
        (status = 422, description = "The pose is unreachable on this machine (code `unreachable`)", body = super::Problem, content_type = "application/problem+json")), tag = "machines")]
pub async fn ik_route(
    State(st): State<Arc<AppState>>,
    Path(id): Path<String>,
    ApiJson(r): ApiJson<PoseRequest>,
) -> Result<Json<Value>, ApiError> {
    let p = profile(&st, &id)?;
    off_runtime(move || {
        let m = &p.machine;
        let sols = kinematics::ik(
            m,
            &pose(m, &r)?,
            &setup(m, r.tool_length, r.work_offset)?,
            &IkOptions::default(),
        )
        .map_err(|e| ApiError::BadRecord {
            message: format!("pose unreachable on {id}: {e}"),
            line: None,
            column: None,
            code: "unreachable",
        })?;
        let list: Vec<Value> = sols.iter().map(|s| crate::output::solution_json(m, s)).collect();
        Ok(Json(serde_json::json!({ "solutions": list })))
    })
    .await?
}

/// Whether a pose can be reached, and within travel: a check before posting.
#[utoipa::path(post, path = "/v1/machines/{id}/validate-pose", params(("id" = String, Path)), request_body = PoseRequest,
    responses((status = 200, description = "Success", body = ReachDto), MachineOpRefusals), tag = "machines")]
pub async fn validate_pose(
    State(st): State<Arc<AppState>>,
    Path(id): Path<String>,
    ApiJson(r): ApiJson<PoseRequest>,
) -> Result<Json<ReachDto>, ApiError> {
    let p = profile(&st, &id)?;
    off_runtime(move || reach(&p.machine, &r).map(Json)).await?
}

/// Whether `r`'s pose can be reached on `m`, and within travel.
fn reach(m: &Machine, r: &PoseRequest) -> Result<ReachDto, ApiError> {
    Ok(
        match kinematics::ik(
            m,
            &pose(m, r)?,
            &setup(m, r.tool_length, r.work_offset)?,
            &IkOptions::default(),
        ) {
            Ok(sols) => {
                let ok = sols.iter().any(|s| kinematics::reachable_within_limits(m, s));
                ReachDto {
                    reachable: true,
                    within_limits: ok,
                    solutions: sols.len(),
                    reason: (!ok).then(|| "every solution leaves an axis's travel".into()),
                    miss_deg: None,
                }
            }
            Err(e) => {
                let miss = match &e {
                    kinematics::Error::Unreachable { miss } => Some(miss.to_degrees()),
                    _ => None,
                };
                ReachDto {
                    reachable: false,
                    within_limits: false,
                    solutions: 0,
                    reason: Some(e.to_string()),
                    miss_deg: miss,
                }
            }
        },
    )
}

/// Fits a rotary's angle-error polynomial (degrees 2–5) from measurements.
#[utoipa::path(post, path = "/v1/machines/{id}/angle-error-fit", params(("id" = String, Path)), request_body = AngleFitRequest,
    responses((status = 200, description = "Success", body = AngleFitResponse), MachineOpRefusals), tag = "machines")]
pub async fn angle_error_fit(
    State(st): State<Arc<AppState>>,
    Path(id): Path<String>,
    ApiJson(r): ApiJson<AngleFitRequest>,
) -> Result<Json<AngleFitResponse>, ApiError> {
    let p = profile(&st, &id)?;
    let idx = p
        .doc
        .rotary
        .iter()
        .position(|x| x.name == r.axis)
        .ok_or_else(|| ApiError::BadParameter(format!("{id} has no rotary {}", quote(&r.axis))))?;
    let mut samples: Vec<(f64, f64)> = r.samples.iter().map(|s| (s[0], s[1])).collect();
    if !r.vertical.is_empty() {
        let l = r
            .pendulum
            .ok_or_else(|| ApiError::BadParameter("vertical errors need the pendulum length".into()))?;
        for v in &r.vertical {
            samples.push((
                v[0],
                calib::delta_from_vertical_error(v[0], v[1], l).map_err(|e| ApiError::BadParameter(e.to_string()))?,
            ));
        }
    }
    let range = samples
        .iter()
        .fold([f64::INFINITY, f64::NEG_INFINITY], |r, s| [r[0].min(s.0), r[1].max(s.0)]);
    let fits = off_runtime(move || calib::fit_angle_error(&samples, 2..=5))
        .await?
        .map_err(|e| ApiError::BadParameter(e.to_string()))?;
    let chosen = calib::choose(&fits)
        .ok_or_else(|| ApiError::BadParameter("no fit".into()))?
        .clone();
    let mut doc = p.doc.clone();
    doc.rotary[idx].angle_error = Some(crate::machines::AngleErrorDoc {
        coefficients: chosen.coefficients.clone(),
        range,
    });
    let dto = |f: &calib::PolyFit| FitDto {
        degree: f.degree,
        coefficients: f.coefficients.clone(),
        rms: f.rms,
        max: f.max,
    };
    Ok(Json(AngleFitResponse {
        fits: fits.iter().map(dto).collect(),
        proposed: dto(&chosen),
        range,
        proposed_profile: toml::to_string(&doc).map_err(|e| ApiError::Internal(e.to_string()))?,
    }))
}

/// Fits pivot offsets from test cuts (measured tip deviations at known joint positions).
#[utoipa::path(post, path = "/v1/machines/{id}/calibrate", params(("id" = String, Path)), request_body = CalibrateRequest,
    responses((status = 200, description = "Success", body = CalibrateResponse), MachineOpRefusals), tag = "machines")]
pub async fn calibrate(
    State(st): State<Arc<AppState>>,
    Path(id): Path<String>,
    ApiJson(r): ApiJson<CalibrateRequest>,
) -> Result<Json<CalibrateResponse>, ApiError> {
    let p = profile(&st, &id)?;
    let m = &p.machine;
    let s = setup(m, r.tool_length, None)?;
    let meas = r
        .measurements
        .iter()
        .map(|x| {
            Ok(Measurement {
                joints: joints(m, &x.joints)?,
                deviation: Vec3::from(x.deviation),
            })
        })
        .collect::<Result<Vec<_>, ApiError>>()?;
    let pm = p.clone();
    let fit = off_runtime(move || calib::fit_pivots(&pm.machine, &s, &meas))
        .await?
        .map_err(|e| ApiError::BadParameter(e.to_string()))?;
    let mut doc = p.doc.clone();
    for (name, off) in &fit.offsets {
        if let Some(rd) = doc.rotary.iter_mut().find(|x| x.name == name.to_string()) {
            for k in 0..3 {
                rd.pivot[k] += off[k];
            }
        }
    }
    Ok(Json(CalibrateResponse {
        offsets: fit.offsets.iter().map(|(n, o)| (n.to_string(), [o.x, o.y, o.z])).collect(),
        rms_before: fit.rms_before,
        rms: fit.rms,
        residuals: fit.residuals.clone(),
        proposed_profile: toml::to_string(&doc).map_err(|e| ApiError::Internal(e.to_string()))?,
    }))
}
