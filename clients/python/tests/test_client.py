"""Every client function against the real server, with the repository's CL files."""

from __future__ import annotations

import io
import re
import uuid

import pytest

import kinepost
from conftest import DATA

PLANE = DATA / "nx_clsf_mech491_simple_mill_plane_mm.cls"  # mm, 3-axis facing
BIG = DATA / "nx_clsf_mech491_project2_inch_5ax.cls"  # inch, 5-axis, ~400 KB of NC
# Its part stands on a 3 in riser: at z = 0 on the platter its flat tool runs into the table.
RISER = (0, 0, 3)
GOOD = "spinner-u5-620"
# The facing pass runs below this machine's Z travel: every block is a limit violation.
TOO_SHORT = "dmu-nutating-45"


def strip_preselect(lines: list) -> list:
    """The program without the blocks that only ready a tool in the magazine (`T2` alone)."""
    return [l for l in lines if not re.fullmatch(r"T\d+", l)]


def program_lines(nc: str) -> list:
    """The program without the lines that differ between two posts of the same CL (the time
    stamp, the uploaded file's name, a job's id)."""
    return [l for l in nc.splitlines() if not l.startswith(("(DATE ", "(SOURCE ", "(JOB "))]


def late_error_cl(points: int = 1500) -> str:
    """A CL whose only error (X far outside the travel) comes after more than the 16 KiB of NC
    the server holds back: with strict mode the run stops once the program has begun."""
    head = ["TOOL PATH/LATE_ERROR,TOOL,MILL", "TLDATA/MILL,30.0000,0.0000,75.0000,0.0000,0.0000",
            "LOAD/TOOL,1,ADJUST,1", "RAPID", "GOTO/0.0000,0.0000,110.0000,0.0000000,0.0000000,1.0000000",
            "FEDRAT/MMPM,1000.0000"]
    moves = [f"GOTO/{(-200.0 if i % 2 else 200.0):.4f},{-200.0 + i * 0.25:.4f},100.0000" for i in range(points)]
    tail = ["GOTO/900.0000,0.0000,100.0000", "GOTO/0.0000,0.0000,100.0000", "END-OF-PATH"]
    return "\n".join(head + moves + tail) + "\n"


# -- posting -------------------------------------------------------------------------------------


def test_post_returns_the_program_and_a_good_outcome(client):
    nc = client.post(PLANE, GOOD)
    assert isinstance(nc, str)
    lines = nc.splitlines()
    assert lines[0] == "%" and lines[-1] == "%" and "M30" in lines
    assert "(SOURCE NX_CLSF_MECH491_SIMPLE_MILL_PLANE_MM.CLS)" in lines
    assert nc.outcome.complete and nc.outcome.ok
    assert nc.outcome.errors == 0 and nc.outcome.warnings == 1


def test_post_takes_bytes_text_a_path_and_a_binary_file(client):
    want = program_lines(client.post(PLANE, GOOD))
    raw = PLANE.read_bytes()
    with open(PLANE, "rb") as f:
        sources = [raw, raw.decode("utf-8"), PLANE, f]
        for cl in sources:
            assert program_lines(client.post(cl, GOOD)) == want
    assert program_lines(client.post(io.BytesIO(raw), GOOD)) == want
    with pytest.raises(TypeError):
        client.post(12345, GOOD)


def test_post_options_reach_the_server(client):
    nc = client.post(PLANE, GOOD, dialect="siemens", program_number=4321, sequence_numbers=True,
                     tolerance=0.005, work_offset=(0, 0, 0))
    assert "; KINEPOST: ERRORS 0, WARNINGS 1" in nc
    assert any(l.startswith("N") for l in nc.splitlines())
    with pytest.raises(kinepost.KinepostError) as e:
        client.post(PLANE, GOOD, no_such_option=1)
    assert e.value.status == 400 and "no_such_option" in e.value.body["detail"]


def test_post_stream_yields_text_as_it_comes(client):
    stream = client.post_stream(BIG, "haas-umc750", work_offset=RISER)
    with pytest.raises(RuntimeError):
        stream.outcome  # not read yet: no outcome to trust
    chunks = list(stream)
    assert len(chunks) > 1 and all(isinstance(c, str) for c in chunks)
    text = "".join(chunks)
    assert text.startswith("%\n") and text.rstrip().endswith("%")
    assert stream.outcome.ok and stream.outcome.warnings == 1
    assert program_lines(text) == program_lines(client.post(BIG, "haas-umc750", work_offset=RISER))


def test_post_ndjson_yields_records_and_the_summary(client):
    with client.post_ndjson(PLANE, GOOD, mode="tcp") as stream:
        records = list(stream)
    header, summary = records[0], records[-1]
    assert header["type"] == "header" and header["machine"] == GOOD
    assert header["mode"] == "tcp" and header["dialect"] == "fanuc"
    assert summary["type"] == "summary" and stream.outcome.summary == summary["summary"]
    motion = [r for r in records if r["type"] == "block" and "n" in r]
    assert len(motion) == summary["summary"]["blocks"] > 0
    assert all(set(r["joints"]) == {"X", "Y", "Z", "B", "C"} for r in motion)
    assert stream.outcome.ok


# -- a program with errors, and errors ---------------------------------------------------------


def test_a_program_with_limit_errors_is_reported(client):
    nc = client.post(PLANE, TOO_SHORT)
    assert not nc.outcome.ok and nc.outcome.complete
    assert nc.outcome.errors == 35
    assert "ERROR LIMIT_VIOLATION" in nc and "NOT FIT TO RUN AS IS" in nc

    stream = client.post_ndjson(PLANE, TOO_SHORT)
    codes = [d["code"] for r in stream if r["type"] == "block" for d in r.get("diagnostics", [])
             if d["severity"] == "error"]
    assert codes and set(codes) == {"limit_violation"}
    assert stream.outcome.errors == len(codes) and not stream.outcome.ok


def test_a_run_that_stops_after_the_program_began_is_not_complete(client):
    cl = late_error_cl(1500)
    text = client.post_stream(cl, GOOD, strict=True)
    nc = "".join(text)
    assert len(nc) > 16 * 1024  # the HTTP status (200) had gone out before the error
    assert not text.outcome.complete and not text.outcome.ok
    assert "LIMIT_VIOLATION" in text.outcome.error and "LINE 1507" in text.outcome.error

    # NDJSON passes the 16 KiB after fewer blocks. (Kept short: a long response cut off by a
    # strict error can lose its end to a connection reset, which the client raises instead.)
    records = client.post_ndjson(late_error_cl(150), GOOD, strict=True)
    seen = list(records)
    assert sum(1 for r in seen if r["type"] == "block") > 150
    last = seen[-1]
    assert last["type"] == "error" and last["error"]["code"] == "limit_violation"
    assert not records.outcome.complete and records.outcome.error == last["error"]["detail"]

    # Without strict mode the same program runs to its end, its one error counted.
    whole = client.post(cl, GOOD)
    assert whole.outcome.complete and whole.outcome.errors == 1 and not whole.outcome.ok


def test_an_early_strict_error_is_raised_with_its_problem(client):
    with pytest.raises(kinepost.KinepostError) as e:
        client.post(PLANE, TOO_SHORT, strict=True)
    assert e.value.status == 422
    assert e.value.code == "limit_violation" and e.value.body["line"] > 0


def test_unknown_machine_is_a_404_with_the_problem_document(client):
    calls = [
        lambda: client.post(PLANE, "no-such-machine"),
        lambda: client.post_stream(BIG, "no-such-machine"),
        lambda: client.post_ndjson(PLANE, "no-such-machine"),
        lambda: client.submit_job(PLANE, "no-such-machine"),
        lambda: client.machine("no-such-machine"),
        lambda: client.fk("no-such-machine", {"X": 0}),
        lambda: client.ik("no-such-machine", ((0, 0, 0), (0, 0, 1))),
    ]
    for call in calls:
        with pytest.raises(kinepost.KinepostError) as e:
            call()
        assert e.value.status == 404
        assert e.value.body["status"] == 404 and "no-such-machine" in e.value.body["detail"]
    assert e.value.code == "unknown-machine"


def test_no_server_is_a_kinepost_error_without_status():
    with kinepost.Client("http://127.0.0.1:9", timeout=2) as c:
        with pytest.raises(kinepost.KinepostError) as e:
            c.machines()
    assert e.value.status is None and e.value.body is None


# -- jobs ----------------------------------------------------------------------------------------


def test_a_job_runs_with_progress_and_its_outputs_stream(client, tmp_path):
    job = client.submit_job(BIG, "haas-umc750", tolerance=0.001, work_offset=RISER)
    assert job.state in ("queued", "running", "succeeded") and job.filename == BIG.name
    assert job.settings["tolerance"] == 0.001
    seen = []
    done = client.wait(job, progress=seen.append, poll=0.05, timeout=60)
    assert done.state == "succeeded" and done.outcome.ok and done.outcome.complete
    assert seen and seen[-1].state == "succeeded" and seen[-1].progress.percent == 100
    percents = [j.progress.percent for j in seen]
    assert percents == sorted(percents)
    assert done.progress.blocks == done.summary["blocks"] > 0
    assert client.job(job.id).state == "succeeded"

    dest = tmp_path / "out.nc"
    size = client.job_nc(job.id, dest)
    assert size == dest.stat().st_size == done.progress.nc_bytes
    assert list(tmp_path.iterdir()) == [dest]  # nothing partial left beside it
    buf = io.BytesIO()
    assert client.job_nc(job.id, buf) == size and buf.getvalue() == dest.read_bytes()
    nc = dest.read_text()
    assert "(KINEPOST: ERRORS 0, WARNINGS" in nc
    # A job reads its spooled CL twice and readies the next tool right after each change
    # (preselect=next, the default); a stream reads its CL once and cannot: the two programs are
    # the same but for those lines.
    streamed = client.post(BIG, "haas-umc750", tolerance=0.001, work_offset=RISER)
    preselects = [l for l in program_lines(nc) if re.fullmatch(r"T\d+", l)]
    assert preselects, "no tool readied in the job's program"
    assert strip_preselect(program_lines(nc)) == strip_preselect(program_lines(streamed))

    diags = client.job_diagnostics(job.id)
    records = list(diags)
    assert records[-1] == {"type": "summary", "summary": done.summary}
    assert sum(1 for r in records if r["type"] == "block") == done.summary["blocks"]
    assert diags.outcome.ok and diags.outcome.summary == done.summary

    ids = [j.id for j in client.jobs()]
    assert job.id in ids
    assert job.id in [j.id for j in client.jobs(state="succeeded")]
    assert job.id not in [j.id for j in client.jobs(state="failed")]

    assert client.delete_job(job.id) is None
    with pytest.raises(kinepost.KinepostError) as e:
        client.job(job.id)
    assert e.value.status == 404


def test_a_job_with_errors_is_reported(client):
    job = client.wait(client.submit_job(PLANE, TOO_SHORT), poll=0.05, timeout=60)
    assert job.state == "succeeded"  # it ran to its end ...
    assert not job.outcome.ok and job.outcome.errors == 35  # ... but the program is not fit to run

    failed = client.wait(client.submit_job(PLANE, TOO_SHORT, strict=True), poll=0.05, timeout=60)
    assert failed.state == "failed" and not failed.outcome.complete
    assert "limit_violation" in failed.outcome.error
    with pytest.raises(kinepost.KinepostError) as e:
        client.job_nc(failed.id, io.BytesIO())
    assert e.value.status == 409
    diags = client.job_diagnostics(failed.id)
    assert list(diags)[-1]["type"] == "error" and not diags.outcome.complete
    assert failed.id in [j.id for j in client.jobs(state="failed")]


def test_a_job_submitted_twice_with_one_key_runs_once(client):
    key = uuid.uuid4().hex
    a = client.submit_job(PLANE, GOOD, idempotency_key=key)
    b = client.submit_job(PLANE, GOOD, idempotency_key=key)
    assert a.id == b.id and a.raw["idempotency_key"] == key
    client.wait(a, poll=0.05, timeout=60)
    assert client.delete_job(a.id) is None


# -- machines ------------------------------------------------------------------------------------


def test_machines_and_dialects(client):
    machines = {m["id"]: m for m in client.machines()}
    assert {GOOD, TOO_SHORT, "haas-umc750", "vmc-3axis"} <= set(machines)
    assert machines["haas-umc750"]["units"] == "inch" and machines[GOOD]["controller"] == "fanuc"
    toml = client.machine("vmc-3axis")
    assert 'id = "vmc-3axis"' in toml and "[[linear]]" in toml
    names = {d["name"] for d in client.dialects()}
    assert {"fanuc", "haas", "siemens", "heidenhain", "linuxcnc"} <= names


def test_fk_and_ik_agree(client):
    joints = {"X": 10.0, "Y": 20.0, "Z": 30.0, "B": 30.0, "C": 45.0}
    pose = client.fk(GOOD, joints, tool_length=100.0)
    assert abs(sum(a * a for a in pose.axis) - 1) < 1e-12
    solutions = client.ik(GOOD, pose, tool_length=100.0)
    assert any(all(abs(s[k] - v) < 1e-6 for k, v in joints.items()) for s in solutions)
    assert all(isinstance(s["within_limits"], bool) for s in solutions)
    reach = client.validate_pose(GOOD, (pose.tip, pose.axis), tool_length=100.0)
    assert reach["reachable"] and reach["within_limits"] and reach["solutions"] == len(solutions)
    # A 3-axis machine cannot tilt the tool.
    with pytest.raises(kinepost.KinepostError) as e:
        client.ik("vmc-3axis", kinepost.Pose((0, 0, 0), (0, 0.6, 0.8)))
    assert e.value.status == 422 and e.value.code == "unreachable"


def test_put_machine_needs_the_token(client, server):
    toml = client.machine("vmc-3axis").replace('id = "vmc-3axis"', 'id = "py-client-vmc"')
    with kinepost.Client(server) as anonymous:
        with pytest.raises(kinepost.KinepostError) as e:
            anonymous.put_machine("py-client-vmc", toml)
        assert e.value.status == 401
    written = client.put_machine("py-client-vmc", toml)
    assert written["id"] == "py-client-vmc" and written["source"] == "api"
    assert client.machine("py-client-vmc") == toml
    assert client.post(PLANE, "py-client-vmc").outcome.complete
