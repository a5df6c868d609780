#!/usr/bin/env python3
"""exr_average.py - average K independent renders into one reference EXR with its variance.

Pure Python (standard library only; reads with exr_mean.py).  For each pixel and channel c of
R, G, B:  mean = (1/K) sum_k x_k,  variance.c = s^2 / K  with s^2 = sum_k (x_k - mean)^2 / (K-1),
the unbiased variance of the mean over the K independent renders.  mcpt compare subtracts that
variance from a measured MSE (noise-corrected metrics, docs/convergence.md).  Writes an
uncompressed scanline float EXR ("OpenEXR File Layout", openexr.com).  Usage:
    python3 scripts/exr_average.py OUT.exr IN1.exr IN2.exr ...
"""

import os
import struct
import sys
from array import array

sys.dont_write_bytecode = True
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import exr_mean  # noqa: E402  (same folder)


def attr(name, typ, payload):
    return name.encode() + b"\0" + typ.encode() + b"\0" + struct.pack("<i", len(payload)) + payload


def write_exr(path, width, height, planes):
    names = sorted(planes)  # channels are stored in alphabetical order
    chlist = b"".join(n.encode() + b"\0" + struct.pack("<iB3xii", 2, 0, 1, 1) for n in names) + b"\0"
    box = struct.pack("<iiii", 0, 0, width - 1, height - 1)
    header = (struct.pack("<ii", 20000630, 2)
              + attr("channels", "chlist", chlist)
              + attr("compression", "compression", b"\0")
              + attr("dataWindow", "box2i", box)
              + attr("displayWindow", "box2i", box)
              + attr("lineOrder", "lineOrder", b"\0")
              + attr("pixelAspectRatio", "float", struct.pack("<f", 1.0))
              + attr("screenWindowCenter", "v2f", struct.pack("<ff", 0.0, 0.0))
              + attr("screenWindowWidth", "float", struct.pack("<f", 1.0))
              + b"\0")
    line_bytes = 4 * width * len(names)
    first = len(header) + 8 * height
    offsets = b"".join(struct.pack("<Q", first + y * (8 + line_bytes)) for y in range(height))
    tmp = path + ".tmp"
    with open(tmp, "wb") as f:
        f.write(header)
        f.write(offsets)
        for y in range(height):
            f.write(struct.pack("<ii", y, line_bytes))
            for n in names:
                f.write(planes[n][y * width:(y + 1) * width].tobytes())
    os.replace(tmp, path)


def main(argv):
    if len(argv) < 3:
        print(__doc__.strip().splitlines()[-1].strip(), file=sys.stderr)
        return 2
    out, inputs = argv[0], argv[1:]
    k = len(inputs)
    width = height = None
    sums = {c: None for c in "RGB"}
    sq = {c: None for c in "RGB"}
    for path in inputs:
        w, h, planes = exr_mean.read_exr(path)
        if width is None:
            width, height = w, h
            for c in "RGB":
                sums[c] = [0.0] * (w * h)
                sq[c] = [0.0] * (w * h)
        elif (w, h) != (width, height):
            print("exr_average: error: %s is %dx%d, expected %dx%d" % (path, w, h, width, height),
                  file=sys.stderr)
            return 2
        for c in "RGB":
            s, q, p = sums[c], sq[c], planes[c]
            for i in range(w * h):
                x = p[i]
                s[i] += x
                q[i] += x * x
    planes = {}
    for c in "RGB":
        mean = array("f", [v / k for v in sums[c]])
        var = array("f", [max(q - s * s / k, 0.0) / (k - 1) / k if k > 1 else 0.0
                          for s, q in zip(sums[c], sq[c])])
        planes[c] = mean
        planes["variance." + c] = var
    write_exr(out, width, height, planes)
    print("exr_average: wrote %s (%dx%d, mean of %d images)" % (out, width, height, k))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
