#!/usr/bin/env python3
"""seed_mse.py - per-sample error of one mcpt configuration, measured over several seeds.

Renders SCENE once per seed with the given mcpt options, compares each image with a reference
(`mcpt compare --json`, noise-corrected when the reference has variance channels) on the whole
image and on the pixels whose reference luminance is <= --max-lum ("off-lamp": the Cornell box
without the lamp seen directly), and prints, over the seeds:
  mse      mean of the per-seed corrected MSE, with the standard error of that mean
  offlamp  the same over the off-lamp pixels
  bias R/G/B  mean of the per-seed image-mean differences (image - reference), with SE
  cpu_s    median CPU seconds (user + sys) of a render, the rays per camera sample (from the
           summary line), and efficiency 1 / (MSE cpu_s), whole image and off-lamp
The per-seed figures go to OUT.csv when --csv is given.  Python standard library only.
docs/performance.md ("Per-sample error") uses it; example:

    python3 scripts/seed_mse.py scenes/cornell-box.txt /work/baseline/cornell256-cycles16384.exr \\
        --seeds 1-4 -- --width 256 --height 256 --spp 256 --threads 2

A reference that is itself a render (Cycles EXRs too) can be passed with --images instead of a
scene: each image is compared as it is (no rendering, cpu_s absent).
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


def parse_seeds(text):
    seeds = []
    for part in text.split(","):
        if "-" in part:
            lo, hi = part.split("-")
            seeds.extend(range(int(lo), int(hi) + 1))
        else:
            seeds.append(int(part))
    return seeds


def compare(mcpt, image, ref, max_lum):
    out = {}
    for key, extra in (("all", []), ("off", ["--max-ref-luminance", str(max_lum)])):
        done = subprocess.run([mcpt, "compare", image, ref, "--json"] + extra,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        if done.returncode != 0:
            sys.exit("seed_mse: compare failed: %s" % done.stderr.strip())
        out[key] = json.loads(done.stdout)
    return out


def render(mcpt, scene, seed, opts, path):
    """Renders one seed; returns the CPU seconds (user + sys) of the child."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    done = subprocess.run([mcpt, scene, "--seed", str(seed), "-o", path] + opts,
                          stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        sys.exit("seed_mse: render failed: %s" % done.stderr.strip())
    # the summary line: "... Msamples/s, Z Mrays/s; ..." gives the rays per camera sample
    m = re.search(r"([0-9.]+) Msamples/s, ([0-9.]+) Mrays/s", done.stdout)
    rays = float(m.group(2)) / float(m.group(1)) if m else float("nan")
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime), rays


def mean_se(values):
    m = statistics.fmean(values)
    se = statistics.stdev(values) / math.sqrt(len(values)) if len(values) > 1 else float("nan")
    return m, se


def main():
    argv = sys.argv[1:]
    opts = []
    if "--" in argv:
        k = argv.index("--")
        argv, opts = argv[:k], argv[k + 1:]
    ap = argparse.ArgumentParser(prog="seed_mse.py")
    ap.add_argument("scene", nargs="?", help="scene file (omit with --images)")
    ap.add_argument("reference", help="reference EXR (with variance.R/G/B: noise-corrected)")
    ap.add_argument("--seeds", default="1-4", help="e.g. 1-8 or 1,3,5 (default 1-4)")
    ap.add_argument("--max-lum", type=float, default=1.0,
                    help="off-lamp: reference luminance at most this (default 1)")
    ap.add_argument("--mcpt", default="./mcpt")
    ap.add_argument("--images", nargs="+", help="compare these EXRs instead of rendering")
    ap.add_argument("--keep", help="keep the renders in this folder (seedN.exr)")
    ap.add_argument("--csv", help="write the per-seed rows here")
    ap.add_argument("--label", default="", help="a name for the printed line")
    args = ap.parse_args(argv)

    rows = []
    tmp = args.keep or tempfile.mkdtemp(prefix="seed_mse_")
    os.makedirs(tmp, exist_ok=True)
    if args.images:
        for path in args.images:
            c = compare(args.mcpt, path, args.reference, args.max_lum)
            c["rays"] = float("nan")
            rows.append((path, None, c))
    else:
        if not args.scene:
            sys.exit("seed_mse: expected a scene or --images")
        for seed in parse_seeds(args.seeds):
            path = os.path.join(tmp, "seed%d.exr" % seed)
            cpu, rays = render(args.mcpt, args.scene, seed, opts, path)
            c = compare(args.mcpt, path, args.reference, args.max_lum)
            c["rays"] = rays
            rows.append((seed, cpu, c))
            if not args.keep:
                os.remove(path)
                png = path[:-4] + ".png"
                if os.path.exists(png):
                    os.remove(png)
            print("seed_mse: seed %s mse %.4g off-lamp %.4g cpu %.1f s"
                  % (seed, c["all"]["mse_corrected"], c["off"]["mse_corrected"], cpu),
                  file=sys.stderr, flush=True)
    if args.csv:
        with open(args.csv, "w") as f:
            f.write("seed,mse,mse_offlamp,bias_r,bias_g,bias_b,cpu_s\n")
            for seed, cpu, c in rows:
                f.write("%s,%.9g,%.9g,%.9g,%.9g,%.9g,%s\n" % (
                    seed, c["all"]["mse_corrected"], c["off"]["mse_corrected"],
                    *c["all"]["bias"], "" if cpu is None else "%.3f" % cpu))
    mse = mean_se([c["all"]["mse_corrected"] for _, _, c in rows])
    off = mean_se([c["off"]["mse_corrected"] for _, _, c in rows])
    bias = [mean_se([c["all"]["bias"][k] for _, _, c in rows]) for k in range(3)]
    cpus = [cpu for _, cpu, _ in rows if cpu is not None]
    line = "%s n=%d mse %.4g +- %.2g  offlamp %.4g +- %.2g  bias R %.2e +- %.1e G %.2e +- %.1e " \
           "B %.2e +- %.1e" % (args.label, len(rows), mse[0], mse[1], off[0], off[1],
                               bias[0][0], bias[0][1], bias[1][0], bias[1][1], bias[2][0],
                               bias[2][1])
    if cpus:
        cpu = statistics.median(cpus)
        rays = statistics.fmean(c["rays"] for _, _, c in rows)
        line += "  cpu_s %.2f  rays/sample %.3f  eff %.4g  eff_off %.4g" % (
            cpu, rays, 1.0 / (mse[0] * cpu), 1.0 / (off[0] * cpu))
    print(line, flush=True)


if __name__ == "__main__":
    main()
