/* embree_bench.c - mcpt's BVH against Embree 3 (Wald et al. 2014, "Embree: A Kernel Framework
 * for Efficient CPU Ray Tracing") on the same mesh and ray files, in one invocation: builds
 * (mcpt against RTC_BUILD_QUALITY_HIGH, on one thread and on all), then per ray file every
 * entry point of both: mcpt's single rays, 8-ray packets and 32-ray streams; Embree's
 * rtcIntersect1 / 8 / 16 and the stream rtcIntersect1M with the coherent and with the
 * incoherent context flag (the rtcOccluded* twins for occlusion files), runs interleaved so
 * that all see the same load.
 * The headline is the best mcpt kernel against the best Embree entry point for that ray file,
 * single thread, by wall clock and by CPU time; both checksums; one JSON line per ray file.
 * Built only when Embree 3 is installed (`make bench-embree`); nothing else in mcpt uses it. */
#include <embree3/rtcore.h>
#include <getopt.h>
#include <stdatomic.h>
#include <stdlib.h>

#include "bench.h"
#include "bvh.h"

static const char usage[] =
    "usage: embree_bench MODEL RAYS.bin... [--runs R] [--threads N] [--robust] [--quality Q]\n"
    "  MODEL     an OBJ file or torus:N (see raybench)\n"
    "  --runs R  timed runs of each tracer after one warm-up, interleaved (default 5)\n"
    "  --threads N  threads of the all-threads figures and builds (default: all CPUs)\n"
    "  --robust  build Embree's scene with RTC_SCENE_FLAG_ROBUST (its watertight mode)\n"
    "  --quality Q  Embree's build quality: high (default; spatial splits), medium or low\n";

/* ---- Embree: scene, memory, tracing ---------------------------------------------------------- */

static atomic_llong embree_bytes; /* bytes Embree holds, from its memory monitor */

static bool memory_monitor(void *ptr, ssize_t bytes, bool post)
{
    (void)ptr;
    (void)post;
    atomic_fetch_add(&embree_bytes, (long long)bytes);
    return true;
}

struct embree {
    RTCDevice device;
    RTCScene scene;
    float *vertices;   /* shared with Embree: 3 floats per vertex plus one float of padding */
    uint32_t *indices; /* shared: 3 per triangle */
    double build_ms;
    long long bytes; /* BVH and primitive data Embree allocated for the scene */
};

static bool embree_build(const struct bench_mesh *mesh, int n_threads, bool robust,
                         enum RTCBuildQuality quality, struct embree *e)
{
    char config[64];
    snprintf(config, sizeof config, "threads=%d", n_threads);
    e->device = rtcNewDevice(config);
    if (!e->device)
        return false;
    rtcSetDeviceMemoryMonitorFunction(e->device, memory_monitor, NULL);
    /* shared buffers, so that the memory monitor counts only what Embree builds */
    e->vertices = malloc((3 * (size_t)mesh->n_positions + 1) * sizeof(float));
    e->indices = malloc(3 * (size_t)mesh->n_tris * sizeof(uint32_t) + 1);
    if (!e->vertices || !e->indices)
        return false;
    memcpy(e->vertices, mesh->positions, 3 * (size_t)mesh->n_positions * sizeof(float));
    e->vertices[3 * (size_t)mesh->n_positions] = 0.0f;
    memcpy(e->indices, mesh->indices, 3 * (size_t)mesh->n_tris * sizeof(uint32_t));
    long long bytes_before = atomic_load(&embree_bytes);
    double t0 = bench_now_ms();
    e->scene = rtcNewScene(e->device);
    rtcSetSceneBuildQuality(e->scene, quality);
    if (robust)
        rtcSetSceneFlags(e->scene, RTC_SCENE_FLAG_ROBUST);
    RTCGeometry g = rtcNewGeometry(e->device, RTC_GEOMETRY_TYPE_TRIANGLE);
    rtcSetGeometryBuildQuality(g, quality);
    rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, e->vertices, 0,
                               3 * sizeof(float), mesh->n_positions);
    rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, e->indices, 0,
                               3 * sizeof(uint32_t), mesh->n_tris);
    rtcCommitGeometry(g);
    rtcAttachGeometry(e->scene, g);
    rtcReleaseGeometry(g);
    rtcCommitScene(e->scene);
    e->build_ms = bench_now_ms() - t0;
    e->bytes = atomic_load(&embree_bytes) - bytes_before;
    return rtcGetDeviceError(e->device) == RTC_ERROR_NONE;
}

static void embree_free(struct embree *e)
{
    if (e->scene)
        rtcReleaseScene(e->scene);
    if (e->device)
        rtcReleaseDevice(e->device);
    free(e->vertices);
    free(e->indices);
    *e = (struct embree){0};
}

enum embree_method {
    EMBREE_1,      /* rtcIntersect1 / rtcOccluded1 */
    EMBREE_8,      /* rtcIntersect8 / rtcOccluded8, 8 consecutive rays a packet */
    EMBREE_16,     /* rtcIntersect16 / rtcOccluded16, 16 consecutive rays a packet */
    EMBREE_STREAM, /* rtcIntersect1M / rtcOccluded1M on EMBREE_STREAM_SIZE rays at a time */
};
#define EMBREE_N_METHODS 4
#define EMBREE_STREAM_SIZE 256

static const char *const embree_method_names[2][EMBREE_N_METHODS] = {
    {"Embree rtcIntersect1", "Embree rtcIntersect8", "Embree rtcIntersect16",
     "Embree rtcIntersect1M"},
    {"Embree rtcOccluded1", "Embree rtcOccluded8", "Embree rtcOccluded16", "Embree rtcOccluded1M"},
};

struct embree_trace {
    RTCScene scene;
    const struct bench_rays *rays;
    enum embree_method method;
    bool coherent; /* the context flag RTC_INTERSECT_CONTEXT_FLAG_COHERENT (streams use it) */
    uint32_t *prim;
    float *t;
};

static void set_ray1(struct RTCRay *r, const struct ray *ray)
{
    r->org_x = ray->o.x;
    r->org_y = ray->o.y;
    r->org_z = ray->o.z;
    r->tnear = ray->t_min;
    r->dir_x = ray->d.x;
    r->dir_y = ray->d.y;
    r->dir_z = ray->d.z;
    r->time = 0.0f;
    r->tfar = ray->t_max;
    r->mask = UINT32_MAX;
    r->id = 0;
    r->flags = 0;
}

/* Lane `lane` of an Embree SoA packet of K rays (struct RTCRay8 or RTCRay16). */
#define SET_RAY_K(r, lane, ray)                                                                    \
    do {                                                                                           \
        (r)->org_x[lane] = (ray)->o.x;                                                             \
        (r)->org_y[lane] = (ray)->o.y;                                                             \
        (r)->org_z[lane] = (ray)->o.z;                                                             \
        (r)->tnear[lane] = (ray)->t_min;                                                           \
        (r)->dir_x[lane] = (ray)->d.x;                                                             \
        (r)->dir_y[lane] = (ray)->d.y;                                                             \
        (r)->dir_z[lane] = (ray)->d.z;                                                             \
        (r)->time[lane] = 0.0f;                                                                    \
        (r)->tfar[lane] = (ray)->t_max;                                                            \
        (r)->mask[lane] = UINT32_MAX;                                                              \
        (r)->id[lane] = 0;                                                                         \
        (r)->flags[lane] = 0;                                                                      \
    } while (0)

/* rays [i, i + K) (fewer at the end: inactive lanes) through rtcIntersectK / rtcOccludedK */
#define TRACE_PACKET_K(K)                                                                          \
    static void embree_trace_##K(const struct embree_trace *tr, struct RTCIntersectContext *ctx,   \
                                 uint64_t begin, uint64_t end)                                     \
    {                                                                                              \
        const struct ray *rays = tr->rays->rays;                                                   \
        bool occlusion = tr->rays->kind == BENCH_KIND_OCCLUSION;                                   \
        for (uint64_t i = begin; i < end; i += K) {                                                \
            _Alignas(64) int valid[K];                                                             \
            int n = end - i < K ? (int)(end - i) : K;                                              \
            if (occlusion) {                                                                       \
                _Alignas(64) struct RTCRay##K r;                                                   \
                for (int lane = 0; lane < K; lane++) {                                             \
                    valid[lane] = lane < n ? -1 : 0;                                               \
                    SET_RAY_K(&r, lane, &rays[i + (uint64_t)(lane < n ? lane : 0)]);               \
                }                                                                                  \
                rtcOccluded##K(valid, tr->scene, ctx, &r);                                         \
                for (int lane = 0; lane < n; lane++)                                               \
                    tr->prim[i + (uint64_t)lane] = r.tfar[lane] < 0.0f ? 0 : UINT32_MAX;           \
                continue;                                                                          \
            }                                                                                      \
            _Alignas(64) struct RTCRayHit##K rh;                                                   \
            for (int lane = 0; lane < K; lane++) {                                                 \
                valid[lane] = lane < n ? -1 : 0;                                                   \
                SET_RAY_K(&rh.ray, lane, &rays[i + (uint64_t)(lane < n ? lane : 0)]);              \
                rh.hit.geomID[lane] = RTC_INVALID_GEOMETRY_ID;                                     \
            }                                                                                      \
            rtcIntersect##K(valid, tr->scene, ctx, &rh);                                           \
            for (int lane = 0; lane < n; lane++) {                                                 \
                bool is_hit = rh.hit.geomID[lane] != RTC_INVALID_GEOMETRY_ID;                      \
                tr->prim[i + (uint64_t)lane] = is_hit ? rh.hit.primID[lane] : UINT32_MAX;          \
                tr->t[i + (uint64_t)lane] = is_hit ? rh.ray.tfar[lane] : 0.0f;                     \
            }                                                                                      \
        }                                                                                          \
    }
TRACE_PACKET_K(8)
TRACE_PACKET_K(16)

/* rays [begin, end) through rtcIntersect1M / rtcOccluded1M, EMBREE_STREAM_SIZE at a time */
static void embree_trace_stream(const struct embree_trace *tr, struct RTCIntersectContext *ctx,
                                uint64_t begin, uint64_t end)
{
    const struct ray *rays = tr->rays->rays;
    bool occlusion = tr->rays->kind == BENCH_KIND_OCCLUSION;
    static _Thread_local struct RTCRayHit rh[EMBREE_STREAM_SIZE];
    for (uint64_t i = begin; i < end; i += EMBREE_STREAM_SIZE) {
        unsigned n = end - i < EMBREE_STREAM_SIZE ? (unsigned)(end - i) : EMBREE_STREAM_SIZE;
        if (occlusion) {
            for (unsigned k = 0; k < n; k++)
                set_ray1(&rh[k].ray, &rays[i + k]);
            rtcOccluded1M(tr->scene, ctx, &rh[0].ray, n, sizeof rh[0]);
            for (unsigned k = 0; k < n; k++)
                tr->prim[i + k] = rh[k].ray.tfar < 0.0f ? 0 : UINT32_MAX;
            continue;
        }
        for (unsigned k = 0; k < n; k++) {
            set_ray1(&rh[k].ray, &rays[i + k]);
            rh[k].hit.geomID = RTC_INVALID_GEOMETRY_ID;
        }
        rtcIntersect1M(tr->scene, ctx, rh, n, sizeof rh[0]);
        for (unsigned k = 0; k < n; k++) {
            bool is_hit = rh[k].hit.geomID != RTC_INVALID_GEOMETRY_ID;
            tr->prim[i + k] = is_hit ? rh[k].hit.primID : UINT32_MAX;
            tr->t[i + k] = is_hit ? rh[k].ray.tfar : 0.0f;
        }
    }
}

static void embree_trace_range(void *arg, uint64_t begin, uint64_t end)
{
    const struct embree_trace *tr = arg;
    const struct ray *rays = tr->rays->rays;
    bool occlusion = tr->rays->kind == BENCH_KIND_OCCLUSION;
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    ctx.flags = tr->coherent ? RTC_INTERSECT_CONTEXT_FLAG_COHERENT
                             : RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
    switch (tr->method) {
    case EMBREE_8:
        embree_trace_8(tr, &ctx, begin, end);
        return;
    case EMBREE_16:
        embree_trace_16(tr, &ctx, begin, end);
        return;
    case EMBREE_STREAM:
        embree_trace_stream(tr, &ctx, begin, end);
        return;
    case EMBREE_1:
        break;
    }
    for (uint64_t i = begin; i < end; i++) {
        if (occlusion) {
            struct RTCRay r;
            set_ray1(&r, &rays[i]);
            rtcOccluded1(tr->scene, &ctx, &r);
            tr->prim[i] = r.tfar < 0.0f ? 0 : UINT32_MAX; /* tfar = -inf when occluded */
            continue;
        }
        struct RTCRayHit rh;
        set_ray1(&rh.ray, &rays[i]);
        rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
        rtcIntersect1(tr->scene, &ctx, &rh);
        bool is_hit = rh.hit.geomID != RTC_INVALID_GEOMETRY_ID;
        tr->prim[i] = is_hit ? rh.hit.primID : UINT32_MAX;
        tr->t[i] = is_hit ? rh.ray.tfar : 0.0f;
    }
}

/* ---- interleaved measurement ----------------------------------------------------------------- */

/* One tracer: its run function and context, results and collected timings. */
struct tracer {
    const char *name;
    void (*fn)(void *ctx, uint64_t begin, uint64_t end);
    void *ctx;
    double cpu_ms[64];  /* single thread */
    double wall_ms[64]; /* single thread */
    double mt_ms[64];   /* all threads */
    struct bench_checksum sum;
    double mrays_1t;
    double mrays_1t_wall;
    double mrays_mt;
};

/* Warm-up of each, then R rounds; in each round every tracer runs once on one thread, then
 * every tracer once on all threads. */
static void measure_interleaved(struct tracer *tr, int n_tr, const struct bench_rays *rays,
                                int runs, int n_threads, uint32_t **prim, float **t)
{
    for (int k = 0; k < n_tr; k++) {
        tr[k].fn(tr[k].ctx, 0, rays->n);
        tr[k].sum = bench_checksum_of(rays, rays->n, prim[k], t[k]);
    }
    for (int r = 0; r < runs; r++) {
        for (int k = 0; k < n_tr; k++) {
            struct bench_time bt = bench_time_1t(tr[k].fn, tr[k].ctx, rays->n);
            tr[k].cpu_ms[r] = bt.cpu_ms;
            tr[k].wall_ms[r] = bt.wall_ms;
        }
        for (int k = 0; k < n_tr; k++)
            tr[k].mt_ms[r] = bench_parallel(rays->n, 4096, n_threads, tr[k].fn, tr[k].ctx);
    }
    for (int k = 0; k < n_tr; k++) {
        tr[k].mrays_1t = (double)rays->n / bench_median(tr[k].cpu_ms, runs) / 1e3;
        tr[k].mrays_1t_wall = (double)rays->n / bench_median(tr[k].wall_ms, runs) / 1e3;
        tr[k].mrays_mt = (double)rays->n / bench_median(tr[k].mt_ms, runs) / 1e3;
    }
}

static double rel_diff(double a, double b)
{
    double m = fabs(a) > fabs(b) ? fabs(a) : fabs(b);
    return m > 0.0 ? fabs(a - b) / m : 0.0;
}

int main(int argc, char **argv)
{
    int runs = 5;
    int n_threads = bench_n_cpus();
    bool robust = false;
    enum RTCBuildQuality quality = RTC_BUILD_QUALITY_HIGH;
    static const struct option long_opts[] = {{"quality", required_argument, NULL, 'q'},
                                              {"runs", required_argument, NULL, 'r'},
                                              {"threads", required_argument, NULL, 't'},
                                              {"robust", no_argument, NULL, 'R'},
                                              {"help", no_argument, NULL, 'h'},
                                              {NULL, 0, NULL, 0}};
    int c;
    while ((c = getopt_long(argc, argv, "h", long_opts, NULL)) != -1) {
        switch (c) {
        case 'r':
            runs = atoi(optarg);
            break;
        case 't':
            n_threads = atoi(optarg);
            break;
        case 'R':
            robust = true;
            break;
        case 'q':
            if (strcmp(optarg, "high") == 0) {
                quality = RTC_BUILD_QUALITY_HIGH;
            } else if (strcmp(optarg, "medium") == 0) {
                quality = RTC_BUILD_QUALITY_MEDIUM;
            } else if (strcmp(optarg, "low") == 0) {
                quality = RTC_BUILD_QUALITY_LOW;
            } else {
                fprintf(stderr, "embree_bench: expected --quality high, medium or low, got '%s'\n",
                        optarg);
                return 2;
            }
            break;
        case 'h':
            fputs(usage, stdout);
            return 0;
        default:
            fputs(usage, stderr);
            return 2;
        }
    }
    if (argc - optind < 2 || runs < 1 || runs > 64 || n_threads < 1 || n_threads > 256) {
        fputs(usage, stderr);
        return 2;
    }
    const char *model = argv[optind];
    struct bench_mesh mesh = {0};
    if (strncmp(model, "torus:", 6) == 0) {
        char *end;
        unsigned long long n = strtoull(model + 6, &end, 10);
        n <<= *end == 'k' ? 10 : *end == 'M' ? 20 : 0;
        if (!bench_mesh_torus(n, &mesh)) {
            fprintf(stderr, "embree_bench: cannot generate %s\n", model);
            return 2;
        }
    } else {
        struct mcpt_error err;
        if (!bench_mesh_load_obj(model, &mesh, &err)) {
            char line[600];
            mcpt_error_format(&err, line, sizeof line);
            fprintf(stderr, "%s\n", line);
            return 2;
        }
    }
    printf("model: %s: %u triangles; load average %.2f on %d CPUs; mcpt kernels %s; Embree %s%s\n",
           model, mesh.n_tris, bench_loadavg(), bench_n_cpus(), bvh_simd_name(), RTC_VERSION_STRING,
           robust ? " (robust)" : "");
    /* builds, interleaved, 1 thread then all threads: mcpt's default (spatial splits) and
     * binned builds, Embree's high-quality (spatial splits) and medium (binned) builds; the
     * BVHs traced below are mcpt's default and Embree's at `quality` */
    enum { MCPT_SPATIAL, MCPT_BINNED, EMBREE_HIGH, EMBREE_MEDIUM, N_BUILDS };
    static const char *const build_names[N_BUILDS] = {"mcpt spatial splits (default)",
                                                      "mcpt binned", "Embree high quality",
                                                      "Embree medium quality"};
    double build_ms[N_BUILDS][2][64];
    double bytes_per_tri[N_BUILDS];
    struct bvh *bvh = NULL;
    struct embree emb = {0};
    for (int r = 0; r <= runs; r++) { /* r == 0: warm-up */
        for (int mt = 0; mt < 2; mt++) {
            int threads = mt ? n_threads : 1;
            for (int k = 0; k < N_BUILDS; k++) {
                double ms;
                if (k == MCPT_SPATIAL || k == MCPT_BINNED) {
                    struct bvh_build_options o = {threads, BVH_LAYOUT_WIDE,
                                                  k == MCPT_SPATIAL ? BVH_QUALITY_SPATIAL
                                                                    : BVH_QUALITY_BINNED};
                    struct bvh *b = bvh_build_with(mesh.positions, mesh.indices, mesh.n_tris, &o);
                    if (!b) {
                        fprintf(stderr, "embree_bench: build failed\n");
                        return 1;
                    }
                    struct bvh_stats st = bvh_get_stats(b);
                    ms = st.build_ms;
                    bytes_per_tri[k] = (double)st.bytes / (double)mesh.n_tris;
                    if (k == MCPT_SPATIAL) {
                        bvh_free(bvh);
                        bvh = b;
                    } else {
                        bvh_free(b);
                    }
                } else {
                    enum RTCBuildQuality q = k == EMBREE_HIGH ? RTC_BUILD_QUALITY_HIGH
                                                              : RTC_BUILD_QUALITY_MEDIUM;
                    struct embree e = {0};
                    if (!embree_build(&mesh, threads, robust, q, &e)) {
                        fprintf(stderr, "embree_bench: Embree build failed\n");
                        return 1;
                    }
                    ms = e.build_ms;
                    bytes_per_tri[k] = (double)e.bytes / (double)mesh.n_tris;
                    embree_free(&e);
                }
                if (r > 0)
                    build_ms[k][mt][r - 1] = ms;
            }
        }
    }
    if (!embree_build(&mesh, n_threads, robust, quality, &emb)) {
        fprintf(stderr, "embree_bench: Embree build failed\n");
        return 1;
    }
    double build_median[N_BUILDS][2];
    for (int k = 0; k < N_BUILDS; k++) {
        for (int mt = 0; mt < 2; mt++)
            build_median[k][mt] = bench_median(build_ms[k][mt], runs);
        printf("build %-30s %8.1f ms 1 thread, %8.1f ms %d threads; %5.1f bytes/triangle\n",
               build_names[k], build_median[k][0], build_median[k][1], n_threads, bytes_per_tri[k]);
    }
    printf("build ratios mcpt / Embree, 1 thread (< 1: mcpt faster): spatial / high %.2f, "
           "binned / medium %.2f\n",
           build_median[MCPT_SPATIAL][0] / build_median[EMBREE_HIGH][0],
           build_median[MCPT_BINNED][0] / build_median[EMBREE_MEDIUM][0]);
    struct bvh_stats st = bvh_get_stats(bvh);
    const char *quality_name = quality == RTC_BUILD_QUALITY_HIGH     ? "high"
                               : quality == RTC_BUILD_QUALITY_MEDIUM ? "medium"
                                                                     : "low";
    double mcpt_bpt = bytes_per_tri[MCPT_SPATIAL];
    double embree_bpt = (double)emb.bytes / (double)mesh.n_tris;
    double mcpt_build[2] = {build_median[MCPT_SPATIAL][0], build_median[MCPT_SPATIAL][1]};
    double embree_build_ms[2] = {
        build_median[quality == RTC_BUILD_QUALITY_HIGH ? EMBREE_HIGH : EMBREE_MEDIUM][0],
        build_median[quality == RTC_BUILD_QUALITY_HIGH ? EMBREE_HIGH : EMBREE_MEDIUM][1]};
    printf("traced: mcpt spatial splits (%u refs for %u triangles, SAH cost %.2f), Embree %s "
           "quality (%.1f bytes/triangle)\n",
           st.n_refs, st.n_tris, st.sah_cost, quality_name, embree_bpt);
    int status = 0;
    for (int f = optind + 1; f < argc; f++) {
        struct bench_rays rays;
        struct mcpt_error err;
        if (!bench_rays_read(argv[f], &rays, &err)) {
            char line[600];
            mcpt_error_format(&err, line, sizeof line);
            fprintf(stderr, "%s\n", line);
            status = 2;
            continue;
        }
        /* mcpt single and packets, Embree's entry points (the stream twice), mcpt streams */
        enum {
            N_EMBREE = EMBREE_N_METHODS + 1,
            N_TRACERS = 2 + N_EMBREE + 1,
            STREAM = N_TRACERS - 1
        };
        uint32_t *prim[N_TRACERS];
        float *t[N_TRACERS];
        for (int k = 0; k < N_TRACERS; k++) {
            prim[k] = malloc(rays.n * sizeof(uint32_t) + 1);
            t[k] = malloc(rays.n * sizeof(float) + 1);
            if (!prim[k] || !t[k])
                return 1;
        }
        bool occlusion = rays.kind == BENCH_KIND_OCCLUSION;
        /* mcpt's single rays and packets, then every Embree entry point, then mcpt's streams:
         * the best of each side is compared (Embree's stream twice, with the coherent and the
         * incoherent context flag) */
        struct bench_trace m1 = {bvh, &rays, BENCH_SINGLE, prim[0], t[0]};
        struct bench_trace m8 = {bvh, &rays, BENCH_PACKET, prim[1], t[1]};
        struct bench_trace ms = {bvh, &rays, BENCH_STREAM, prim[STREAM], t[STREAM]};
        struct embree_trace e[EMBREE_N_METHODS + 1];
        struct tracer tr[N_TRACERS] = {
            {.name = "mcpt single", .fn = bench_trace_range, .ctx = &m1},
            {.name = "mcpt packets", .fn = bench_trace_range, .ctx = &m8},
        };
        tr[STREAM] = (struct tracer){.name = "mcpt streams", .fn = bench_trace_range, .ctx = &ms};
        for (int k = 0; k <= EMBREE_N_METHODS; k++) {
            enum embree_method m = k < EMBREE_N_METHODS ? (enum embree_method)k : EMBREE_STREAM;
            e[k] = (struct embree_trace){emb.scene,          &rays,       m,
                                         k == EMBREE_STREAM, prim[2 + k], t[2 + k]};
            tr[2 + k] = (struct tracer){.name = embree_method_names[occlusion][m],
                                        .fn = embree_trace_range,
                                        .ctx = &e[k]};
        }
        measure_interleaved(tr, N_TRACERS, &rays, runs, n_threads, prim, t);
        printf("rays: %s: %llu %s rays; load average %.2f\n", argv[f], (unsigned long long)rays.n,
               occlusion ? "occlusion" : "closest-hit", bench_loadavg());
        for (int k = 0; k < N_TRACERS; k++) {
            char name[64];
            snprintf(name, sizeof name, "%s%s", tr[k].name,
                     k < 2 + EMBREE_STREAM || k == STREAM ? ""
                     : k == 2 + EMBREE_STREAM             ? " coherent"
                                                          : " incoherent");
            printf("  %-33s %8.3f Mrays/s 1 thread (CPU time; %.3f wall), %8.3f on %d threads; "
                   "hits %llu",
                   name, tr[k].mrays_1t, tr[k].mrays_1t_wall, tr[k].mrays_mt, n_threads,
                   (unsigned long long)tr[k].sum.hits);
            if (!occlusion)
                printf(" t_sum %.6e prim_sum %llu", tr[k].sum.t_sum,
                       (unsigned long long)tr[k].sum.prim_sum);
            printf("\n");
        }
        /* checksums: mcpt single against Embree single */
        double hit_diff = rays.n ? fabs((double)tr[0].sum.hits - (double)tr[2].sum.hits) /
                                       (double)rays.n
                                 : 0.0;
        double t_diff = rel_diff(tr[0].sum.t_sum, tr[2].sum.t_sum);
        /* the comparison of docs/bvh.md: the best mcpt kernel against the best Embree entry
         * point for this ray set, by wall clock and by CPU time (single thread each) */
        int best_m_wall = tr[1].mrays_1t_wall > tr[0].mrays_1t_wall ? 1 : 0;
        int best_m_cpu = tr[1].mrays_1t > tr[0].mrays_1t ? 1 : 0;
        if (tr[STREAM].mrays_1t_wall > tr[best_m_wall].mrays_1t_wall)
            best_m_wall = STREAM;
        if (tr[STREAM].mrays_1t > tr[best_m_cpu].mrays_1t)
            best_m_cpu = STREAM;
        int best_e_wall = 2;
        int best_e_cpu = 2;
        for (int k = 3; k < 2 + N_EMBREE; k++) {
            best_e_wall = tr[k].mrays_1t_wall > tr[best_e_wall].mrays_1t_wall ? k : best_e_wall;
            best_e_cpu = tr[k].mrays_1t > tr[best_e_cpu].mrays_1t ? k : best_e_cpu;
        }
        double r_wall = tr[best_m_wall].mrays_1t_wall / tr[best_e_wall].mrays_1t_wall;
        double r_cpu = tr[best_m_cpu].mrays_1t / tr[best_e_cpu].mrays_1t;
        double r1 = tr[0].mrays_1t_wall / tr[2].mrays_1t_wall;
        double r_mt = tr[0].mrays_mt / tr[2].mrays_mt;
        printf("  best mcpt / best Embree: %.2f by wall clock (%s %.3f / %s %.3f), %.2f by CPU "
               "time (%s / %s); single / rtc*1 %.2f (wall), all threads %.2f; checksums: hits "
               "differ by %.5f%% of rays, t_sum by %.2e relative\n",
               r_wall, tr[best_m_wall].name, tr[best_m_wall].mrays_1t_wall, tr[best_e_wall].name,
               tr[best_e_wall].mrays_1t_wall, r_cpu, tr[best_m_cpu].name, tr[best_e_cpu].name, r1,
               r_mt, 100.0 * hit_diff, t_diff);
        printf("{\"model\":\"%s\",\"rays_file\":\"%s\",\"triangles\":%u,\"kind\":\"%s\","
               "\"rays\":%llu,\"build_ms\":%.3f,\"build_ms_embree\":%.3f,\"build_ms_mt\":%.3f,"
               "\"build_ms_mt_embree\":%.3f,\"bytes_per_tri\":%.2f,\"bytes_per_tri_embree\":%.2f,"
               "\"sah_cost\":%.4f,\"refs\":%u,\"build_ms_binned\":%.3f,"
               "\"build_ms_embree_medium\":%.3f,\"bytes_per_tri_binned\":%.2f,"
               "\"bytes_per_tri_embree_medium\":%.2f,\"hits\":%llu,\"hits_embree\":%llu,"
               "\"t_sum\":%.6e,\"t_sum_embree\":%.6e,\"prim_sum\":%llu,"
               "\"prim_sum_embree\":%llu,",
               model, argv[f], mesh.n_tris, occlusion ? "occlusion" : "closest",
               (unsigned long long)rays.n, mcpt_build[0], embree_build_ms[0], mcpt_build[1],
               embree_build_ms[1], mcpt_bpt, embree_bpt, st.sah_cost, st.n_refs,
               build_median[MCPT_BINNED][0], build_median[EMBREE_MEDIUM][0],
               bytes_per_tri[MCPT_BINNED], bytes_per_tri[EMBREE_MEDIUM],
               (unsigned long long)tr[0].sum.hits, (unsigned long long)tr[2].sum.hits,
               tr[0].sum.t_sum, tr[2].sum.t_sum, (unsigned long long)tr[0].sum.prim_sum,
               (unsigned long long)tr[2].sum.prim_sum);
        static const char *const keys[N_TRACERS] = {"mcpt",
                                                    "mcpt_packet",
                                                    "embree1",
                                                    "embree8",
                                                    "embree16",
                                                    "embree_stream_coherent",
                                                    "embree_stream_incoherent",
                                                    "mcpt_stream"};
        for (int k = 0; k < N_TRACERS; k++)
            printf("\"mrays_1t_wall_%s\":%.4f,\"mrays_1t_cpu_%s\":%.4f,\"mrays_mt_%s\":%.4f,",
                   keys[k], tr[k].mrays_1t_wall, keys[k], tr[k].mrays_1t, keys[k], tr[k].mrays_mt);
        printf("\"best_mcpt\":\"%s\",\"best_embree\":\"%s\",\"ratio_best\":%.4f,"
               "\"ratio_best_cpu\":%.4f,\"ratio_1t\":%.4f,\"ratio_mt\":%.4f,\"threads\":%d,"
               "\"runs\":%d,\"load_avg\":%.2f,\"robust\":%s,\"embree_quality\":\"%s\"}\n",
               keys[best_m_wall], keys[best_e_wall], r_wall, r_cpu, r1, r_mt, n_threads, runs,
               bench_loadavg(), robust ? "true" : "false", quality_name);
        fflush(stdout);
        for (int k = 0; k < N_TRACERS; k++) {
            free(prim[k]);
            free(t[k]);
        }
        bench_rays_free(&rays);
    }
    embree_free(&emb);
    bvh_free(bvh);
    bench_mesh_free(&mesh);
    return status;
}
