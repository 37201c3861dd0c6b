//! What the download routes share: a Range that applies only to what its If-Range names, and a
//! body made by a blocking reader (a job's diagnostics and line map, rebuilt as they stream).

use axum::body::Body;
use axum::extract::Request;
use axum::http::header;

/// A blocking reader as a body, a 64 KiB chunk at a time: each chunk is read on the blocking
/// pool when the client has taken the last one, the reader handed back and forth, so a client
/// that reads nothing holds no thread (hundreds of them once took every thread of the pool, and
/// no post could start) and a chunk of memory at most; a read error ends the body with an error
/// (never a silent cut).
pub(super) fn pumped(r: impl std::io::Read + Send + 'static) -> Body {
    Body::from_stream(futures_util::stream::unfold(Some(r), |r| async move {
        let mut r = r?;
        let read = tokio::task::spawn_blocking(move || {
            let mut buf = vec![0u8; 64 << 10];
            loop {
                match r.read(&mut buf) {
                    Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                    Ok(n) => {
                        buf.truncate(n);
                        return (r, Ok(buf));
                    }
                    Err(e) => return (r, Err(e)),
                }
            }
        })
        .await;
        match read {
            Ok((_, Ok(buf))) if buf.is_empty() => None,
            Ok((r, Ok(buf))) => Some((Ok(bytes::Bytes::from(buf)), Some(r))),
            Ok((_, Err(e))) => Some((Err(e), None)),
            Err(e) => Some((Err(std::io::Error::other(e)), None)),
        }
    }))
}

/// RFC 9110 §13.1.5: a Range sent with an If-Range that does not name this output (its strong
/// ETag, or the Last-Modified date served with it) is ignored, so that a client resuming a
/// download of something else gets the whole output (200), never a part spliced onto another.
pub(super) fn if_range(mut req: Request, etag: &str, modified: Option<std::time::SystemTime>) -> Request {
    let Some(v) = req.headers().get(header::IF_RANGE) else {
        return req;
    };
    let v = v.to_str().unwrap_or_default().trim();
    // A weak ETag (`W/"…"`) never matches: a range needs byte-for-byte identity.
    let same = if v.starts_with('"') {
        v == etag
    } else {
        modified.is_some_and(|m| v.parse::<httpdate::HttpDate>().ok() == Some(httpdate::HttpDate::from(m)))
    };
    if !same {
        req.headers_mut().remove(header::RANGE);
    }
    req
}
