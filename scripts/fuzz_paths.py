#!/usr/bin/env python3
"""Fuzzes the engine with generated paths made hard: every shipped profile, joint, TCP and tilted
planes, fanuc, siemens and heidenhain. A program that kinepost wrote without an error diagnostic must
pass `kinepost verify` (every point, every segment, the joint-space motion) with its blocks on the
CL orientation (within what the summary owns up to as singular deviation), and, in fanuc, the
independent verifier in ../shared. Programs with errors (the CL asks for what the machine cannot
do) are counted, and fail only where a block misses its pose under the engine's own replay.
Seeded: the same seeds give the same paths. Exit 1 on any finding.

    python3 scripts/fuzz_paths.py --kinepost target/release/kinepost --shared ../shared --seeds 1 3

What it found first (all fixed, each with a test): a singular point reached by feed turned its free
rotary during the next cut; positioning came down at rapid onto a feed point; a block's chord
error peaked between the engine's samples; a singular point outside travel at its held angle was
told "near" its limit.
"""
import argparse, json, math, os, random, shutil, subprocess, sys, tempfile

KINDS = ['plain', 'shuffle', 'jitter', 'vertical_runs', 'rapids_tools', 'fixed_axis']


def run(cmd):
    return subprocess.run(cmd, capture_output=True, text=True)


def goto(p):
    return 'GOTO/' + ','.join(('%.6f' if k < 3 else '%.9f') % v for k, v in enumerate(p))


def unit(a):
    n = math.sqrt(sum(x * x for x in a))
    return [x / n for x in a]


def transform(kind, pts, rnd):
    """The generated path's points made hard in one way; GOTO lines and RAPID/LOADTL records."""
    body = []
    if kind == 'shuffle':  # long segments with large turns
        rnd.shuffle(pts)
        body = [goto(p) for p in pts]
    elif kind == 'jitter':  # microradians to degrees from vertical: singular for most tables
        for p in pts:
            s = rnd.choice([0, 1e-6, 1e-3, 0.02, 0.05])
            body.append(goto(p[:3] + unit([rnd.gauss(0, 1) * s, rnd.gauss(0, 1) * s, 1.0])))
    elif kind == 'vertical_runs':  # reach the singular direction by feed, leave it elsewhere
        for i, p in enumerate(pts):
            body.append(goto(p))
            if i and rnd.random() < 0.15:
                for k in range(rnd.randint(1, 4)):
                    body.append(goto([p[0], p[1], p[2] + 0.5 * (k + 1), 0, 0, 1]))
    elif kind == 'rapids_tools':  # rapids and tool changes anywhere (one length: the shared
        for p in pts:             # verifier takes one for the file)
            r = rnd.random()
            if r < 0.05:
                body.append('RAPID')
            elif r < 0.08:
                body.append('LOADTL/%d' % rnd.randint(1, 4))
            body.append(goto(p))
    elif kind == 'fixed_axis':  # 3+2: runs of one tool axis between rapids
        for i, p in enumerate(pts):
            if i % 10 == 0:
                axis = p[3:]
                if i:
                    body.append('RAPID')
            body.append(goto(p[:3] + axis))
    else:
        body = [goto(p) for p in pts]
    return body


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--kinepost', required=True)
    ap.add_argument('--shared', default='../shared')
    ap.add_argument('--machines', default=os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'machines'))
    ap.add_argument('--seeds', nargs=2, type=int, default=[1, 3], metavar=('FIRST', 'END'))
    ap.add_argument('--points', type=int, default=40)
    a = ap.parse_args()
    K = a.kinepost
    shared_verify = os.path.join(a.shared, 'tools/verifier/verify.py')
    machines = sorted(f[:-5] for f in os.listdir(a.machines) if f.endswith('.toml'))
    tmp = tempfile.mkdtemp(prefix='kinepost-fuzz-')
    cl_path, nc_path, nd_path = (os.path.join(tmp, n) for n in ('path.cls', 'out.nc', 'out.ndjson'))
    findings, programs, with_errors = [], 0, 0

    def keep(tag):
        """The CL of the last finding, if it is this program's, kept and named in it."""
        if findings and findings[-1].startswith(tag):
            path = os.path.join(tmp, f'finding-{len(findings)}.cls')
            shutil.copy(cl_path, path)
            findings[-1] += f' ({path})'
    for seed in range(*a.seeds):
        for m in machines:
            gen = run([K, 'generate', '--machine', m, '--points', str(a.points), '--seed', str(seed)]).stdout.splitlines()
            head = [l for l in gen if not l.startswith(('GOTO', 'FEDRAT', 'RAPID', 'END'))]
            pts = [[float(x) for x in l[5:].split(',')] for l in gen if l.startswith('GOTO/')]
            units_mm = 'UNITS/MM' in head
            for kind in KINDS:
                body = transform(kind, [p[:] for p in pts], random.Random(seed * 1000 + KINDS.index(kind)))
                first = next(i for i, l in enumerate(body) if l.startswith('GOTO'))
                feed = 'FEDRAT/%s' % ('500' if units_mm else '20')
                body = body[:first] + ['RAPID', body[first], feed] + body[first + 1:]
                with open(cl_path, 'w') as f:
                    f.write('\n'.join(head + body + ['END']) + '\n')
                for mode in ['joint', 'tcp', 'planes']:
                    if mode == 'planes' and kind != 'fixed_axis':
                        continue
                    for dialect in ['fanuc', 'siemens', 'heidenhain']:
                        tag = f'{m} {kind} seed={seed} {mode} {dialect}'
                        opts = ['--mode', 'joint', '--tilted-planes', '--canned-cycles'] if mode == 'planes' else ['--mode', mode]
                        r = run([K, 'post', '--machine', m, *opts, '--dialect', dialect, cl_path, '-o', nc_path,
                                 '--diagnostics', nd_path])
                        programs += 1
                        # 1: written with error diagnostics (counted below); 2: nothing written.
                        if r.returncode not in (0, 1):
                            findings.append(f'{tag}: post failed: {r.stderr.strip()[-300:]}')
                            continue
                        summary = next(json.loads(l)['summary'] for l in open(nd_path) if '"summary"' in l)
                        if summary['errors']:
                            with_errors += 1
                            # Whatever the CL asks, no block may miss its pose under the
                            # engine's own replay.
                            if summary['counts'].get('verify_deviation'):
                                findings.append(f'{tag}: {summary["counts"]["verify_deviation"]} blocks miss their pose')
                                keep(tag)
                            continue
                        v = run([K, 'verify', '--machine', m, '--mode', 'joint' if mode == 'planes' else mode,
                                 '--cl', cl_path, '--nc', nc_path])
                        try:
                            rep = json.loads(v.stdout)
                        except ValueError:
                            findings.append(f'{tag}: verify could not read it: {v.stderr.strip()[-300:]}')
                            continue
                        if not rep['ok']:
                            findings.append(f'{tag}: verify: matched {rep["matched"]}/{rep["cl_points"]}, '
                                            f'{rep["off_segment_blocks"]} off segment, {rep["nonlinear_blocks"]} nonlinear, '
                                            f'misses {rep["misses"][:2]}')
                        owned = summary['max_singular_deviation_deg'] + 0.01
                        if rep.get('max_axis_off_arc_deg', 0.0) > owned:
                            findings.append(f'{tag}: blocks {rep["max_axis_off_arc_deg"]:.4f}° off the CL arc, '
                                            f'summary owns {summary["max_singular_deviation_deg"]:.4f}°')
                        if dialect == 'fanuc' and mode != 'planes' and os.path.exists(shared_verify):
                            s = run([sys.executable, shared_verify, '--profile', os.path.join(a.machines, m + '.toml'),
                                     '--cl', cl_path, '--nc', nc_path, '--dialect', 'fanuc', '--mode', mode])
                            checks = json.loads(s.stdout).get('checks', {})
                            bad = {k: c['first'][:1] for k, c in checks.items() if not c.get('ok', True)}
                            if bad:
                                findings.append(f'{tag}: shared verifier: {bad}')
                        keep(tag)
    for f in findings:
        print('FINDING', f)
    print(f'{programs} programs, {with_errors} with error diagnostics (counted, not judged), {len(findings)} findings')
    sys.exit(1 if findings else 0)


if __name__ == '__main__':
    main()
