/* bench_scene.c - see bench_scene.h. */
#include "bench_scene.h"

#include <stdio.h>
#include <stdlib.h>

bool bench_parse_u32(const char *prog, const char *s, const char *name, uint32_t min, uint32_t *v)
{
    char *end;
    unsigned long long x = strtoull(s, &end, 10);
    if (*s == '\0' || *end != '\0' || x < min || x > UINT32_MAX) {
        fprintf(stderr, "%s: expected %s >= %u, got '%s'\n", prog, name, min, s);
        return false;
    }
    *v = (uint32_t)x;
    return true;
}

bool bench_scene_load(const char *path, uint32_t width, uint32_t height, uint32_t spp,
                      uint32_t seed, struct scene *scene, struct trace_options *opt)
{
    struct mcpt_error err;
    if (!scene_load(path, scene, &err)) {
        char line[600];
        mcpt_error_format(&err, line, sizeof line);
        fprintf(stderr, "%s\n", line);
        return false;
    }
    if (width)
        scene->width = (int)width;
    if (height)
        scene->height = (int)height;
    *opt = (struct trace_options){
        .spp = spp,
        .max_depth = scene->render.max_depth,
        .seed = seed,
        .sampler = scene->render.sampler,
        .n_threads = 1,
        .direct = scene->render.direct,
        .light_samples = scene->render.light_samples,
        .split = scene->render.split,
        .rr_prob = scene->render.rr_prob,
        .rr_threshold = scene->render.rr_threshold,
        .rr_depth = scene->render.rr_depth,
    };
    return true;
}
