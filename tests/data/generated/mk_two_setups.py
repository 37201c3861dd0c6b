# Writes nx_two_setups.cls and nx_two_setups_first_mcs.cls from `kinepost generate --machine spinner-u5-620 --points 80 --seed 7`:
# python3 mk_two_setups.py gen.cls nx_two_setups.cls nx_two_setups_first_mcs.cls
# and nx_two_setups_moved.cls (the second MCS only moved): the same with a fourth argument, 0.
"""Two NX-style operations from one generated path: the second written in its own MCS (moved
100 mm along the first's X, turned 90° about its Z); and the same path in the first MCS."""
import math, re, sys
src = open(sys.argv[1]).read().splitlines()
def rz(deg):
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return [[c, -s, 0], [s, c, 0], [0, 0, 1]]
def mul(a, b): return [[sum(a[i][k]*b[k][j] for k in range(3)) for j in range(3)] for i in range(3)]
def mv(a, v): return [sum(a[i][k]*v[k] for k in range(3)) for i in range(3)]
def tr(a): return [[a[j][i] for j in range(3)] for i in range(3)]
R1, O1 = rz(30), [10.0, 20.0, 0.0]
TURN = float(sys.argv[4]) if len(sys.argv) > 4 else 90.0
R2 = mul(R1, rz(TURN)); O2 = [O1[i] + mv(R1, [100, 0, 0])[i] for i in range(3)]
def msys(o, r):
    x = [r[i][0] for i in range(3)]; y = [r[i][1] for i in range(3)]
    return "MSYS/" + ",".join(f"{v:.4f}" for v in o) + "," + ",".join(f"{v:.7f}" for v in x + y)
gotos = [i for i, l in enumerate(src) if l.startswith("GOTO/")]
half = gotos[len(gotos) // 2]
one, two = [], []
head = ["TOOL PATH/SETUP_ONE,TOOL,BALL_MILL", "TLDATA/MILL,10.0000,5.0000,100.0000,0.0000,0.0000"]
for i, l in enumerate(src):
    if l.startswith("PARTNO") or l.startswith("LOADTL"):
        one.append(l); two.append(l); continue
    if i == gotos[0]:
        one += head + [msys(O1, R1), "PAINT/PATH"]; two += head + [msys(O1, R1), "PAINT/PATH"]
    if i == half:
        for out in (one, two):
            out += ["END-OF-PATH", "TOOL PATH/SETUP_TWO,TOOL,BALL_MILL", "TLDATA/MILL,10.0000,5.0000,100.0000,0.0000,0.0000"]
        one.append(msys(O1, R1)); two.append(msys(O2, R2)); two.append("RAPID")
        one.append("RAPID")
    if l.startswith("FINI"):
        one.append("END-OF-PATH"); two.append("END-OF-PATH")
    if l.startswith("GOTO/") and i >= half:
        v = [float(x) for x in l[5:].split(",")]
        q = [O1[k] + mv(R1, v[:3])[k] for k in range(3)]
        p2 = mv(tr(R2), [q[k] - O2[k] for k in range(3)])
        a2 = mv(tr(R2), mv(R1, v[3:]))
        two.append("GOTO/" + ",".join(f"{x:.6f}" for x in p2) + "," + ",".join(f"{x:.9f}" for x in a2))
        one.append(l); continue
    one.append(l); two.append(l)
open(sys.argv[2], "w").write("\n".join(two) + "\n")
open(sys.argv[3], "w").write("\n".join(one) + "\n")
