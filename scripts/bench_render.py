#!/usr/bin/env python3
"""bench_render.py - what a render costs and what it buys, per scene (`make bench-render`).

For each scene of SCENES at its reduced size and fixed spp, and for each mcpt binary given (the
current one and, with --base, a baseline built from another commit), interleaved over R rounds
after one warm-up each:
  - per-sample cost: Msamples/s and Mrays/s of the render on --threads threads (default 1), by
    the CPU time of the process (user + sys, which the load of a shared machine inflates less
    than wall time) less that of a 1-spp run of the same binary, so that loading, the BVH build
    and writing the image are left out;
  - error: the noise-corrected MSE against the stored reference bench/ref/SCENE.exr (`mcpt
    compare`; round k renders with seed k, so the MSE is a mean over seeds, +- its standard error);
  - efficiency = 1 / (MSE * render CPU seconds), the figure of merit of equal-time comparisons:
    the mean MSE over the seeds times the median seconds (a median of the per-round products
    would mix the seeds' MSE, which scatters by 15%, into the time: two binaries with the same
    pixels read efficiency x0.96 where their speed was x1.008);
  - the render's rays/s as a fraction of raybench's on the same scene's own rays: bench/raydump
    writes a 4-spp render's rays (camera and bounce rays; shadow rays) and bench/raybench traces
    them, once per round (single rays, thread CPU time); the fraction needs a scene of triangles
    only (raybench sees no analytic shape);
  - camera packets (trace.c, render_pixel) against single camera rays, end to end:
    bench/packetbench renders the scene both ways on one thread, interleaved over the same number
    of rounds, and prints the median time ratio single/packets (> 1: packets win) and whether
    the two films are the same to the bit (they must be).
Medians over the rounds; ratios current/baseline per round, then their median.

References: `--make-refs` renders bench/ref/SCENE.exr with --sampler independent at
REF_FACTOR (16) times the scene's spp, seed 1000003 (the commands are printed).

usage: scripts/bench_render.py [--mcpt ./mcpt] [--base OLD/mcpt] [--runs R] [--threads T]
                               [--scenes a,b] [--raybench bench/raybench] [--raydump bench/raydump]
                               [--packetbench bench/packetbench]
                               [--json OUT.json] [--make-refs]
Python standard library only.
"""

import argparse
import json
import os
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import time

# name, scene file, width, height, spp of the timed and measured render
SCENES = [
    ("cornell-box", "scenes/cornell-box.txt", 128, 128, 64),
    ("bunny", "scenes/bunny.txt", 128, 128, 32),
    ("glass-balls", "scenes/glass-balls.txt", 128, 72, 64),
]
REF_FACTOR = 16
REF_SEED = 1000003
REF_DIR = "bench/ref"
SUMMARY = re.compile(r"render ([0-9.]+) s(?: wall, [0-9.]+ s CPU)?, ([0-9.]+) Msamples/s, "
                     r"([0-9.]+) Mrays/s")


def run_timed(cmd):
    """Runs cmd; returns (CPU seconds of the child, wall seconds, stdout)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.monotonic()
    p = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    wall = time.monotonic() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if p.returncode != 0:
        sys.exit("bench_render: %s failed (%d): %s" % (" ".join(cmd), p.returncode, p.stderr))
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return cpu, wall, p.stdout + p.stderr


def render(binary, scene, w, h, spp, seed, threads, out):
    cmd = [binary, scene[1], "--width", str(w), "--height", str(h), "--spp", str(spp),
           "--seed", str(seed), "--threads", str(threads), "-o", out]
    cpu, wall, text = run_timed(cmd)
    m = SUMMARY.search(text)
    if not m:
        sys.exit("bench_render: no summary line from %s:\n%s" % (" ".join(cmd), text))
    msamples, mrays = float(m.group(2)), float(m.group(3))
    return cpu, wall, mrays / msamples  # rays per sample, to 3 digits of the printed rates


def compare(mcpt, image, ref):
    p = subprocess.run([mcpt, "compare", image, ref, "--json"], stdout=subprocess.PIPE,
                       stderr=subprocess.PIPE, text=True)
    if p.returncode != 0:
        sys.exit("bench_render: mcpt compare failed: %s" % p.stderr)
    return json.loads(p.stdout)["mse_corrected"]


def kernel_rate(raybench, prefix):
    """Single-ray Mrays/s of raybench on the dumped closest and shadow rays together."""
    p = subprocess.run([raybench, prefix + ".obj", prefix + "-closest.bin",
                        prefix + "-shadow.bin", "--runs", "3", "--threads", "1"],
                       stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    if p.returncode != 0:
        sys.exit("bench_render: raybench failed: %s" % p.stderr)
    n_rays = secs = 0.0
    for line in p.stdout.splitlines():
        if line.startswith("{") and '"mrays_1t"' in line:
            d = json.loads(line)
            n_rays += d["rays"]
            secs += d["rays"] / (d["mrays_1t"] * 1e6)
    return n_rays / secs / 1e6 if secs > 0 else float("nan")


PACKETS = re.compile(r"packets ([0-9.]+) ms .*single rays ([0-9.]+) ms .*single/packets "
                     r"x([0-9.]+); films (\w+)")


def packet_ratio(packetbench, scene, runs):
    """bench/packetbench on the scene: the median time ratio single rays / packets."""
    name, path, w, h, spp = scene
    p = subprocess.run([packetbench, path, "--width", str(w), "--height", str(h), "--spp",
                        str(spp), "--runs", str(runs)], stdout=subprocess.PIPE,
                       stderr=subprocess.PIPE, text=True)
    m = PACKETS.search(p.stdout)
    if not m:
        sys.exit("bench_render: packetbench failed (%d): %s%s" % (p.returncode, p.stdout,
                                                                  p.stderr))
    return {"packets_ms": float(m.group(1)), "single_ms": float(m.group(2)),
            "single_over_packets": float(m.group(3)), "identical": m.group(4) == "identical"}


def scene_has_only_triangles(path):
    with open(path) as f:
        return not any(re.match(r"\s*(sphere|quad|plane)\b", line) for line in f)


def make_refs(mcpt, scenes):
    os.makedirs(REF_DIR, exist_ok=True)
    for s in scenes:
        cmd = [mcpt, s[1], "--width", str(s[2]), "--height", str(s[3]),
               "--spp", str(REF_FACTOR * s[4]), "--sampler", "independent",
               "--seed", str(REF_SEED), "--quiet", "-o", os.path.join(REF_DIR, s[0] + ".exr")]
        print(" ".join(cmd), flush=True)
        subprocess.run(cmd, check=True)


def mean_se(xs):
    m = statistics.mean(xs)
    se = statistics.stdev(xs) / len(xs) ** 0.5 if len(xs) > 1 else float("nan")
    return m, se


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mcpt", default="./mcpt")
    ap.add_argument("--base", help="baseline mcpt binary, timed in the same rounds")
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--scenes", help="comma-separated subset of " +
                    ",".join(s[0] for s in SCENES))
    ap.add_argument("--raybench", default="bench/raybench")
    ap.add_argument("--raydump", default="bench/raydump")
    ap.add_argument("--packetbench", default="bench/packetbench")
    ap.add_argument("--json", help="write the figures here as JSON")
    ap.add_argument("--make-refs", action="store_true", help="(re)render bench/ref/*.exr")
    args = ap.parse_args()
    scenes = SCENES
    if args.scenes:
        want = args.scenes.split(",")
        scenes = [s for s in SCENES if s[0] in want]
    if args.make_refs:
        make_refs(args.mcpt, scenes)
        return 0
    bins = [("current", args.mcpt)] + ([("base", args.base)] if args.base else [])
    tmp = tempfile.mkdtemp(prefix="bench-render-")
    load = os.getloadavg()[0]
    print("bench_render: %d rounds, %d thread(s), load average %.2f on %d CPUs; %s"
          % (args.runs, args.threads, load, os.cpu_count(),
             ", ".join("%s = %s" % b for b in bins)), flush=True)
    results = {}
    for s in scenes:
        name, path, w, h, spp = s
        ref = os.path.join(REF_DIR, name + ".exr")
        has_ref = os.path.exists(ref)
        kernel_prefix = None
        if scene_has_only_triangles(path) and os.path.exists(args.raydump):
            kernel_prefix = os.path.join(tmp, name)
            subprocess.run([args.raydump, path, "--width", str(w), "--height", str(h),
                            "--spp", "4", "-o", kernel_prefix], check=True,
                           stdout=subprocess.DEVNULL)
        out = os.path.join(tmp, name + ".exr")
        fig = {label: {"cpu": [], "cpu1": [], "mse": [], "rays_per_sample": None}
               for label, _ in bins}
        kernel = []
        for label, b in bins:  # warm-up: caches, page cache, CPU frequency
            render(b, s, w, h, 1, 0, args.threads, out)
        for k in range(1, args.runs + 1):
            for label, b in bins:
                cpu1, _, _ = render(b, s, w, h, 1, k, args.threads, out)
                cpu, _, rps = render(b, s, w, h, spp, k, args.threads, out)
                fig[label]["cpu1"].append(cpu1)
                fig[label]["cpu"].append(cpu)
                fig[label]["rays_per_sample"] = rps
                if has_ref:
                    fig[label]["mse"].append(compare(args.mcpt, out, ref))
            if kernel_prefix:
                kernel.append(kernel_rate(args.raybench, kernel_prefix))
        n_samples = w * h * (spp - 1)
        res = {"width": w, "height": h, "spp": spp, "runs": args.runs, "threads": args.threads}
        for label, _ in bins:
            f = fig[label]
            secs = [max(c - c1, 1e-9) for c, c1 in zip(f["cpu"], f["cpu1"])]
            msps = [n_samples / t / 1e6 for t in secs]
            r = {"render_cpu_s": statistics.median(secs), "msamples_s": statistics.median(msps),
                 "rays_per_sample": f["rays_per_sample"],
                 "mrays_s": statistics.median(msps) * f["rays_per_sample"]}
            if f["mse"]:
                mse, mse_se = mean_se(f["mse"])
                t = statistics.median(secs)
                r.update(mse=mse, mse_se=mse_se,
                         efficiency=1.0 / (mse * t) if mse > 0 else float("nan"))
            if kernel:
                r["kernel_mrays_s"] = statistics.median(kernel)
                r["render_over_kernel"] = statistics.median(
                    [m * f["rays_per_sample"] / kr for m, kr in zip(msps, kernel)])
            r["_secs"] = secs
            res[label] = r
        if args.base:
            c, b = res["current"], res["base"]
            res["ratio"] = {"speed": statistics.median(
                [bs / cs for cs, bs in zip(c["_secs"], b["_secs"])])}
            if "mse" in c and "mse" in b:
                res["ratio"]["mse"] = c["mse"] / b["mse"]
                res["ratio"]["efficiency"] = c["efficiency"] / b["efficiency"]
        for label, _ in bins:
            del res[label]["_secs"]
        if os.path.exists(args.packetbench):
            res["packets"] = packet_ratio(args.packetbench, s, args.runs)
        results[name] = res
        print_scene(name, res, [label for label, _ in bins])
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"load_avg": load, "scenes": results}, f, indent=1)
    return 0


def print_scene(name, res, labels):
    print("%s, %dx%d, %d spp:" % (name, res["width"], res["height"], res["spp"]))
    print("  %-8s %11s %9s %8s %21s %11s %8s %8s"
          % ("binary", "Msamples/s", "Mrays/s", "rays/spl", "MSE +- SE", "efficiency",
             "kernel", "fraction"))
    for label in labels:
        r = res[label]
        mse = ("%.3e +- %.1e" % (r["mse"], r["mse_se"])) if "mse" in r else "(no ref)"
        eff = ("%.4g" % r["efficiency"]) if "efficiency" in r else "-"
        ker = ("%.2f" % r["kernel_mrays_s"]) if "kernel_mrays_s" in r else "-"
        frac = ("%.2f" % r["render_over_kernel"]) if "render_over_kernel" in r else "-"
        print("  %-8s %11.3f %9.3f %8.2f %21s %11s %8s %8s"
              % (label, r["msamples_s"], r["mrays_s"], r["rays_per_sample"], mse, eff, ker,
                 frac))
    if "ratio" in res:
        q = res["ratio"]
        print("  current/base: speed x%.3f%s" % (q["speed"], (", MSE x%.3f, efficiency x%.3f"
                                                           % (q["mse"], q["efficiency"]))
                                                          if "mse" in q else ""))
    if "packets" in res:
        q = res["packets"]
        print("  camera packets: %.1f ms, single rays %.1f ms (1 thread): single/packets x%.3f; "
              "films %s" % (q["packets_ms"], q["single_ms"], q["single_over_packets"],
                            "identical" if q["identical"] else "DIFFER"))
    sys.stdout.flush()


if __name__ == "__main__":
    sys.exit(main())
