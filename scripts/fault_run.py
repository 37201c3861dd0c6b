#!/usr/bin/env python3
"""A bounded fault run like issue 56's, on loopback only: replicas of `kinepost serve` on a private
PostgreSQL and one shared spool, clients submitting jobs (with idempotency keys, retrying 503, 507
and 429 after their Retry-After), while replicas that have just claimed a job are killed with
SIGKILL and restarted, the database is restarted (a fast shutdown: 57P01 to every session), and
the spool (a tmpfs, as root) is filled to the last byte for a few seconds. Prints the counts:
accepted, succeeded, failed by cause, ran again, answers by status, NC identical to the CLI's,
spool files no job owns.

Everything it starts is its own and ends with it: a PostgreSQL server made with Debian's initdb in
a temporary directory on a free port (run as the `postgres` user when root), the replicas, the
tmpfs. Bounded by --seconds of faults, --jobs submissions and --settle seconds to let the queue
drain.

    cargo build && sudo scripts/fault_run.py --replicas 3 --seconds 90 --jobs 400
"""

import argparse
import collections
import glob
import json
import os
import random
import re
import shutil
import socket
import subprocess
import sys
import tempfile
import threading
import time
import urllib.error
import urllib.request

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
MACHINE = "dmg-dmc75v"


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def as_root():
    return os.geteuid() == 0


class Pg:
    """A PostgreSQL server of this run's own."""

    def __init__(self, tmp):
        bins = sorted(glob.glob("/usr/lib/postgresql/*/bin/pg_ctl"))
        if not bins:
            sys.exit("no /usr/lib/postgresql/*/bin/pg_ctl (apt-get install postgresql)")
        self.bin = os.path.dirname(bins[-1])
        self.dir = os.path.join(tmp, "pg")
        os.makedirs(self.dir)
        if as_root():
            shutil.chown(self.dir, "postgres")
        self.port = free_port()
        self.run("initdb", "-D", self.data(), "-U", "postgres", "--auth=trust", "-E", "UTF8")
        self.start()

    def data(self):
        return os.path.join(self.dir, "data")

    def run(self, cmd, *args):
        argv = [os.path.join(self.bin, cmd), *args]
        if as_root():
            argv = ["runuser", "-u", "postgres", "--", *argv]
        with open(os.path.join(self.dir, "commands.log"), "a") as log:
            subprocess.run(argv, stdout=log, stderr=log, check=True, timeout=120)

    def ctl(self, *args):
        self.run("pg_ctl", "-D", self.data(), "-w", "-t", "60", *args)

    def start(self):
        opts = f"-p {self.port} -k {self.dir} -c listen_addresses=127.0.0.1 -c max_connections=200"
        self.ctl("-o", opts, "-l", os.path.join(self.dir, "server.log"), "start")

    def restart(self):
        self.ctl("-m", "fast", "stop")
        self.start()

    def stop(self):
        try:
            self.ctl("-m", "immediate", "stop")
        except subprocess.SubprocessError:
            pass

    def url(self):
        return f"postgres://postgres@127.0.0.1:{self.port}/postgres"


class Replica:
    def __init__(self, binary, tmp, tag, url, spool, lease):
        self.binary, self.url, self.spool, self.lease = binary, url, spool, lease
        self.data = os.path.join(tmp, f"replica-{tag}")
        self.proc, self.base, self.node = None, None, None
        self.start()

    def start(self):
        self.proc = subprocess.Popen(
            [self.binary, "serve", "--bind", "127.0.0.1:0", "--data-dir", self.data, "--database-url", self.url,
             "--spool-dir", self.spool, "--workers", "1", "--job-lease-secs", str(self.lease),
             "--max-jobs-per-client", "0", "--max-queued", "100000"],
            stderr=subprocess.PIPE, text=True, env={**os.environ, "KINEPOST_MACHINES": os.path.join(ROOT, "machines")})
        deadline = time.time() + 120
        for line in self.proc.stderr:
            m = re.search(r"listening on (http://[^\s\"]+)", line)
            if m:
                self.base = m.group(1)
                break
            if time.time() > deadline:
                raise SystemExit("a replica did not start")
        if not self.base:
            raise SystemExit("a replica exited at start")
        threading.Thread(target=lambda p=self.proc: [None for _ in p.stderr], daemon=True).start()
        status, _, body = http("GET", self.base + "/readyz")
        self.node = body.decode().rsplit("node ", 1)[-1].strip() if status == 200 else None

    def kill9(self):
        self.proc.kill()
        self.proc.wait()

    def alive(self):
        return self.proc.poll() is None


def http(method, url, body=None, headers=None, timeout=60):
    req = urllib.request.Request(url, data=body, method=method, headers=headers or {})
    try:
        with urllib.request.urlopen(req, timeout=timeout) as r:
            return r.status, dict(r.headers), r.read()
    except urllib.error.HTTPError as e:
        return e.code, dict(e.headers), e.read()
    except (urllib.error.URLError, ConnectionError, TimeoutError, OSError):
        return 0, {}, b""


class Counts:
    def __init__(self):
        self.lock = threading.Lock()
        self.statuses = collections.Counter()
        self.five_hundreds = []
        self.accepted = {}
        self.submitted = 0
        self.while_full = collections.Counter()

    def saw(self, what, status, body=b""):
        with self.lock:
            self.statuses[status] += 1
            if FULL.is_set():
                self.while_full[f"{what} {status}"] += 1
            if status >= 500 and status not in (503, 507):
                self.five_hundreds.append(f"{what}: {status} {body[:300]!r}")


def submitter(replicas, inputs, counts, stop, budget, tag, pace):
    k = 0
    while not stop.is_set() and budget():
        started = time.time()
        key = f"run-{tag}-{k}"
        with counts.lock:
            counts.submitted += 1
        # One long job in five.
        name = random.choice([n for n in inputs if n.startswith("l")] if random.random() < 0.2 else [n for n in inputs if n.startswith("s")])
        for _ in range(120):
            r = random.choice(replicas)
            status, headers, body = http("POST", f"{r.base}/v1/jobs?machine={MACHINE}", inputs[name]["cl"],
                                         {"Idempotency-Key": key, "Content-Type": "text/plain"})
            counts.saw("POST /v1/jobs", status, body)
            if status == 202:
                with counts.lock:
                    counts.accepted[key] = (json.loads(body)["id"], name)
                break
            wait = float(headers.get("Retry-After", "1") or 1)
            time.sleep(min(wait, 2.0) * random.uniform(0.3, 1.0))
        k += 1
        for r in random.sample(replicas, 1):
            status, _, body = http("GET", f"{r.base}/v1/jobs?limit=5")
            counts.saw("GET /v1/jobs", status, body)
        time.sleep(max(0.0, pace - (time.time() - started)))


def running_nodes(replicas):
    for r in replicas:
        if r.alive():
            status, _, body = http("GET", f"{r.base}/v1/jobs?state=running&limit=100")
            if status == 200:
                return [j for j in json.loads(body)["jobs"] if j.get("node")]
    return []


FULL = threading.Event()


def fill(spool, seconds):
    FULL.set()
    path = os.path.join(spool, "..", "filler")
    chunk = b"\0" * (1 << 16)
    end = time.time() + seconds
    with open(path, "ab") as f:
        # At once: what is free taken in one call, then kept taken as runs free theirs.
        st = os.statvfs(spool)
        try:
            os.posix_fallocate(f.fileno(), 0, st.f_bavail * st.f_frsize)
        except OSError:
            pass
        while time.time() < end:
            try:
                f.write(chunk)
                f.flush()
            except OSError:
                time.sleep(0.05)
    os.remove(path)
    FULL.clear()


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--binary", default=os.path.join(ROOT, "target", "debug", "kinepost"))
    ap.add_argument("--replicas", type=int, default=3)
    ap.add_argument("--clients", type=int, default=4)
    ap.add_argument("--seconds", type=int, default=90, help="how long faults are made (at most 600)")
    ap.add_argument("--jobs", type=int, default=400, help="submissions at most (at most 5000)")
    ap.add_argument("--kill-every", type=float, default=8.0)
    ap.add_argument("--lease", type=float, default=3.0)
    ap.add_argument("--settle", type=int, default=300, help="seconds the queue may take to drain after")
    ap.add_argument("--spool-mb", type=int, default=1024)
    a = ap.parse_args()
    a.seconds, a.jobs = min(a.seconds, 600), min(a.jobs, 5000)
    tmp = tempfile.mkdtemp(prefix="kinepost-faultrun-")
    if as_root():
        os.chmod(tmp, 0o755)
    spool_fs = os.path.join(tmp, "spoolfs")
    os.makedirs(spool_fs)
    tmpfs = as_root() and subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={a.spool_mb}m", "tmpfs", spool_fs]).returncode == 0
    spool = os.path.join(spool_fs, "spool")
    os.makedirs(spool)
    pg, replicas = None, []
    try:
        # Inputs: short jobs and long ones, each posted once by the CLI for reference.
        inputs = {}
        for name, points, seed in [("s1", 1500, 1), ("s2", 2500, 2), ("s3", 4000, 3), ("l1", 20000, 11), ("l2", 30000, 12)]:
            cl = subprocess.run([a.binary, "generate", "--machines", os.path.join(ROOT, "machines"), "--machine", MACHINE,
                                 "--points", str(points), "--seed", str(seed)], capture_output=True, check=True).stdout
            path = os.path.join(tmp, f"{name}.cl")
            with open(path, "wb") as f:
                f.write(cl)
            nc = subprocess.run([a.binary, "post", "--machines", os.path.join(ROOT, "machines"), "--machine", MACHINE, path],
                                capture_output=True).stdout
            inputs[name] = {"cl": cl, "nc": nc}
        pg = Pg(tmp)
        for i in range(a.replicas):
            replicas.append(Replica(a.binary, tmp, i, pg.url(), spool, a.lease))
            time.sleep(0.5)
        counts, stop = Counts(), threading.Event()
        sent = [0]
        lock = threading.Lock()

        def budget():
            with lock:
                sent[0] += 1
                return sent[0] <= a.jobs

        pace = a.seconds * a.clients / a.jobs
        clients = [threading.Thread(target=submitter, args=(replicas, inputs, counts, stop, budget, t, pace)) for t in range(a.clients)]
        for c in clients:
            c.start()
        faults = collections.Counter()
        t0 = time.time()
        plan = {a.seconds * 0.25: "db", a.seconds * 0.4: "spool", a.seconds * 0.5: "db", a.seconds * 0.75: "db"}
        next_kill = a.kill_every
        while time.time() - t0 < a.seconds:
            now = time.time() - t0
            for at in sorted(plan):
                if now >= at:
                    what = plan.pop(at)
                    if what == "db":
                        pg.restart()
                        faults["database restarts"] += 1
                    elif what == "spool" and tmpfs:
                        threading.Thread(target=fill, args=(spool, 6), daemon=True).start()
                        faults["spool filled 6 s"] += 1
            if now >= next_kill:
                next_kill += a.kill_every
                # The replica that claimed a job last (the youngest start among running jobs).
                jobs = sorted(running_nodes(replicas), key=lambda j: j.get("started_ms") or 0)
                victim = next((r for j in reversed(jobs) for r in replicas if r.node == j["node"] and r.alive()), None)
                if victim:
                    victim.kill9()
                    faults["replicas killed"] += 1
                    time.sleep(0.5)
                    victim.start()
            time.sleep(0.2)
        stop.set()
        for c in clients:
            c.join()
        # Drain, then count.
        deadline = time.time() + a.settle
        states = {}
        while time.time() < deadline:
            states = {}
            for key, (jid, name) in list(counts.accepted.items()):
                status, _, body = http("GET", f"{replicas[0].base}/v1/jobs/{jid}")
                if status == 200:
                    states[key] = json.loads(body)
            if len(states) == len(counts.accepted) and all(j["state"] in ("succeeded", "failed", "cancelled") for j in states.values()):
                break
            time.sleep(2)
        by_state = collections.Counter(j["state"] for j in states.values())
        failed_by = collections.Counter(re.sub(r"[0-9a-f]{32}", "<id>", j.get("error") or "")[:160] for j in states.values() if j["state"] == "failed")
        causes = collections.Counter(re.sub(r"node-?[\w.-]*|[0-9a-f]{8,}", "<node>", j.get("last_cause") or "")[:120] for j in states.values() if j.get("last_cause"))
        same, differ = 0, 0

        def body(nc):
            # Without the lines naming the run, and the block numbers they shift.
            lines = nc.decode(errors="replace").splitlines()
            return [re.sub(r"^N?\d+ ", "", l) for l in lines if not any(w in l for w in ("DATE ", "JOB ", "SOURCE "))]

        for key, j in states.items():
            if j["state"] == "succeeded":
                status, _, nc = http("GET", f"{replicas[0].base}/v1/jobs/{j['id']}/nc")
                if status == 200 and body(nc) == body(inputs[counts.accepted[key][1]]["nc"]):
                    same += 1
                else:
                    differ += 1
        ids = set()
        offset = 0
        while True:
            status, _, b = http("GET", f"{replicas[0].base}/v1/jobs?limit=500&offset={offset}")
            page = json.loads(b) if status == 200 else {"jobs": []}
            ids.update(j["id"] for j in page["jobs"])
            if not page.get("next_offset"):
                break
            offset = page["next_offset"]
        unowned = [f for f in os.listdir(spool) if f.split(".")[0] not in ids]
        # An input renamed into place by a replica killed before its row committed: a replica
        # removes it once it is an hour old (another may be about to commit it).
        orphans = [f for f in unowned if not re.fullmatch(r"[0-9a-f]{32}\.cl", f)]
        inputs_without_row = [f for f in unowned if f not in orphans]
        report = {
            "replicas": a.replicas, "seconds": a.seconds, "faults": dict(faults), "tmpfs_spool": bool(tmpfs),
            "submitted": counts.submitted, "accepted": len(counts.accepted), "jobs_in_store": len(ids), "by_state": dict(by_state),
            "not_finished": len(counts.accepted) - sum(by_state[s] for s in ("succeeded", "failed", "cancelled")),
            "ran_again": sum(1 for j in states.values() if j.get("attempts", 0) > 1),
            "attempts": dict(collections.Counter(j.get("attempts") for j in states.values())),
            "last_causes": dict(causes), "failed_by_cause": dict(failed_by),
            "answers_by_status": {str(k): v for k, v in sorted(counts.statuses.items())},
            "answers_while_the_spool_was_full": dict(counts.while_full),
            "5xx_other_than_503_507": counts.five_hundreds[:20],
            "nc_identical_to_cli": same, "nc_different": differ, "orphan_spool_files": orphans[:20],
            "inputs_without_a_row_left_for_the_hourly_sweep": inputs_without_row[:20],
        }
        print(json.dumps(report, indent=2))
        return 0 if not counts.five_hundreds and not failed_by and not differ and not orphans else 1
    finally:
        for r in replicas:
            if r.proc and r.alive():
                r.kill9()
        if pg:
            pg.stop()
        if tmpfs:
            subprocess.run(["umount", "-l", spool_fs])
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
