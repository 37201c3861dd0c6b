#!/usr/bin/env python3
"""Post a CL file with kinepost: write the NC program, print the warnings, errors and summary,
and exit non-zero unless the program is fit to run. Copy it into a plug-in and adapt.

    python3 post_file.py part.cls haas-umc750 [-o part.nc] [--url http://127.0.0.1:8080]

Exit status: 0 fit to run, 1 the program has errors (written, each marked on its block),
2 no program (the server refused the CL, or the run stopped before its end).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import kinepost


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("cl", type=Path, help="the CL file (APT/CLSF)")
    ap.add_argument("machine", help="machine profile id (see GET /v1/machines)")
    ap.add_argument("-o", "--output", type=Path, help="the NC file (default: the CL's name with .nc)")
    ap.add_argument("--url", default=os.environ.get("KINEPOST_URL", "http://127.0.0.1:8080"))
    ap.add_argument("--dialect", help="NC dialect (default: the machine's controller)")
    ap.add_argument("--mode", choices=["joint", "tcp"])
    args = ap.parse_args()
    out = args.output or args.cl.with_suffix(".nc")
    part = out.with_name(out.name + ".part")

    # NDJSON carries every line of the program and each block's diagnostics in one pass.
    try:
        with kinepost.Client(args.url) as client, open(part, "w", encoding="utf-8") as nc:
            stream = client.post_ndjson(args.cl, args.machine, dialect=args.dialect, mode=args.mode)
            for rec in stream:
                if rec["type"] == "block":
                    nc.write(rec["nc"] + "\n")
                    diags = rec.get("diagnostics", [])
                elif rec["type"] == "diagnostic":
                    diags = [rec["diagnostic"]]
                else:
                    continue
                for d in diags:
                    if d["severity"] != "info":
                        print(f"{d['severity']}: CL line {d.get('line')}: {d['message']} [{d['code']}]")
    except kinepost.KinepostError as e:
        part.unlink(missing_ok=True)
        print(f"kinepost: {e}", file=sys.stderr)
        return 2

    outcome = stream.outcome
    if not outcome.complete:
        part.unlink()
        print(f"kinepost: no program: {outcome.error}", file=sys.stderr)
        return 2
    part.replace(out)
    s = outcome.summary or {}
    print(f"{out}: {s.get('blocks')} blocks, cycle time {s.get('cycle_time_s', 0) / 60:.1f} min, "
          f"max tip deviation {s.get('max_tip_deviation')} {s.get('units')}")
    print(f"errors {outcome.errors}, warnings {outcome.warnings}")
    if not outcome.ok:
        print("NOT FIT TO RUN: see the errors above (each is marked on its NC block)", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
