#!/usr/bin/env python3
"""exr_mean.py - per-channel image mean of an OpenEXR file, with its standard error.

Pure Python (standard library only), so it runs under any python3 and under Blender's Python
(`blender -b --python scripts/exr_mean.py -- FILE.exr`).  Reads single-part scanline EXRs with
NONE, ZIPS or ZIP compression and HALF/FLOAT/UINT channels (what mcpt and Blender write); the
file layout follows the OpenEXR file-format document ("OpenEXR File Layout", openexr.com).

For each of R, G, B: mean = sum of pixels / N.  When the file carries mcpt's per-pixel
variance-of-the-mean planes (variance.R/G/B), the standard error of the image mean is
    SE = sqrt(sum over pixels of variance) / N
because the pixels are independent estimates.  The variance planes treat a pixel's samples as
independent; with mcpt's stratified (Sobol') sampler they over-estimate the error (about 2-3x on
the Cornell box), so for a sharp figure render several --seed values and use the spread.  Usage:
    python3 scripts/exr_mean.py IMAGE.exr... [--json]
    python3 scripts/exr_mean.py IMAGE.exr... --reference REF.json
The second form averages the images (independent seeds) and compares them with a reference such
as tests/data/reference/cornell-box-cycles.json.
"""

import json
import math
import struct
import sys
import zlib
from array import array
from itertools import accumulate

EXR_MAGIC = 20000630
COMPRESSION_NAMES = {0: "NONE", 1: "RLE", 2: "ZIPS", 3: "ZIP", 4: "PIZ", 5: "PXR24",
                     6: "B44", 7: "B44A", 8: "DWAA", 9: "DWAB"}
LINES_PER_CHUNK = {0: 1, 2: 1, 3: 16}
PIXEL_BYTES = {0: 4, 1: 2, 2: 4}  # UINT, HALF, FLOAT
PIXEL_CODE = {0: "I", 1: "e", 2: "f"}

# Byte table for the ZIP predictor: b -> (b - 128) mod 256.
_MINUS_128 = bytes((b - 128) & 0xFF for b in range(256))


def _read_cstr(data, pos):
    end = data.index(b"\0", pos)
    return data[pos:end].decode("latin-1"), end + 1


def _parse_header(data):
    magic, version = struct.unpack_from("<ii", data, 0)
    if magic != EXR_MAGIC:
        raise ValueError("expected the OpenEXR magic number, got %d" % magic)
    flags = version & ~0xFF
    if flags & 0x200:
        raise ValueError("expected a scanline image, got a tiled one")
    if flags & (0x800 | 0x1000):
        raise ValueError("expected a single-part, non-deep image")
    pos = 8
    attrs = {}
    while data[pos] != 0:
        name, pos = _read_cstr(data, pos)
        typ, pos = _read_cstr(data, pos)
        (size,) = struct.unpack_from("<i", data, pos)
        pos += 4
        attrs[name] = (typ, data[pos:pos + size])
        pos += size
    pos += 1  # the header's terminating null byte

    channels = []  # (name, pixel_type), in file (alphabetical) order
    raw = attrs["channels"][1]
    cpos = 0
    while raw[cpos] != 0:
        name, cpos = _read_cstr(raw, cpos)
        ptype, _plinear, xs, ys = struct.unpack_from("<iB3xii", raw, cpos)
        cpos += 16
        if xs != 1 or ys != 1:
            raise ValueError("expected full-resolution channels, got subsampled '%s'" % name)
        channels.append((name, ptype))
    compression = attrs["compression"][1][0]
    xmin, ymin, xmax, ymax = struct.unpack("<iiii", attrs["dataWindow"][1])
    return channels, compression, (xmin, ymin, xmax, ymax), pos


def _unzip(block, expected_bytes):
    """OpenEXR ZIP/ZIPS: zlib, then undo the byte predictor, then re-interleave the halves."""
    if len(block) == expected_bytes:
        return block  # stored uncompressed because compression did not help
    t = zlib.decompress(block)
    if len(t) != expected_bytes:
        raise ValueError("expected %d bytes in a chunk, got %d" % (expected_bytes, len(t)))
    # predictor: t[i] = t[i-1] + t[i] - 128, i.e. a running sum of (t[i] - 128) after t[0]
    d = bytearray(t.translate(_MINUS_128))
    d[0] = t[0]
    t = bytes(map((255).__and__, accumulate(d)))
    out = bytearray(expected_bytes)
    half = (expected_bytes + 1) // 2
    out[0::2] = t[:half]
    out[1::2] = t[half:]
    return bytes(out)


def read_exr(path):
    """Returns (width, height, {channel name: array of floats in row-major order})."""
    with open(path, "rb") as f:
        data = f.read()
    channels, compression, (xmin, ymin, xmax, ymax), pos = _parse_header(data)
    if compression not in LINES_PER_CHUNK:
        raise ValueError("expected NONE, ZIPS or ZIP compression, got %s"
                         % COMPRESSION_NAMES.get(compression, str(compression)))
    width, height = xmax - xmin + 1, ymax - ymin + 1
    lines = LINES_PER_CHUNK[compression]
    n_chunks = (height + lines - 1) // lines
    offsets = struct.unpack_from("<%dQ" % n_chunks, data, pos)
    planes = {name: array(PIXEL_CODE[pt] if pt != 1 else "f") for name, pt in channels}
    row_bytes = sum(PIXEL_BYTES[pt] for _, pt in channels) * width
    for off in offsets:
        y, size = struct.unpack_from("<ii", data, off)
        n_lines = min(lines, ymax - y + 1)
        block = _unzip(data[off + 8:off + 8 + size], n_lines * row_bytes) \
            if compression != 0 else data[off + 8:off + 8 + size]
        p = 0
        for _ in range(n_lines):
            for name, pt in channels:
                nb = PIXEL_BYTES[pt] * width
                seg = block[p:p + nb]
                p += nb
                if pt == 1:
                    planes[name].extend(struct.unpack("<%de" % width, seg))
                else:
                    a = array(PIXEL_CODE[pt])
                    a.frombytes(seg)
                    if sys.byteorder == "big":
                        a.byteswap()
                    planes[name].extend(a)
    return width, height, planes


def image_stats(path):
    """Per-channel mean of R, G, B and, if variance planes exist, the SE of that mean."""
    width, height, planes = read_exr(path)
    n = width * height
    out = {"file": path, "width": width, "height": height, "mean": [], "se": None}
    has_var = all("variance." + c in planes for c in "RGB")
    if has_var:
        out["se"] = []
    for c in "RGB":
        if c not in planes:
            raise ValueError("expected a channel named %s, got %s" % (c, sorted(planes)))
        out["mean"].append(math.fsum(planes[c]) / n)
        if has_var:
            out["se"].append(math.sqrt(math.fsum(planes["variance." + c])) / n)
    if "samples" in planes:
        out["samples_mean"] = math.fsum(planes["samples"]) / n
    return out


def compare(paths, ref_path):
    """Averages the images (independent renders, e.g. different --seed) and compares the
    per-channel mean with a reference JSON {"mean": [r,g,b], "se": [r,g,b]} such as
    tests/data/reference/cornell-box-cycles.json.  Two standard errors of the images' mean:
    se_var from the variance planes, sqrt(sum_k sum_px var) / (N K), which assumes independent
    samples inside a pixel (an over-estimate for stratified samplers), and, with K >= 2 images,
    se_seeds = std(image means) / sqrt(K).  z = difference / sqrt(se_img^2 + se_ref^2), using
    se_seeds when there is one."""
    with open(ref_path) as f:
        ref = json.load(f)
    stats = [image_stats(p) for p in paths]
    k = len(stats)
    out = {"images": paths, "reference": ref_path, "channels": []}
    for i, c in enumerate("RGB"):
        means = [s["mean"][i] for s in stats]
        mean = math.fsum(means) / k
        se_var = None
        if all(s["se"] is not None for s in stats):
            se_var = math.sqrt(math.fsum(s["se"][i] ** 2 for s in stats)) / k
        se_seeds = None
        if k >= 2:
            se_seeds = math.sqrt(math.fsum((m - mean) ** 2 for m in means) / (k - 1) / k)
        se_img = se_seeds if se_seeds is not None else se_var
        diff = mean - ref["mean"][i]
        se_comb = math.sqrt((se_img or 0.0) ** 2 + ref["se"][i] ** 2)
        out["channels"].append({
            "channel": c, "mean": mean, "se_var": se_var, "se_seeds": se_seeds,
            "ref_mean": ref["mean"][i], "ref_se": ref["se"][i], "diff": diff,
            "rel_diff": diff / ref["mean"][i], "se_combined": se_comb,
            "z": diff / se_comb if se_comb > 0 else float("inf")})
    return out


def main(argv):
    if "--" in argv:  # under Blender: arguments after "--"
        argv = argv[argv.index("--") + 1:]
    else:
        argv = argv[1:]
    as_json = "--json" in argv
    argv = [a for a in argv if a != "--json"]
    ref_path = None
    if "--reference" in argv:
        i = argv.index("--reference")
        if i + 1 >= len(argv):
            sys.stderr.write("exr_mean.py: expected a JSON file after --reference\n")
            return 2
        ref_path = argv[i + 1]
        del argv[i:i + 2]
    paths = argv
    if not paths:
        sys.stderr.write("usage: exr_mean.py IMAGE.exr... [--json] [--reference REF.json]\n")
        return 2
    if ref_path is not None:
        cmp = compare(paths, ref_path)
        if as_json:
            print(json.dumps(cmp, indent=2))
            return 0
        print("%d image(s) vs %s" % (len(paths), ref_path))
        for ch in cmp["channels"]:
            se_img = ch["se_seeds"] if ch["se_seeds"] is not None else ch["se_var"]
            print("  %s image %.6f +- %.6f  ref %.6f +- %.6f  diff %+.4f%%  (%+.2f combined SE)"
                  % (ch["channel"], ch["mean"], se_img or 0.0, ch["ref_mean"], ch["ref_se"],
                     100.0 * ch["rel_diff"], ch["z"]))
        return 0
    for path in paths:
        s = image_stats(path)
        if as_json:
            print(json.dumps(s))
            continue
        print("%s: %dx%d" % (path, s["width"], s["height"]))
        for i, c in enumerate("RGB"):
            line = "  %s mean %.6f" % (c, s["mean"][i])
            if s["se"] is not None:
                line += "  SE %.6f" % s["se"][i]
                if s["mean"][i] != 0.0:  # an all-zero image (a closed box) has no relative SE
                    line += " (%.4f%%)" % (100.0 * s["se"][i] / s["mean"][i])
            print(line)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
