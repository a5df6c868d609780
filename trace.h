/* trace.h - the path-tracing integrator and the tile-scheduled render loop.
 * trace_prepare turns a loaded scene into what rendering needs (BVH, camera, light table of
 * light.h); trace_render adds samples to a film; trace_radiance estimates the radiance along one
 * ray.  Depths count bounces (scattering events): 0 = emission seen directly, 1 = direct light. */
#ifndef MCPT_TRACE_H
#define MCPT_TRACE_H

#include <stdatomic.h>

#include "bvh.h"
#include "film.h"
#include "sample.h"
#include "scene.h"

#define TRACE_DEPTH_INFINITE UINT32_MAX /* max_depth meaning "until Russian roulette ends it" */
#define TRACE_DEPTH_CAP 1024u           /* hard cap on bounces, whatever max_depth says */
#define TRACE_TILE_SIZE 16              /* tile edge in pixels */

struct trace_scene; /* opaque: scene + BVH + camera + light table */

/* Builds the BVH (with n_threads) and the light table for scene, which must outlive the result.
 * Returns NULL and fills *err on failure: a bad-input error for a bad camera or a light of
 * non-finite power (light_table_build), a runtime error when memory runs out. */
struct trace_scene *trace_prepare(const struct scene *scene, int n_threads, struct mcpt_error *err);
/* Benchmarks and tests: the scene's spheres and quads found through a tree over their boxes
 * (on) or tested one by one (off), whatever trace_prepare chose by their number; the image is
 * the same.  False where out of memory (the shapes are then tested one by one). */
bool trace_set_shape_tree(struct trace_scene *ts, bool on);

void trace_free(struct trace_scene *ts);
struct bvh_stats trace_bvh_stats(const struct trace_scene *ts);

struct trace_options {
    uint32_t spp;           /* render every pixel up to this many samples */
    uint32_t sample_offset; /* sample index of a pixel's first film sample (split renders) */
    uint32_t max_depth;     /* bounces (0: emission seen directly only); TRACE_DEPTH_INFINITE */
    uint64_t seed;
    enum sampler_kind sampler;
    int n_threads;
    const atomic_int *cancel; /* when non-NULL and nonzero, workers stop after their pixel */
    /* called about every 100 ms from the calling thread (may be NULL) */
    void (*progress)(void *user, uint64_t samples_done, uint64_t samples_total);
    void *progress_user;
    /* sampling (docs/sampling.md) */
    uint32_t sampler_spp; /* stratified: samples per stratified set; 0 = spp, or batch when
                              adaptive.  Progressive renders pass their final spp here so that
                              the last image equals a one-call render. */
    bool adaptive;        /* adaptive sampling (docs/sampling.md); spp is then the maximum */
    enum render_adaptive_rule adaptive_rule; /* pilot or budget (unbiased), or stop (the
                                                teaching rule) */
    uint32_t budget_spp;    /* adaptive budget: the mean samples per pixel, its pilot included */
    float tolerance;        /* adaptive: T, relative half-width of the 95% interval */
    float adaptive_floor;   /* adaptive: luminance below which T applies absolutely */
    uint32_t min_spp;       /* adaptive: stop, samples before the first test; pilot, the least
                             samples a pixel gets */
    uint32_t batch;         /* adaptive: samples between tests, or the pilot's unit (>= 1) */
    uint32_t pilot_spp;     /* adaptive pilot: samples of the pilot (>= 2); 0 means the default */
    uint32_t max_spp;       /* adaptive pilot: most samples a pixel gets; 0 = spp.  A render in
                             passes (spp growing to max_spp) must give the final maximum. */
    uint32_t *pilot_target; /* adaptive pilot and budget: per pixel, its sample count once
                               computed (0 before), kept between the calls of a render in
                               passes; NULL: recomputed by every call (the same numbers, more
                               work) */
    /* light transport (trace_radiance) */
    enum render_direct direct; /* direct-lighting estimator; 0 is RENDER_DIRECT_MIS */
    uint32_t light_samples;    /* light samples (shadow rays) per path vertex; 0 means 1 */
    enum render_split split;   /* bounces kept; 0 is RENDER_SPLIT_FULL */
    float rr_prob;             /* Russian roulette: fixed continuation probability in (0, 1], or
                                  0 for the throughput-based rule, min(1, max beta / threshold) */
    float rr_threshold;        /* the throughput below which roulette plays; 0 means
                                  TRACE_RR_THRESHOLD_DEFAULT */
    uint32_t rr_depth;         /* roulette may end a path after its rr_depth-th bounce and any
                                  later one; 0 means TRACE_RR_DEPTH_DEFAULT */
    /* benchmarking (may be NULL): every ray the render traces, from the thread that traces it
     * (so the hook must be thread-safe, or the render use one thread): camera and bounce rays
     * (closest hit, is_shadow false) and shadow rays (any hit, is_shadow true).  bench/raydump
     * writes them as ray files for bench/raybench. */
    void (*ray_hook)(void *user, const struct ray *ray, bool is_shadow);
    void *ray_hook_user;
    /* benchmarking and tests: every camera ray intersected alone, not in the packets of
     * render_pixel; the image is the same to the bit (bench/packetbench times the two) */
    bool single_rays;
};

#define TRACE_RR_DEPTH_DEFAULT 2u /* as PBRT 4e: the first two bounces are never cut short */
/* Paths whose throughput max(beta) eta^2 is at least this never meet roulette; below, they go on
 * with probability max(beta) eta^2 / threshold and carry the threshold as their weight.  PBRT
 * 4e's rule is 1; 0.25 measured 1.5x more efficient on the Cornell box (docs/performance.md,
 * "Per-sample error"). */
#define TRACE_RR_THRESHOLD_DEFAULT 0.25f

#define TRACE_ADAPTIVE_TOLERANCE 0.1f /* default T (docs/sampling.md: why) */
#define TRACE_ADAPTIVE_FLOOR 0.01f    /* default floor, luminance in the image's linear units */
#define TRACE_ADAPTIVE_BATCH 32u      /* default batch */
#define TRACE_ADAPTIVE_MIN_SPP 64u    /* default minimum spp */
#define TRACE_ADAPTIVE_PILOT_SPP 16u  /* default pilot samples */
#define TRACE_BUDGET_PILOT_SPP 8u     /* default pilot samples of the budget rule */
#define TRACE_BUDGET_MAX_FACTOR 8u    /* budget rule: default max-spp, this times the budget */
/* budget rule: p, a pixel's count grows as (sigma / sqrt(t))^p for its pilot's sigma and rays
 * per sample t (trace_budget_counts; docs/performance.md, "Adaptive sampling": measured on the
 * Cornell box, where 0.35-0.5 did best; plain Monte Carlo's optimum is 1) */
#define TRACE_BUDGET_POWER 0.4

/* The adaptive stopping rule on one pixel's n samples of luminance x, s1 = sum x and
 * s2 = sum x^2: mu = s1 / n, sigma^2 = s2 / n - mu^2, I = 1.96 sigma / sqrt(n) (the half-width
 * of the normal 95% confidence interval of the mean); true when I <= T max(mu, floor).  The
 * floor makes the test absolute (I <= T floor) for pixels darker than floor, which would
 * otherwise never reach a relative tolerance; n = 0 never stops.  Pure: a pixel's decisions
 * depend on its own samples only, so adaptive renders are identical for any thread count. */
bool trace_adaptive_stop(double s1, double s2, uint64_t n, double tolerance, double floor_lum);

/* The pilot rule's sample count for a pixel whose pilot gave n samples of luminance with
 * s1 = sum x, s2 = sum x^2 (mu, sigma^2 as in trace_adaptive_stop): the N at which
 * I = 1.96 sigma / sqrt(N) reaches T max(mu, floor), N = (1.96 sigma / (T max(mu, floor)))^2,
 * rounded up to whole batches and clamped to [min_spp, max_spp].  Pure, like the stop rule. */
uint32_t trace_pilot_spp(double s1, double s2, uint64_t n, double tolerance, double floor_lum,
                         uint32_t min_spp, uint32_t max_spp, uint32_t batch);

/* The budget rule's sample counts: count[i] = clamp(2^round(log2(k w[i])), min_spp, max_spp) for
 * the n pixels' weights w[i] >= 0, given as log2w[i] = log2 w[i] (-inf for w = 0, which gets
 * min_spp), with the largest scale k at which sum_i count[i] cost[i] <= total (cost NULL: 1
 * each).  Powers of two keep each pixel's Sobol' prefix a whole (0, m, 2)-net.  Minimising
 * sum_i sigma_i^2 / n_i subject to sum_i n_i t_i = T gives n_i proportional to
 * sigma_i / sqrt(t_i) (the Lagrange condition sigma_i^2 / n_i^2 = lambda t_i: Neyman's 1934
 * optimal allocation over strata, with costs as in Cochran's "Sampling Techniques", sec. 5.5);
 * the caller passes w = (sigma / sqrt(t))^TRACE_BUDGET_POWER, a power below 1 because a Sobol'
 * pixel's error falls faster than 1 / n.  Every count is min_spp when even those exceed total.
 * Pure: the same weights give the same counts. */
void trace_budget_counts(const double *log2w, const double *cost, size_t n, double total,
                         uint32_t min_spp, uint32_t max_spp, uint32_t *count);

struct trace_result {
    uint64_t n_samples;   /* camera samples added to the film by this call */
    uint64_t n_pilot;     /* camera samples of adaptive pilots (traced, not in the film) */
    uint64_t n_rays;      /* rays traced (camera, bounce and shadow) */
    uint64_t n_nonfinite; /* samples dropped because a component was NaN or infinite */
    uint32_t first_bad_x; /* pixel and sample index of the first dropped sample, if any */
    uint32_t first_bad_y;
    uint32_t first_bad_sample;
    bool cancelled;
};

/* Adds the counts of r to sum; sum keeps its first dropped sample, else takes r's. */
void trace_result_add(struct trace_result *sum, const struct trace_result *r);

/* Renders each pixel from its current count film->pixels[i].n up to opt->spp samples (sample
 * indices sample_offset + n), tiles handed out to opt->n_threads threads.  With opt->adaptive,
 * by the stop rule a pixel also stops when trace_adaptive_stop holds at a test point, i.e. when
 * n + n_dropped is min_spp + k batch (k >= 0); by the pilot rule it renders only up to the count
 * trace_pilot_spp gives for its pilot, pilot_spp samples from a stream independent of the
 * image's (seed hashed with a tag), which the film never sees.  The film's result is
 * bit-identical for any thread count and any split of the work into calls.  Returns false only
 * when threads cannot be started (err filled). */
bool trace_render(const struct trace_scene *ts, const struct trace_options *opt, struct film *film,
                  struct trace_result *result, struct mcpt_error *err);

/* Radiance estimate along ray (a camera ray), Kajiya 1986 eq. 1 solved by path tracing with the
 * estimator opt->direct (NEE and MIS by default), up to opt->max_depth bounces, keeping the
 * bounces opt->split asks for.  sampler is the camera sample's, past its pixel and lens
 * dimensions; the path reads its bounce dimensions from it (sample.h).  *n_rays is incremented
 * by the rays traced. */
vec3 trace_radiance(const struct trace_scene *ts, const struct trace_options *opt, struct ray ray,
                    struct sampler *sampler, uint64_t *n_rays);

/* The camera ray of film position (px, py) for this sample's lens dimensions. */
struct ray trace_camera_ray(const struct trace_scene *ts, float px, float py, vec2 u_lens);

#endif
