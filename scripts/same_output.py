#!/usr/bin/env python3
"""Posts every CL file in tests/data (and the shared corpus where it is beside the tree) and the
generated paths of every profile, joint and TCP, with a few option sets, and writes one SHA-256
per (input, machine, mode, options) for the NC and the NDJSON diagnostics, so that a refactor can
show its output unchanged byte for byte:

    scripts/same_output.py --kinepost OLD/kinepost --out /tmp/before.json
    scripts/same_output.py --kinepost NEW/kinepost --out /tmp/after.json --against /tmp/before.json

The clock is the only thing dropped: the NC header's DATE line, the NDJSON's time fields.
"""
import argparse
import concurrent.futures
import hashlib
import json
import os
import pathlib
import re
import shutil
import subprocess
import sys
import tempfile

ROOT = pathlib.Path(__file__).resolve().parent.parent
DATE = re.compile(rb"DATE \d{4}-\d\d-\d\d \d\d:\d\d( UTC)?")
CLOCK = re.compile(r'"(started|finished|elapsed_ms|elapsed_s|wall_ms|time_stamp|at)":[^,}]*')
OPTION_SETS = [
    [],
    ["--canned-cycles", "--tilted-planes"],
    ["--threads", "1", "--sequence-numbers", "--collisions", "off"],
]


def inputs(shared):
    files = sorted(p for p in (ROOT / "tests/data").glob("*") if p.suffix in {".cls", ".ncl", ".apt", ".aptsource", ".clt"})
    files += sorted((ROOT / "tests/data/generated").glob("*.cls"))
    corpus = pathlib.Path(shared) / "corpus"
    if corpus.is_dir():
        # Copies kept in tests/data are posted once (the results are keyed by file name).
        have = {p.name for p in files}
        files += sorted(p for p in corpus.glob("*") if p.is_file() and p.suffix != ".md" and p.name not in have)
    return files


def run(kinepost, machine, mode, opts, cl, tmp, keep=None):
    nc = tmp / "out.nc"
    diag = tmp / "out.ndjson"
    for f in (nc, diag):
        if f.exists():
            f.unlink()
    r = subprocess.run([kinepost, "post", "--machine", machine, "--mode", mode, *opts,
                        "--diagnostics", str(diag), "-o", str(nc), str(cl)],
                       capture_output=True, timeout=600)
    h = hashlib.sha256()
    h.update(b"rc=%d\n" % r.returncode)
    h.update(DATE.sub(b"DATE", nc.read_bytes()) if nc.exists() else b"<no nc>")
    d = hashlib.sha256()
    if diag.exists():
        d.update(CLOCK.sub("", diag.read_text()).encode())
    if keep is not None:
        keep.mkdir(parents=True, exist_ok=True)
        for f in (nc, diag):
            if f.exists():
                f.rename(keep / f.name)
    return h.hexdigest()[:16], d.hexdigest()[:16]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--kinepost", required=True)
    ap.add_argument("--shared", default=str(ROOT.parent / "shared"),
                    help="the shared folder whose corpus/ is posted too (default: ../shared)")
    ap.add_argument("--out", required=True)
    ap.add_argument("--against")
    ap.add_argument("--keep", help="a folder to keep every NC and NDJSON in, to diff two runs")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 2)
    a = ap.parse_args()
    kinepost = os.path.abspath(a.kinepost)
    if not (pathlib.Path(a.shared) / "corpus").is_dir():
        print(f"no corpus at {a.shared}/corpus: only tests/data is posted (--shared)", file=sys.stderr)
    machines = sorted(p.stem for p in (ROOT / "machines").glob("*.toml") if not p.name.endswith(".tools.toml"))
    work = pathlib.Path(tempfile.mkdtemp())
    cases = []
    for m in machines:
        gen = work / f"gen-{m}.cls"
        with open(gen, "wb") as f:
            subprocess.run([kinepost, "generate", "--machine", m, "--points", "3000", "--seed", "7"], stdout=f, check=True)
        for mode in ("joint", "tcp"):
            for i, opts in enumerate(OPTION_SETS):
                cases.append((m, mode, i, gen))
                for cl in inputs(a.shared):
                    cases.append((m, mode, i, cl))

    def one(case):
        m, mode, i, cl = case
        tmp = pathlib.Path(tempfile.mkdtemp(dir=work))
        key = f"{cl.name} {m} {mode} opts{i}"
        keep = pathlib.Path(a.keep) / key.replace(" ", "_") if a.keep else None
        return key, run(kinepost, m, mode, OPTION_SETS[i], cl, tmp, keep)

    with concurrent.futures.ThreadPoolExecutor(a.jobs) as ex:
        results = dict(ex.map(one, cases))
    shutil.rmtree(work, ignore_errors=True)
    pathlib.Path(a.out).write_text(json.dumps(results, indent=0, sort_keys=True))
    print(f"{len(results)} posts")
    if a.against:
        before = json.loads(pathlib.Path(a.against).read_text())
        diff = [k for k in sorted(before) if before[k] != list(results.get(k) or [])]
        for k in diff[:40]:
            print("DIFFERS:", k, before[k], results.get(k))
        print(f"{len(diff)} of {len(before)} differ")
        sys.exit(1 if diff else 0)


if __name__ == "__main__":
    main()
