#!/usr/bin/env python3
"""random_spheres.py - writes scenes/random-spheres.txt: the cover of Shirley's "Ray Tracing in
One Weekend" (2016-2020, section 13), about 480 small spheres on a 22 x 22 grid, jittered, each
diffuse (80%), a rough or polished metal (15%) or glass (5%), around three large spheres, on a
ground sphere of radius 1000.  Deterministic (Python's random with a fixed seed).

    python3 scripts/random_spheres.py > scenes/random-spheres.txt
"""
import random

HEADER = """\
# random-spheres.txt - the cover of Shirley's "Ray Tracing in One Weekend" (section 13): {n}
# small spheres on a jittered 22 x 22 grid, diffuse, metal (conductor, GGX roughness 0-0.5) or
# glass, around three large ones (glass, diffuse, polished metal) on a ground sphere of radius
# 1000 under a gradient sky.  Every primitive is a sphere: their hits are found through a tree
# over their boxes (bvh.c, bvh_boxes_build; trace.c), not by testing each one.  Written by
# scripts/random_spheres.py.
# Render: ./mcpt scenes/random-spheres.txt
camera eye=13,2,3 look-at=0,0,0 up=0,1,0 fov=20 aperture=0.05 focus-dist=10
film width=512 height=288
render spp=128
material name=ground type=diffuse albedo=0.5,0.5,0.5
material name=glass type=dielectric ior=1.5
material name=brown type=diffuse albedo=0.4,0.2,0.1
material name=steel type=conductor specular=0.7,0.6,0.5 roughness=0
sphere center=0,-1000,0 radius=1000 material=ground
sphere center=0,1,0 radius=1 material=glass
sphere center=-4,1,0 radius=1 material=brown
sphere center=4,1,0 radius=1 material=steel
"""


def main():
    rng = random.Random(2016)
    lines = []
    n = 0
    for a in range(-11, 11):
        for b in range(-11, 11):
            x, z = a + 0.9 * rng.random(), b + 0.9 * rng.random()
            if (x - 4) ** 2 + z ** 2 <= 0.81:
                continue
            pick = rng.random()
            if pick < 0.8:
                rgb = [rng.random() * rng.random() for _ in range(3)]
                lines.append("material name=d%d type=diffuse albedo=%.3f,%.3f,%.3f" % (n, *rgb))
                mat = "d%d" % n
            elif pick < 0.95:
                rgb = [0.5 + 0.5 * rng.random() for _ in range(3)]
                lines.append("material name=m%d type=conductor specular=%.3f,%.3f,%.3f roughness=%.3f"
                             % (n, *rgb, 0.5 * rng.random() ** 2))
                mat = "m%d" % n
            else:
                mat = "glass"
            lines.append("sphere center=%.4f,0.2,%.4f radius=0.2 material=%s" % (x, z, mat))
            n += 1
    print(HEADER.format(n=n) + "\n".join(lines) + "\nsky type=gradient horizon=1,1,1 zenith=0.5,0.7,1\n", end="")


if __name__ == "__main__":
    main()
