/* trace.c - unidirectional path tracing with next-event estimation and multiple importance
 * sampling, and the tile-scheduled render loop.  Lights live in light.c, shapes in shape.c.
 *
 * Estimator: Kajiya 1986, eq. 1, L(x, wo) = Le(x, wo) + int f(x, wo, wi) L(x', -wi) |cos| dwi,
 * sampled one path vertex at a time, beta carrying the product of f |cos| / pdf so far:
 *   L += beta Le w_bsdf                                   (emission the path runs into)
 *   L += beta (1/N) sum_j f |cos theta_i| Le / (pmf pdf_light) w_light   (N light samples)
 *   beta *= f |cos theta_i| / pdf_bsdf                    (the next direction)
 * with the power heuristic over the sample counts (Veach 1997, sec. 9.2.4, eq. 9.13)
 *   w_light = (N pmf pdf_light)^2 / ((N pmf pdf_light)^2 + pdf_bsdf^2),
 *   w_bsdf = pdf_bsdf^2 / (pdf_bsdf^2 + (N pmf pdf_light)^2)  (both densities at one direction);
 * the teaching estimators (--direct) drop one strategy or sample directions independently of
 * the BSDF.  Russian roulette on the throughput or with a fixed probability (PBRT 4e, ch. 13,
 * "A Better Path Tracer").  Bounces: 0 = emission seen directly, 1 = direct light, ...
 *
 * Glossary (PBRT's symbols): wo, wi - unit directions away from the surface (wo towards the
 * previous vertex, wi towards the next); n, ng, ns - normals (geometric, shading); L - radiance
 * carried to the camera; Le - emitted radiance; f - BSDF value; beta - path throughput
 * f |cos| / pdf accumulated along the path; pdf_sa, pdf_area - densities per steradian and per
 * unit area; pmf - discrete probability of picking a light; N - light samples per vertex. */
#include "trace.h"

#include <math.h>
#include <pthread.h>
#include <stdlib.h>
#include <time.h>

#include "camera.h"
#include "light.h"
#include "material.h"

/* Camera rays are intersected TRACE_PACKET at a time (a BVH packet), the samples of one pixel
 * (render_pixel); fewer than TRACE_PACKET_MIN go one by one, and so do all of them with
 * trace_options.single_rays (the same image to the bit).  docs/performance.md measures it. */
#define TRACE_PACKET BVH_PACKET_SIZE
#define TRACE_PACKET_MIN 2

/* A scene of at most this many triangles keeps each one's plane for its hits (trace_prepare):
 * 8192 of 160 bytes, 1.25 MiB. */
#define TRACE_PLANE_CACHE_TRIS 8192u

/* A scene with at least this many spheres and quads finds their hits through a tree over their
 * boxes (bvh_boxes_build); fewer are tested one by one.  Tree against loop, one thread, user
 * time (docs/bvh.md, "Analytic shapes"): cornell-spheres (8) x1.06, depth-of-field (8) x1.00,
 * glass-balls (9) x0.96, materials (11) x0.93, random-spheres (484) x0.16. */
#define TRACE_SHAPE_TREE_MIN 9u

/* PBRT 4e, ch. 6, "Robust Spawned Ray Origins": shadow rays stop this fraction short of the
 * light point, whose own origin is offset by its error bound. */
static const float SHADOW_EPSILON = 1e-4f;

struct trace_scene {
    const struct scene *scene;
    struct bvh *bvh;
    struct camera camera;
    struct light_table *lights;
    struct triangle_plane *planes; /* each triangle's, in a small scene (trace_prepare); or NULL */
    struct bvh_boxes *shapes;      /* spheres then quads, where the scene has many; or NULL */
};

/* What a ray hit: the surface and, if the primitive is an area light, its light index. */
struct hit_record {
    struct surface sf;
    uint32_t light_idx; /* or LIGHT_NONE */
    uint32_t tri;       /* the triangle hit (the BVH's prim_idx), or BVH_NO_PRIM */
};

/* The first intersection of a camera ray, found before its path starts (the packets of the
 * render loop). */
struct first_hit {
    bool hit;
    struct hit_record hr; /* when hit */
};

/* A path vertex as the estimators see it. */
struct vertex {
    const struct surface *sf;
    const struct material *m; /* the material, its albedo texture looked up */
    vec3 t;                   /* shading frame: x = t, y = b, z = sf->ns */
    vec3 b;
    vec3 wo_world; /* unit direction towards the previous vertex */
    vec3 wo;       /* wo_world in the shading frame */
    vec3 n_sky;    /* ns turned to the side of wo: the sky is sampled about it */
    uint32_t tri;  /* the triangle it lies on, or BVH_NO_PRIM: its rays never report it */
};

/* The vertex a ray left from and how its direction was drawn: what MIS needs to weigh the
 * emission that ray finds. */
struct last_bounce {
    struct surface sf; /* the vertex (valid once the path has bounced) */
    vec3 n_sky;        /* its sky-sampling normal */
    float pdf_bsdf;    /* solid-angle pdf of the direction sample */
    bool is_specular;  /* the sample came from a delta lobe: no MIS */
};

static void count_ray(const struct trace_options *opt, const struct ray *ray, bool is_shadow,
                      uint64_t *n_rays);
static vec3 radiance(const struct trace_scene *ts, const struct trace_options *opt, struct ray ray,
                     const struct first_hit *first, struct sampler *sampler, uint64_t *n_rays);
static bool intersect(const struct trace_scene *ts, const struct ray *ray, uint32_t from,
                      struct hit_record *hr);
static bool intersect_camera_rays(const struct trace_scene *ts, const struct trace_options *opt,
                                  const struct ray *rays, uint32_t n, struct first_hit *first);
static bool occluded(const struct trace_scene *ts, const struct ray *ray, uint32_t from);
static struct ray spawn_ray(const struct surface *sf, vec3 d);
static struct ray spawn_ray_to(const struct surface *from, vec3 p_to, vec3 p_to_error, vec3 n_to);
static struct vertex make_vertex(const struct surface *sf, const struct material *m, vec3 wo_world,
                                 struct material *m_textured);
static float emission_weight(const struct trace_scene *ts, const struct trace_options *opt,
                             const struct last_bounce *last, uint32_t light_idx,
                             const struct surface *on, vec3 wi);
static struct sampler *light_sampler(struct sampler *sampler, struct sampler *extra,
                                     bool *extra_started, uint32_t bounce, uint32_t j,
                                     uint32_t n_ls);
static vec3 sample_one_light(const struct trace_scene *ts, const struct trace_options *opt,
                             const struct vertex *v, float u_choice, vec2 u_light,
                             uint64_t *n_rays);
static bool sample_direction(const struct material *m, vec3 wo, enum render_direct direct,
                             float u_lobe, vec2 u, struct mat_sample *s);

/* Does the image keep a contribution that left the light n_bounces scattering events before
 * reaching the camera?  Direct: 0 (emission seen directly) and 1; indirect: the rest. */
static bool split_keeps(enum render_split split, uint32_t n_bounces)
{
    return split == RENDER_SPLIT_FULL || (split == RENDER_SPLIT_DIRECT) == (n_bounces <= 1);
}

/* ---- the path loop ---- */

vec3 trace_radiance(const struct trace_scene *ts, const struct trace_options *opt, struct ray ray,
                    struct sampler *sampler, uint64_t *n_rays)
{
    return radiance(ts, opt, ray, NULL, sampler, n_rays);
}

/* trace_radiance, with the camera ray's intersection already found when first is not NULL. */
static vec3 radiance(const struct trace_scene *ts, const struct trace_options *opt, struct ray ray,
                     const struct first_hit *first, struct sampler *sampler, uint64_t *n_rays)
{
    const struct scene *scene = ts->scene;
    const uint32_t n_ls = opt->light_samples ? opt->light_samples : 1;
    const uint32_t rr_depth = opt->rr_depth ? opt->rr_depth : TRACE_RR_DEPTH_DEFAULT;
    const float rr_threshold = opt->rr_threshold > 0.0f ? opt->rr_threshold
                                                        : TRACE_RR_THRESHOLD_DEFAULT;
    /* inf (TRACE_DEPTH_INFINITE) and anything deeper stop at the cap, which also keeps the
     * bounce dimensions below sample.h's SAMPLE_DIM_LIGHT_EXTRA */
    uint32_t max_bounces = opt->max_depth < TRACE_DEPTH_CAP ? opt->max_depth : TRACE_DEPTH_CAP;
    if (opt->split == RENDER_SPLIT_DIRECT && max_bounces > 1)
        max_bounces = 1; /* nothing beyond the first bounce is kept */
    vec3 L = v3_splat(0.0f);
    vec3 beta = v3_splat(1.0f);
    float eta_scale = 1.0f; /* product of etap^2 over refractions, undone for roulette */
    struct last_bounce last = {0};
    struct sampler extra; /* light samples 1 .. N-1 (sample.h, SAMPLE_DIM_LIGHT_EXTRA) */
    bool extra_started = false;

    uint32_t from = BVH_NO_PRIM; /* the triangle the ray leaves */
    for (uint32_t n_bounces = 0;;) {
        /* find the next vertex */
        struct hit_record hr;
        count_ray(opt, &ray, false, n_rays);
        bool hit = first ? first->hit : intersect(ts, &ray, from, &hr);
        if (first && hit)
            hr = first->hr;
        first = NULL;
        vec3 wo_world = v3_normalize(v3_neg(ray.d));

        /* emission where the ray ends, or the sky where it escapes: L += beta Le w_bsdf */
        vec3 Le = hit ? mat_emission(&scene->materials[hr.sf.mat_idx], hr.sf.ng, wo_world)
                      : light_sky_radiance(&scene->sky, v3_neg(wo_world));
        if (!v3_is_zero(Le) && split_keeps(opt->split, n_bounces)) {
            float w_bsdf = 1.0f; /* camera rays, specular bounces, emitters no light sample finds */
            uint32_t light_idx = hit ? hr.light_idx : light_sky_idx(ts->lights);
            if (n_bounces > 0 && !last.is_specular && light_idx != LIGHT_NONE)
                w_bsdf = emission_weight(ts, opt, &last, light_idx, hit ? &hr.sf : NULL,
                                         v3_neg(wo_world));
            L = v3_add(L, v3_scale(v3_mul(beta, Le), w_bsdf));
        }
        if (!hit || n_bounces++ == max_bounces)
            break;

        /* the vertex: its material (albedo texture looked up) and local shading frame; a
         * shading normal that puts wo on the other side than the geometric one does (seen
         * near a smooth mesh's silhouette) gives way to the geometric normal, so no sampled
         * direction is thrown away for being on the wrong side of the surface */
        if (v3_dot(wo_world, hr.sf.ns) * v3_dot(wo_world, hr.sf.ng) <= 0.0f)
            hr.sf.ns = hr.sf.ng;
        struct material m_textured;
        struct vertex v = make_vertex(&hr.sf, &scene->materials[hr.sf.mat_idx], wo_world,
                                      &m_textured);
        v.tri = hr.tri;
        uint32_t bounce = n_bounces - 1;
        uint32_t dim0 = SAMPLE_DIM_BOUNCE0 + bounce * SAMPLE_DIMS_PER_BOUNCE;

        /* the next direction, read ahead of the light sample's dimensions (sample.h,
         * sample_1d_ahead) and drawn before it, taken after it: independent work that the core
         * then overlaps with the light sample's chains of dependent operations (2% of a Cornell
         * box render; docs/performance.md, "The BSDF sample before the light sample") */
        float u_lobe = sample_1d_ahead(sampler, dim0 + SAMPLE_BOUNCE_BSDF_LOBE);
        vec2 u_dir = sample_2d_ahead(sampler, dim0 + SAMPLE_BOUNCE_BSDF_DIR);
        struct mat_sample bs;
        bool sampled = sample_direction(v.m, v.wo, opt->direct, u_lobe, u_dir, &bs);

        /* sample the lights (next-event estimation), N samples:
         * L += beta (1/N) sum_j f |cos theta_i| Le / (pmf pdf_light) w_light */
        if (!mat_is_specular(v.m) && light_count(ts->lights) > 0 &&
            split_keeps(opt->split, n_bounces)) {
            for (uint32_t j = 0; j < n_ls; j++) {
                struct sampler *s = light_sampler(sampler, &extra, &extra_started, bounce, j, n_ls);
                float u_choice = sample_1d(s);
                vec2 u_light = sample_2d(s);
                L = v3_add(L,
                           v3_mul(beta, sample_one_light(ts, opt, &v, u_choice, u_light, n_rays)));
            }
        }

        /* take the next direction: beta *= f |cos theta_i| / pdf */
        sample_set_dim(sampler, dim0 + SAMPLE_BOUNCE_BSDF_DIR + 2);
        if (!sampled)
            break;
        vec3 wi_world = v3_from_local(bs.wi, v.t, v.b, hr.sf.ns);
        /* the geometric normal decides the side: a reflection must stay on the side of wo, a
         * refraction must cross, whatever the shading normal says (no leaks) */
        bool is_reflection = bs.wi.z * v.wo.z > 0.0f;
        bool stays = v3_dot(wi_world, hr.sf.ng) * v3_dot(wo_world, hr.sf.ng) > 0.0f;
        if (is_reflection != stays)
            break;
        beta = v3_mul(beta, v3_scale(bs.f, fabsf(bs.wi.z) / bs.pdf_sa));
        if (!is_reflection) {
            /* refraction: f was divided by etap^2; roulette looks at the unscaled beta */
            float eta_rel = v.wo.z > 0.0f ? v.m->ior : 1.0f / v.m->ior;
            eta_scale *= eta_rel * eta_rel;
        }
        last = (struct last_bounce){hr.sf, v.n_sky, bs.pdf_sa, bs.is_specular};
        ray = spawn_ray(&hr.sf, wi_world);
        from = hr.tri;

        /* Russian roulette after bounce rr_depth: continue with probability p, beta /= p;
         * p = min(1, max(beta) eta^2 / threshold) by throughput (a survivor below the threshold
         * carries max(beta) eta^2 = threshold on), or the fixed --rr p */
        if (n_bounces >= rr_depth) {
            float p = opt->rr_prob > 0.0f
                          ? opt->rr_prob
                          : min_f(1.0f, v3_max_comp(beta) * eta_scale / rr_threshold);
            if (p < 1.0f) {
                sample_set_dim(sampler, dim0 + SAMPLE_BOUNCE_ROULETTE);
                if (!(sample_1d(sampler) < p))
                    break;
                beta = v3_scale(beta, 1.0f / p);
            }
        }
        if (v3_is_zero(beta))
            break;
    }
    return L;
}

/* ---- the render loop: tiles handed out by an atomic counter ---- */

struct render_job {
    const struct trace_scene *ts;
    const struct trace_options *opt;
    struct film *film;
    uint32_t tiles_x;
    uint32_t n_tiles;
    uint32_t set_spp; /* samples per stratified set (sample_start_spp) */
    atomic_uint next_tile;
    atomic_uint_fast64_t samples_done; /* for progress: taken, plus the budget of stopped pixels */
    atomic_int n_running;
    bool is_budget_pilot;   /* this round of the workers runs the budget rule's pilots */
    double *budget_log2w;   /* budget rule: each pixel's log2 weight, filled by its pilot */
    double *budget_cost;    /* budget rule: each pixel's rays per pilot sample */
    const uint32_t *budget; /* budget rule: each pixel's sample count */
};

struct worker {
    pthread_t thread;
    struct render_job *job;
    struct trace_result result;
};

bool trace_adaptive_stop(double s1, double s2, uint64_t n, double tolerance, double floor_lum)
{
    if (n == 0)
        return false;
    /* mu = s1 / n, sigma^2 = s2 / n - mu^2, I = 1.96 sigma / sqrt(n): stop when I <= T max(mu,
     * floor), squared to avoid the square roots: 1.96^2 sigma^2 / n <= (T max(mu, floor))^2 */
    double dn = (double)n;
    double mu = s1 / dn;
    double sigma2 = fmax(0.0, s2 / dn - mu * mu); /* rounding can make a zero variance < 0 */
    double bound = tolerance * fmax(mu, floor_lum);
    return 1.96 * 1.96 * sigma2 / dn <= bound * bound;
}

uint32_t trace_pilot_spp(double s1, double s2, uint64_t n, double tolerance, double floor_lum,
                         uint32_t min_spp, uint32_t max_spp, uint32_t batch)
{
    if (n == 0 || min_spp >= max_spp)
        return max_spp;
    /* N = (1.96 sigma / (T max(mu, floor)))^2, the n at which the stop rule's I reaches T mu */
    double dn = (double)n;
    double mu = s1 / dn;
    double sigma2 = fmax(0.0, s2 / dn - mu * mu);
    double bound = tolerance * fmax(mu, floor_lum);
    double need = bound > 0.0 ? 1.96 * 1.96 * sigma2 / (bound * bound) : (double)max_spp;
    if (!(need < (double)max_spp)) /* also NaN */
        return max_spp;
    uint32_t b = batch ? batch : 1;
    uint64_t n_spp = ((uint64_t)ceil(need) + b - 1) / b * b; /* whole batches */
    if (n_spp < min_spp)
        n_spp = min_spp;
    return n_spp < max_spp ? (uint32_t)n_spp : max_spp;
}

/* Adaptive sampling, the stop rule: whether pixel px, at a test point (min_spp + k batch
 * samples taken), has met the stopping rule.  It reads only the pixel's own sums, so the
 * decision is the same whichever thread, call or resumed run makes it. */
static bool adaptive_converged(const struct trace_options *opt, const struct film_pixel *px)
{
    uint32_t taken = px->n + px->n_dropped;
    uint32_t batch = opt->batch ? opt->batch : 1;
    if (!opt->adaptive || opt->adaptive_rule != RENDER_ADAPTIVE_STOP || taken < opt->min_spp ||
        (taken - opt->min_spp) % batch != 0)
        return false;
    return trace_adaptive_stop(film_sum_lum(px), px->sum_lum_sq, px->n, opt->tolerance,
                               opt->adaptive_floor);
}

/* The tag hashed into the seed of the pilots' stream ("pilot" in ASCII). */
static const uint64_t PILOT_SEED_TAG = 0x70696c6f74ull;

/* The sums of a pilot's n finite samples, per channel R, G, B and luminance (index 3). */
struct pilot_sums {
    double s1[4], s2[4];
    uint64_t n;
    uint32_t n_taken; /* samples traced, the non-finite ones included */
};

/* The pilot of pixel (x, y): n_pilot samples from a stream of its own (the seed hashed with
 * PILOT_SEED_TAG, so its scrambles and its values are independent of the image's), summed into
 * *ps.  Returns false when the render is cancelled during it. */
static bool pilot_run(const struct render_job *job, struct worker *w, uint32_t x, uint32_t y,
                      uint32_t n_pilot, uint64_t *n_rays, struct pilot_sums *ps)
{
    const struct trace_options *opt = job->opt;
    uint32_t pixel_idx = y * (uint32_t)job->film->width + x;
    struct sampler sampler;
    sample_start_pixel(&sampler, opt->sampler, sample_hash64(opt->seed ^ PILOT_SEED_TAG), pixel_idx,
                       job->set_spp);
    *ps = (struct pilot_sums){0};
    for (uint32_t i = 0; i < n_pilot; i++) {
        /* a signal stops a long pilot too; its count is not kept, so the pilot is redone whole
         * (the same samples) when the render resumes */
        if (opt->cancel && atomic_load_explicit(opt->cancel, memory_order_relaxed)) {
            w->result.cancelled = true;
            return false;
        }
        sample_start_index(&sampler, i);
        vec2 u_pixel = sample_2d(&sampler);
        vec2 u_lens = sample_2d(&sampler);
        struct ray ray = camera_ray(&job->ts->camera, (float)x + u_pixel.x, (float)y + u_pixel.y,
                                    u_lens);
        vec3 L = trace_radiance(job->ts, opt, ray, &sampler, n_rays);
        w->result.n_pilot++;
        ps->n_taken++;
        if (!v3_is_finite(L))
            continue; /* as in the film: not counted */
        const double x4[4] = {L.x, L.y, L.z, 0.2126 * L.x + 0.7152 * L.y + 0.0722 * L.z};
        for (int c = 0; c < 4; c++) {
            ps->s1[c] += x4[c];
            ps->s2[c] += x4[c] * x4[c];
        }
        ps->n++;
    }
    return true;
}

/* Adaptive sampling, the pilot rule (two-stage sampling, Kirk & Arvo 1991, "Unbiased Sampling
 * Techniques for Image Synthesis", SIGGRAPH 91): the samples pixel (x, y) gets.  A pilot of
 * pilot_spp samples from a stream of its own (the seed hashed with PILOT_SEED_TAG, so its
 * scrambles and its values are independent of the image's) estimates mu and sigma of the
 * pixel's luminance, and trace_pilot_spp turns them into N.  The pilot is then discarded: the
 * pixel's estimate is the mean of its N image samples, and since N depends on the pilot alone,
 * which is independent of them, E[estimate | N] = E[one sample] = the pixel's value.  The stop
 * rule's estimate is biased because one set of samples both decides and estimates.  The count
 * is a pure function of (seed, pixel), the same for every call; opt->pilot_target keeps it.
 * Returns false, keeping nothing, when the render is cancelled during the pilot. */
static bool pilot_target(const struct render_job *job, struct worker *w, uint32_t x, uint32_t y,
                         uint64_t *n_rays, uint32_t *target_out)
{
    const struct trace_options *opt = job->opt;
    uint32_t pixel_idx = y * (uint32_t)job->film->width + x;
    if (opt->pilot_target && opt->pilot_target[pixel_idx]) {
        *target_out = opt->pilot_target[pixel_idx];
        return true;
    }
    struct pilot_sums ps;
    if (!pilot_run(job, w, x, y, opt->pilot_spp ? opt->pilot_spp : TRACE_ADAPTIVE_PILOT_SPP, n_rays,
                   &ps))
        return false;
    uint32_t max_spp = opt->max_spp ? opt->max_spp : opt->spp;
    uint32_t target = trace_pilot_spp(ps.s1[3], ps.s2[3], ps.n, opt->tolerance, opt->adaptive_floor,
                                      opt->min_spp, max_spp, opt->batch);
    if (opt->pilot_target)
        opt->pilot_target[pixel_idx] = target;
    *target_out = target;
    return true;
}

/* Adaptive sampling, the budget rule: the pilot of pixel (x, y), pilot_spp samples as the pilot
 * rule's, gives the pixel's cost t, its rays per sample, and its weight (sigma / sqrt(t))^p,
 * p = TRACE_BUDGET_POWER, sigma^2 the mean over R, G, B of the samples' variance (the image's
 * MSE is that mean).  Like the pilot rule's, the pilot is then discarded, so the counts
 * trace_budget_counts makes of all the weights are independent of the image's samples and the
 * estimate stays unbiased. */
static void budget_pilot(const struct render_job *job, struct worker *w, uint32_t x, uint32_t y)
{
    const struct trace_options *opt = job->opt;
    struct pilot_sums ps;
    uint64_t n_rays = 0;
    bool done = pilot_run(job, w, x, y, opt->pilot_spp ? opt->pilot_spp : TRACE_BUDGET_PILOT_SPP,
                          &n_rays, &ps);
    w->result.n_rays += n_rays;
    if (!done)
        return; /* cancelled (w->result says so): the render stops before its image pass */
    uint32_t pixel_idx = y * (uint32_t)job->film->width + x;
    double cost = ps.n_taken ? (double)n_rays / (double)ps.n_taken : 1.0;
    job->budget_cost[pixel_idx] = cost;
    double var = 0.0, n = (double)ps.n; /* mean over R, G, B of the sample variances */
    if (ps.n >= 2)
        for (int c = 0; c < 3; c++)
            var += fmax(0.0, (ps.s2[c] - ps.s1[c] * ps.s1[c] / n) / (n - 1.0)) / 3.0;
    /* log2 of the weight (sigma^2 / t)^(p/2), -inf for a pixel whose pilot saw no variance */
    job->budget_log2w[pixel_idx] = var > 0.0 ? 0.5 * TRACE_BUDGET_POWER * log2(var / cost)
                                             : -INFINITY;
}

/* The budget rule's count of a pixel of weight 2^log2w at scale 2^s. */
static uint32_t budget_count(double log2w, double s, uint32_t min_spp, uint32_t max_spp)
{
    double e = floor(s + log2w + 0.5); /* -inf, or NaN, for a weight of 0: the least count */
    uint32_t c = !(e >= 0.0) ? 1u : e >= 31.0 ? 1u << 31 : 1u << (int)e;
    return c < min_spp ? min_spp : c > max_spp ? max_spp : c;
}

void trace_budget_counts(const double *log2w, const double *cost, size_t n, double total,
                         uint32_t min_spp, uint32_t max_spp, uint32_t *count)
{
    /* count_i(s) = clamp(2^floor(s + log2 w_i + 1/2)) grows with s = log2 k: bisect for the
     * largest s whose sum fits; [-2100, 2100] spans every double's log2 */
    double lo = -2100.0, hi = 2100.0;
    for (int it = 0; it < 200 && hi - lo > 1e-9; it++) {
        double s = 0.5 * (lo + hi);
        double sum = 0.0;
        for (size_t i = 0; i < n && sum <= total; i++)
            sum += budget_count(log2w[i], s, min_spp, max_spp) * (cost ? cost[i] : 1.0);
        if (sum <= total)
            lo = s;
        else
            hi = s;
    }
    for (size_t i = 0; i < n; i++)
        count[i] = budget_count(log2w[i], lo, min_spp, max_spp);
}

/* How many samples the pixel may take, from `taken`, before its next adaptive test point
 * (min_spp + k batch) of the stop rule: a batch of samples never steps over one. */
static uint32_t samples_to_test(const struct trace_options *opt, uint32_t taken)
{
    if (!opt->adaptive || opt->adaptive_rule != RENDER_ADAPTIVE_STOP)
        return UINT32_MAX;
    if (taken < opt->min_spp)
        return opt->min_spp - taken;
    uint32_t batch = opt->batch ? opt->batch : 1;
    return batch - (taken - opt->min_spp) % batch;
}

/* The samples of a pixel are taken TRACE_PACKET at a time (fewer before a test point or the
 * end): their camera rays are made from their own samplers, intersected together
 * (intersect_camera_rays), and each path then goes on alone from its first hit.  A sample's
 * numbers, rays and film updates are those of one taken alone, in sample-index order. */
static void render_pixel(struct render_job *job, struct worker *w, uint32_t x, uint32_t y)
{
    const struct trace_options *opt = job->opt;
    struct film *film = job->film;
    uint32_t pixel_idx = y * (uint32_t)film->width + x;
    struct film_pixel *px = &film->pixels[pixel_idx];
    uint64_t done = 0;
    uint64_t skipped = 0; /* samples adaptive sampling saved, counted as progress */
    uint64_t n_rays = 0;  /* kept here, added to the worker's count once per pixel */
    uint32_t spp = opt->spp;
    if (opt->adaptive && opt->adaptive_rule != RENDER_ADAPTIVE_STOP &&
        px->n + px->n_dropped < opt->spp) {
        uint32_t target = 0;
        if (opt->adaptive_rule == RENDER_ADAPTIVE_BUDGET) {
            target = job->budget[pixel_idx];
        } else if (!pilot_target(job, w, x, y, &n_rays, &target)) {
            w->result.n_rays += n_rays;
            return; /* cancelled: the pixel keeps what it has */
        }
        if (target < spp) {
            skipped = spp - (px->n + px->n_dropped > target ? px->n + px->n_dropped : target);
            spp = target;
        }
    }
    struct sampler samplers[TRACE_PACKET];
    uint32_t n_started = 1; /* samplers started on the pixel: copies of the first */
    sample_start_pixel(&samplers[0], opt->sampler, opt->seed, pixel_idx, job->set_spp);
    while (px->n + px->n_dropped < spp) {
        if (opt->cancel && atomic_load_explicit(opt->cancel, memory_order_relaxed)) {
            w->result.cancelled = true;
            break;
        }
        if (adaptive_converged(opt, px)) {
            skipped = opt->spp - (px->n + px->n_dropped);
            break;
        }
        uint32_t taken = px->n + px->n_dropped;
        uint32_t n = spp - taken;
        uint32_t to_test = samples_to_test(opt, taken);
        n = n < to_test ? n : to_test;
        n = n < TRACE_PACKET ? n : TRACE_PACKET;
        /* the camera rays: box filter (uniform jitter inside the pixel), then the lens */
        struct ray rays[TRACE_PACKET];
        for (; n_started < n; n_started++)
            samplers[n_started] = samplers[0];
        for (uint32_t i = 0; i < n; i++) {
            sample_start_index(&samplers[i], opt->sample_offset + taken + i);
            vec2 u_pixel = sample_2d(&samplers[i]);
            vec2 u_lens = sample_2d(&samplers[i]);
            rays[i] = camera_ray(&job->ts->camera, (float)x + u_pixel.x, (float)y + u_pixel.y,
                                 u_lens);
        }
        struct first_hit first[TRACE_PACKET];
        bool packet = intersect_camera_rays(job->ts, opt, rays, n, first);
        for (uint32_t i = 0; i < n; i++) {
            vec3 L = packet ? radiance(job->ts, opt, rays[i], &first[i], &samplers[i], &n_rays)
                            : trace_radiance(job->ts, opt, rays[i], &samplers[i], &n_rays);
            if (v3_is_finite(L)) {
                film_add(px, L);
            } else {
                if (w->result.n_nonfinite == 0) {
                    w->result.first_bad_x = x;
                    w->result.first_bad_y = y;
                    w->result.first_bad_sample = samplers[i].sample_idx;
                }
                w->result.n_nonfinite++;
                px->n_dropped++;
            }
        }
        done += n;
    }
    w->result.n_samples += done;
    w->result.n_rays += n_rays;
    atomic_fetch_add_explicit(&job->samples_done, done + skipped, memory_order_relaxed);
}

static void *render_worker(void *arg)
{
    struct worker *w = arg;
    struct render_job *job = w->job;
    for (;;) {
        uint32_t tile = atomic_fetch_add(&job->next_tile, 1);
        if (tile >= job->n_tiles)
            break;
        uint32_t x0 = (tile % job->tiles_x) * TRACE_TILE_SIZE;
        uint32_t y0 = (tile / job->tiles_x) * TRACE_TILE_SIZE;
        uint32_t x1 = x0 + TRACE_TILE_SIZE, y1 = y0 + TRACE_TILE_SIZE;
        if (x1 > (uint32_t)job->film->width)
            x1 = (uint32_t)job->film->width;
        if (y1 > (uint32_t)job->film->height)
            y1 = (uint32_t)job->film->height;
        for (uint32_t y = y0; y < y1; y++)
            for (uint32_t x = x0; x < x1; x++)
                if (job->is_budget_pilot)
                    budget_pilot(job, w, x, y);
                else
                    render_pixel(job, w, x, y);
        if (w->result.cancelled)
            break;
    }
    atomic_fetch_sub(&job->n_running, 1);
    return NULL;
}

void trace_result_add(struct trace_result *sum, const struct trace_result *r)
{
    if (r->n_nonfinite && !sum->n_nonfinite) {
        sum->first_bad_x = r->first_bad_x;
        sum->first_bad_y = r->first_bad_y;
        sum->first_bad_sample = r->first_bad_sample;
    }
    sum->n_samples += r->n_samples;
    sum->n_pilot += r->n_pilot;
    sum->n_rays += r->n_rays;
    sum->n_nonfinite += r->n_nonfinite;
    sum->cancelled |= r->cancelled;
}

/* Runs job's round (its tiles from next_tile) on n_threads workers, adding their counts to
 * *result; the calling thread reports progress towards total until they are done. */
static bool run_workers(struct render_job *job, int n_threads, uint64_t total,
                        struct trace_result *result, struct mcpt_error *err)
{
    const struct trace_options *opt = job->opt;
    atomic_store(&job->next_tile, 0);
    atomic_store(&job->n_running, n_threads);
    struct worker *workers = calloc((size_t)n_threads, sizeof *workers);
    if (!workers) {
        mcpt_error_runtime(err, NULL, "out of memory starting %d threads", n_threads);
        return false;
    }
    int started = 0;
    for (; started < n_threads; started++) {
        workers[started].job = job;
        if (pthread_create(&workers[started].thread, NULL, render_worker, &workers[started]))
            break;
    }
    if (started < n_threads)
        atomic_fetch_sub(&job->n_running, n_threads - started);
    if (started == 0) {
        free(workers);
        mcpt_error_runtime(err, NULL, "cannot start render threads");
        return false;
    }
    const struct timespec tick = {0, 20 * 1000 * 1000}; /* 20 ms poll */
    int ticks = 0;
    while (atomic_load(&job->n_running) > 0) {
        nanosleep(&tick, NULL);
        if (opt->progress && ++ticks % 5 == 0)
            opt->progress(opt->progress_user, atomic_load(&job->samples_done), total);
    }
    for (int i = 0; i < started; i++) {
        pthread_join(workers[i].thread, NULL);
        trace_result_add(result, &workers[i].result);
    }
    free(workers);
    return true;
}

/* The budget rule's counts into job->budget (count, or opt->pilot_target when that already
 * holds them): every pixel's pilot on the workers, then trace_budget_counts.  False on a
 * runtime error (err filled); result->cancelled when a signal stopped the pilots. */
static bool budget_counts(struct render_job *job, int n_threads, uint32_t *count,
                          struct trace_result *result, struct mcpt_error *err)
{
    const struct trace_options *opt = job->opt;
    size_t n_pixels = (size_t)job->film->width * (size_t)job->film->height;
    if (opt->pilot_target && n_pixels > 0 && opt->pilot_target[0]) {
        job->budget = opt->pilot_target; /* this render's earlier call made them */
        return true;
    }
    job->budget_log2w = malloc(n_pixels * sizeof *job->budget_log2w);
    job->budget_cost = malloc(n_pixels * sizeof *job->budget_cost);
    if (!job->budget_log2w || !job->budget_cost) {
        free(job->budget_log2w);
        free(job->budget_cost);
        mcpt_error_runtime(err, NULL, "out of memory for the adaptive budget's pilot");
        return false;
    }
    job->is_budget_pilot = true;
    bool ok = run_workers(job, n_threads, 0, result, err);
    job->is_budget_pilot = false;
    if (ok && !result->cancelled) {
        uint32_t pilot = opt->pilot_spp ? opt->pilot_spp : TRACE_BUDGET_PILOT_SPP;
        double per_pixel = opt->budget_spp > pilot ? (double)(opt->budget_spp - pilot) : 0.0;
        double cost = 0.0; /* of the uniform render's samples after the pilot */
        for (size_t i = 0; i < n_pixels; i++)
            cost += job->budget_cost[i];
        uint32_t *out = opt->pilot_target ? opt->pilot_target : count;
        trace_budget_counts(job->budget_log2w, job->budget_cost, n_pixels, per_pixel * cost,
                            opt->min_spp, opt->max_spp ? opt->max_spp : opt->spp, out);
        job->budget = out;
    }
    free(job->budget_log2w);
    free(job->budget_cost);
    job->budget_log2w = NULL;
    job->budget_cost = NULL;
    return ok;
}

bool trace_render(const struct trace_scene *ts, const struct trace_options *opt, struct film *film,
                  struct trace_result *result, struct mcpt_error *err)
{
    memset(result, 0, sizeof *result);
    int n_threads = opt->n_threads > 0 ? opt->n_threads : 1;
    struct render_job job = {.ts = ts, .opt = opt, .film = film};
    /* stratified sets: as the caller says, else one set per pixel, or per batch when adaptive
     * (the final count is unknown then; every test point min_spp + k batch with min_spp a
     * multiple of batch sees whole sets) */
    job.set_spp = opt->sampler_spp ? opt->sampler_spp
                  : opt->adaptive  ? (opt->batch ? opt->batch : 1)
                                   : opt->spp;
    job.tiles_x = ((uint32_t)film->width + TRACE_TILE_SIZE - 1) / TRACE_TILE_SIZE;
    uint32_t tiles_y = ((uint32_t)film->height + TRACE_TILE_SIZE - 1) / TRACE_TILE_SIZE;
    job.n_tiles = job.tiles_x * tiles_y;
    atomic_init(&job.next_tile, 0);
    atomic_init(&job.samples_done, 0);
    atomic_init(&job.n_running, n_threads);

    uint64_t total = 0;
    size_t n_pixels = (size_t)film->width * (size_t)film->height;
    for (size_t i = 0; i < n_pixels; i++) {
        uint32_t taken = film->pixels[i].n + film->pixels[i].n_dropped;
        total += taken < opt->spp ? opt->spp - taken : 0;
    }

    uint32_t *count = NULL; /* the budget rule's counts when opt->pilot_target cannot keep them */
    if (opt->adaptive && opt->adaptive_rule == RENDER_ADAPTIVE_BUDGET && total > 0) {
        if (!opt->pilot_target && !(count = malloc(n_pixels * sizeof *count))) {
            mcpt_error_runtime(err, NULL, "out of memory for the adaptive budget's counts");
            return false;
        }
        bool ok = budget_counts(&job, n_threads, count, result, err);
        if (!ok || result->cancelled) {
            free(count);
            return ok;
        }
    }
    bool ok = run_workers(&job, n_threads, total, result, err);
    if (ok && opt->progress)
        opt->progress(opt->progress_user, atomic_load(&job.samples_done), total);
    free(count);
    return ok;
}

/* ---- preparation ---- */

struct trace_scene *trace_prepare(const struct scene *scene, int n_threads, struct mcpt_error *err)
{
    struct trace_scene *ts = calloc(1, sizeof *ts);
    uint32_t *indices = NULL;
    if (!ts)
        goto oom;
    ts->scene = scene;
    if (!camera_init(&ts->camera, &scene->camera, scene->width, scene->height, err))
        goto fail;

    indices = malloc(sizeof(uint32_t) * 3 * (size_t)(scene->n_tris ? scene->n_tris : 1));
    if (!indices)
        goto oom;
    for (uint32_t i = 0; i < scene->n_tris; i++)
        for (int k = 0; k < 3; k++)
            indices[3 * (size_t)i + k] = scene->tris[i].v[k];
    ts->bvh = bvh_build(scene->positions, indices, scene->n_tris, n_threads);
    if (!ts->bvh)
        goto oom;
    ts->lights = light_table_build(scene, err);
    if (!ts->lights)
        goto fail;
    /* a small scene keeps each triangle's plane, so that a hit does not recompute it (edges,
     * normal, its square root and division, in double): a Cornell box renders 3-4% faster.  A
     * large mesh would pay 160 bytes a triangle, more than its BVH, for a gain within the noise
     * (docs/performance.md, "Latency levers") */
    if (scene->n_tris <= TRACE_PLANE_CACHE_TRIS && scene->n_tris > 0) {
        ts->planes = malloc(sizeof *ts->planes * scene->n_tris);
        if (!ts->planes)
            goto oom;
        for (uint32_t i = 0; i < scene->n_tris; i++) {
            vec3 p[3];
            for (int k = 0; k < 3; k++)
                p[k] = scene->positions[scene->tris[i].v[k]];
            shape_triangle_plane(p, scene_tri_groove(scene, i), &ts->planes[i]);
        }
    }
    if (scene->n_spheres + (uint64_t)scene->n_quads >= TRACE_SHAPE_TREE_MIN &&
        !trace_set_shape_tree(ts, true))
        goto oom;
    free(indices);
    return ts;
oom:
    mcpt_error_runtime(err, NULL, "out of memory preparing the scene");
fail:
    free(indices);
    trace_free(ts);
    return NULL;
}

/* A sphere's or quad's box: its extent in double, rounded to float and then moved one float
 * step outwards, so at least half a step wider on every side (the shapes decide their hits in
 * double, far closer to the exact surface than that). */
static void shape_box(const struct scene *scene, uint32_t i, float box[2][3])
{
    double lo[3], hi[3];
    if (i < scene->n_spheres) {
        const struct sphere *sp = &scene->spheres[i];
        const double c[3] = {sp->center.x, sp->center.y, sp->center.z};
        for (int a = 0; a < 3; a++) {
            lo[a] = c[a] - sp->radius;
            hi[a] = c[a] + sp->radius;
        }
    } else {
        const struct quad *q = &scene->quads[i - scene->n_spheres];
        const double c[3] = {q->corner.x, q->corner.y, q->corner.z};
        const double e1[3] = {q->e1.x, q->e1.y, q->e1.z}, e2[3] = {q->e2.x, q->e2.y, q->e2.z};
        for (int a = 0; a < 3; a++) {
            lo[a] = c[a] + fmin(e1[a], 0.0) + fmin(e2[a], 0.0);
            hi[a] = c[a] + fmax(e1[a], 0.0) + fmax(e2[a], 0.0);
        }
    }
    for (int a = 0; a < 3; a++) {
        box[0][a] = nextafterf((float)lo[a], -INFINITY);
        box[1][a] = nextafterf((float)hi[a], INFINITY);
    }
}

bool trace_set_shape_tree(struct trace_scene *ts, bool on)
{
    bvh_boxes_free(ts->shapes);
    ts->shapes = NULL;
    const struct scene *scene = ts->scene;
    uint32_t n = scene->n_spheres + scene->n_quads;
    if (!on || n == 0)
        return true;
    float(*boxes)[2][3] = malloc((size_t)n * sizeof *boxes);
    if (!boxes)
        return false;
    for (uint32_t i = 0; i < n; i++)
        shape_box(scene, i, boxes[i]);
    ts->shapes = bvh_boxes_build((const float(*)[2][3])boxes, n);
    free(boxes);
    return ts->shapes != NULL;
}

void trace_free(struct trace_scene *ts)
{
    if (!ts)
        return;
    bvh_free(ts->bvh);
    bvh_boxes_free(ts->shapes);
    light_table_free(ts->lights);
    free(ts->planes);
    free(ts);
}

struct bvh_stats trace_bvh_stats(const struct trace_scene *ts) { return bvh_get_stats(ts->bvh); }

struct ray trace_camera_ray(const struct trace_scene *ts, float px, float py, vec2 u_lens)
{
    return camera_ray(&ts->camera, px, py, u_lens);
}

/* ---- at a path vertex ---- */

/* The vertex at surface sf reached from direction wo_world: its material m, with the albedo
 * texture looked up into *m_textured when it has one, and the local shading frame z = ns. */
static struct vertex make_vertex(const struct surface *sf, const struct material *m, vec3 wo_world,
                                 struct material *m_textured)
{
    struct vertex v;
    v.sf = sf;
    v.m = m;
    if (m->checker_scale > 0.0f) {
        *m_textured = *m;
        m_textured->albedo = mat_albedo_at(m, sf->p, sf->uv);
        v.m = m_textured;
    }
    v3_basis(sf->ns, &v.t, &v.b);
    v.wo_world = wo_world;
    v.wo = v3_to_local(wo_world, v.t, v.b, sf->ns);
    v.n_sky = v.wo.z >= 0.0f ? sf->ns : v3_neg(sf->ns);
    return v;
}

/* The weight of emission from light light_idx that the ray leaving the last bounce along wi
 * found at `on` (NULL: the sky): with --direct mis the power heuristic against the N light
 * samples, w_bsdf = pdf_bsdf^2 / (pdf_bsdf^2 + (N pmf pdf_light)^2); with --direct light 0
 * (light sampling alone counts this emitter); 1 for the estimators without light sampling. */
static float emission_weight(const struct trace_scene *ts, const struct trace_options *opt,
                             const struct last_bounce *last, uint32_t light_idx,
                             const struct surface *on, vec3 wi)
{
    if (opt->direct == RENDER_DIRECT_LIGHT)
        return 0.0f;
    if (opt->direct != RENDER_DIRECT_MIS)
        return 1.0f;
    const uint32_t n_ls = opt->light_samples ? opt->light_samples : 1;
    float pdf_light = (float)n_ls * light_pmf(ts->lights, light_idx) *
                      light_pdf(ts->lights, light_idx, &last->sf, last->n_sky, on, wi);
    return mis_power(last->pdf_bsdf, pdf_light);
}

/* The sampler that light sample j (of N = n_ls) at bounce `bounce` reads its light choice and
 * position from: sample 0 the bounce's own dimensions, samples 1 .. N-1 a copy of the path's
 * sampler (*extra, copied at its first use) moved to sample.h's SAMPLE_DIM_LIGHT_EXTRA block. */
static struct sampler *light_sampler(struct sampler *sampler, struct sampler *extra,
                                     bool *extra_started, uint32_t bounce, uint32_t j,
                                     uint32_t n_ls)
{
    if (j == 0) {
        sample_set_dim(sampler, SAMPLE_DIM_BOUNCE0 + bounce * SAMPLE_DIMS_PER_BOUNCE +
                                    SAMPLE_BOUNCE_LIGHT_CHOICE);
        return sampler;
    }
    if (!*extra_started) {
        *extra = *sampler;
        *extra_started = true;
    }
    uint32_t slot = bounce * (n_ls - 1) + j - 1;
    sample_set_dim(extra, SAMPLE_DIM_LIGHT_EXTRA + SAMPLE_DIMS_PER_LIGHT * slot);
    return extra;
}

/* One light sample at vertex v (next-event estimation), unweighted by beta:
 *   Ld = f |cos theta_i| Le / (N pmf pdf_light) w_light   (area lights and the sky),
 *   Ld = f |cos theta_i| I / (N pmf r^2)                 (point lights: delta, no MIS).
 * The estimators without light sampling still sample point lights here: nothing else can find
 * a delta light. */
static vec3 sample_one_light(const struct trace_scene *ts, const struct trace_options *opt,
                             const struct vertex *v, float u_choice, vec2 u_light, uint64_t *n_rays)
{
    const vec3 zero = v3_splat(0.0f);
    const uint32_t n_ls = opt->light_samples ? opt->light_samples : 1;
    const struct surface *sf = v->sf;
    float pmf;
    uint32_t light_idx = light_pick(ts->lights, u_choice, &pmf);
    bool nee = opt->direct == RENDER_DIRECT_MIS || opt->direct == RENDER_DIRECT_LIGHT;
    if (!nee && !light_is_delta(ts->lights, light_idx))
        return zero;
    struct light_sample ls;
    if (!light_sample(ts->lights, light_idx, sf, &v->n_sky, &u_light, &ls))
        return zero;
    /* reflection only towards the geometric side of wo: no leaks through surfaces whose
     * shading normal disagrees with the geometry (no material has a non-delta transmission) */
    if (v3_dot(ls.wi, sf->ng) * v3_dot(v->wo_world, sf->ng) <= 0.0f)
        return zero;
    vec3 wi = v3_to_local(ls.wi, v->t, v->b, sf->ns);
    vec3 f = mat_eval(v->m, v->wo, wi);
    if (v3_is_zero(f))
        return zero;
    /* the shadow ray: to infinity for the sky, else to the light point */
    struct ray shadow = ls.is_infinite ? spawn_ray(sf, ls.wi)
                                       : spawn_ray_to(sf, ls.p, ls.p_error, ls.n);
    count_ray(opt, &shadow, true, n_rays);
    if (occluded(ts, &shadow, v->tri))
        return zero;
    vec3 Ld = v3_scale(v3_mul(f, ls.Le), fabsf(wi.z) / ((float)n_ls * pmf));
    if (ls.is_delta)
        return Ld;
    float w_light = 1.0f;
    if (opt->direct == RENDER_DIRECT_MIS)
        w_light = mis_power((float)n_ls * pmf * ls.pdf_sa, mat_pdf(v->m, v->wo, wi));
    return v3_scale(Ld, w_light / ls.pdf_sa);
}

/* The next direction from wo: the BSDF's own sampling, or for --direct cosine | hemisphere a
 * direction independent of the BSDF (cosine-weighted or uniform over the hemisphere of wo) at
 * materials without a delta lobe; a delta lobe can only be found by sampling it. */
static bool sample_direction(const struct material *m, vec3 wo, enum render_direct direct,
                             float u_lobe, vec2 u, struct mat_sample *s)
{
    bool is_cosine = direct == RENDER_DIRECT_COSINE;
    if ((!is_cosine && direct != RENDER_DIRECT_HEMISPHERE) || mat_has_delta(m))
        return mat_sample(m, wo, u_lobe, u, s);
    if (wo.z == 0.0f)
        return false;
    vec3 wi = is_cosine ? sample_cosine_hemisphere(u) : sample_uniform_hemisphere(u);
    s->pdf_sa = is_cosine ? pdf_cosine_hemisphere(wi.z) : pdf_uniform_hemisphere();
    s->wi = v3(wi.x, wi.y, wo.z > 0.0f ? wi.z : -wi.z);
    s->f = mat_eval(m, wo, s->wi);
    s->is_specular = false;
    return s->pdf_sa > 0.0f && wi.z > 0.0f;
}

/* ---- scene queries ---- */

/* Every ray traced is counted, and shown to the benchmark's hook if there is one. */
static void count_ray(const struct trace_options *opt, const struct ray *ray, bool is_shadow,
                      uint64_t *n_rays)
{
    (*n_rays)++;
    if (opt->ray_hook)
        opt->ray_hook(opt->ray_hook_user, ray, is_shadow);
}

/* The surface of scene triangle tri_idx where ray hit it, at t_hit and barycentrics (b1, b2). */
static struct surface triangle_surface(const struct trace_scene *ts, uint32_t tri_idx,
                                       const struct ray *ray, float t_hit, float b1, float b2)
{
    const struct scene *scene = ts->scene;
    const struct scene_tri *tri = &scene->tris[tri_idx];
    vec3 p[3], ns[3];
    vec2 uv[3];
    bool has_ns = true, has_uv = true;
    for (int k = 0; k < 3; k++) {
        has_ns = has_ns && tri->vn[k] >= 0;
        has_uv = has_uv && tri->vt[k] >= 0;
        ns[k] = tri->vn[k] >= 0 ? scene->normals[tri->vn[k]] : v3_splat(0.0f);
        uv[k] = tri->vt[k] >= 0 ? scene->uvs[tri->vt[k]] : (vec2){0.0f, 0.0f};
    }
    if (ts->planes)
        return shape_triangle_plane_surface(&ts->planes[tri_idx], has_ns ? ns : NULL,
                                            has_uv ? uv : NULL, ray, t_hit, b1, b2, tri->mat_idx);
    for (int k = 0; k < 3; k++)
        p[k] = scene->positions[tri->v[k]];
    return shape_triangle_surface(p, scene_tri_groove(scene, tri_idx), has_ns ? ns : NULL,
                                  has_uv ? uv : NULL, ray, t_hit, b1, b2, tri->mat_idx);
}

enum hit_kind { HIT_NONE, HIT_TRI, HIT_SPHERE, HIT_QUAD, HIT_PLANE };

/* The closest sphere or quad so far, as the shape tree visits them (shape_closest). */
struct shape_hit {
    const struct scene *scene;
    enum hit_kind kind;
    uint32_t idx;
};

/* bvh_box_visit for a closest hit: shape i (spheres, then quads) tested against ray's interval,
 * which a hit shortens. */
static bool shape_closest(void *ctx, uint32_t i, struct ray *ray)
{
    struct shape_hit *sh = ctx;
    const struct scene *scene = sh->scene;
    float t;
    if (i < scene->n_spheres) {
        if (shape_sphere_intersect(&scene->spheres[i], ray, &t)) {
            sh->kind = HIT_SPHERE;
            sh->idx = i;
            ray->t_max = t;
        }
    } else if (shape_quad_intersect(&scene->quads[i - scene->n_spheres], ray, &t)) {
        sh->kind = HIT_QUAD;
        sh->idx = i - scene->n_spheres;
        ray->t_max = t;
    }
    return false;
}

/* bvh_box_visit for an any hit: whether shape i blocks the ray. */
static bool shape_any(void *ctx, uint32_t i, struct ray *ray)
{
    const struct scene *scene = ctx;
    float t;
    return i < scene->n_spheres
               ? shape_sphere_intersect(&scene->spheres[i], ray, &t)
               : shape_quad_intersect(&scene->quads[i - scene->n_spheres], ray, &t);
}

/* A hit sf on surface k (scene_contacts: planes, then quads, then triangles) kept clear of the
 * walls that stand on it, on the side the ray came from (shape_pull_from_contacts). */
static void pull_from_contacts(const struct scene *scene, uint32_t k, struct surface *sf,
                               const struct ray *ray)
{
    uint32_t n;
    const struct contact *cs = scene_contacts(scene, k, &n);
    if (cs)
        shape_pull_from_contacts(sf, cs, n, ray->o);
}

/* The closest hit along ray_in among the analytic shapes, nearer than the triangle hit bh (NULL:
 * none) the BVH found, as a hit record: the second half of every intersection. */
static bool closest_hit(const struct trace_scene *ts, const struct ray *ray_in,
                        const struct bvh_hit *bh, struct hit_record *hr)
{
    const struct scene *scene = ts->scene;
    struct ray ray = *ray_in;
    enum hit_kind kind = HIT_NONE;
    uint32_t idx = 0;
    if (bh) {
        kind = HIT_TRI;
        idx = bh->prim_idx;
        ray.t_max = bh->t;
    }
    float t;
    struct shape_hit sh = {scene, kind, idx};
    if (ts->shapes)
        bvh_boxes_traverse(ts->shapes, &ray, shape_closest, &sh);
    else /* a few: each in turn, spheres then quads */
        for (uint32_t i = 0; i < scene->n_spheres + scene->n_quads; i++)
            shape_closest(&sh, i, &ray);
    kind = sh.kind;
    idx = sh.idx;
    for (uint32_t i = 0; i < scene->n_planes; i++)
        if (shape_plane_intersect(&scene->planes[i], &ray, &t)) {
            kind = HIT_PLANE;
            idx = i;
            ray.t_max = t;
        }
    hr->tri = BVH_NO_PRIM;
    switch (kind) {
    case HIT_NONE:
        return false;
    case HIT_TRI:
        hr->sf = triangle_surface(ts, idx, &ray, bh->t, bh->u, bh->v);
        hr->light_idx = light_idx_of(ts->lights, LIGHT_TRIANGLE, idx);
        hr->tri = idx;
        pull_from_contacts(scene, scene->n_planes + scene->n_quads + idx, &hr->sf, ray_in);
        return true;
    case HIT_SPHERE:
        hr->sf = shape_sphere_surface(&scene->spheres[idx], &ray, ray.t_max);
        hr->light_idx = light_idx_of(ts->lights, LIGHT_SPHERE, idx);
        return true;
    case HIT_QUAD:
        hr->sf = shape_quad_surface(&scene->quads[idx], &ray, ray.t_max);
        hr->light_idx = light_idx_of(ts->lights, LIGHT_QUAD, idx);
        pull_from_contacts(scene, scene->n_planes + idx, &hr->sf, ray_in);
        return true;
    case HIT_PLANE:
        hr->sf = shape_plane_surface(&scene->planes[idx], &ray, ray.t_max);
        hr->light_idx = LIGHT_NONE;
        pull_from_contacts(scene, idx, &hr->sf, ray_in);
        return true;
    }
    return false;
}

static bool intersect(const struct trace_scene *ts, const struct ray *ray, uint32_t from,
                      struct hit_record *hr)
{
    struct bvh_hit bh;
    bool tri_hit = bvh_intersect_from(ts->bvh, ray, from, &bh);
    return closest_hit(ts, ray, tri_hit ? &bh : NULL, hr);
}

/* The first hits of n <= TRACE_PACKET camera rays of one pixel, their triangles found as one
 * packet (bvh_intersect_packet reports each ray's bvh_intersect result).  Returns false, filling
 * nothing, where a packet does not pay (fewer than TRACE_PACKET_MIN rays, a scene without
 * triangles) or is not wanted (opt->single_rays). */
static bool intersect_camera_rays(const struct trace_scene *ts, const struct trace_options *opt,
                                  const struct ray *rays, uint32_t n, struct first_hit *first)
{
    if (opt->single_rays || n < TRACE_PACKET_MIN || ts->scene->n_tris == 0)
        return false;
    struct bvh_packet packet;
    for (uint32_t i = 0; i < n; i++)
        bvh_packet_set(&packet, (int)i, &rays[i]);
    struct bvh_packet_hit ph;
    uint32_t hits = bvh_intersect_packet(ts->bvh, &packet, (1u << n) - 1u, &ph);
    for (uint32_t i = 0; i < n; i++) {
        struct bvh_hit bh = {ph.t[i], ph.u[i], ph.v[i], ph.prim_idx[i]};
        first[i].hit = closest_hit(ts, &rays[i], hits >> i & 1u ? &bh : NULL, &first[i].hr);
    }
    return true;
}

static bool occluded(const struct trace_scene *ts, const struct ray *ray, uint32_t from)
{
    const struct scene *scene = ts->scene;
    float t;
    uint32_t n_shapes = scene->n_spheres + scene->n_quads;
    if (n_shapes > 0) {
        /* the visits take a mutable ray; a scene of meshes alone makes no copy */
        struct ray r = *ray;
        if (ts->shapes) {
            if (bvh_boxes_traverse(ts->shapes, &r, shape_any, (void *)scene))
                return true;
        } else { /* a few: each in turn */
            for (uint32_t i = 0; i < n_shapes; i++)
                if (shape_any((void *)scene, i, &r))
                    return true;
        }
    }
    for (uint32_t i = 0; i < scene->n_planes; i++)
        if (shape_plane_intersect(&scene->planes[i], ray, &t))
            return true;
    return bvh_occluded_from(ts->bvh, ray, from);
}

/* PBRT 4e, ch. 6, "Robust Spawned Ray Origins": SpawnRay */
static struct ray spawn_ray(const struct surface *sf, vec3 d)
{
    struct ray r;
    r.o = offset_ray_origin(sf->p, sf->p_error, sf->ng, d);
    r.d = d;
    r.t_min = 0.0f;
    r.t_max = INFINITY;
    return r;
}

/* PBRT 4e, ch. 6, "Robust Spawned Ray Origins": SpawnRayTo between two offset points; the ray
 * covers t in (0, 1 - SHADOW_EPSILON) of d = p_to' - p_from'.  n_to = 0: p_to is not offset. */
static struct ray spawn_ray_to(const struct surface *from, vec3 p_to, vec3 p_to_error, vec3 n_to)
{
    struct ray r;
    r.o = offset_ray_origin(from->p, from->p_error, from->ng, v3_sub(p_to, from->p));
    vec3 pt = v3_is_zero(n_to) ? p_to
                               : offset_ray_origin(p_to, p_to_error, n_to, v3_sub(r.o, p_to));
    r.d = v3_sub(pt, r.o);
    r.t_min = 0.0f;
    r.t_max = 1.0f - SHADOW_EPSILON;
    return r;
}
