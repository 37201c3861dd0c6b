"""The client: one method per thing a CAM plug-in asks of kinepost."""

from __future__ import annotations

import os
import time
import uuid
from pathlib import Path
from typing import IO, Any, Callable, Dict, Iterator, List, Mapping, Optional, Sequence, Tuple, Union

import requests

from ._streams import RecordStream, TextStream
from ._types import Job, KinepostError, Pose, Program

#: CL data: its bytes, its text, a path to its file, or a binary file object (read as sent).
CL = Union[bytes, bytearray, memoryview, str, "os.PathLike[str]", IO[bytes]]
Timeout = Union[float, Tuple[float, float]]

_CHUNK = 64 * 1024
_NDJSON = "application/x-ndjson"


class Client:
    """A kinepost service at ``base_url`` (``http://host:8080``).

    ``token`` is sent as ``Authorization: Bearer`` (profile writes need the service's admin
    token). ``timeout`` bounds connecting and each wait for the next bytes, not a whole stream:
    a long program streams for as long as it keeps coming.
    """

    def __init__(self, base_url: str, token: Optional[str] = None, timeout: Timeout = 60.0):
        self.base_url = base_url.rstrip("/")
        self.timeout = timeout
        self._session = requests.Session()
        if token:
            self._session.headers["Authorization"] = f"Bearer {token}"

    def close(self) -> None:
        self._session.close()

    def __enter__(self) -> "Client":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- posting -------------------------------------------------------------------------------

    def post(self, cl: CL, machine: str, *, dialect: Optional[str] = None, mode: Optional[str] = None,
             filename: Optional[str] = None, **options: Any) -> Program:
        """The whole NC program as text, with its outcome (``program.outcome.ok``).

        ``options`` are ``POST /v1/post``'s other parameters: ``tool_length``, ``tool_table``
        (TOML text), ``work_offset`` (x, y, z), ``tolerance``, ``strict``, ``cycles``,
        ``planes``, ``program_number`` …; an unknown one is the server's 400.
        """
        stream = self.post_stream(cl, machine, dialect=dialect, mode=mode, filename=filename, **options)
        text = "".join(stream)
        return Program(text, stream.outcome)

    def post_stream(self, cl: CL, machine: str, *, dialect: Optional[str] = None, mode: Optional[str] = None,
                    filename: Optional[str] = None, **options: Any) -> TextStream:
        """The NC program in text chunks as they come; ``stream.outcome`` once read to the end.

        Errors found before output began are raised (:class:`KinepostError`, e.g. 404 for an
        unknown machine, 422 for strict mode); later ones end the stream and its outcome.
        """
        return TextStream(self._post("/v1/post", cl, machine, dialect, mode, filename, options, accept="text/plain"))

    def post_ndjson(self, cl: CL, machine: str, *, dialect: Optional[str] = None, mode: Optional[str] = None,
                    filename: Optional[str] = None, **options: Any) -> RecordStream:
        """The post as NDJSON records (header, blocks, diagnostics, summary) as they come."""
        return RecordStream(self._post("/v1/post", cl, machine, dialect, mode, filename, options, accept=_NDJSON))

    # -- jobs ----------------------------------------------------------------------------------

    def submit_job(self, cl: CL, machine: str, *, dialect: Optional[str] = None, mode: Optional[str] = None,
                   filename: Optional[str] = None, idempotency_key: Optional[str] = None,
                   **options: Any) -> Job:
        """Hands the CL over as a background job (accepted once it is on the server's disk).
        The same ``idempotency_key`` returns the same job, so a retried submit runs once."""
        headers = {"Idempotency-Key": idempotency_key} if idempotency_key else {}
        r = self._post("/v1/jobs", cl, machine, dialect, mode, filename, options, headers=headers)
        return Job.from_json(r.json())

    def job(self, job_id: str) -> Job:
        return Job.from_json(self._request("GET", f"/v1/jobs/{job_id}").json())

    def jobs(self, state: Optional[str] = None) -> List[Job]:
        """Every job the server keeps (newest first), optionally only those in ``state``."""
        out: List[Job] = []
        offset: Optional[int] = 0
        while offset is not None:
            params: Dict[str, Any] = {"limit": 500, "offset": offset}
            if state:
                params["state"] = state
            page = self._request("GET", "/v1/jobs", params=params).json()
            out.extend(Job.from_json(j) for j in page["jobs"])
            offset = page.get("next_offset")
        return out

    def wait(self, job: Union[str, Job], progress: Optional[Callable[[Job], None]] = None,
             poll: float = 0.5, timeout: Optional[float] = None) -> Job:
        """Polls until the job has finished and returns it; ``progress(job)`` is called on each
        poll (``job.progress.percent``, ``.blocks``). Raises ``TimeoutError`` after ``timeout``
        seconds. A finished job is not necessarily a good program: see ``job.outcome``."""
        job_id = job.id if isinstance(job, Job) else job
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            current = self.job(job_id)
            if progress is not None:
                progress(current)
            if current.finished:
                return current
            if deadline is not None and time.monotonic() + poll > deadline:
                raise TimeoutError(f"job {job_id} is still {current.state} after {timeout} s")
            time.sleep(poll)

    def job_nc(self, job_id: str, dest: Union[str, "os.PathLike[str]", IO[bytes]]) -> int:
        """Streams a succeeded job's NC program into ``dest`` (a path or a binary file) and
        returns its size. A path is written beside itself first and renamed when complete,
        so a broken download never leaves a program that looks whole."""
        r = self._request("GET", f"/v1/jobs/{job_id}/nc", stream=True)
        if hasattr(dest, "write"):
            return _copy(r, dest)  # type: ignore[arg-type]
        path = Path(dest)  # type: ignore[arg-type]
        part = path.with_name(path.name + ".part")
        try:
            with open(part, "wb") as f:
                n = _copy(r, f)
            os.replace(part, path)
        finally:
            if part.exists():
                part.unlink()
        return n

    def job_diagnostics(self, job_id: str) -> RecordStream:
        """A finished job's NDJSON: motion blocks, diagnostics, then the summary (or the error
        of a failed job), as records; ``stream.outcome`` once read."""
        return RecordStream(self._request("GET", f"/v1/jobs/{job_id}/diagnostics", stream=True))

    def delete_job(self, job_id: str) -> Optional[Job]:
        """Cancels a queued or running job (returned, ``cancelled``), or removes a finished
        one and its files (``None``)."""
        r = self._request("DELETE", f"/v1/jobs/{job_id}")
        return Job.from_json(r.json()) if r.status_code == 200 else None

    # -- machines ------------------------------------------------------------------------------

    def machines(self) -> List[Dict[str, Any]]:
        """Every machine profile: ``id``, ``name``, ``units``, ``controller``, ``kinematics``,
        axes and travel."""
        return self._request("GET", "/v1/machines").json()

    def machine(self, machine: str) -> str:
        """A profile's TOML, exactly as stored."""
        r = self._request("GET", f"/v1/machines/{machine}", headers={"Accept": "application/toml"})
        r.encoding = "utf-8"
        return r.text

    def put_machine(self, machine: str, toml: str) -> Dict[str, Any]:
        """Creates or replaces a profile (a new version); needs the service's admin token."""
        r = self._request("PUT", f"/v1/machines/{machine}", data=toml.encode("utf-8"),
                          headers={"Content-Type": "application/toml"})
        return r.json()

    def dialects(self) -> List[Dict[str, Any]]:
        """The NC dialects a post may name (``name``, ``title``, ``default_for`` …)."""
        return self._request("GET", "/v1/dialects").json()

    def fk(self, machine: str, joints: Mapping[str, float], *, tool_length: Optional[float] = None,
           work_offset: Optional[Sequence[float]] = None) -> Pose:
        """Forward kinematics: axis words (``X Y Z`` in profile units, rotaries in degrees) to
        the tool pose in the part frame."""
        body: Dict[str, Any] = {"joints": dict(joints)}
        _put(body, tool_length=tool_length, work_offset=_vec(work_offset))
        d = self._request("POST", f"/v1/machines/{machine}/fk", json=body).json()
        return Pose(tuple(d["tip"]), tuple(d["axis"]))  # type: ignore[arg-type]

    def ik(self, machine: str, pose: Union[Pose, Sequence[Sequence[float]]], *,
           tool_length: Optional[float] = None, work_offset: Optional[Sequence[float]] = None,
           units: Optional[str] = None) -> List[Dict[str, Any]]:
        """Every joint solution of a pose, in travel or not: axis words with ``branch``,
        ``within_limits`` and ``singular``. An unreachable orientation is a 422."""
        body = self._pose_body(pose, tool_length, work_offset, units)
        return self._request("POST", f"/v1/machines/{machine}/ik", json=body).json()["solutions"]

    def validate_pose(self, machine: str, pose: Union[Pose, Sequence[Sequence[float]]], *,
                      tool_length: Optional[float] = None, work_offset: Optional[Sequence[float]] = None,
                      units: Optional[str] = None) -> Dict[str, Any]:
        """Whether a pose can be reached, and within travel (``reachable``, ``within_limits``,
        ``reason``, ``miss_deg``)."""
        body = self._pose_body(pose, tool_length, work_offset, units)
        return self._request("POST", f"/v1/machines/{machine}/validate-pose", json=body).json()

    # -- the wire ------------------------------------------------------------------------------

    @staticmethod
    def _pose_body(pose: Union[Pose, Sequence[Sequence[float]]], tool_length: Optional[float],
                   work_offset: Optional[Sequence[float]], units: Optional[str]) -> Dict[str, Any]:
        p = Pose.of(pose)
        body: Dict[str, Any] = {"tip": list(p.tip), "axis": list(p.axis)}
        _put(body, tool_length=tool_length, work_offset=_vec(work_offset), units=units)
        return body

    def _post(self, path: str, cl: CL, machine: str, dialect: Optional[str], mode: Optional[str],
              filename: Optional[str], options: Dict[str, Any], accept: Optional[str] = None,
              headers: Optional[Dict[str, str]] = None) -> requests.Response:
        """The CL as the file part of a form whose fields come first (the server reads them
        before the file), streamed: a large file is never held in memory."""
        fields: Dict[str, Any] = {"machine": machine, "dialect": dialect, "mode": mode, **options}
        boundary = uuid.uuid4().hex
        name = filename or _name_of(cl)
        hdrs = {"Content-Type": f"multipart/form-data; boundary={boundary}", **(headers or {})}
        if accept:
            hdrs["Accept"] = accept
        body = _form(boundary, fields, name, _chunks(cl))
        return self._request("POST", path, data=body, headers=hdrs, stream=accept is not None)

    def _request(self, method: str, path: str, *, stream: bool = False, **kw: Any) -> requests.Response:
        try:
            r = self._session.request(method, self.base_url + path, timeout=self.timeout, stream=stream, **kw)
        except requests.RequestException as e:
            raise KinepostError(f"{method} {path}: {e}") from e
        if r.status_code >= 400:
            try:
                body = r.json()
            except ValueError:
                body = None
            r.close()
            detail = (body or {}).get("detail") or r.reason
            raise KinepostError(f"{method} {path}: {r.status_code} {detail}", r.status_code, body)
        return r


def _put(body: Dict[str, Any], **values: Any) -> None:
    body.update({k: v for k, v in values.items() if v is not None})


def _vec(v: Optional[Sequence[float]]) -> Optional[List[float]]:
    return None if v is None else [float(x) for x in v]


def _field(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (list, tuple)):
        return ",".join(str(x) for x in value)
    return str(value)


def _form(boundary: str, fields: Dict[str, Any], filename: str, data: Iterator[bytes]) -> Iterator[bytes]:
    for k, v in fields.items():
        if v is not None:
            yield (f'--{boundary}\r\nContent-Disposition: form-data; name="{k}"\r\n\r\n{_field(v)}\r\n').encode("utf-8")
    safe = filename.replace('"', "%22").replace("\r", " ").replace("\n", " ")
    yield (f'--{boundary}\r\nContent-Disposition: form-data; name="file"; filename="{safe}"\r\n'
           "Content-Type: application/octet-stream\r\n\r\n").encode("utf-8")
    yield from data
    yield f"\r\n--{boundary}--\r\n".encode("ascii")


def _name_of(cl: CL) -> str:
    if isinstance(cl, os.PathLike):
        return Path(cl).name
    name = getattr(cl, "name", None)
    return Path(name).name if isinstance(name, str) else "program.cl"


def _chunks(cl: CL) -> Iterator[bytes]:
    """The CL's bytes in pieces; a path is opened only when the upload starts."""
    if isinstance(cl, str):
        cl = cl.encode("utf-8")
    if isinstance(cl, (bytes, bytearray, memoryview)):
        view = memoryview(cl)
        return (bytes(view[i:i + _CHUNK]) for i in range(0, len(view), _CHUNK))
    if isinstance(cl, os.PathLike):
        return _read_path(cl)
    if hasattr(cl, "read"):
        return _read(cl)
    raise TypeError(f"cl: expected bytes, str, a path or a binary file, got {type(cl).__name__}")


def _read_path(path: "os.PathLike[str]") -> Iterator[bytes]:
    with open(path, "rb") as f:
        yield from _read(f)


def _read(f: IO[bytes]) -> Iterator[bytes]:
    while True:
        b = f.read(_CHUNK)
        if not b:
            return
        if not isinstance(b, (bytes, bytearray)):
            raise TypeError("cl: the file must be opened in binary mode ('rb')")
        yield bytes(b)


def _copy(r: requests.Response, out: IO[bytes]) -> int:
    n = 0
    try:
        for chunk in r.iter_content(chunk_size=_CHUNK):
            out.write(chunk)
            n += len(chunk)
    except requests.RequestException as e:
        raise KinepostError(f"the download broke off: {e}") from e
    finally:
        r.close()
    return n
