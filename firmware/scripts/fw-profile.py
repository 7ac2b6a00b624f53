#!/usr/bin/env python3
"""Per-tick instruction split from two insnprof histograms (see firmware/scripts/fw-profile.sh).

Usage: fw-profile.py N DIR   (DIR holds nm-0.txt, nm-N.txt, prof-0.txt, prof-N.txt)
       fw-profile.py --loop N DIR   (DIR holds nm-fil.txt and tickhist.txt of a firmware-in-the-loop
       session of N ticks: only the ticks' instructions, the fake chips excluded; see
       firmware/scripts/fil-profile.sh)
Instructions are attributed to the function whose code they are (self counts: an inlined
callee counts in its caller; a called soft-float routine counts as soft-float, not in the
caller)."""
import bisect, re, sys
from collections import defaultdict

LOOP = sys.argv[1] == "--loop"
if LOOP:
    sys.argv.pop(1)
N, D = int(sys.argv[1]), sys.argv[2]
GROUPS = [
    ("replay devices (QEMU only: the fake chips' SPI)", [r"^paragyro_firmware::replay", r"<paragyro_firmware::replay", r"paragyro_firmware\.\.replay", r"Frame::encode"]),
    ("drivers (ADS131M08 frames + CRC, ADXL355, AD9959)", [r"paragyro_firmware::drivers"]),
    ("app glue (App::tick, guard, DDS plan)", [r"paragyro_firmware::app", r"paragyro_firmware::run"]),
    ("RLS (core::rls)", [r"paragyro_core::rls"]),
    ("projections (core::harmonics)", [r"paragyro_core::harmonics"]),
    ("rows (core::rows)", [r"paragyro_core::rows"]),
    ("filters (core::lpf, core::svf)", [r"paragyro_core::lpf", r"paragyro_core::svf"]),
    ("estimator rest (step, monitor, scheduler, retune)", [r"paragyro_core::"]),
    ("soft-f64 (compiler_builtins float, __aeabi_d*)", [r"compiler_builtins::float", r"^__aeabi_(d|f2d|i2d|ui2d|l2d|ul2d)", r"__(add|sub|mul|div)df3", r"__(eq|ne|lt|le|gt|ge|un)df2"]),
    ("libm", [r"^libm::"]),
    ("memcpy/memset", [r"compiler_builtins::mem", r"^__aeabi_mem", r"^mem(cpy|set|move)"]),
    ("integer builtins", [r"compiler_builtins::int", r"^__aeabi_(u?l|u?i)div"]),
    ("fil shims' remainder and markers (loop only)", [r"paragyro_firmware::fil", r"paragyro_firmware\.\.fil"]),
    ("board main (the replay loop; in the loop: App::tick inlined)", [r"board::"]),
]

def group(name):
    for g, pats in GROUPS:
        if any(re.search(p, name) for p in pats):
            return g
    return "other"

def strip(name):
    return re.sub(r"::h[0-9a-f]{16}$", "", name)

def load(n, prof=None):
    syms = []
    for line in open(f"{D}/nm-{n}.txt"):
        p = line.split(None, 3)
        if len(p) == 4 and p[2] in "tTwW":
            start, size = int(p[0], 16) & ~1, int(p[1], 16)
            if size:
                syms.append((start, start + size, strip(p[3].strip())))
    syms.sort()
    starts = [s[0] for s in syms]
    counts = defaultdict(int)
    total = None
    for line in open(prof or f"{D}/prof-{n}.txt"):
        if line.startswith("#"):
            total = int(line.split()[2])
            continue
        a, c = line.split()
        a, c = int(a, 16), int(c)
        i = bisect.bisect_right(starts, a) - 1
        name = syms[i][2] if i >= 0 and a < syms[i][1] else "?"
        counts[name] += c
    return counts, total

if LOOP:
    c1, _ = load("fil", f"{D}/tickhist.txt")
    per = {k: v / N for k, v in c1.items() if v}
    tot = sum(per.values())
    print(f"instructions per tick in the loop (mean over {N} ticks, exact, fake chips excluded) = {tot:.0f}")
else:
    c0, t0 = load(0)
    c1, t1 = load(N)
    diff = {k: c1.get(k, 0) - c0.get(k, 0) for k in set(c0) | set(c1)}
    per = {k: v / N for k, v in diff.items() if v}
    tot = sum(per.values())
    print(f"instructions per tick (mean over {N} ticks, exact: {N}-tick run {t1} - set-up-only run {t0}) = {(t1 - t0) / N:.0f}")
by = defaultdict(float)
for k, v in per.items():
    by[group(k)] += v
print(f"\n{'group':55s} {'instr/tick':>10s} {'share':>6s}")
for g, v in sorted(by.items(), key=lambda x: -x[1]):
    print(f"{g:55s} {v:10.0f} {100 * v / tot:5.1f}%")
print(f"{'total':55s} {tot:10.0f}")
print("\ntop functions (self instructions per tick):")
for k, v in sorted(per.items(), key=lambda x: -x[1])[:25]:
    print(f"  {v:9.0f}  {k[:110]}")
