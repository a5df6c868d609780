/* bench.h - what raybench.c and embree_bench.c share: meshes (OBJ or generated), ray files and
 * the standard ray sets of ../shared/BENCHMARKS.md, checksums, timing and a thread pool over
 * ray ranges.  Not part of the renderer: only the benchmark programs include it. */
#ifndef MCPT_BENCH_H
#define MCPT_BENCH_H

#include <stddef.h>

#include "bvh.h"
#include "vec.h"

/* A triangle mesh: indices[3i .. 3i+2] are triangle i's vertices in positions.  Triangles are
 * numbered in OBJ face order after fan triangulation (obj_load's order). */
struct bench_mesh {
    vec3 *positions;
    uint32_t n_positions;
    uint32_t *indices;
    uint32_t n_tris;
};

/* Loads an OBJ (positions and faces only).  false and *err filled on bad input. */
bool bench_mesh_load_obj(const char *path, struct bench_mesh *mesh, struct mcpt_error *err);

/* A closed bumpy torus of about n_tris triangles (2 a b, a = b * 2 rounded so that 2^20, 2^22
 * and 2^24 come out exactly): the generated mesh of the scale table.  false when out of
 * memory or n_tris < 32. */
bool bench_mesh_torus(uint64_t n_tris, struct bench_mesh *mesh);

void bench_mesh_free(struct bench_mesh *mesh);

/* Ray files (BENCHMARKS.md, "Ray files"). */
enum bench_kind {
    BENCH_KIND_CLOSEST = 0,   /* closest hit */
    BENCH_KIND_OCCLUSION = 1, /* any hit */
};

struct bench_rays {
    uint32_t kind; /* enum bench_kind */
    uint64_t n;
    struct ray *rays;
};

bool bench_rays_read(const char *path, struct bench_rays *rays, struct mcpt_error *err);
bool bench_rays_write(const char *path, const struct bench_rays *rays, struct mcpt_error *err);
void bench_rays_free(struct bench_rays *rays);

/* The standard sets of BENCHMARKS.md, "The standard ray sets for a mesh". */
enum bench_set {
    BENCH_SET_PRIMARY = 0,
    BENCH_SET_DIFFUSE = 1,
    BENCH_SET_SHADOW = 2,
};
#define BENCH_N_SETS 3
extern const char *const bench_set_names[BENCH_N_SETS];

/* Generates all three sets (the stream is shared, so diffuse and shadow depend on each other);
 * hits are found with bvh.  Returns false when out of memory (sets left empty). */
bool bench_gen_sets(const struct bench_mesh *mesh, const struct bvh *bvh,
                    struct bench_rays sets[BENCH_N_SETS]);

/* BENCHMARKS.md, "Checksums". */
struct bench_checksum {
    uint64_t hits;     /* rays that hit (occlusion: rays occluded) */
    double t_sum;      /* sum of t over hits (closest hit only) */
    uint64_t prim_sum; /* sum of triangle indices over hits (closest hit only) */
};

/* The triangle's geometric normal, unnormalised (p1 - p0) x (p2 - p0). */
vec3 bench_tri_normal(const struct bench_mesh *mesh, uint32_t prim_idx);

/* Tracing a ray file through mcpt's BVH, one result per ray so that checksums do not depend
 * on the thread count: prim[i] is the hit triangle (closest hit) or 0 / UINT32_MAX for
 * occluded / not (occlusion); t[i] the hit distance. */
enum bench_method {
    BENCH_SINGLE, /* bvh_intersect / bvh_occluded, ray by ray */
    BENCH_PACKET, /* bvh_intersect_packet / bvh_occluded_packet, 8 consecutive rays a packet */
    BENCH_STREAM, /* bvh_intersect_stream / bvh_occluded_stream, 256 consecutive rays a call */
    BENCH_BRUTE,  /* bvh_intersect_brute (every triangle) */
};

struct bench_trace {
    const struct bvh *bvh;
    const struct bench_rays *rays;
    enum bench_method method;
    uint32_t *prim; /* rays->n results */
    float *t;
};

/* fn for bench_parallel: traces rays [begin, end) (packets: begin a multiple of 8). */
void bench_trace_range(void *trace, uint64_t begin, uint64_t end);

/* Checksums of a results array (BENCHMARKS.md), over rays [0, n). */
struct bench_checksum bench_checksum_of(const struct bench_rays *rays, uint64_t n,
                                        const uint32_t *prim, const float *t);

/* Timing and machine. */
struct bench_time {
    double wall_ms; /* elapsed */
    double cpu_ms;  /* CPU time of the calling thread: what the kernel cost, whatever the load */
};

/* Runs fn(ctx, 0, n) on the calling thread and times it. */
struct bench_time bench_time_1t(void (*fn)(void *ctx, uint64_t begin, uint64_t end), void *ctx,
                                uint64_t n);

double bench_now_ms(void);
double bench_median(double *v, int n); /* sorts v */
long bench_peak_rss_kib(void);         /* getrusage ru_maxrss */
int bench_n_cpus(void);
double bench_loadavg(void); /* 1-minute load average, or -1 */

/* Runs fn(ctx, begin, end) over [0, n) in chunks of `chunk` taken from an atomic counter, on
 * n_threads threads (the caller's thread is one of them).  Returns wall-clock ms. */
double bench_parallel(uint64_t n, uint64_t chunk, int n_threads,
                      void (*fn)(void *ctx, uint64_t begin, uint64_t end), void *ctx);

#endif
