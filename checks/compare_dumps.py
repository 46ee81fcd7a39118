#!/usr/bin/env python3
"""Compare two `--dump` files of examples/dimension_scene.rs number by number.

    python3 checks/compare_dumps.py BEFORE AFTER KINDS

BEFORE and AFTER are `--dump` files (one number a line, `# seed S filter N`
headers); KINDS is the `--dump-kinds` file of either run (one label a line,
`method:field`), which names every line. Both dumps must have the same
layout (same headers and counts): the same pairs, system tracks and
samples, which the decision digest already says.

Prints, per method and kind of number, the largest absolute difference and
the largest relative one |a − b| / max(|a|, |b|), and for the state and the
covariance the differences normalised by the before estimate's σ:
|Δx_i| / √P_ii and |ΔP_ij| / √(P_ii P_jj) (a covariance's off-diagonal
elements may be near zero, where a relative difference says little).
Exits with status 1 when the layouts differ.
"""

import math
import sys
from collections import defaultdict


def read(path):
    with open(path) as f:
        return [line.rstrip("\n") for line in f]


def group(field):
    if field in ("stat", "t", "alt"):
        return field
    if field[0] == "x":
        return "x position" if int(field[1]) % 2 == 0 else "x velocity"
    r, c = int(field[1]), int(field[2])
    kind = {0: "pos", 1: "vel"}
    if r % 2 == c % 2:
        return f"P {kind[r % 2]}-{kind[c % 2]}"
    return "P pos-vel"


def main():
    before, after, kinds = (read(p) for p in sys.argv[1:4])
    if not (len(before) == len(after) == len(kinds)):
        print(f"layouts differ: {len(before)} / {len(after)} / {len(kinds)} lines")
        sys.exit(1)
    stats = defaultdict(lambda: [0, 0, 0.0, 0.0, 0.0, 0.0])  # n, differing, abs, rel, norm, vector rel
    sample = {}  # field -> (before, after) of the current sample

    def flush(method):
        if not sample:
            return
        for kind, idx in (("x position", (0, 2, 4)), ("x velocity", (1, 3, 5))):
            a = [sample[f"x{i}"][0] for i in idx]
            b = [sample[f"x{i}"][1] for i in idx]
            na = math.sqrt(sum(v * v for v in a))
            if na > 0:
                st = stats[(method, kind)]
                d = math.sqrt(sum((u - v) ** 2 for u, v in zip(a, b)))
                st[5] = max(st[5], d / na)
        for field, (a, b) in sample.items():
            if field[0] == "x":
                i = int(field[1])
                s = math.sqrt(sample[f"p{i}{i}"][0])
            elif field[0] == "p":
                i, j = int(field[1]), int(field[2])
                s = math.sqrt(sample[f"p{i}{i}"][0] * sample[f"p{j}{j}"][0])
            else:
                continue
            st = stats[(method, group(field))]
            if s > 0:
                st[4] = max(st[4], abs(a - b) / s)
        sample.clear()

    method = None
    for lb, la, k in zip(before, after, kinds):
        if lb.startswith("#") or la.startswith("#") or k.startswith("#"):
            if not (lb == la and k.startswith("#")):
                print(f"headers differ: {lb!r} / {la!r} / {k!r}")
                sys.exit(1)
            flush(method)
            continue
        m, field = k.split(":")
        if field == "t":
            flush(method)
        method = m
        a, b = float(lb), float(la)
        st = stats[(m, group(field))]
        st[0] += 1
        if a != b and not (math.isnan(a) and math.isnan(b)):
            st[1] += 1
            d = abs(a - b)
            st[2] = max(st[2], d)
            scale = max(abs(a), abs(b))
            if scale > 0 and math.isfinite(d):
                st[3] = max(st[3], d / scale)
        if field[0] in "xp":
            sample[field] = (a, b)
    flush(method)
    head = ("method", "kind", "numbers", "differ", "max |Δ|", "max rel", "max Δ/σ", "vector rel")
    print("{:<10} {:<12} {:>9} {:>9} {:>10} {:>10} {:>10} {:>10}".format(*head))
    for (m, g), (n, nd, d, r, s, v) in sorted(stats.items()):
        norm = f"{s:10.2e}" if g.startswith(("x", "P")) else f"{'':>10}"
        vec = f"{v:10.2e}" if g.startswith("x") else f"{'':>10}"
        print(f"{m:<10} {g:<12} {n:>9} {nd:>9} {d:10.2e} {r:10.2e} {norm} {vec}")


if __name__ == "__main__":
    main()
