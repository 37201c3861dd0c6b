"""A real kinepost server for the whole session: the binary from `KINEPOST_BIN` (default
../../target/release/kinepost from clients/python), on a free port, with a temporary data
directory that is removed afterwards."""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import tempfile
import time
from pathlib import Path

import pytest
import requests

import kinepost

HERE = Path(__file__).resolve().parent
REPO = HERE.parent.parent.parent
DATA = REPO / "tests" / "data"
ADMIN_TOKEN = "python-client-tests"


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="session")
def server():
    binary = Path(os.environ.get("KINEPOST_BIN", HERE.parent / "../../target/release/kinepost")).resolve()
    if not binary.is_file():
        pytest.fail(f"no kinepost binary at {binary}: build it (cargo build --release) or set KINEPOST_BIN")
    data_dir = tempfile.mkdtemp(prefix="kinepost-py-")
    url = f"http://127.0.0.1:{_free_port()}"
    # The server reads its settings from KINEPOST_* too: none of the caller's may leak in.
    env = {k: v for k, v in os.environ.items() if not k.startswith("KINEPOST_")}
    env["KINEPOST_ADMIN_TOKEN"] = ADMIN_TOKEN
    log = open(os.path.join(data_dir, "serve.log"), "wb")
    proc = subprocess.Popen(
        [str(binary), "serve", "--bind", url[len("http://"):], "--data-dir", data_dir,
         "--machines", str(REPO / "machines")],
        stdout=log, stderr=subprocess.STDOUT, env=env,
    )
    try:
        deadline = time.monotonic() + 20
        while True:
            if proc.poll() is not None:
                pytest.fail(f"kinepost exited with {proc.returncode}:\n{Path(log.name).read_text()}")
            try:
                if requests.get(f"{url}/readyz", timeout=1).status_code == 200:
                    break
            except requests.ConnectionError:
                pass
            if time.monotonic() > deadline:
                pytest.fail(f"kinepost not ready within 20 s:\n{Path(log.name).read_text()}")
            time.sleep(0.1)
        yield url
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        log.close()
        shutil.rmtree(data_dir, ignore_errors=True)


@pytest.fixture
def client(server):
    with kinepost.Client(server, token=ADMIN_TOKEN) as c:
        yield c
