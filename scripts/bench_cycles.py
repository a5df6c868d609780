#!/usr/bin/env python3
"""bench_cycles.py - mcpt against Blender Cycles at equal error on the Cornell box (`make
bench-cycles`; only where Blender is installed, never a dependency of mcpt).

Both renderers draw scenes/cornell-box.txt at 256x256 on --threads threads (default 2), in the
same run, interleaved over R rounds (default 3):
  - Cycles (scripts/cycles_reference.py builds the scene from the OBJ/MTL, PMJ sampler) at
    CYCLES_SPP = 256 spp, seed 100 + round: its render time t_C (Blender's own timing of the
    render call, scene building and start-up left out) and its RMSE e_C;
  - mcpt (default Sobol' sampler) at MCPT_SPP = 128, 256, 512 and 1024 spp, seed round: the
    render time mcpt prints (loading, BVH build and writing left out) and RMSE; then again with
    the budget rule of adaptive sampling (`--adaptive --adaptive-rule budget`: the rays of the
    same spp, every pixel's count set by a discarded pilot; unbiased), unless --no-budget.
RMSE is sqrt of the noise-corrected MSE against REF (`mcpt compare`), a Cycles render of
16 x 1024 spp whose own variance is subtracted.  Equal error: per round, a least-squares line
log RMSE = a + b log t through mcpt's four points, solved for t* at RMSE = e_C; the ratio is
t* / t_C, its median over the rounds is the figure (goal <= 0.2), for each of mcpt's series.  On a loaded machine the
times scatter more than the errors, so a second figure fits log RMSE = a + b log spp instead
(the errors alone), solves it for spp* at e_C, and prices spp* at the round's seconds per spp
(the four renders' time over their spp): ratio spp* s/spp / t_C.  Also printed: the smallest
spp at which mcpt's RMSE is at most e_C, and the time it took.

The reference: REF (default bench/ref/cornell256-cycles16384.exr) is not in the repository
(1.5 MB).  When it is absent this script makes it: 16 Cycles renders of 1024 spp (seeds 1..16,
about 15 minutes on 2 cores), averaged by scripts/exr_average.py into the mean and the variance
of the mean.  Pass --ref to use an existing one.

usage: scripts/bench_cycles.py [--mcpt ./mcpt] [--blender blender] [--ref REF.exr]
                               [--runs R] [--threads T] [--no-budget] [--json OUT.json]
Python standard library only.
"""

import argparse
import json
import math
import os
import re
import statistics
import subprocess
import sys
import tempfile

SCENE = "scenes/cornell-box.txt"
OBJ = "scenes/models/CornellBox-Original.obj"
SIZE = 256
CYCLES_SPP = 256
MCPT_SPP = [128, 256, 512, 1024]
REF_DEFAULT = "bench/ref/cornell256-cycles16384.exr"
REF_SEEDS = 16
REF_SPP = 1024
HERE = os.path.dirname(os.path.abspath(__file__))
SUMMARY = re.compile(r"render ([0-9.]+) s(?: wall, [0-9.]+ s CPU)?, ([0-9.]+) Msamples/s")
CYCLES_SEED = re.compile(r"cycles_reference: seed (\d+): .*\(([0-9.]+) s\)")


def cycles(blender, spp, seeds, first_seed, threads, exr_dir):
    """Renders seeds with Cycles; returns [(path, render seconds)]."""
    out_json = os.path.join(exr_dir, "cycles.json")
    cmd = [blender, "-b", "--factory-startup", "--python",
           os.path.join(HERE, "cycles_reference.py"), "--", "--obj", OBJ, "--out", out_json,
           "--spp", str(spp), "--size", str(SIZE), "--seeds", str(seeds),
           "--first-seed", str(first_seed), "--threads", str(threads), "--exr-dir", exr_dir,
           "--no-checks"]
    p = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    if p.returncode != 0:
        sys.exit("bench_cycles: Blender failed:\n" + p.stdout[-3000:])
    runs = [(os.path.join(exr_dir, "seed%s.exr" % m.group(1)), float(m.group(2)))
            for m in CYCLES_SEED.finditer(p.stdout)]
    if len(runs) != seeds:
        sys.exit("bench_cycles: expected %d Cycles renders, got:\n%s" % (seeds, p.stdout[-3000:]))
    return runs


def make_ref(blender, ref, threads):
    print("bench_cycles: %s is absent; rendering it: %d Cycles renders of %d spp (about 15 "
          "minutes on 2 cores)" % (ref, REF_SEEDS, REF_SPP), flush=True)
    d = tempfile.mkdtemp(prefix="cycles-ref-")
    runs = cycles(blender, REF_SPP, REF_SEEDS, 1, threads, d)
    os.makedirs(os.path.dirname(ref) or ".", exist_ok=True)
    subprocess.run([sys.executable, os.path.join(HERE, "exr_average.py"), ref] +
                   [path for path, _ in runs], check=True)


def rmse(mcpt, image, ref):
    p = subprocess.run([mcpt, "compare", image, ref, "--json"], stdout=subprocess.PIPE,
                       stderr=subprocess.PIPE, text=True)
    if p.returncode != 0:
        sys.exit("bench_cycles: mcpt compare failed: " + p.stderr)
    mse = json.loads(p.stdout)["mse_corrected"]
    return math.sqrt(mse) if mse > 0 else float("nan")


BUDGET_ARGS = ["--adaptive", "--adaptive-rule", "budget"]


def mcpt_render(mcpt, spp, seed, threads, out, extra=()):
    cmd = [mcpt, SCENE, "--width", str(SIZE), "--height", str(SIZE), "--spp", str(spp),
           "--seed", str(seed), "--threads", str(threads), "-o", out] + list(extra)
    p = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    m = SUMMARY.search(p.stdout)
    if p.returncode != 0 or not m:
        sys.exit("bench_cycles: %s failed:\n%s" % (" ".join(cmd), p.stdout))
    return float(m.group(1))


def fit_time_at(points, target):
    """t at which the least-squares line log e = a + b log t through points (t, e) gives e =
    target, and the slope b."""
    xs = [math.log(t) for t, _ in points]
    ys = [math.log(e) for _, e in points]
    mx, my = statistics.mean(xs), statistics.mean(ys)
    b = sum((x - mx) * (y - my) for x, y in zip(xs, ys)) / sum((x - mx) ** 2 for x in xs)
    a = my - b * mx
    return math.exp((math.log(target) - a) / b), b


def equal_error(points, t_c, e_c):
    """One round's figures for mcpt's points (spp, seconds, RMSE) against Cycles' t_c, e_c."""
    t_star, slope = fit_time_at([(t, e) for _, t, e in points], e_c)
    spp_star, spp_slope = fit_time_at([(spp, e) for spp, _, e in points], e_c)
    per_spp = sum(t for _, t, _ in points) / sum(spp for spp, _, _ in points)
    first = next(((spp, t) for spp, t, e in points if e <= e_c), None)
    return {"cycles_s": t_c, "cycles_rmse": e_c, "mcpt": points, "slope": slope,
            "t_equal": t_star, "ratio": t_star / t_c, "spp_slope": spp_slope,
            "spp_equal": spp_star, "s_per_spp": per_spp, "ratio_by_spp": spp_star * per_spp / t_c,
            "first_spp_at_or_below": first[0] if first else None,
            "first_ratio": first[1] / t_c if first else None}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mcpt", default="./mcpt")
    ap.add_argument("--blender", default="blender")
    ap.add_argument("--ref", default=REF_DEFAULT)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--no-budget", action="store_true",
                    help="leave out the series with the adaptive budget rule")
    ap.add_argument("--json", help="write the figures here as JSON")
    args = ap.parse_args()
    if not os.path.exists(args.ref):
        make_ref(args.blender, args.ref, args.threads)
    tmp = tempfile.mkdtemp(prefix="bench-cycles-")
    load = os.getloadavg()[0]
    print("bench_cycles: %d rounds, %d threads, %dx%d, load average %.2f on %d CPUs; "
          "reference %s" % (args.runs, args.threads, SIZE, SIZE, load, os.cpu_count(), args.ref),
          flush=True)
    series = [("uniform", [])] + ([] if args.no_budget else [("budget", BUDGET_ARGS)])
    rounds = {name: [] for name, _ in series}
    for k in range(1, args.runs + 1):
        (c_path, t_c), = cycles(args.blender, CYCLES_SPP, 1, 100 + k, args.threads, tmp)
        e_c = rmse(args.mcpt, c_path, args.ref)
        for name, extra in series:
            points = []
            for spp in MCPT_SPP:
                out = os.path.join(tmp, "mcpt-%s-%d.exr" % (name, spp))
                t = mcpt_render(args.mcpt, spp, k, args.threads, out, extra)
                points.append((spp, t, rmse(args.mcpt, out, args.ref)))
            r = equal_error(points, t_c, e_c)
            rounds[name].append(r)
            print("round %d, mcpt %s: Cycles %d spp %.2f s RMSE %.3e; mcpt %s; fit slope %.3f: "
                  "equal error at %.2f s, ratio mcpt/Cycles %.3f; by spp: slope %.3f, equal "
                  "error at %.0f spp x %.4f s, ratio %.3f%s"
                  % (k, name, CYCLES_SPP, t_c, e_c,
                     ", ".join("%d spp %.2f s %.3e" % p for p in points), r["slope"],
                     r["t_equal"], r["ratio"], r["spp_slope"], r["spp_equal"], r["s_per_spp"],
                     r["ratio_by_spp"],
                     "; first spp at or below Cycles' RMSE: %d (%.3f)"
                     % (r["first_spp_at_or_below"], r["first_ratio"])
                     if r["first_ratio"] is not None else ""), flush=True)
    figures = {}
    for name, _ in series:
        rs = rounds[name]
        figures[name] = statistics.median(r["ratio"] for r in rs)
        print("bench_cycles: equal-error time ratio mcpt (%s)/Cycles = %.3f by the time fit, "
              "%.3f by the spp fit (medians of %d rounds; Cycles %d spp: %.2f s, RMSE %.3e)"
              % (name, figures[name], statistics.median(r["ratio_by_spp"] for r in rs), len(rs),
                 CYCLES_SPP, statistics.median(r["cycles_s"] for r in rs),
                 statistics.median(r["cycles_rmse"] for r in rs)))
    ratio = figures["uniform"]
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"load_avg": load, "ratio": ratio, "ratios": figures, "rounds": rounds}, f,
                      indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
