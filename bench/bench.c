/* bench.c - shared parts of the ray-throughput benchmarks: meshes, the ray file format and the
 * standard ray sets of ../shared/BENCHMARKS.md (PCG32, O'Neill 2014, seeded pcg32_srandom(1, 1);
 * cosine directions by Malley's method in the frame of Duff et al. 2017, "Building an
 * Orthonormal Basis, Revisited"; Fisher-Yates shuffle), checksums, timing and a thread pool. */
#include "bench.h"

#include <errno.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <sys/resource.h>
#include <time.h>
#include <unistd.h>

#include "camera.h"
#include "obj.h"
#include "sample.h"

const char *const bench_set_names[BENCH_N_SETS] = {"primary", "diffuse", "shadow"};

/* ---- meshes ---------------------------------------------------------------------------------- */

bool bench_mesh_load_obj(const char *path, struct bench_mesh *mesh, struct mcpt_error *err)
{
    struct obj_mesh obj;
    *mesh = (struct bench_mesh){0};
    if (!obj_load(path, &obj, err))
        return false;
    mesh->indices = malloc(3 * (size_t)obj.n_tris * sizeof *mesh->indices + 1);
    if (!mesh->indices) {
        obj_free(&obj);
        mcpt_error_set(err, path, 0, 0, "out of memory for %u triangles", obj.n_tris);
        return false;
    }
    for (uint32_t i = 0; i < obj.n_tris; i++)
        for (int k = 0; k < 3; k++)
            mesh->indices[3 * (size_t)i + (size_t)k] = obj.tris[i].v[k];
    mesh->n_tris = obj.n_tris;
    mesh->positions = obj.positions; /* taken over from obj */
    mesh->n_positions = obj.n_positions;
    obj.positions = NULL;
    obj.n_positions = 0;
    obj_free(&obj);
    return true;
}

bool bench_mesh_torus(uint64_t n_tris, struct bench_mesh *mesh)
{
    *mesh = (struct bench_mesh){0};
    if (n_tris < 32)
        return false;
    /* a x b quads of two triangles: b around the tube, a = about 2 b around the ring */
    uint64_t b = (uint64_t)llround(sqrt((double)n_tris / 4.0));
    uint64_t a = (uint64_t)llround((double)n_tris / (2.0 * (double)b));
    if (2 * a * b > UINT32_MAX / 3 || a * b > UINT32_MAX)
        return false;
    mesh->n_positions = (uint32_t)(a * b);
    mesh->n_tris = (uint32_t)(2 * a * b);
    mesh->positions = malloc((size_t)mesh->n_positions * sizeof *mesh->positions);
    mesh->indices = malloc(3 * (size_t)mesh->n_tris * sizeof *mesh->indices);
    if (!mesh->positions || !mesh->indices) {
        bench_mesh_free(mesh);
        return false;
    }
    const double two_pi = 6.283185307179586;
    for (uint64_t i = 0; i < a; i++) {
        double u = two_pi * (double)i / (double)a;
        for (uint64_t j = 0; j < b; j++) {
            double v = two_pi * (double)j / (double)b;
            /* tube radius with bumps at three scales, so the surface is not smooth at any
             * resolution the table uses */
            double r = 0.35 * (1.0 + 0.15 * sin(9.0 * u) * sin(7.0 * v) +
                               0.04 * sin(61.0 * u + 3.0 * v) * cos(29.0 * v) +
                               0.01 * sin(499.0 * u) * sin(251.0 * v));
            double ring = 1.0 + r * cos(v);
            mesh->positions[i * b + j] = v3((float)(ring * cos(u)), (float)(r * sin(v)),
                                            (float)(ring * sin(u)));
        }
    }
    size_t k = 0;
    for (uint64_t i = 0; i < a; i++) {
        for (uint64_t j = 0; j < b; j++) {
            uint32_t v00 = (uint32_t)(i * b + j);
            uint32_t v10 = (uint32_t)(((i + 1) % a) * b + j);
            uint32_t v01 = (uint32_t)(i * b + (j + 1) % b);
            uint32_t v11 = (uint32_t)(((i + 1) % a) * b + (j + 1) % b);
            uint32_t quad[6] = {v00, v01, v11, v00, v11, v10};
            memcpy(&mesh->indices[k], quad, sizeof quad);
            k += 6;
        }
    }
    return true;
}

void bench_mesh_free(struct bench_mesh *mesh)
{
    free(mesh->positions);
    free(mesh->indices);
    *mesh = (struct bench_mesh){0};
}

vec3 bench_tri_normal(const struct bench_mesh *mesh, uint32_t prim_idx)
{
    const uint32_t *v = &mesh->indices[3 * (size_t)prim_idx];
    vec3 p0 = mesh->positions[v[0]];
    return v3_cross(v3_sub(mesh->positions[v[1]], p0), v3_sub(mesh->positions[v[2]], p0));
}

/* ---- ray files (little-endian, BENCHMARKS.md "Ray files") ------------------------------------ */

static const char ray_magic[8] = {'M', 'C', 'P', 'T', 'R', 'A', 'Y', 'S'};

static void put_u32(unsigned char *p, uint32_t v)
{
    for (int i = 0; i < 4; i++)
        p[i] = (unsigned char)(v >> (8 * i));
}

static uint32_t get_u32(const unsigned char *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

static void put_f32(unsigned char *p, float f)
{
    uint32_t v;
    memcpy(&v, &f, sizeof v);
    put_u32(p, v);
}

static float get_f32(const unsigned char *p)
{
    uint32_t v = get_u32(p);
    float f;
    memcpy(&f, &v, sizeof f);
    return f;
}

bool bench_rays_read(const char *path, struct bench_rays *rays, struct mcpt_error *err)
{
    *rays = (struct bench_rays){0};
    FILE *f = fopen(path, "rb");
    if (!f) {
        mcpt_error_set(err, path, 0, 0, "cannot open: %s", strerror(errno));
        return false;
    }
    unsigned char header[24];
    if (fread(header, 1, sizeof header, f) != sizeof header) {
        mcpt_error_set(err, path, 0, 0, "expected a 24-byte header, got a shorter file");
        goto fail;
    }
    if (memcmp(header, ray_magic, sizeof ray_magic) != 0) {
        mcpt_error_set(err, path, 0, 0, "expected magic MCPTRAYS, got other bytes");
        goto fail;
    }
    uint32_t version = get_u32(header + 8);
    uint32_t kind = get_u32(header + 12);
    uint64_t n = (uint64_t)get_u32(header + 16) | (uint64_t)get_u32(header + 20) << 32;
    if (version != 1) {
        mcpt_error_set(err, path, 0, 0, "expected version 1, got %u", version);
        goto fail;
    }
    if (kind > 1) {
        mcpt_error_set(err, path, 0, 0, "expected kind 0 or 1, got %u", kind);
        goto fail;
    }
    if (n > SIZE_MAX / sizeof(struct ray) || n > SIZE_MAX / 32) {
        mcpt_error_set(err, path, 0, 0, "expected a ray count that fits in memory, got %llu",
                       (unsigned long long)n);
        goto fail;
    }
    rays->kind = kind;
    rays->n = n;
    rays->rays = malloc((size_t)n * sizeof *rays->rays + 1);
    if (!rays->rays) {
        mcpt_error_set(err, path, 0, 0, "out of memory for %llu rays", (unsigned long long)n);
        goto fail;
    }
    unsigned char rec[32 * 256];
    for (uint64_t i = 0; i < n;) {
        size_t batch = n - i < 256 ? (size_t)(n - i) : 256;
        if (fread(rec, 32, batch, f) != batch) {
            mcpt_error_set(err, path, 0, 0, "expected %llu ray records, got %llu",
                           (unsigned long long)n, (unsigned long long)i);
            goto fail;
        }
        for (size_t k = 0; k < batch; k++, i++) {
            const unsigned char *p = rec + 32 * k;
            struct ray *r = &rays->rays[i];
            r->o = v3(get_f32(p), get_f32(p + 4), get_f32(p + 8));
            r->t_min = get_f32(p + 12);
            r->d = v3(get_f32(p + 16), get_f32(p + 20), get_f32(p + 24));
            r->t_max = get_f32(p + 28);
            if (!v3_is_finite(r->o) || !v3_is_finite(r->d) || !isfinite(r->t_min) ||
                isnan(r->t_max)) {
                mcpt_error_set(err, path, 0, 0, "expected finite ray %llu, got NaN or Inf",
                               (unsigned long long)i);
                goto fail;
            }
        }
    }
    if (fgetc(f) != EOF) {
        mcpt_error_set(err, path, 0, 0, "expected %llu ray records, got trailing bytes",
                       (unsigned long long)n);
        goto fail;
    }
    fclose(f);
    return true;
fail:
    fclose(f);
    bench_rays_free(rays);
    return false;
}

bool bench_rays_write(const char *path, const struct bench_rays *rays, struct mcpt_error *err)
{
    char tmp[4096];
    snprintf(tmp, sizeof tmp, "%s.tmp", path);
    FILE *f = fopen(tmp, "wb");
    if (!f) {
        mcpt_error_set(err, tmp, 0, 0, "cannot open for writing: %s", strerror(errno));
        return false;
    }
    unsigned char header[24];
    memcpy(header, ray_magic, sizeof ray_magic);
    put_u32(header + 8, 1);
    put_u32(header + 12, rays->kind);
    put_u32(header + 16, (uint32_t)rays->n);
    put_u32(header + 20, (uint32_t)(rays->n >> 32));
    bool ok = fwrite(header, 1, sizeof header, f) == sizeof header;
    for (uint64_t i = 0; ok && i < rays->n; i++) {
        const struct ray *r = &rays->rays[i];
        unsigned char p[32];
        const float v[8] = {r->o.x, r->o.y, r->o.z, r->t_min, r->d.x, r->d.y, r->d.z, r->t_max};
        for (int k = 0; k < 8; k++)
            put_f32(p + 4 * k, v[k]);
        ok = fwrite(p, 1, sizeof p, f) == sizeof p;
    }
    if (fclose(f) != 0)
        ok = false;
    if (!ok || rename(tmp, path) != 0) {
        mcpt_error_set(err, path, 0, 0, "cannot write: %s", strerror(errno));
        remove(tmp);
        return false;
    }
    return true;
}

void bench_rays_free(struct bench_rays *rays)
{
    free(rays->rays);
    *rays = (struct bench_rays){0};
}

/* ---- the standard ray sets (BENCHMARKS.md) --------------------------------------------------- */

static void mesh_bounds(const struct bench_mesh *mesh, vec3 *lo, vec3 *hi)
{
    *lo = v3_splat(INFINITY);
    *hi = v3_splat(-INFINITY);
    for (size_t i = 0; i < 3 * (size_t)mesh->n_tris; i++) {
        vec3 p = mesh->positions[mesh->indices[i]];
        *lo = v3_min(*lo, p);
        *hi = v3_max(*hi, p);
    }
}

bool bench_gen_sets(const struct bench_mesh *mesh, const struct bvh *bvh,
                    struct bench_rays sets[BENCH_N_SETS])
{
    enum { WIDTH = 1024, HEIGHT = 1024 };
    for (int s = 0; s < BENCH_N_SETS; s++)
        sets[s] = (struct bench_rays){0};
    vec3 lo;
    vec3 hi;
    mesh_bounds(mesh, &lo, &hi);
    vec3 centre = v3_scale(v3_add(lo, hi), 0.5f);
    float diag = v3_length(v3_sub(hi, lo)); /* D */
    /* primary: look at C from direction normalize(0.3, 0.4, 1.0), eye at distance 1.6 D, up +Y,
     * vertical field of view 40 degrees, one ray through each pixel centre, scanline order */
    vec3 dir = v3_normalize(v3(0.3f, 0.4f, 1.0f));
    struct camera_params cp = {.eye = v3_add(centre, v3_scale(dir, 1.6f * diag)),
                               .look_at = centre,
                               .up = v3(0, 1, 0),
                               .fov_deg = 40.0f};
    struct camera cam;
    if (!camera_init(&cam, &cp, WIDTH, HEIGHT, NULL))
        return false;
    uint64_t n_primary = (uint64_t)WIDTH * HEIGHT;
    sets[0].kind = BENCH_KIND_CLOSEST;
    sets[0].rays = malloc(n_primary * sizeof(struct ray));
    /* the hits of the primary rays, in order: the origins of the other two sets */
    vec3 *origin = malloc(n_primary * sizeof *origin);
    vec3 *normal = malloc(n_primary * sizeof *normal);
    if (!sets[0].rays || !origin || !normal)
        goto fail;
    sets[0].n = n_primary;
    uint64_t n_hits = 0;
    for (int y = 0; y < HEIGHT; y++) {
        for (int x = 0; x < WIDTH; x++) {
            struct ray r = camera_ray(&cam, (float)x + 0.5f, (float)y + 0.5f, (vec2){0.5f, 0.5f});
            sets[0].rays[(size_t)y * WIDTH + (size_t)x] = r;
            struct bvh_hit hit;
            if (!bvh_intersect(bvh, &r, &hit))
                continue;
            /* the hit point moved by 1e-4 D along the geometric normal facing the ray */
            vec3 n = v3_normalize(bench_tri_normal(mesh, hit.prim_idx));
            if (v3_dot(n, r.d) > 0.0f)
                n = v3_neg(n);
            vec3 p = v3_add(r.o, v3_scale(r.d, hit.t));
            origin[n_hits] = v3_add(p, v3_scale(n, 1e-4f * diag));
            normal[n_hits] = n;
            n_hits++;
        }
    }
    sets[1].kind = BENCH_KIND_CLOSEST;
    sets[2].kind = BENCH_KIND_OCCLUSION;
    sets[1].rays = malloc(n_hits * sizeof(struct ray) + 1);
    sets[2].rays = malloc(n_hits * sizeof(struct ray) + 1);
    if (!sets[1].rays || !sets[2].rays)
        goto fail;
    sets[1].n = n_hits;
    sets[2].n = n_hits;
    struct pcg32 rng;
    sample_pcg32_seed(&rng, 1, 1);
    /* diffuse: cosine-distributed around n (Malley: polar disk map lifted to the hemisphere,
     * r = sqrt(u1), phi = 2 pi u2, z = sqrt(1 - u1)), in the frame of Duff et al. 2017 */
    for (uint64_t i = 0; i < n_hits; i++) {
        float u1 = sample_pcg32_float(&rng);
        float u2 = sample_pcg32_float(&rng);
        float r = sqrtf(u1);
        float phi = 2.0f * MCPT_PI * u2;
        vec3 local = v3(r * cosf(phi), r * sinf(phi), sqrtf(1.0f - u1));
        vec3 t;
        vec3 b;
        v3_basis(normal[i], &t, &b);
        vec3 d = v3_normalize(v3_from_local(local, t, b, normal[i]));
        sets[1].rays[i] = (struct ray){origin[i], 0.0f, d, INFINITY};
    }
    /* then the shuffle: Fisher-Yates, i = n - 1 down to 1, j bounded random in [0, i] */
    for (uint64_t i = n_hits > 0 ? n_hits - 1 : 0; i >= 1; i--) {
        uint64_t j = sample_pcg32_bounded(&rng, (uint32_t)(i + 1));
        struct ray tmp = sets[1].rays[i];
        sets[1].rays[i] = sets[1].rays[j];
        sets[1].rays[j] = tmp;
    }
    /* shadow: toward a uniform point of the square of side 0.5 D centred at C + (0, D, 0),
     * parallel to XZ (u1 along x, u2 along z); t_max = 0.999 of the distance */
    for (uint64_t i = 0; i < n_hits; i++) {
        float u1 = sample_pcg32_float(&rng);
        float u2 = sample_pcg32_float(&rng);
        vec3 light = v3(centre.x + 0.5f * diag * (u1 - 0.5f), centre.y + diag,
                        centre.z + 0.5f * diag * (u2 - 0.5f));
        vec3 to = v3_sub(light, origin[i]);
        float dist = v3_length(to);
        sets[2].rays[i] = (struct ray){origin[i], 0.0f, v3_scale(to, 1.0f / dist), 0.999f * dist};
    }
    free(origin);
    free(normal);
    return true;
fail:
    free(origin);
    free(normal);
    for (int s = 0; s < BENCH_N_SETS; s++)
        bench_rays_free(&sets[s]);
    return false;
}

/* ---- tracing through mcpt -------------------------------------------------------------------- */

void bench_trace_range(void *trace, uint64_t begin, uint64_t end)
{
    const struct bench_trace *tr = trace;
    const struct ray *rays = tr->rays->rays;
    bool occlusion = tr->rays->kind == BENCH_KIND_OCCLUSION;
    if (tr->method == BENCH_STREAM) { /* 256 rays a call, as embree_bench's rtc*1M */
        struct bvh_hit hit[256];
        bool is_hit[256];
        for (uint64_t i = begin; i < end; i += 256) {
            size_t n = end - i < 256 ? (size_t)(end - i) : 256;
            if (occlusion)
                bvh_occluded_stream(tr->bvh, rays + i, NULL, n, is_hit);
            else
                bvh_intersect_stream(tr->bvh, rays + i, NULL, n, hit, is_hit);
            for (size_t k = 0; k < n; k++) {
                tr->prim[i + k] = !is_hit[k] ? UINT32_MAX : occlusion ? 0 : hit[k].prim_idx;
                tr->t[i + k] = is_hit[k] && !occlusion ? hit[k].t : 0.0f;
            }
        }
        return;
    }
    if (tr->method == BENCH_PACKET) {
        for (uint64_t i = begin; i < end; i += BVH_PACKET_SIZE) {
            struct bvh_packet p;
            uint32_t active = 0;
            for (int lane = 0; lane < BVH_PACKET_SIZE && i + (uint64_t)lane < end; lane++) {
                bvh_packet_set(&p, lane, &rays[i + (uint64_t)lane]);
                active |= 1u << lane;
            }
            if (occlusion) {
                uint32_t occluded = bvh_occluded_packet(tr->bvh, &p, active);
                for (int lane = 0; lane < BVH_PACKET_SIZE && (active >> lane & 1u); lane++)
                    tr->prim[i + (uint64_t)lane] = occluded >> lane & 1u ? 0 : UINT32_MAX;
                continue;
            }
            struct bvh_packet_hit hit;
            uint32_t hits = bvh_intersect_packet(tr->bvh, &p, active, &hit);
            for (int lane = 0; lane < BVH_PACKET_SIZE && (active >> lane & 1u); lane++) {
                bool is_hit = hits >> lane & 1u;
                tr->prim[i + (uint64_t)lane] = is_hit ? hit.prim_idx[lane] : UINT32_MAX;
                tr->t[i + (uint64_t)lane] = is_hit ? hit.t[lane] : 0.0f;
            }
        }
        return;
    }
    for (uint64_t i = begin; i < end; i++) {
        if (occlusion && tr->method == BENCH_SINGLE) {
            tr->prim[i] = bvh_occluded(tr->bvh, &rays[i]) ? 0 : UINT32_MAX;
            continue;
        }
        struct bvh_hit hit;
        bool is_hit = tr->method == BENCH_BRUTE ? bvh_intersect_brute(tr->bvh, &rays[i], &hit)
                                                : bvh_intersect(tr->bvh, &rays[i], &hit);
        if (occlusion)
            tr->prim[i] = is_hit ? 0 : UINT32_MAX;
        else
            tr->prim[i] = is_hit ? hit.prim_idx : UINT32_MAX;
        tr->t[i] = is_hit ? hit.t : 0.0f;
    }
}

struct bench_checksum bench_checksum_of(const struct bench_rays *rays, uint64_t n,
                                        const uint32_t *prim, const float *t)
{
    struct bench_checksum c = {0, 0.0, 0};
    for (uint64_t i = 0; i < n; i++) {
        if (prim[i] == UINT32_MAX)
            continue;
        c.hits++;
        if (rays->kind == BENCH_KIND_CLOSEST) {
            c.t_sum += (double)t[i];
            c.prim_sum += prim[i];
        }
    }
    return c;
}

/* ---- timing, machine, threads ---------------------------------------------------------------- */

static double thread_cpu_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

struct bench_time bench_time_1t(void (*fn)(void *ctx, uint64_t begin, uint64_t end), void *ctx,
                                uint64_t n)
{
    double wall0 = bench_now_ms();
    double cpu0 = thread_cpu_ms();
    fn(ctx, 0, n);
    return (struct bench_time){bench_now_ms() - wall0, thread_cpu_ms() - cpu0};
}

double bench_now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

static int compare_double(const void *a, const void *b)
{
    double x = *(const double *)a;
    double y = *(const double *)b;
    return (x > y) - (x < y);
}

double bench_median(double *v, int n)
{
    if (n <= 0)
        return 0.0;
    qsort(v, (size_t)n, sizeof *v, compare_double);
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

long bench_peak_rss_kib(void)
{
    struct rusage ru;
    return getrusage(RUSAGE_SELF, &ru) == 0 ? ru.ru_maxrss : -1;
}

int bench_n_cpus(void)
{
    long n = sysconf(_SC_NPROCESSORS_ONLN);
    return n > 0 ? (int)n : 1;
}

double bench_loadavg(void)
{
    FILE *f = fopen("/proc/loadavg", "r");
    double load = -1.0;
    if (f) {
        if (fscanf(f, "%lf", &load) != 1)
            load = -1.0;
        fclose(f);
    }
    return load;
}

struct pool_job {
    uint64_t n;
    uint64_t chunk;
    atomic_uint_fast64_t next;
    void (*fn)(void *ctx, uint64_t begin, uint64_t end);
    void *ctx;
};

static void *pool_worker(void *arg)
{
    struct pool_job *job = arg;
    for (;;) {
        uint64_t begin = atomic_fetch_add(&job->next, job->chunk);
        if (begin >= job->n)
            break;
        uint64_t end = begin + job->chunk < job->n ? begin + job->chunk : job->n;
        job->fn(job->ctx, begin, end);
    }
    return NULL;
}

double bench_parallel(uint64_t n, uint64_t chunk, int n_threads,
                      void (*fn)(void *ctx, uint64_t begin, uint64_t end), void *ctx)
{
    struct pool_job job = {n, chunk > 0 ? chunk : 1, 0, fn, ctx};
    pthread_t threads[256];
    int n_extra = n_threads - 1 < 256 ? n_threads - 1 : 255;
    double t0 = bench_now_ms();
    int n_started = 0;
    for (int i = 0; i < n_extra; i++)
        if (pthread_create(&threads[n_started], NULL, pool_worker, &job) == 0)
            n_started++;
    pool_worker(&job);
    for (int i = 0; i < n_started; i++)
        pthread_join(threads[i], NULL);
    return bench_now_ms() - t0;
}
