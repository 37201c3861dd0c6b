"""Responses read as they arrive: NC text and NDJSON records, each learning the run's outcome."""

from __future__ import annotations

import codecs
import json
import re
from typing import Any, Dict, Iterator, Optional

import requests

from ._types import KinepostError, Outcome

# The engine's closing comment, the program's last line before its end: `(KINEPOST: ERRORS 2,
# WARNINGS 1: NOT FIT TO RUN AS IS …)`, `; KINEPOST: ERRORS 0, WARNINGS 0` …
_CLOSING = re.compile(rb"KINEPOST: ERRORS (\d+), WARNINGS (\d+)")
# What a stream that fails after it began ends with instead: a comment `ERROR: …`.
_FAILED = re.compile(rb"^\s*(?:\d+\s*)?[(;]\s*ERROR: ([^)\r\n]*)", re.MULTILINE)


class _Stream:
    """One streamed response, closed when read to the end, on error, or by ``close()``."""

    def __init__(self, response: requests.Response):
        self._response = response
        self._outcome: Optional[Outcome] = None

    @property
    def outcome(self) -> Outcome:
        """How the run went; known once the stream has been read to its end."""
        if self._outcome is None:
            raise RuntimeError("the outcome is known once the stream has been read to its end")
        return self._outcome

    def close(self) -> None:
        self._response.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _chunks(self) -> Iterator[bytes]:
        try:
            yield from self._response.iter_content(chunk_size=None)
        except requests.RequestException as e:
            self._outcome = Outcome(complete=False, error=f"the stream broke off: {e}")
            raise KinepostError(f"the stream broke off: {e}") from e
        finally:
            self._response.close()


class TextStream(_Stream):
    """The NC program as text chunks, as the server sends them; iterate it once."""

    def __iter__(self) -> Iterator[str]:
        decoder = codecs.getincrementaldecoder("utf-8")(errors="replace")
        closing: Optional[re.Match] = None
        failed: Optional[bytes] = None
        partial = b""
        for chunk in self._chunks():
            # Whole lines only: a comment split between two chunks is read once it is whole.
            data = partial + chunk
            cut = data.rfind(b"\n") + 1
            lines, partial = data[:cut], data[cut:]
            for m in _CLOSING.finditer(lines):
                closing, failed = m, None
            for m in _FAILED.finditer(lines):
                failed = m.group(1)
            yield decoder.decode(chunk)
        tail = decoder.decode(b"", final=True)
        if tail:
            yield tail
        for m in _CLOSING.finditer(partial):
            closing, failed = m, None
        if closing is None or failed is not None:
            why = failed.decode("utf-8", "replace").strip() if failed else None
            self._outcome = Outcome(
                complete=False,
                error=why or "the program ended without kinepost's closing comment (cut short)",
            )
        else:
            self._outcome = Outcome(complete=True, errors=int(closing.group(1)), warnings=int(closing.group(2)))


class RecordStream(_Stream):
    """NDJSON records as dicts, each with its ``type``: ``header``, ``block`` (motion blocks
    carry ``n``, ``joints`` and their ``diagnostics``), ``diagnostic``, then ``summary`` — or
    ``error`` when the run failed. Iterate it once."""

    def __iter__(self) -> Iterator[Dict[str, Any]]:
        summary: Optional[Dict[str, Any]] = None
        error: Optional[Dict[str, Any]] = None
        partial = b""
        for chunk in self._chunks():
            *lines, partial = (partial + chunk).split(b"\n")
            for line in lines:
                if line.strip():
                    rec = json.loads(line)
                    if rec.get("type") == "summary":
                        summary = rec["summary"]
                    elif rec.get("type") == "error":
                        error = rec["error"]
                    yield rec
        if partial.strip():
            # A last line without its newline: the stream was cut inside a record.
            self._outcome = Outcome(complete=False, error="the stream ended inside a record (cut short)", summary=summary)
            return
        if error is not None or summary is None:
            detail = (error or {}).get("detail") or "the stream ended without its summary (cut short)"
            self._outcome = Outcome(complete=False, error=detail, summary=summary)
        else:
            self._outcome = Outcome(
                complete=True,
                errors=int(summary.get("errors", 0)),
                warnings=int(summary.get("warnings", 0)),
                summary=summary,
            )
