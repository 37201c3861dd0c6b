"""examples/post_file.py, run as a plug-in author would run it."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from conftest import DATA

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "post_file.py"
PLANE = DATA / "nx_clsf_mech491_simple_mill_plane_mm.cls"


def run(server, *args):
    return subprocess.run([sys.executable, str(EXAMPLE), *map(str, args), "--url", server],
                          capture_output=True, text=True, timeout=60)


def test_a_good_program_is_written_and_exits_0(server, client, tmp_path):
    out = tmp_path / "plane.nc"
    r = run(server, PLANE, "spinner-u5-620", "-o", out)
    assert r.returncode == 0, r.stderr
    assert "errors 0, warnings 1" in r.stdout and "warning: CL line" in r.stdout
    strip = lambda t: [l for l in t.splitlines() if not l.startswith("(DATE ")]
    assert strip(out.read_text()) == strip(client.post(PLANE, "spinner-u5-620"))
    assert list(tmp_path.iterdir()) == [out]


def test_a_program_with_errors_exits_1(server, tmp_path):
    out = tmp_path / "plane.nc"
    r = run(server, PLANE, "dmu-nutating-45", "-o", out)
    assert r.returncode == 1
    assert "errors 35," in r.stdout and r.stdout.count("error: CL line") == 35
    assert "NOT FIT TO RUN" in r.stderr and "NOT FIT TO RUN AS IS" in out.read_text()


def test_an_unknown_machine_exits_2_without_a_file(server, tmp_path):
    out = tmp_path / "plane.nc"
    r = run(server, PLANE, "no-such-machine", "-o", out)
    assert r.returncode == 2 and "404" in r.stderr
    assert list(tmp_path.iterdir()) == []
