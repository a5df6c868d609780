/* scene.h - struct scene and the scene-file parser.  A scene is camera, film size, material
 * table, world-space triangles (meshes after their transforms), analytic shapes, lights, sky and
 * render defaults.  The grammar is in docs/scene-format.md. */
#ifndef MCPT_SCENE_H
#define MCPT_SCENE_H

#include "camera.h"
#include "material.h"
#include "sample.h"
#include "shape.h"
#include "vec.h"

/* A triangle of the scene, in world space.  vn/vt index normals/uvs, or -1. */
struct scene_tri {
    uint32_t v[3];
    int32_t vn[3];
    int32_t vt[3];
    uint32_t mat_idx;
}; /* 40 bytes */

enum light_kind {
    LIGHT_TRIANGLE, /* emissive scene triangle prim_idx */
    LIGHT_QUAD,     /* emissive quad prim_idx */
    LIGHT_SPHERE,   /* emissive sphere prim_idx */
    LIGHT_POINT,    /* point light: position, intensity */
};

struct light {
    enum light_kind kind;
    uint32_t prim_idx; /* into tris, quads or spheres by kind */
    vec3 position;     /* LIGHT_POINT */
    vec3 intensity;    /* LIGHT_POINT: radiant intensity, W/sr */
};

enum sky_kind {
    SKY_NONE,     /* black */
    SKY_CONSTANT, /* radiance everywhere */
    SKY_GRADIENT, /* lerp(horizon, zenith, max(d.y, 0)); below the horizon: horizon */
};

struct sky {
    enum sky_kind kind;
    vec3 radiance; /* SKY_CONSTANT */
    vec3 horizon;  /* SKY_GRADIENT */
    vec3 zenith;   /* SKY_GRADIENT */
};

/* Direct-lighting estimator (trace.c; docs/scene-format.md, "render"): every one converges to
 * the same image. */
enum render_direct {
    RENDER_DIRECT_MIS,        /* light and BSDF sampling, power heuristic (Veach 1997, ch. 9) */
    RENDER_DIRECT_LIGHT,      /* light sampling only (next-event estimation) */
    RENDER_DIRECT_BSDF,       /* BSDF sampling only: emission counted where a ray hits it */
    RENDER_DIRECT_COSINE,     /* cosine-weighted hemisphere directions, emission on hit */
    RENDER_DIRECT_HEMISPHERE, /* uniform hemisphere directions, emission on hit */
};
#define RENDER_DIRECT_COUNT 5

/* Which bounces an image keeps: all, bounces 0-1 (emission seen directly and direct light), or
 * bounces > 1; direct + indirect = full, sample by sample. */
enum render_split {
    RENDER_SPLIT_FULL,
    RENDER_SPLIT_DIRECT,
    RENDER_SPLIT_INDIRECT,
};
#define RENDER_SPLIT_COUNT 3

/* How an area light (triangle, quad) is sampled from a point: uniformly by area (the default:
 * cheaper, and as good where visibility dominates the error) or by solid angle (light.c,
 * shape.h; docs/performance.md, "Per-sample error"). */
enum render_light_sampling {
    RENDER_LIGHT_AREA,
    RENDER_LIGHT_SOLID_ANGLE,
};
#define RENDER_LIGHT_SAMPLING_COUNT 2

/* "area", "solid-angle"; "?" outside the enum. */
const char *scene_light_sampling_name(enum render_light_sampling mode);
bool scene_light_sampling_parse(const char *name, enum render_light_sampling *mode);

/* Adaptive sampling's rule (trace.c; docs/sampling.md, "Adaptive sampling"). */
enum render_adaptive_rule {
    /* a pilot of independent samples, discarded, sets each pixel's count: unbiased (Kirk &
     * Arvo 1991) */
    RENDER_ADAPTIVE_PILOT,
    /* stop when the pixel's own 95% interval is narrow: biased low */
    RENDER_ADAPTIVE_STOP,
    /* a discarded pilot of every pixel shares the rays of spp uniform samples out where they
     * lower the image's MSE most: unbiased */
    RENDER_ADAPTIVE_BUDGET,
};
#define RENDER_ADAPTIVE_RULE_COUNT 3

/* "pilot", "stop", "budget"; "?" outside the enum. */
const char *scene_adaptive_rule_name(enum render_adaptive_rule rule);
bool scene_adaptive_rule_parse(const char *name, enum render_adaptive_rule *rule);

/* "mis", "light", "bsdf", "cosine", "hemisphere"; "?" outside the enum. */
const char *scene_direct_name(enum render_direct direct);
/* Sets *direct to the estimator called name; false (untouched) when there is none. */
bool scene_direct_parse(const char *name, enum render_direct *direct);
/* "full", "direct", "indirect"; "?" outside the enum. */
const char *scene_split_name(enum render_split split);
bool scene_split_parse(const char *name, enum render_split *split);

/* The largest adaptive tolerance and luminance floor, in a scene and on the command line. */
#define SCENE_MAX_TOLERANCE 1e6f
#define SCENE_MAX_ADAPTIVE_FLOOR 1e30f

/* Render defaults from the scene's "render" statement; the CLI overrides them. */
struct render_settings {
    uint32_t spp;       /* samples per pixel */
    uint32_t max_depth; /* longest path in segments from the camera; 0 = emission only */
    /* sampling (docs/sampling.md); 0 in a count or tolerance: not given, the CLI's default */
    enum sampler_kind sampler;               /* SAMPLER_* */
    bool adaptive;                           /* adaptive sampling on */
    bool has_adaptive_rule;                  /* adaptive-rule given */
    enum render_adaptive_rule adaptive_rule; /* adaptive: pilot (default), stop or budget */
    int adaptive_rule_line;                  /* where adaptive-rule was written (1-based), */
    int adaptive_rule_col;                   /* for main.c's checks of the budget rule */
    float tolerance;                         /* adaptive: relative 95% half-width T */
    float adaptive_floor; /* adaptive: absolute luminance floor; < 0: not given */
    uint32_t batch;       /* adaptive: samples between tests, or the pilot's unit */
    uint32_t min_spp;     /* adaptive: samples before the first test, or the least */
    int min_spp_line;     /* where min-spp was written (1-based), for main.c's check against */
    int min_spp_col;      /* the samples per pixel the run ends up with */
    uint32_t max_spp;     /* adaptive: most samples per pixel */
    uint32_t pilot_spp;   /* adaptive pilot: the pilot's samples */
    /* light transport (trace.c); 0 in a count or probability: not given, the CLI's default */
    enum render_direct direct;                 /* direct-lighting estimator (default MIS) */
    uint32_t light_samples;                    /* light samples per path vertex */
    enum render_split split;                   /* bounces kept (default all) */
    enum render_light_sampling light_sampling; /* area lights: by area (default) or solid angle */
    float rr_prob;      /* fixed Russian-roulette continuation probability; 0: by beta */
    float rr_threshold; /* roulette by beta below this throughput; 0: not given */
    uint32_t rr_depth;  /* bounces before Russian roulette starts */
};

#define SCENE_MAX_WARNINGS 8    /* warning lines a scene keeps */
#define SCENE_WARNING_BYTES 400 /* one warning line with its NUL */

struct scene {
    struct camera_params camera;
    int width;  /* film width, pixels */
    int height; /* film height, pixels */
    struct render_settings render;

    struct material *materials;
    uint32_t n_materials;

    vec3 *positions; /* world-space vertices */
    uint32_t n_positions;
    vec3 *normals; /* world-space shading normals (unit), referenced by scene_tri.vn */
    uint32_t n_normals;
    vec2 *uvs;
    uint32_t n_uvs;
    struct scene_tri *tris;
    uint32_t n_tris;
    /* per triangle, the factor of each edge's margin (edge opposite corner i; shape.h, struct
     * triangle_plane) where another triangle shares the edge's corners at a groove sharper than
     * 80 degrees, 1 elsewhere; NULL when every factor is 1 (scene.c, grooves) */
    float (*tri_groove)[3];

    struct sphere *spheres;
    uint32_t n_spheres;
    struct quad *quads;
    uint32_t n_quads;
    struct plane *planes;
    uint32_t n_planes;
    /* where meshes stand on the planes, quads and triangles (scene.c, contacts): surface k's
     * (planes first, then quads, then triangles, n_contact_surfaces in all) are
     * contacts[contact_start[k] .. contact_start[k + 1]); both NULL when there are none */
    struct contact *contacts;
    uint32_t *contact_start;
    uint32_t n_contact_surfaces;

    struct light *lights; /* every emissive triangle, quad and sphere, then point lights */
    uint32_t n_lights;
    struct sky sky;

    /* what the load accepted but did not use as written (an MTL 'spectral' colour, a usemtl
     * no mtllib defines): lines "file:line:col: warning: ..." for main to print on stderr, the
     * first SCENE_MAX_WARNINGS of n_warnings */
    char warnings[SCENE_MAX_WARNINGS][SCENE_WARNING_BYTES];
    uint32_t n_warnings;

    uint64_t file_hash;  /* FNV-1a 64 of the scene file's bytes as read (file.h): a checkpoint
                             names its scene by it, and a pipe cannot be read twice */
    char **loaded_paths; /* every mesh and MTL file loaded, as opened (paths from the scene's
                             folder): inputs no output may overwrite */
    uint32_t n_loaded;
};

/* The contacts of surface k (planes first, then quads, then triangles) in *n; NULL where it has
 * none. */
static inline const struct contact *scene_contacts(const struct scene *scene, uint32_t k,
                                                   uint32_t *n)
{
    *n = k < scene->n_contact_surfaces ? scene->contact_start[k + 1] - scene->contact_start[k] : 0;
    return *n ? scene->contacts + scene->contact_start[k] : NULL;
}

/* scene->tri_groove's factors of triangle i, or NULL where the scene has none. */
static inline const float *scene_tri_groove(const struct scene *scene, uint32_t i)
{
    return scene->tri_groove ? scene->tri_groove[i] : NULL;
}

/* Parses the scene file at path (and the OBJ/MTL files it names, relative to its folder).
 * The scene file may be a regular file or a pipe; meshes and MTL files must be regular files.
 * On success fills *scene (free with scene_free) and returns true; scene->warnings holds what
 * main should print.  On bad input returns false with *scene zeroed and *err naming
 * file:line:col and what was expected (err->kind: MCPT_ERROR_RUNTIME for out of memory or a
 * read failure). */
bool scene_load(const char *path, struct scene *scene, struct mcpt_error *err);

/* As scene_load, from the open stream f, e.g. a copy of standard input: read through its
 * descriptor from the descriptor's offset (rewind f first) to the end; not closed.  name
 * stands for the file in error messages ("<stdin>"), and the OBJ/MTL files it names are
 * relative to the working directory. */
bool scene_load_stream(FILE *f, const char *name, struct scene *scene, struct mcpt_error *err);

/* Frees everything scene_load allocated and zeroes *scene.  Safe on a zeroed scene. */
void scene_free(struct scene *scene);

#endif
