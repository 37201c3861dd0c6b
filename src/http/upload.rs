//! A CL upload, as every route that takes one reads it: the CL as a raw body (`text/plain`,
//! `application/octet-stream`) with the post's parameters in the query, or a multipart form
//! whose text fields (over the query's) come before its `file` part. Either way the handler
//! gets the parameters, the file's name, and the CL as a body it reads as it arrives: nothing
//! is buffered whole, whatever its size.

use super::error::{ApiError, ApiQuery};
use super::{AppState, limits};
use crate::post::Settings;
use axum::body::Body;
use axum::extract::multipart::Field;
use axum::extract::{FromRequest, FromRequestParts, Multipart, Request};
use axum::http::header;
use bytes::Bytes;
use std::sync::Arc;
use tokio::sync::{mpsc, oneshot};

/// The extractor: the last argument of a handler that takes CL (`POST /v1/post`,
/// `POST /v1/jobs`). Refuses with [`super::refusals::UploadRefusals`]' statuses: a parameter
/// (400), the content type (415), a form's field (400, 413) before its file.
pub(super) struct ClUpload {
    /// The query's parameters, then the form's fields.
    pub params: Settings,
    /// The form's file name (none for a raw body).
    pub filename: Option<String>,
    /// The CL bytes as they arrive; a read that fails says why (`post::upload_error`).
    pub body: Body,
}

impl FromRequest<Arc<AppState>> for ClUpload {
    type Rejection = ApiError;

    async fn from_request(req: Request, st: &Arc<AppState>) -> Result<Self, ApiError> {
        let (mut parts, body) = req.into_parts();
        let ApiQuery(query) = ApiQuery::<Settings>::from_request_parts(&mut parts, st).await?;
        let (params, filename, body) = upload(st, query, Request::from_parts(parts, body)).await?;
        Ok(ClUpload { params, filename, body })
    }
}

/// The CL upload: a raw body with query parameters, or a multipart form whose fields come
/// before its `file` part.
async fn upload(
    st: &Arc<AppState>,
    query: Settings,
    req: Request,
) -> Result<(Settings, Option<String>, Body), ApiError> {
    let ctype = req
        .headers()
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .unwrap_or("text/plain")
        .to_ascii_lowercase();
    if ctype.starts_with("multipart/form-data") {
        multipart_body(st, query, req).await
    } else if ctype.starts_with("text/plain") || ctype.starts_with("application/octet-stream") || ctype.is_empty() {
        Ok((query, None, req.into_body()))
    } else {
        Err(ApiError::UnsupportedMediaType(ctype))
    }
}

/// Reads form fields up to the file part, then hands the file's bytes over as a body stream fed
/// by a task that owns the form (fields after the file are not read).
async fn multipart_body(
    st: &Arc<AppState>,
    query: Settings,
    req: Request,
) -> Result<(Settings, Option<String>, Body), ApiError> {
    let mp = Multipart::from_request(req, st)
        .await
        .map_err(|e| ApiError::BadParameter(format!("multipart: {e}")))?;
    let (ptx, prx) = oneshot::channel::<FormHead>();
    let (btx, brx) = mpsc::channel::<Result<Bytes, std::io::Error>>(8);
    tokio::spawn(read_form(mp, query, ptx, btx));
    let (params, fname) = prx.await.map_err(|_| ApiError::Internal("multipart reader ended".into()))??;
    let stream = futures_util::stream::unfold(brx, |mut rx| async move { rx.recv().await.map(|item| (item, rx)) });
    Ok((params, fname, Body::from_stream(stream)))
}

/// What a form says before its file: the parameters and the file's name, or why it is refused.
type FormHead = Result<(Settings, Option<String>), ApiError>;

/// The form task: text fields until the file part, then them over `params` and the file's
/// name to `ptx` and its bytes to `btx`. A form that fails before its file says so on `ptx`.
async fn read_form(
    mut mp: Multipart,
    params: Settings,
    ptx: oneshot::Sender<FormHead>,
    btx: mpsc::Sender<Result<Bytes, std::io::Error>>,
) {
    let mut fields = Vec::new();
    let failure = loop {
        let field = match mp.next_field().await {
            Ok(Some(field)) => field,
            Ok(None) => {
                let no_file = ApiError::BadParameter("multipart: no file part (name it \"file\")".into());
                break with_form(params, fields).err().unwrap_or(no_file);
            }
            Err(e) => break limits::multipart_error(e),
        };
        let name = field.name().unwrap_or("").to_string();
        if field.file_name().is_some() || name == "file" {
            let fname = field.file_name().map(str::to_string);
            let _ = ptx.send(with_form(params, fields).map(|p| (p, fname)));
            return stream_file(field, btx).await;
        }
        match limits::read_field(&name, field).await {
            Ok(v) => fields.push((name, v)),
            Err(e) => break e,
        }
    };
    let _ = ptx.send(Err(failure));
}

/// A multipart form's text fields over the query's (a field given in both: the form's), read by
/// the same definition as the query: an unknown field is refused, a value that is not its
/// field's kind is refused naming the field, an empty one is as none.
fn with_form(query: Settings, fields: Vec<(String, String)>) -> Result<Settings, ApiError> {
    let known = serde_json::to_value(Settings::default()).unwrap_or_default();
    let mut given = serde_json::to_value(&query).unwrap_or_default();
    for (name, value) in fields {
        if !known.as_object().is_some_and(|k| k.contains_key(&name)) {
            return Err(ApiError::BadParameter(format!("unknown form field {}", crate::text::quote(&name))));
        }
        if value.trim().is_empty() {
            if let Some(to) = given.as_object_mut() {
                to.insert(name, serde_json::Value::Null);
            }
            continue;
        }
        let one: Settings = serde_urlencoded::from_str(&serde_urlencoded::to_string([(&name, &value)]).unwrap_or_default())
            .map_err(|e| ApiError::BadParameter(format!("{name}: {e}")))?;
        if let (Some(to), Ok(serde_json::Value::Object(from))) = (given.as_object_mut(), serde_json::to_value(one)) {
            to.extend(from.into_iter().filter(|(k, _)| *k == name));
        }
    }
    serde_json::from_value(given).map_err(|e| ApiError::BadParameter(e.to_string()))
}

/// The file part's bytes into the body channel until the part ends, the upload breaks (the
/// error goes on to the engine) or the handler is gone.
async fn stream_file(mut field: Field<'_>, btx: mpsc::Sender<Result<Bytes, std::io::Error>>) {
    loop {
        match field.chunk().await {
            Ok(Some(b)) => {
                if btx.send(Ok(b)).await.is_err() {
                    return;
                }
            }
            Ok(None) => return,
            Err(e) => {
                let cut = limits::Cut::of_multipart(e);
                let _ = btx.send(Err(std::io::Error::other(cut))).await;
                return;
            }
        }
    }
}
