/* trace.h - the path-tracing integrator and the tile-scheduled render loop.
 * trace_prepare turns a loaded scene into what rendering needs (BVH, camera, light table);
 * trace_render adds samples to a film; trace_radiance estimates the radiance along one ray. */
#ifndef MCPT_TRACE_H
#define MCPT_TRACE_H

#include <stdatomic.h>

#include "bvh.h"
#include "film.h"
#include "sample.h"
#include "scene.h"

#define TRACE_DEPTH_INFINITE UINT32_MAX /* max_depth meaning "until Russian roulette ends it" */
#define TRACE_DEPTH_CAP 1024u /* hard cap on path segments when max_depth is infinite */
#define TRACE_TILE_SIZE 16    /* tile edge in pixels */

struct trace_scene; /* opaque: scene + BVH + camera + light-selection table */

/* Builds the BVH (with n_threads) and the light table for scene, which must outlive the result.
 * Returns NULL and fills *err on failure (bad camera, out of memory). */
struct trace_scene *trace_prepare(const struct scene *scene, int n_threads,
                                  struct mcpt_error *err);
void trace_free(struct trace_scene *ts);
struct bvh_stats trace_bvh_stats(const struct trace_scene *ts);

struct trace_options {
    uint32_t spp;           /* render every pixel up to this many samples */
    uint32_t sample_offset; /* sample index of a pixel's first film sample (split renders) */
    uint32_t max_depth;     /* path segments from the camera; TRACE_DEPTH_INFINITE allowed */
    uint64_t seed;
    enum sampler_kind sampler;
    int n_threads;
    const atomic_int *cancel; /* when non-NULL and nonzero, workers stop after their pixel */
    /* called about every 100 ms from the calling thread (may be NULL) */
    void (*progress)(void *user, uint64_t samples_done, uint64_t samples_total);
    void *progress_user;
};

struct trace_result {
    uint64_t n_samples;   /* camera samples added to the film by this call */
    uint64_t n_rays;      /* rays traced (camera, bounce and shadow) */
    uint64_t n_nonfinite; /* samples dropped because a component was NaN or infinite */
    uint32_t first_bad_x; /* pixel and sample index of the first dropped sample, if any */
    uint32_t first_bad_y;
    uint32_t first_bad_sample;
    bool cancelled;
};

/* Renders each pixel from its current count film->pixels[i].n up to opt->spp samples (sample
 * indices sample_offset + n), tiles handed out to opt->n_threads threads.  The film's result is
 * bit-identical for any thread count and any split of the work into calls.  Returns false only
 * when threads cannot be started (err filled). */
bool trace_render(const struct trace_scene *ts, const struct trace_options *opt, struct film *film,
                  struct trace_result *result, struct mcpt_error *err);

/* Radiance estimate along the camera ray of (pixel px, py; sample sampler), Kajiya 1986 eq. 1
 * solved by path tracing with NEE and MIS.  n_rays is incremented by rays traced. */
vec3 trace_radiance(const struct trace_scene *ts, const struct trace_options *opt,
                    struct ray ray, struct sampler *sampler, uint64_t *n_rays);

/* The camera ray of film position (px, py) for this sample's lens dimensions. */
struct ray trace_camera_ray(const struct trace_scene *ts, float px, float py, vec2 u_lens);

#endif
