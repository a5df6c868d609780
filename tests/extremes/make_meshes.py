#!/usr/bin/env python3
"""make_meshes.py - writes the OBJ fixtures of tests/extremes/ (a one-off, not part of the build;
Python standard library only).  Run from the repo root: python3 tests/extremes/make_meshes.py"""
import math

D = 'tests/extremes'


def obj(name, verts, faces, header):
    lines = [f'# {header}'] + ['v %.9g %.9g %.9g' % v for v in verts]
    lines += ['f %d %d %d' % f for f in faces]
    with open(f'{D}/{name}', 'w') as f:
        f.write('\n'.join(lines) + '\n')


# the square [-1,1]^2 at y = 0 as 2 triangles, the other diagonal, and a fan of slivers
sq = [(-1, 0, 1), (1, 0, 1), (1, 0, -1), (-1, 0, -1)]
obj('floor.obj', sq, [(1, 2, 3), (1, 3, 4)],
    'the square [-1,1]^2 at y = 0, facing +y, split along one diagonal')
obj('floor-other-diagonal.obj', sq, [(1, 2, 4), (2, 3, 4)],
    'the same square split along the other diagonal')
N = 200
verts = [(-1, 0, 1)]
for i in range(N + 1):  # the far edge x = 1, z from 1 to -1
    verts.append((1, 0, 1 - 2 * i / N))
for i in range(1, N + 1):  # then z = -1, x from 1 to -1
    verts.append((1 - 2 * i / N, 0, -1))
faces = [(1, k, k + 1) for k in range(2, len(verts))]
obj('floor-slivers.obj', verts, faces,
    f'the same square as a fan of {len(faces)} slivers from one corner')

# triangles of area 1e-12 down to 0, and slivers 0.1 wide and 1e-6 to 1e-22 high
tv, tf = [], []


def tri(a, b, c):
    tv.extend([a, b, c])
    tf.append((len(tv) - 2, len(tv) - 1, len(tv)))


for k, e in enumerate([1e-6, 1e-8, 1e-10, 1e-19, 1e-22]):
    x = -0.5 + 0.25 * k
    tri((x, 0.3, 0), (x + e, 0.3, 0), (x, 0.3 + e, 0))
    tri((x, 0.5, 0), (x + 0.1, 0.5, 0), (x + 0.1, 0.5 + e, 0))
tri((0, 0.4, 0.2), (0.1, 0.4, 0.2), (0.2, 0.4, 0.2))  # collinear: area 0
tri((0, 0.4, 0.3), (0, 0.4, 0.3), (0, 0.4, 0.3))  # one point
obj('tiny-triangles.obj', tv, tf,
    'triangles of area 1e-12 down to 0 (and slivers 0.1 wide, 1e-6 to 1e-22 high)')

# a closed unit icosphere: the icosahedron subdivided twice, vertices on the sphere
t = (1 + 5 ** 0.5) / 2
V = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t),
     (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
F = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
     (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9),
     (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
V = [tuple(c / math.sqrt(sum(x * x for x in v)) for c in v) for v in V]
for _ in range(2):
    cache = {}

    def mid(a, b):
        key = (min(a, b), max(a, b))
        if key not in cache:
            m = [(V[a][i] + V[b][i]) / 2 for i in range(3)]
            n = math.sqrt(sum(x * x for x in m))
            V.append(tuple(x / n for x in m))
            cache[key] = len(V) - 1
        return cache[key]

    F2 = []
    for a, b, c in F:
        ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
        F2 += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
    F = F2
obj('icosphere.obj', V, [(a + 1, b + 1, c + 1) for a, b, c in F],
    f'a closed unit icosphere: {len(V)} vertices, {len(F)} faces, outward winding')

# issue 12: the closed 2x2x2 cube, two triangles per face, wound outward and inward
cube_v = [(x, y, z) for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]
cube_f = [(1, 3, 4), (1, 4, 2),  # x = -1 (each face wound inward)
          (5, 6, 8), (5, 8, 7),  # x = +1
          (1, 2, 6), (1, 6, 5),  # y = -1
          (3, 7, 8), (3, 8, 4),  # y = +1
          (1, 5, 7), (1, 7, 3),  # z = -1
          (2, 4, 8), (2, 8, 6)]  # z = +1
obj('cube-inward.obj', cube_v, cube_f, 'the cube [-1,1]^3, 12 triangles, normals inward')
obj('cube-outward.obj', cube_v, [(a, c, b) for a, b, c in cube_f],
    'the cube [-1,1]^3, 12 triangles, normals outward')

# issue 12: floors of two triangles, [-S,S]^2 at y = 0, S = 1e6 and 1e7
for s in ('1e6', '1e7'):
    S = float(s)
    obj(f'floor-{s}.obj', [(-S, 0, -S), (S, 0, -S), (S, 0, S), (-S, 0, S)],
        [(1, 4, 3), (1, 3, 2)], f'the square [-{s},{s}]^2 at y = 0 as two triangles, facing +y')


# issue 12: parallelograms whose edges meet at 10, 3, 1, 0.3 and 0.1 degrees, in a general
# orientation, seen face-on from a camera close enough that every pixel sees the quad
def quad_scene(deg):
    a = math.radians(deg)
    # a fixed rotation: the orthonormal frame of two fixed vectors (Gram-Schmidt)
    u = [0.37, -0.62, 0.69]
    n = math.sqrt(sum(x * x for x in u))
    u = [x / n for x in u]
    v = [0.81, 0.23, -0.11]
    d = sum(u[i] * v[i] for i in range(3))
    v = [v[i] - d * u[i] for i in range(3)]
    n = math.sqrt(sum(x * x for x in v))
    v = [x / n for x in v]
    w = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]]
    e1 = [1.3 * x for x in u]
    e2 = [0.4 * (math.cos(a) * u[i] + math.sin(a) * v[i]) for i in range(3)]
    centre = [0.41, 4.49, -0.16]
    corner = [centre[i] - 0.5 * (e1[i] + e2[i]) for i in range(3)]
    # the quad is 0.4 sin(a) wide: the camera's 0.5 degree field, tilted 20 degrees off the
    # normal, covers a quarter of that
    width = 0.4 * math.sin(a)
    dist = 0.25 * width * math.cos(math.radians(20)) / (2 * math.tan(math.radians(0.25)) * 1.5)
    view = [math.cos(math.radians(20)) * w[i] + math.sin(math.radians(20)) * u[i]
            for i in range(3)]
    eye = [centre[i] + dist * view[i] for i in range(3)]

    def vec(p):
        return ','.join('%.9g' % x for x in p)
    with open(f'{D}/quad-shear-{deg:g}deg.txt', 'w') as f:
        f.write(f'# A parallelogram whose edges meet at {deg:g} degrees, general orientation, '
                'albedo 0.8 under a\n# constant sky of 2: every pixel is 2 x 0.8 = 1.6 (zero '
                'variance) unless rays spawned\n# from it hit it again.  '
                'Written by make_meshes.py.\n')
        f.write(f'camera eye={vec(eye)} look-at={vec(centre)} up={vec(v)} fov=0.5\n')
        f.write('film width=16 height=16\nrender spp=16 sampler=independent\n')
        f.write('material name=f type=diffuse albedo=0.8,0.8,0.8\n')
        f.write(f'quad corner={vec(corner)} edge1={vec(e1)} edge2={vec(e2)} material=f\n')
        f.write('sky type=constant radiance=2,2,2\n')


for deg in (10, 3, 1, 0.3, 0.1):
    quad_scene(deg)

# issue 12, scenes that must not abort: only zero-area faces; and three chains of 126 triangles
# at 2^-k along x, y and z, which the binned SAH peels one at a time down to the depth cap
obj('degenerate-only.obj', [(0, 0, 0), (1, 0, 0), (2, 0, 0), (0, 1, 0)],
    [(1, 2, 3), (1, 1, 4), (4, 4, 4)], 'zero-area faces only: collinear, repeated vertices')
dv, df = [], []
for axis in range(3):
    for k in range(126):
        x = 2.0 ** -k
        s = x / 8
        c = [x if a == axis else 0.0 for a in range(3)]
        for off in ((-s, -s, s), (s, -s, -s), (-s, s, -s)):
            dv.append(tuple(c[a] + off[a] for a in range(3)))
        df.append((len(dv) - 2, len(dv) - 1, len(dv)))
with open(f'{D}/depth-cap.obj', 'w') as f:
    f.write('# three chains of 126 triangles at 2^-k along x, y, z: the BVH reaches its depth cap\n')
    f.write(''.join('v %r %r %r\n' % v for v in dv))
    f.write(''.join('f %d %d %d\n' % t for t in df))

# The Cornell box with every coordinate on the grid of 1/64 (the lamp lowered to 126/64, one step
# under the ceiling, which the rounding would otherwise meet): moved by up to 1e5 (ulp 2^-7) its
# vertices stay exact, so the moved scenes hold the same geometry and differ only in precision.
with open('scenes/models/CornellBox-Original.obj') as f:
    src = f.read().splitlines()
grid = ['# CornellBox-Original.obj (scenes/models) with its coordinates rounded to the grid of 1/64',
        'mtllib ../../scenes/models/CornellBox-Original.mtl']
for line in src:
    if line.startswith('mtllib'):
        continue
    if line.startswith('v '):
        v = [round(float(t) * 64) / 64 for t in line.split()[1:4]]
        if float(line.split()[2]) == 1.98:  # the lamp
            v[1] = 126 / 64
        line = 'v %r %r %r' % tuple(v)
    grid.append(line)
with open(f'{D}/cornell-grid.obj', 'w') as f:
    f.write('\n'.join(grid) + '\n')
for off in ('0', '1e3', '1e5'):
    o = float(off)
    with open(f'{D}/cornell-moved-{off}.txt', 'w') as f:
        f.write(f'# The Cornell box of the 1/64 grid moved by {off} on every axis (camera too): the image\n'
                '# must not depend on where the scene is (extremes_test.c, cornell_moved_far_from_the_origin).\n'
                f'camera eye={o:.9g},{o + 1:.9g},{o + 3.90625:.9g} look-at={o:.9g},{o + 1:.9g},{o:.9g} '
                'up=0,1,0 fov=40\n'
                'film width=32 height=32\nrender spp=2048 max-depth=6 sampler=independent\n'
                f'mesh file=cornell-grid.obj translate={o:.9g},{o:.9g},{o:.9g}\n')
