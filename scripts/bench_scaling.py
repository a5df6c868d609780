#!/usr/bin/env python3
"""bench_scaling.py - how mcpt scales with threads (`make bench-scaling`).

Three curves, at 1, 2, 4, ... threads up to the machine's CPUs (or --threads LIST), interleaved
over R rounds, medians reported:
  - render: each scene rendered on T threads; the whole process by wall clock (load, BVH build
    and write included, what a user waits for) and the render alone (mcpt's own "render S s
    wall" line); speedup = time on 1 thread / time on T;
  - control: T independent single-thread renders of the same scene run at once; their mean
    Msamples/s over that of one alone is what the hardware gives T busy cores (shared caches,
    memory, the clock lowering as more cores run).  A threaded render's efficiency
    (speedup / T) below the control's points at the renderer (scheduling, sharing); at the
    control's, at the machine;
  - build: bench/raybench MODEL --build-only, the median BVH build on T threads.
With --base-mcpt / --base-raybench, a baseline binary is timed in the same rounds and the
ratios current/baseline are printed.

usage: scripts/bench_scaling.py [--mcpt ./mcpt] [--raybench bench/raybench] [--base-mcpt B]
                                [--base-raybench B] [--threads 1,2,4] [--runs R]
                                [--models a.obj,torus:1M] [--no-render] [--no-build]
                                [--json OUT.json]
Python standard library only.
"""

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time

# scene, arguments: 256 pixels wide as in issue 13's thread-scaling figure
SCENES = [
    ("cornell-box", "scenes/cornell-box.txt", ["--width", "256", "--spp", "64"]),
    ("bunny", "scenes/bunny.txt", ["--width", "256", "--spp", "16"]),
]
MODELS = ["../shared/models/lucy-100k.obj", "../shared/models/sponza-dabrovic.obj", "torus:1M"]
SUMMARY = re.compile(r"render ([0-9.]+) s wall, [0-9.]+ s CPU, ([0-9.]+) Msamples/s")


def render(mcpt, scene, args, threads, out):
    """One render: (process wall s, render wall s, Msamples/s)."""
    cmd = [mcpt, scene] + args + ["--threads", str(threads), "--no-preview", "-o", out]
    t0 = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    m = SUMMARY.search(p.stdout + p.stderr)
    if p.returncode != 0 or not m:
        sys.exit("bench_scaling: %s failed (%d): %s" % (" ".join(cmd), p.returncode,
                                                        (p.stderr or p.stdout)[-400:]))
    return wall, float(m.group(1)), float(m.group(2))


def control(mcpt, scene, args, copies, tmp):
    """copies single-thread renders at once, of a quarter of the spp: their median Msamples/s."""
    args = list(args)
    if "--spp" in args:
        i = args.index("--spp") + 1
        args[i] = str(max(1, int(args[i]) // 4))
    procs = []
    for i in range(copies):
        cmd = [mcpt, scene] + args + ["--threads", "1", "--no-preview", "-o",
                                      os.path.join(tmp, "control%d.exr" % i)]
        procs.append(subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                      text=True))
    rates = []
    for p in procs:
        out, _ = p.communicate()
        m = SUMMARY.search(out)
        if p.returncode != 0 or not m:
            sys.exit("bench_scaling: control render failed: %s" % out[-400:])
        rates.append(float(m.group(2)))
    return statistics.median(rates)


def build(raybench, model, threads, build_runs):
    cmd = [raybench, model, "--build-only", "--threads", str(threads), "--build-runs",
           str(build_runs)]
    p = subprocess.run(cmd, capture_output=True, text=True)
    lines = [l for l in p.stdout.splitlines() if l.startswith("{")]
    if p.returncode != 0 or not lines:
        sys.exit("bench_scaling: %s failed: %s" % (" ".join(cmd), p.stderr[-400:]))
    return json.loads(lines[-1])


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--mcpt", default="./mcpt")
    ap.add_argument("--raybench", default="bench/raybench")
    ap.add_argument("--base-mcpt")
    ap.add_argument("--base-raybench")
    ap.add_argument("--threads", help="comma-separated thread counts (default 1, 2, 4, ... CPUs)")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--build-runs", type=int, default=3)
    ap.add_argument("--models", help="comma-separated OBJ files or torus:N (default %s)" %
                    ",".join(MODELS))
    ap.add_argument("--no-render", action="store_true")
    ap.add_argument("--no-build", action="store_true")
    ap.add_argument("--json")
    a = ap.parse_args()
    n_cpus = os.cpu_count() or 1
    if a.threads:
        threads = [int(t) for t in a.threads.split(",")]
    else:
        threads = []
        t = 1
        while t < n_cpus:
            threads.append(t)
            t *= 2
        threads.append(n_cpus)
    if 1 not in threads:
        threads.insert(0, 1)
    models = a.models.split(",") if a.models else MODELS
    bins = [("current", a.mcpt, a.raybench)]
    if a.base_mcpt or a.base_raybench:
        bins.append(("base", a.base_mcpt or a.mcpt, a.base_raybench or a.raybench))
    print("bench_scaling: %d CPUs, threads %s, %d rounds; load average %.2f" %
          (n_cpus, threads, a.runs, os.getloadavg()[0]), flush=True)
    results = {"cpus": n_cpus, "threads": threads, "render": [], "build": []}
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "out.exr")
        if not a.no_render:
            for name, scene, args in SCENES:  # warm the page cache
                render(a.mcpt, scene, args, n_cpus, out)
            times = {}
            ctl = {}
            for r in range(a.runs):
                for name, scene, args in SCENES:
                    for t in threads:
                        for tag, mcpt, _ in bins:
                            times.setdefault((name, t, tag), []).append(
                                render(mcpt, scene, args, t, out))
                        ctl.setdefault((name, t), []).append(
                            control(a.mcpt, scene, args, t, tmp))
                print("  render round %d done" % (r + 1), flush=True)
            print("\nrender (median of %d; speedup = 1 thread / T threads; control = T "
                  "independent 1-thread renders, per-render rate / one alone)" % a.runs)
            print("%-12s %3s %9s %9s %8s %8s %8s %8s" % ("scene", "T", "wall s", "render s",
                                                         "x wall", "x render", "eff", "control"))
            for name, scene, args in SCENES:
                w1 = statistics.median(x[0] for x in times[(name, 1, "current")])
                r1 = statistics.median(x[1] for x in times[(name, 1, "current")])
                c1 = statistics.median(ctl[(name, 1)])
                for t in threads:
                    xs = times[(name, t, "current")]
                    w = statistics.median(x[0] for x in xs)
                    rw = statistics.median(x[1] for x in xs)
                    c = statistics.median(ctl[(name, t)]) / c1
                    print("%-12s %3d %9.3f %9.3f %8.2f %8.2f %8.2f %8.2f" %
                          (name, t, w, rw, w1 / w, r1 / rw, r1 / rw / t, c))
                    row = {"scene": name, "args": args, "threads": t, "wall_s": w, "render_s": rw,
                           "speedup_wall": w1 / w, "speedup_render": r1 / rw,
                           "control_efficiency": c}
                    if len(bins) > 1:
                        ratios = [b[0] / c[0] for b, c in zip(times[(name, t, "base")], xs)]
                        row["wall_base_over_current"] = statistics.median(ratios)
                        print("%-12s %3s base/current wall %.3f" % ("", "", row[
                            "wall_base_over_current"]))
                    results["render"].append(row)
        if not a.no_build:
            ms = {}
            for r in range(a.runs):
                for m in models:
                    for t in threads:
                        for tag, _, raybench in bins:
                            ms.setdefault((m, t, tag), []).append(
                                build(raybench, m, t, a.build_runs))
                print("  build round %d done" % (r + 1), flush=True)
            print("\nBVH build (median of %d rounds, each the median of %d builds)" %
                  (a.runs, a.build_runs))
            print("%-40s %3s %9s %8s %9s %9s" % ("model", "T", "build ms", "speedup", "convert",
                                                  "peak MiB") +
                  ("  base/current" if len(bins) > 1 else ""))
            for m in models:
                b1 = statistics.median(d["build_ms"] for d in ms[(m, 1, "current")])
                for t in threads:
                    ds = ms[(m, t, "current")]
                    b = statistics.median(d["build_ms"] for d in ds)
                    row = {"model": m, "threads": t, "build_ms": b, "speedup": b1 / b,
                           "convert_ms": statistics.median(d["convert_ms"] for d in ds),
                           "peak_rss_mib": max(d["peak_rss_mib"] for d in ds),
                           "sah_cost": ds[0]["sah_cost"], "bytes_per_tri": ds[0]["bytes_per_tri"]}
                    extra = ""
                    if len(bins) > 1:
                        bs = ms[(m, t, "base")]
                        row["base_over_current"] = statistics.median(
                            x["build_ms"] / y["build_ms"] for x, y in zip(bs, ds))
                        row["base_peak_rss_mib"] = max(d["peak_rss_mib"] for d in bs)
                        extra = "  %.3f (base peak %.0f MiB)" % (row["base_over_current"],
                                                                 row["base_peak_rss_mib"])
                    print("%-40s %3d %9.1f %8.2f %9.1f %9.0f" %
                          (m[-40:], t, b, row["speedup"], row["convert_ms"],
                           row["peak_rss_mib"]) + extra)
                    results["build"].append(row)
    if a.json:
        with open(a.json, "w") as f:
            json.dump(results, f, indent=1)


if __name__ == "__main__":
    main()
