"""What the API answers, as plain typed values."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Dict, Optional, Sequence, Tuple

Vec3 = Tuple[float, float, float]

FINISHED = frozenset({"succeeded", "failed", "cancelled"})


class KinepostError(Exception):
    """Any failure talking to kinepost.

    ``status`` is the HTTP status and ``body`` the server's problem document (RFC 9457:
    ``type``, ``title``, ``status``, ``detail``, and ``line``/``column``/``code`` for a bad CL
    record, ``key`` for a bad profile). Both are ``None`` when no answer came (connection
    refused, cut off mid-stream).
    """

    def __init__(self, message: str, status: Optional[int] = None, body: Optional[Dict[str, Any]] = None):
        super().__init__(message)
        self.status = status
        self.body = body

    @property
    def code(self) -> Optional[str]:
        """The problem's short name: the engine's diagnostic code where it has one
        (``bad-record``'s ``code``), else the last part of its ``type`` (``unknown-machine``)."""
        if not self.body:
            return None
        if self.body.get("code"):
            return str(self.body["code"])
        kind = str(self.body.get("type", ""))
        return kind.rsplit("/", 1)[-1] or None


@dataclass(frozen=True)
class Outcome:
    """How a post went. A program is fit to run only when ``ok``: it was written to its end
    (``complete``) and the engine found no errors (limit violations, unreachable poses …; each
    is marked on its NC block too)."""

    complete: bool
    errors: int = 0
    warnings: int = 0
    #: Why the run stopped before the program's end (the server's words), if it did.
    error: Optional[str] = None
    #: The engine's summary (NDJSON streams and jobs; a text stream carries only the counts).
    summary: Optional[Dict[str, Any]] = None

    @property
    def ok(self) -> bool:
        return self.complete and self.errors == 0


class Program(str):
    """The NC text of a post, with its :class:`Outcome` (check ``program.outcome.ok``)."""

    outcome: Outcome

    def __new__(cls, text: str, outcome: Outcome) -> "Program":
        p = super().__new__(cls, text)
        p.outcome = outcome
        return p


@dataclass(frozen=True)
class Pose:
    """A tool pose in the part frame: the tip point and the tool axis (tip toward spindle)."""

    tip: Vec3
    axis: Vec3

    @staticmethod
    def of(p: "Pose | Sequence[Sequence[float]]") -> "Pose":
        if isinstance(p, Pose):
            return p
        tip, axis = p
        return Pose(tuple(tip), tuple(axis))  # type: ignore[arg-type]


@dataclass(frozen=True)
class JobProgress:
    input_bytes: int
    bytes_read: int
    #: NC motion blocks written so far.
    blocks: int
    #: Of the input read; 100 once succeeded.
    percent: float
    nc_bytes: Optional[int] = None


@dataclass(frozen=True)
class Job:
    """A background job as ``GET /v1/jobs/{id}`` shows it; every field is in ``raw``."""

    id: str
    #: ``queued``, ``running``, ``succeeded``, ``failed`` or ``cancelled``.
    state: str
    machine: str
    progress: JobProgress
    filename: Optional[str]
    settings: Dict[str, Any]
    summary: Optional[Dict[str, Any]]
    error: Optional[str]
    raw: Dict[str, Any] = field(repr=False, compare=False)

    @classmethod
    def from_json(cls, d: Dict[str, Any]) -> "Job":
        p = d["progress"]
        return cls(
            id=d["id"],
            state=d["state"],
            machine=d["machine"],
            progress=JobProgress(
                input_bytes=p["input_bytes"],
                bytes_read=p["bytes_read"],
                blocks=p["blocks"],
                percent=p["percent"],
                nc_bytes=p.get("nc_bytes"),
            ),
            filename=d.get("filename"),
            settings=d.get("settings") or {},
            summary=d.get("summary"),
            error=d.get("error"),
            raw=d,
        )

    @property
    def finished(self) -> bool:
        return self.state in FINISHED

    @property
    def outcome(self) -> Outcome:
        """Complete only when the job succeeded; its counts come from the summary."""
        s = self.summary or {}
        error = self.error
        if error is None and self.state != "succeeded":
            error = f"job is {self.state}"
        return Outcome(
            complete=self.state == "succeeded",
            errors=int(s.get("errors", 0)),
            warnings=int(s.get("warnings", 0)),
            error=error,
            summary=self.summary,
        )
