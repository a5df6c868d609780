#!/usr/bin/env python3
"""Sweep mcpt's estimators on one scene and answer "which one should I use here?".

Renders SCENE once per combination of sampler x direct-lighting mode x max depth, each as one
progressive run with --curve (error at 1, 2, 4, ... spp against a reference, and time), collects
every CSV row into one table (OUT/sweep.csv), plots RMSE against render time for all of them in
one SVG (OUT/sweep.svg) and prints them ranked by efficiency 1 / (MSE x seconds) at the final spp.

Python standard library only.  Example (docs/convergence.md, "Sweeps"):

    python3 scripts/sweep.py scenes/cornell-box.txt --width 64 --height 64 --spp 256 \\
        --samplers independent,stratified,sobol --direct mis,light,bsdf --depths 2,inf \\
        --out sweep/

Without --reference, a reference is rendered first (--reference-spp, default 16384, independent
sampler, a seed no sweep run uses).  An axis whose flag this mcpt lacks (mcpt --help) is skipped
with a note.  Max depths below the reference's count their truncation bias as error: their
curves flatten where the bias dominates, which is part of the answer.
"""
import argparse
import csv
from html import escape
import itertools
import math
import os
import subprocess
import sys

COLOURS = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2",
           "#7f7f7f", "#bcbd22", "#17becf"]
DASHES = ["", "6,3", "2,3", "8,3,2,3"]
REFERENCE_SEED = "4000000037"  # far from the sweep's seeds, so reference and runs are independent


def run(cmd):
    print("+ " + " ".join(cmd), file=sys.stderr)
    done = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    if done.returncode != 0:
        sys.exit("sweep: %s failed (exit %d): %s" % (cmd[0], done.returncode,
                                                      done.stderr.strip()))
    return done.stdout


def mcpt_flags(mcpt):
    return run([mcpt, "--help"])


def svg_plot(path, series, title):
    """series: list of (label, [(seconds, rmse), ...]); log-log RMSE vs seconds."""
    pts = [(t, e) for _, s in series for (t, e) in s if t > 0 and e > 0]
    if not pts:
        return
    xlo, xhi = math.floor(math.log10(min(t for t, _ in pts))), math.ceil(
        math.log10(max(t for t, _ in pts)))
    ylo, yhi = math.floor(math.log10(min(e for _, e in pts))), math.ceil(
        math.log10(max(e for _, e in pts)))
    xhi, yhi = max(xhi, xlo + 1), max(yhi, ylo + 1)
    x0, x1, y0, y1 = 80, 620, 45, 445
    height = 500 + 18 * len(series)

    def px(t):
        return x0 + (math.log10(t) - xlo) / (xhi - xlo) * (x1 - x0)

    def py(e):
        return y1 - (math.log10(e) - ylo) / (yhi - ylo) * (y1 - y0)

    out = ['<?xml version="1.0" encoding="UTF-8"?>',
           '<svg xmlns="http://www.w3.org/2000/svg" width="700" height="%d" '
           'font-family="Helvetica, Arial, sans-serif">' % height,
           '<rect width="700" height="%d" fill="white"/>' % height,
           '<text x="350" y="24" text-anchor="middle" font-size="15">%s</text>' % escape(title),
           '<clipPath id="c"><rect x="%d" y="%d" width="%d" height="%d"/></clipPath>'
           % (x0, y0, x1 - x0, y1 - y0),
           '<rect x="%d" y="%d" width="%d" height="%d" fill="none" stroke="#333"/>'
           % (x0, y0, x1 - x0, y1 - y0)]
    for k in range(xlo, xhi + 1):
        x = px(10.0 ** k)
        out.append('<line x1="%.1f" y1="%d" x2="%.1f" y2="%d" stroke="#ccc"/>' % (x, y0, x, y1))
        out.append('<text x="%.1f" y="%d" text-anchor="middle" font-size="12">%g</text>'
                   % (x, y1 + 16, 10.0 ** k))
    for k in range(ylo, yhi + 1):
        y = py(10.0 ** k)
        out.append('<line x1="%d" y1="%.1f" x2="%d" y2="%.1f" stroke="#ccc"/>' % (x0, y, x1, y))
        out.append('<text x="%d" y="%.1f" text-anchor="end" font-size="12">10<tspan dy="-6" '
                   'font-size="9">%d</tspan></text>' % (x0 - 6, y + 4, k))
    out.append('<text x="%d" y="%d" text-anchor="middle" font-size="13">render seconds</text>'
               % ((x0 + x1) // 2, y1 + 36))
    out.append('<text x="%d" y="%d" text-anchor="middle" font-size="13" '
               'transform="rotate(-90 %d %d)">RMSE</text>' % (30, (y0 + y1) // 2, 30,
                                                             (y0 + y1) // 2))
    for i, (label, s) in enumerate(series):
        colour, dash = COLOURS[i % len(COLOURS)], DASHES[(i // len(COLOURS)) % len(DASHES)]
        dash_attr = ' stroke-dasharray="%s"' % dash if dash else ""
        pts = " ".join("%.1f,%.1f" % (px(t), py(e)) for t, e in s if t > 0 and e > 0)
        out.append('<polyline clip-path="url(#c)" fill="none" stroke="%s" stroke-width="1.8"%s '
                   'points="%s"/>' % (colour, dash_attr, pts))
        ly = y1 + 62 + 18 * i
        out.append('<line x1="%d" y1="%d" x2="%d" y2="%d" stroke="%s" stroke-width="1.8"%s/>'
                   % (x0, ly - 4, x0 + 24, ly - 4, colour, dash_attr))
        out.append('<text x="%d" y="%d" font-size="12">%s</text>' % (x0 + 30, ly, escape(label)))
    out.append("</svg>")
    with open(path + ".tmp", "w") as f:
        f.write("\n".join(out) + "\n")
    os.replace(path + ".tmp", path)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scene")
    ap.add_argument("--mcpt", default="./mcpt", help="the mcpt binary (default ./mcpt)")
    ap.add_argument("--out", default="sweep", help="output folder (default sweep/)")
    ap.add_argument("--spp", default="256", help="final spp of every run (default 256)")
    ap.add_argument("--width", help="film width override")
    ap.add_argument("--height", help="film height override")
    ap.add_argument("--seed", default="0", help="seed of every run (default 0)")
    ap.add_argument("--seeds", default="1", help="seeds per run, for error bars (default 1)")
    ap.add_argument("--reference", help="reference EXR (default: render one)")
    ap.add_argument("--reference-spp", default="16384",
                    help="spp of the reference rendered when none is given (default 16384)")
    ap.add_argument("--samplers", default="independent,stratified,sobol",
                    help="comma-separated --sampler values")
    ap.add_argument("--direct", default="mis,light,bsdf",
                    help="comma-separated --direct values (direct-lighting modes)")
    ap.add_argument("--depths", default="inf", help="comma-separated --max-depth values")
    ap.add_argument("--threads", help="render threads")
    a = ap.parse_args()

    os.makedirs(a.out, exist_ok=True)
    helptext = mcpt_flags(a.mcpt)
    common = [a.scene, "--spp", a.spp, "--quiet"]
    for flag, value in (("--width", a.width), ("--height", a.height), ("--threads", a.threads)):
        if value:
            common += [flag, value]

    axes = []  # (column, flag, values)
    for column, flag, values in (("sampler", "--sampler", a.samplers),
                                 ("direct", "--direct", a.direct),
                                 ("max_depth", "--max-depth", a.depths)):
        if flag not in helptext:
            print("sweep: note: this mcpt has no %s; that axis is skipped" % flag,
                  file=sys.stderr)
            continue
        axes.append((column, flag, [v for v in values.split(",") if v]))

    reference = a.reference
    if not reference:
        reference = os.path.join(a.out, "reference.exr")
        if not os.path.exists(reference):
            # independent samples: only then is the variance channel the reference's true
            # variance of the mean, which the noise correction subtracts
            indep = ["--sampler", "independent"] if "--sampler" in helptext else []
            run([a.mcpt] + common[:1] + ["--spp", a.reference_spp, "--seed", REFERENCE_SEED,
                                         "-o", reference, "--quiet"] + indep + common[4:])

    table = os.path.join(a.out, "sweep.csv")
    series, finals, header = [], [], None
    with open(table + ".tmp", "w", newline="") as f_table:
        writer = None
        for combo in itertools.product(*[values for _, _, values in axes]):
            name = "-".join("%s_%s" % (col, v) for (col, _, _), v in zip(axes, combo)) or "run"
            cmd = [a.mcpt] + common + ["--seed", a.seed, "--seeds", a.seeds,
                                       "--reference", reference,
                                       "--curve", os.path.join(a.out, name + ".csv"),
                                       "-o", os.path.join(a.out, name + ".exr")]
            for (_, flag, _), v in zip(axes, combo):
                cmd += [flag, v]
            run(cmd)
            with open(os.path.join(a.out, name + ".csv")) as f:
                rows = list(csv.DictReader(f))
            if writer is None:
                header = ["run"] + [col for col, _, _ in axes if col not in rows[0]] + \
                    list(rows[0].keys())
                writer = csv.DictWriter(f_table, fieldnames=header)
                writer.writeheader()
            for r in rows:
                r = dict(r, run=name)
                for (col, _, _), v in zip(axes, combo):
                    r.setdefault(col, v)
                writer.writerow(r)
            # mean over seeds per spp
            by_spp = {}
            for r in rows:
                by_spp.setdefault(int(r["spp"]), []).append(r)
            curve = []
            for spp in sorted(by_spp):
                rs = by_spp[spp]
                mse = sum(float(r["mse"]) for r in rs) / len(rs)
                sec = sum(float(r["seconds"]) for r in rs) / len(rs)
                curve.append((sec, math.sqrt(mse) if mse > 0 else float("nan"), mse, spp))
            series.append((name, [(t, e) for t, e, _, _ in curve]))
            t, e, mse, spp = curve[-1]
            finals.append((1.0 / (mse * t) if mse > 0 and t > 0 else 0.0, name, spp, t, mse))
    os.replace(table + ".tmp", table)

    svg_plot(os.path.join(a.out, "sweep.svg"), series,
             "%s: RMSE vs render time" % os.path.basename(a.scene))
    print("%-48s %8s %10s %12s %12s" % ("run (best first)", "spp", "seconds", "mse",
                                        "efficiency"))
    for eff, name, spp, t, mse in sorted(finals, reverse=True):
        print("%-48s %8d %10.3f %12.4g %12.4g" % (name, spp, t, mse, eff))
    print("wrote %s, %s" % (table, os.path.join(a.out, "sweep.svg")))


if __name__ == "__main__":
    main()
