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
