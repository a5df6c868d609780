/* raybench.c - ray-throughput benchmark of mcpt's BVH (../shared/BENCHMARKS.md): builds the
 * BVH of a mesh and traces a ray file through it, printing build time, bytes per triangle, SAH
 * cost, Mrays/s on one thread and on all threads (median of R runs after a warm-up) and the
 * checksums, then one JSON line.  It also writes the standard ray sets, traces them in memory
 * for generated meshes (the scale table), and runs the brute-force baseline (--no-bvh). */
#include <getopt.h>
#include <stdlib.h>

#include "bench.h"
#include "bvh.h"

static const char usage[] =
    "usage: raybench MODEL RAYS.bin... [options]   trace ray files (one JSON line each)\n"
    "       raybench MODEL --gen SET -o RAYS.bin    write a standard ray set\n"
    "       raybench MODEL --gen all -o PREFIX      write PREFIX-primary.bin, -diffuse, -shadow\n"
    "       raybench MODEL --sets [--set SET] [options]  generate and trace the three sets\n"
    "       raybench MODEL --build-only [--threads N] [--build-runs B]  time the build alone\n"
    "MODEL is an OBJ file or torus:N, a generated bumpy torus of N triangles (N may end in k =\n"
    "2^10 or M = 2^20: torus:1M has exactly 2^20).  SET is primary, diffuse or shadow.\n"
    "options:\n"
    "  --threads N        threads of the all-threads figure and the build (default: all CPUs)\n"
    "  --runs R           timed runs after one warm-up; the median is reported (default 5)\n"
    "  --build-runs B     timed builds per thread count (default R)\n"
    "  --packets          also trace in packets of 8 rays (mrays_1t_packet) and in streams of 32\n"
    "                     (mrays_1t_stream)\n"
    "  --layout L         wide (default) or binary: the traversal to time\n"
    "  --no-bvh           brute force on a subset of the rays, against the BVH on the same rays\n"
    "  --subset K         rays of the --no-bvh subset, evenly strided (default 1000)\n"
    "  --set SET          with --sets: only this set\n";

struct options {
    const char *model;
    char **rays_paths; /* ray files to trace */
    int n_rays_paths;
    const char *gen_set;
    const char *out_path;
    bool sets;
    bool build_only; /* --build-only: time the build at --threads, no rays */
    int only_set; /* --set, or -1 */
    int threads;
    int runs;
    int build_runs;
    bool packets;
    enum bvh_layout layout;
    bool no_bvh;
    uint64_t subset;
};

/* Parses "torus:N[k|M]". */
static bool parse_torus(const char *model, uint64_t *n_tris)
{
    if (strncmp(model, "torus:", 6) != 0)
        return false;
    char *end;
    unsigned long long n = strtoull(model + 6, &end, 10);
    if (*end == 'k' || *end == 'K')
        n <<= 10, end++;
    else if (*end == 'M')
        n <<= 20, end++;
    if (*end != '\0' || n < 32) {
        fprintf(stderr, "raybench: expected torus:N with N >= 32, got %s\n", model);
        exit(2);
    }
    *n_tris = n;
    return true;
}

static bool load_model(const char *model, struct bench_mesh *mesh)
{
    uint64_t n_tris;
    if (parse_torus(model, &n_tris)) {
        if (!bench_mesh_torus(n_tris, mesh)) {
            fprintf(stderr, "raybench: out of memory for %s\n", model);
            return false;
        }
        return true;
    }
    struct mcpt_error err;
    if (!bench_mesh_load_obj(model, mesh, &err)) {
        char line[600];
        mcpt_error_format(&err, line, sizeof line);
        fprintf(stderr, "%s\n", line);
        return false;
    }
    return true;
}

/* Median build time over opt->build_runs builds after a warm-up; returns the last BVH. */
static struct bvh *timed_build(const struct bench_mesh *mesh, int n_threads, unsigned layouts,
                               int build_runs, double *build_ms)
{
    double times[64];
    struct bvh_build_options bo = {n_threads, layouts, BVH_QUALITY_DEFAULT};
    struct bvh *bvh = bvh_build_with(mesh->positions, mesh->indices, mesh->n_tris, &bo);
    int n = build_runs < 64 ? build_runs : 64;
    for (int r = 0; r < n && bvh; r++) {
        bvh_free(bvh);
        bvh = bvh_build_with(mesh->positions, mesh->indices, mesh->n_tris, &bo);
        if (bvh)
            times[r] = bvh_get_stats(bvh).build_ms;
    }
    if (!bvh) {
        fprintf(stderr, "raybench: out of memory building the BVH\n");
        return NULL;
    }
    *build_ms = n > 0 ? bench_median(times, n) : bvh_get_stats(bvh).build_ms;
    return bvh;
}

struct figures {
    struct bench_checksum sum;
    double mrays_1t;      /* by thread CPU time */
    double mrays_1t_wall; /* by wall time */
    double mrays_mt;      /* all threads, wall time */
};

/* Warm-up (which also gives the checksums), then R timed runs on one thread and, when
 * n_threads > 0, R on n_threads threads. */
static bool measure(const struct bvh *bvh, const struct bench_rays *rays, enum bench_method method,
                    int runs, int n_threads, struct figures *fig)
{
    uint32_t *prim = malloc(rays->n * sizeof *prim + 1);
    float *t = malloc(rays->n * sizeof *t + 1);
    if (!prim || !t) {
        free(prim);
        free(t);
        return false;
    }
    struct bench_trace tr = {bvh, rays, method, prim, t};
    bench_time_1t(bench_trace_range, &tr, rays->n);
    fig->sum = bench_checksum_of(rays, rays->n, prim, t);
    double cpu[64];
    double wall[64];
    int n = runs < 64 ? runs : 64;
    for (int r = 0; r < n; r++) {
        struct bench_time bt = bench_time_1t(bench_trace_range, &tr, rays->n);
        cpu[r] = bt.cpu_ms;
        wall[r] = bt.wall_ms;
    }
    fig->mrays_1t = (double)rays->n / bench_median(cpu, n) / 1e3;
    fig->mrays_1t_wall = (double)rays->n / bench_median(wall, n) / 1e3;
    fig->mrays_mt = 0.0;
    if (n_threads > 0) {
        bench_parallel(rays->n, 4096, n_threads, bench_trace_range, &tr);
        for (int r = 0; r < n; r++)
            wall[r] = bench_parallel(rays->n, 4096, n_threads, bench_trace_range, &tr);
        fig->mrays_mt = (double)rays->n / bench_median(wall, n) / 1e3;
    }
    free(prim);
    free(t);
    return true;
}

static const char *kind_name(uint32_t kind)
{
    return kind == BENCH_KIND_OCCLUSION ? "occlusion" : "closest";
}

/* Traces one ray set and prints its figures; the JSON line last. */
static bool run_set(const struct options *opt, const struct bench_mesh *mesh, const struct bvh *bvh,
                    double build_ms_1t, double build_ms_mt, const char *set_name,
                    const struct bench_rays *rays)
{
    struct bvh_stats st = bvh_get_stats(bvh);
    double bytes_per_tri = mesh->n_tris ? (double)st.bytes / (double)mesh->n_tris : 0.0;
    printf("rays: %s: %llu %s rays\n", set_name, (unsigned long long)rays->n,
           kind_name(rays->kind));
    if (opt->no_bvh) {
        /* the teaching table: naive O(n) per ray against the BVH, on the same strided subset */
        uint64_t k = opt->subset < rays->n ? opt->subset : rays->n;
        struct bench_rays sub = {rays->kind, k, malloc(k * sizeof(struct ray) + 1)};
        if (!sub.rays)
            return false;
        for (uint64_t i = 0; i < k; i++)
            sub.rays[i] = rays->rays[i * (rays->n / (k ? k : 1))];
        /* brute force once (it is slow; no warm-up needed), the BVH as usual */
        struct figures naive;
        struct figures fast;
        uint32_t *prim = malloc(k * sizeof *prim + 1);
        float *t = malloc(k * sizeof *t + 1);
        if (!prim || !t || !measure(bvh, &sub, BENCH_SINGLE, opt->runs, 0, &fast)) {
            free(prim);
            free(t);
            free(sub.rays);
            return false;
        }
        struct bench_trace tr = {bvh, &sub, BENCH_BRUTE, prim, t};
        struct bench_time bt = bench_time_1t(bench_trace_range, &tr, k);
        naive.sum = bench_checksum_of(&sub, k, prim, t);
        free(prim);
        free(t);
        double naive_s = bt.cpu_ms * 1e-3;
        double bvh_s = (double)k / (fast.mrays_1t * 1e6);
        printf("no-bvh: %llu rays: brute force %.3f s, BVH %.6f s (%.0fx); hits %llu vs %llu\n",
               (unsigned long long)k, naive_s, bvh_s, naive_s / bvh_s,
               (unsigned long long)naive.sum.hits, (unsigned long long)fast.sum.hits);
        printf("{\"triangles\":%u,\"kind\":\"%s\",\"subset\":%llu,\"naive_s\":%.6g,\"bvh_s\":%.6g,"
               "\"hits_naive\":%llu,\"hits_bvh\":%llu,\"t_sum_naive\":%.6e,\"t_sum_bvh\":%.6e}\n",
               mesh->n_tris, kind_name(rays->kind), (unsigned long long)k, naive_s, bvh_s,
               (unsigned long long)naive.sum.hits, (unsigned long long)fast.sum.hits,
               naive.sum.t_sum, fast.sum.t_sum);
        free(sub.rays);
        return true;
    }
    struct figures single;
    struct figures packet = {{0, 0.0, 0}, 0.0, 0.0, 0.0};
    if (!measure(bvh, rays, BENCH_SINGLE, opt->runs, opt->threads, &single))
        return false;
    if (opt->packets && !measure(bvh, rays, BENCH_PACKET, opt->runs, 0, &packet))
        return false;
    bool streams = opt->packets; /* and streams */
    struct figures stream = {{0, 0.0, 0}, 0.0, 0.0, 0.0};
    if (streams && !measure(bvh, rays, BENCH_STREAM, opt->runs, 0, &stream))
        return false;
    if (rays->kind == BENCH_KIND_CLOSEST)
        printf("checksum: hits %llu t_sum %.6e prim_sum %llu\n",
               (unsigned long long)single.sum.hits, single.sum.t_sum,
               (unsigned long long)single.sum.prim_sum);
    else
        printf("checksum: occluded %llu\n", (unsigned long long)single.sum.hits);
    printf("single thread: %.3f Mrays/s (CPU time; %.3f by wall clock)\n", single.mrays_1t,
           single.mrays_1t_wall);
    if (opt->packets) {
        printf("packets of %d: %.3f Mrays/s (CPU time; %.3f by wall clock)%s\n", BVH_PACKET_SIZE,
               packet.mrays_1t, packet.mrays_1t_wall,
               packet.sum.hits == single.sum.hits ? "" : "  CHECKSUM DIFFERS");
    }
    if (streams)
        printf("streams of %d: %.3f Mrays/s (CPU time; %.3f by wall clock)%s\n", BVH_STREAM_RAYS,
               stream.mrays_1t, stream.mrays_1t_wall,
               stream.sum.hits == single.sum.hits ? "" : "  CHECKSUM DIFFERS");
    printf("all threads (%d): %.3f Mrays/s (wall clock)\n", opt->threads, single.mrays_mt);
    printf("{\"model\":\"%s\",\"rays_file\":\"%s\",\"triangles\":%u,\"build_ms\":%.3f,"
           "\"build_ms_mt\":%.3f,\"bytes_per_tri\":%.2f,\"sah_cost\":%.4f,\"kind\":\"%s\","
           "\"rays\":%llu,\"hits\":%llu,",
           opt->model, set_name, mesh->n_tris, build_ms_1t, build_ms_mt, bytes_per_tri, st.sah_cost,
           kind_name(rays->kind), (unsigned long long)rays->n, (unsigned long long)single.sum.hits);
    if (rays->kind == BENCH_KIND_CLOSEST)
        printf("\"t_sum\":%.6e,\"prim_sum\":%llu,", single.sum.t_sum,
               (unsigned long long)single.sum.prim_sum);
    else
        printf("\"t_sum\":null,\"prim_sum\":null,");
    printf("\"mrays_1t\":%.4f,\"mrays_1t_wall\":%.4f,\"mrays_mt\":%.4f,", single.mrays_1t,
           single.mrays_1t_wall, single.mrays_mt);
    if (opt->packets)
        printf("\"mrays_1t_packet\":%.4f,", packet.mrays_1t);
    if (streams)
        printf("\"mrays_1t_stream\":%.4f,", stream.mrays_1t);
    printf("\"threads\":%d,\"layout\":\"%s\",\"simd\":\"%s\",\"load_avg\":%.2f}\n", opt->threads,
           opt->layout == BVH_LAYOUT_WIDE ? "wide" : "binary", bvh_simd_name(), bench_loadavg());
    fflush(stdout);
    return true;
}

static int parse_set(const char *name)
{
    for (int s = 0; s < BENCH_N_SETS; s++)
        if (strcmp(name, bench_set_names[s]) == 0)
            return s;
    return -1;
}

static int parse_int(const char *arg, const char *what, int lo)
{
    char *end;
    long v = strtol(arg, &end, 10);
    if (*end != '\0' || v < lo || v > 1 << 20) {
        fprintf(stderr, "raybench: expected %s >= %d, got '%s'\n", what, lo, arg);
        exit(2);
    }
    return (int)v;
}

int main(int argc, char **argv)
{
    struct options opt = {.threads = bench_n_cpus(),
                          .runs = 5,
                          .build_runs = -1,
                          .only_set = -1,
                          .layout = BVH_LAYOUT_WIDE,
                          .subset = 1000};
    static const struct option long_opts[] = {
        {"gen", required_argument, NULL, 'g'},        {"sets", no_argument, NULL, 'S'},
        {"threads", required_argument, NULL, 't'},    {"runs", required_argument, NULL, 'r'},
        {"build-runs", required_argument, NULL, 'b'}, {"packets", no_argument, NULL, 'p'},
        {"layout", required_argument, NULL, 'l'},     {"no-bvh", no_argument, NULL, 'n'},
        {"subset", required_argument, NULL, 'k'},     {"help", no_argument, NULL, 'h'},
        {"set", required_argument, NULL, 's'},        {"build-only", no_argument, NULL, 'B'},
        {NULL, 0, NULL, 0}};
    int c;
    while ((c = getopt_long(argc, argv, "o:h", long_opts, NULL)) != -1) {
        switch (c) {
        case 'g':
            opt.gen_set = optarg;
            break;
        case 'o':
            opt.out_path = optarg;
            break;
        case 'S':
            opt.sets = true;
            break;
        case 't':
            opt.threads = parse_int(optarg, "--threads", 1);
            break;
        case 'r':
            opt.runs = parse_int(optarg, "--runs", 1);
            break;
        case 'b':
            opt.build_runs = parse_int(optarg, "--build-runs", 0);
            break;
        case 'B':
            opt.build_only = true;
            break;
        case 'p':
            opt.packets = true;
            break;
        case 'n':
            opt.no_bvh = true;
            break;
        case 'k':
            opt.subset = (uint64_t)parse_int(optarg, "--subset", 1);
            break;
        case 's':
            if ((opt.only_set = parse_set(optarg)) < 0) {
                fprintf(stderr, "raybench: expected --set primary, diffuse or shadow, got '%s'\n",
                        optarg);
                return 2;
            }
            break;
        case 'l':
            if (strcmp(optarg, "wide") == 0) {
                opt.layout = BVH_LAYOUT_WIDE;
            } else if (strcmp(optarg, "binary") == 0) {
                opt.layout = BVH_LAYOUT_BINARY;
            } else {
                fprintf(stderr, "raybench: expected --layout wide or binary, got '%s'\n", optarg);
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
    if (opt.build_runs < 0)
        opt.build_runs = opt.runs;
    int n_pos = argc - optind;
    bool trace_files = !opt.gen_set && !opt.sets && !opt.build_only;
    if (n_pos < 1 || (trace_files ? n_pos < 2 : n_pos != 1) || (opt.gen_set && !opt.out_path)) {
        fputs(usage, stderr);
        return 2;
    }
    opt.model = argv[optind];
    opt.rays_paths = argv + optind + 1;
    opt.n_rays_paths = trace_files ? n_pos - 1 : 0;
    int gen = -1;
    if (opt.gen_set && strcmp(opt.gen_set, "all") != 0 && (gen = parse_set(opt.gen_set)) < 0) {
        fprintf(stderr, "raybench: expected --gen primary, diffuse, shadow or all, got '%s'\n",
                opt.gen_set);
        return 2;
    }
    /* read the rays first: bad input costs no build */
    struct bench_rays *file_rays = calloc((size_t)opt.n_rays_paths + 1, sizeof *file_rays);
    if (!file_rays)
        return 1;
    for (int i = 0; i < opt.n_rays_paths; i++) {
        struct mcpt_error err;
        if (!bench_rays_read(opt.rays_paths[i], &file_rays[i], &err)) {
            char line[600];
            mcpt_error_format(&err, line, sizeof line);
            fprintf(stderr, "%s\n", line);
            for (int j = 0; j < i; j++)
                bench_rays_free(&file_rays[j]);
            free(file_rays);
            return 2;
        }
    }
    struct bench_mesh mesh;
    if (!load_model(opt.model, &mesh)) {
        for (int i = 0; i < opt.n_rays_paths; i++)
            bench_rays_free(&file_rays[i]);
        free(file_rays);
        return 2;
    }
    int status = 1;
    struct bvh *bvh = NULL;
    struct bench_rays sets[BENCH_N_SETS] = {{0}};
    printf("model: %s: %u triangles; load average %.2f on %d CPUs; kernels %s\n", opt.model,
           mesh.n_tris, bench_loadavg(), bench_n_cpus(), bvh_simd_name());
    if (opt.gen_set) {
        bvh = bvh_build(mesh.positions, mesh.indices, mesh.n_tris, opt.threads);
        if (!bvh || !bench_gen_sets(&mesh, bvh, sets)) {
            fprintf(stderr, "raybench: out of memory\n");
            goto done;
        }
        for (int set = 0; set < BENCH_N_SETS; set++) {
            if (gen >= 0 && set != gen)
                continue;
            char path[4096];
            if (gen >= 0)
                snprintf(path, sizeof path, "%s", opt.out_path);
            else
                snprintf(path, sizeof path, "%s-%s.bin", opt.out_path, bench_set_names[set]);
            struct mcpt_error err;
            if (!bench_rays_write(path, &sets[set], &err)) {
                char line[600];
                mcpt_error_format(&err, line, sizeof line);
                fprintf(stderr, "%s\n", line);
                goto done;
            }
            printf("wrote %s: %llu %s rays\n", path, (unsigned long long)sets[set].n,
                   bench_set_names[set]);
        }
        status = 0;
        goto done;
    }
    if (opt.build_only) { /* one line: the median build on --threads threads */
        double ms = 0.0;
        bvh = timed_build(&mesh, opt.threads, opt.layout, opt.build_runs, &ms);
        if (!bvh)
            goto done;
        struct bvh_stats bs = bvh_get_stats(bvh);
        printf("{\"model\":\"%s\",\"triangles\":%u,\"threads\":%d,\"build_ms\":%.3f,"
               "\"convert_ms\":%.3f,\"build_runs\":%d,\"bytes_per_tri\":%.2f,\"sah_cost\":%.4f,"
               "\"layout_hash\":\"%016llx\",\"peak_rss_mib\":%.1f}\n",
               opt.model, mesh.n_tris, opt.threads, ms, bs.convert_ms, opt.build_runs,
               mesh.n_tris ? (double)bs.bytes / (double)mesh.n_tris : 0.0, bs.sah_cost,
               (unsigned long long)bvh_layout_hash(bvh), (double)bench_peak_rss_kib() / 1024.0);
        status = 0;
        goto done;
    }
    /* build: median of the timed builds on one thread, then on all threads */
    double build_ms_1t = 0.0;
    double build_ms_mt = 0.0;
    bvh = timed_build(&mesh, 1, opt.layout, opt.build_runs, &build_ms_1t);
    if (!bvh)
        goto done;
    if (opt.threads > 1) {
        bvh_free(bvh);
        bvh = timed_build(&mesh, opt.threads, opt.layout, opt.build_runs, &build_ms_mt);
        if (!bvh)
            goto done;
    } else {
        build_ms_mt = build_ms_1t;
    }
    struct bvh_stats st = bvh_get_stats(bvh);
    printf("build: %.1f ms on 1 thread, %.1f ms on %d (median of %d); conversion %.1f ms\n",
           build_ms_1t, build_ms_mt, opt.threads, opt.build_runs, st.convert_ms);
    printf("tree: %u binary nodes, %u leaves, depth %u, SAH cost %.2f; %u wide nodes, %u wide "
           "leaves; %.1f bytes/triangle (%zu bytes)\n",
           st.n_nodes, st.n_leaves, st.max_depth, st.sah_cost, st.n_wide_nodes, st.n_wide_leaves,
           mesh.n_tris ? (double)st.bytes / (double)mesh.n_tris : 0.0, st.bytes);
    if (opt.n_rays_paths > 0) {
        for (int i = 0; i < opt.n_rays_paths; i++)
            if (!run_set(&opt, &mesh, bvh, build_ms_1t, build_ms_mt, opt.rays_paths[i],
                         &file_rays[i]))
                goto done;
        status = 0;
        goto done;
    }
    if (!bench_gen_sets(&mesh, bvh, sets)) {
        fprintf(stderr, "raybench: out of memory\n");
        goto done;
    }
    for (int s = 0; s < BENCH_N_SETS; s++)
        if ((opt.only_set < 0 || opt.only_set == s) &&
            !run_set(&opt, &mesh, bvh, build_ms_1t, build_ms_mt, bench_set_names[s], &sets[s]))
            goto done;
    printf("{\"model\":\"%s\",\"triangles\":%u,\"build_ms\":%.3f,\"build_ms_mt\":%.3f,"
           "\"bytes_per_tri\":%.2f,\"sah_cost\":%.4f,\"peak_rss_mib\":%.1f}\n",
           opt.model, mesh.n_tris, build_ms_1t, build_ms_mt,
           mesh.n_tris ? (double)st.bytes / (double)mesh.n_tris : 0.0, st.sah_cost,
           (double)bench_peak_rss_kib() / 1024.0);
    status = 0;
done:
    for (int s = 0; s < BENCH_N_SETS; s++)
        bench_rays_free(&sets[s]);
    for (int i = 0; i < opt.n_rays_paths; i++)
        bench_rays_free(&file_rays[i]);
    free(file_rays);
    bvh_free(bvh);
    bench_mesh_free(&mesh);
    return status;
}
