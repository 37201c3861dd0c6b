#!/usr/bin/env python3
"""Second opinion on kinepost's kinematics: the shared verifier's kin.py (an independent
implementation of docs/machine-model.md) against `kinepost fk` and `kinepost ik`, on random joints
of every shipped profile.

    python3 scripts/crosscheck_kinematics.py --kinepost target/release/kinepost \
        --verifier ../shared/tools/verifier [--samples 25]
Exit 0 only if every FK agrees to 1e-9 and every IK solution reproduces its pose under kin.py.
"""
import argparse, glob, json, math, os, random, subprocess, sys


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('--kinepost', required=True)
    ap.add_argument('--verifier', required=True)
    ap.add_argument('--machines', default=os.path.join(os.path.dirname(__file__), '..', 'machines'))
    ap.add_argument('--samples', type=int, default=25)
    a = ap.parse_args()
    sys.path.insert(0, a.verifier)
    import kin  # noqa: E402

    rnd = random.Random(20261121)
    worst_fk = worst_ik = 0.0
    checked = failures = 0
    for path in sorted(glob.glob(os.path.join(a.machines, '*.toml'))):
        prof = kin.load_profile(path)
        mid = prof.id
        for _ in range(a.samples):
            joints = {}
            for n, (lo, hi) in prof.linears.items():
                joints[n] = rnd.uniform(lo, hi)
            for r in prof.rotaries:
                joints[r.name] = rnd.uniform(r.min, r.max) if r.bounded else rnd.uniform(-400, 400)
            L = prof.tool_length * rnd.uniform(0.5, 1.5)
            wo = [rnd.uniform(-50, 50) for _ in range(3)]
            words = [f'{k}={v!r}' for k, v in joints.items()]
            common = ['--machine', mid, '--tool-length', repr(L), '--work-offset', ','.join(map(repr, wo))]
            out = subprocess.run([a.kinepost, 'fk', *common, *words], capture_output=True, text=True)
            if out.returncode:
                print(f'{mid}: fk failed: {out.stderr}'); failures += 1; continue
            ours = json.loads(out.stdout)
            tip, ax = kin.fk(prof, joints, L, wo)
            e = max(max(abs(x - y) for x, y in zip(ours['tip'], tip)), max(abs(x - y) for x, y in zip(ours['axis'], ax)))
            worst_fk = max(worst_fk, e)
            if e > 1e-9 * (1 + max(map(abs, tip)) / 1000):
                print(f'{mid}: FK differs by {e} at {joints}'); failures += 1
            out = subprocess.run([a.kinepost, 'ik', *common, *map(repr, [*tip, *ax])], capture_output=True, text=True)
            if out.returncode:
                print(f'{mid}: ik failed: {out.stderr.strip()}'); failures += 1; continue
            sols = json.loads(out.stdout)['solutions']
            if not sols:
                print(f'{mid}: ik returned no solution for a pose FK reached'); failures += 1
            for s in sols:
                p, u = kin.fk(prof, s, L, wo)
                ep = kin.norm(kin.sub(p, tip))
                ea = kin.angle(u, ax)
                worst_ik = max(worst_ik, ep)
                if ep > 1e-8 * (1 + max(map(abs, tip)) / 1000) or ea > 1e-9:
                    print(f'{mid}: IK solution {s} misses by {ep} / {ea} rad; pose {tip} {ax} L={L} wo={wo}'); failures += 1
            checked += 1
    print(json.dumps(dict(poses=checked, failures=failures, worst_fk_diff=worst_fk, worst_ik_tip_err=worst_ik)))
    return 1 if failures or not checked else 0


if __name__ == '__main__':
    sys.exit(main())
