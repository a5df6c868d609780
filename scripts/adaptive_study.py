#!/usr/bin/env python3
"""adaptive_study.py - adaptive sampling (pilot and stop rules) against uniform sampling at equal
total samples, over several seeds (docs/performance.md, "Adaptive sampling").

For each seed and rule, renders SCENE with --adaptive --adaptive-rule RULE --tolerance T, reads
the mean spp (and the pilot's samples a pixel) from the summary line, then renders the same
scene uniformly at that total (mean + pilot, rounded) with another seed, and compares both with
REF (`mcpt compare --json`, noise-corrected).  Prints per rule, over the seeds: the MSE and
relMSE of adaptive and uniform renders and their ratios (RMSE ratio = sqrt of the MSE ratio),
the image mean of adaptive minus uniform (mean over channels) with its standard error and its
z-score, and the median CPU seconds of each.  Python standard library only; example:

    python3 scripts/adaptive_study.py ./mcpt cg_ref.exr --tolerance 0.1 --seeds 1-6

with cg_ref.exr from
    ./mcpt scenes/cornell-glass.txt --width 64 --height 64 --spp 16384 --sampler independent \\
        --seed 4242 -o cg_ref.exr
"""
import argparse
import json
import math
import os
import re
import resource
import statistics
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from seed_mse import mean_se, parse_seeds  # noqa: E402  (the seeds and their statistics)


def run(cmd):
    """Runs cmd; returns its stdout and the CPU seconds (user + sys) it took."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    done = subprocess.run(cmd, capture_output=True, text=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode:
        sys.exit("adaptive_study: %s failed:\n%s" % (" ".join(cmd), done.stderr))
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return done.stdout, cpu


def compare(mcpt, image, ref):
    out, _ = run([mcpt, "compare", image, ref, "--json"])
    return json.loads(out)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("mcpt")
    ap.add_argument("reference")
    ap.add_argument("--scene", default="scenes/cornell-glass.txt")
    ap.add_argument("--size", type=int, default=64, help="width and height (default 64)")
    ap.add_argument("--tolerance", default="0.1")
    ap.add_argument("--max-spp", default="1024")
    ap.add_argument("--seeds", default="1-6")
    ap.add_argument("--threads", default="2")
    ap.add_argument("--rules", default="pilot,stop")
    args = ap.parse_args()
    size = ["--width", str(args.size), "--height", str(args.size), "--threads", args.threads,
            "--no-preview"]
    tmp = tempfile.mkdtemp(prefix="adaptive_study.")
    rules = args.rules.split(",")
    rows = {rule: [] for rule in rules}
    for seed in parse_seeds(args.seeds):
        for rule in rules:
            a_path = os.path.join(tmp, "adaptive.exr")
            out, cpu_a = run([args.mcpt, args.scene] + size +
                             ["--adaptive", "--adaptive-rule", rule, "--tolerance", args.tolerance,
                              "--max-spp", args.max_spp, "--seed", str(seed), "-o", a_path])
            spp = float(re.search(r"adaptive ([0-9.]+) spp", out).group(1))
            m = re.search(r"([0-9.]+) pilot samples a pixel", out)
            pilot = float(m.group(1)) if m else 0.0
            a = compare(args.mcpt, a_path, args.reference)
            n_uniform = int(round(spp + pilot))
            u_path = os.path.join(tmp, "uniform.exr")
            _, cpu_u = run([args.mcpt, args.scene] + size +
                           ["--spp", str(n_uniform), "--seed", str(seed + 1000), "-o", u_path])
            u = compare(args.mcpt, u_path, args.reference)
            rows[rule].append((spp, pilot, cpu_a, a, n_uniform, cpu_u, u))
            print("seed %d %s: %.1f spp + %.1f pilot, MSE %.3g relMSE %.3g | uniform %d spp, "
                  "MSE %.3g relMSE %.3g" % (seed, rule, spp, pilot, a["mse_corrected"],
                                            a["relmse_corrected"], n_uniform,
                                            u["mse_corrected"], u["relmse_corrected"]),
                  file=sys.stderr, flush=True)
    for rule in rules:
        r = rows[rule]
        mse_a = mean_se([x[3]["mse_corrected"] for x in r])
        mse_u = mean_se([x[6]["mse_corrected"] for x in r])
        rel_a = mean_se([x[3]["relmse_corrected"] for x in r])
        rel_u = mean_se([x[6]["relmse_corrected"] for x in r])
        # the image mean of adaptive minus uniform: the reference's own noise cancels
        diff = mean_se([statistics.fmean(x[3]["bias"]) - statistics.fmean(x[6]["bias"])
                        for x in r])
        print("T %s %s, %d seeds: %.1f spp + %.1f pilot; MSE %.3g +- %.2g vs uniform %.3g +- %.2g "
              "(RMSE ratio %.3f); relMSE %.3g vs %.3g (ratio %.3f); image mean minus uniform's "
              "%.3g +- %.2g (%.1f SE); CPU s %.2f vs %.2f"
              % (args.tolerance, rule, len(r), statistics.fmean(x[0] for x in r),
                 statistics.fmean(x[1] for x in r), mse_a[0], mse_a[1], mse_u[0], mse_u[1],
                 math.sqrt(mse_a[0] / mse_u[0]), rel_a[0], rel_u[0], rel_a[0] / rel_u[0], diff[0],
                 diff[1], diff[0] / diff[1] if diff[1] else float("nan"),
                 statistics.median(x[2] for x in r), statistics.median(x[5] for x in r)),
              flush=True)


if __name__ == "__main__":
    main()
