/* fuzz/fuzz_scene.c - libFuzzer harness for scene_load (scene.c, and obj.c through `mesh`),
 * and for what renders an accepted scene (trace_prepare: BVH and light table; trace_radiance on
 * a few camera rays: shapes, materials, the path loop).  Each input becomes a scene file in a
 * private temporary folder that also holds a small OBJ with its MTL (a.obj, a.mtl) and, as
 * models/, links to the Cornell box models of scenes/models, so inputs can reach the mesh
 * loader.  The scanned meshes (bunny, dragon: 70k-100k triangles) are left out: an input that
 * loaded one spent a second in the BVH build under ASan, and mutations of their scenes kept the
 * harness at 56 executions a second; their parsing is fuzz_obj's.  A crash, hang, leak or sanitizer
 * report is a bug.  A rejected input must carry a one-line message naming a file; an accepted
 * one must satisfy the struct scene invariants checked below (indices in range, finite
 * geometry), which the renderer relies on without checking.
 * Run: make fuzz FUZZ_SECONDS=N (fuzz/run.sh); seeds: scenes/ and tests/bad/. */
#include "scene.h"

#include "trace.h"

#include <limits.h>
#include <math.h>
#include <stdlib.h>
#include <unistd.h>

#include "fuzz_util.h"

static char scene_path[96]; /* the scratch folder's scene.txt: each input */

static void write_text(const char *path, const char *text)
{
    fuzz_write_file(path, text, strlen(text));
}

int LLVMFuzzerInitialize(int *argc, char ***argv);
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerInitialize(int *argc, char ***argv)
{
    (void)argc;
    (void)argv;
    fuzz_make_dir("scene");
    fuzz_path(scene_path, sizeof scene_path, "scene.txt");
    char path[160], models[PATH_MAX];
    fuzz_path(path, sizeof path, "a.obj");
    write_text(path, "mtllib a.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvn 0 0 1\nvt 0 0\n"
                     "usemtl lamp\nf 1/1/1 2/1/1 3/1/1\nusemtl glass\nf 2 4 3\n");
    fuzz_path(path, sizeof path, "a.mtl");
    write_text(path, "newmtl lamp\nKd 0 0 0\nKe 5 5 5\nnewmtl glass\nillum 7\nNi 1.33\n");
    fuzz_path(path, sizeof path, "models"); /* models/X is the folder's own X */
    (void)symlink(".", path);
    const char *small[] = {"CornellBox-Original.obj", "CornellBox-Original.mtl",
                           "CornellBox-Empty-RG.obj", "CornellBox-Empty-RG.mtl"};
    for (size_t i = 0; i < sizeof small / sizeof small[0]; i++) {
        char from[PATH_MAX];
        snprintf(from, sizeof from, "scenes/models/%s", small[i]);
        fuzz_path(path, sizeof path, small[i]);
        if (realpath(from, models))
            (void)symlink(models, path);
    }
    return 0;
}

/* The invariants trace.c and bvh.c assume of a loaded scene. */
static void check_scene(const struct scene *s)
{
    if (s->width < 1 || s->height < 1 || s->render.spp < 1)
        abort();
    for (uint32_t i = 0; i < s->n_positions; i++) /* inside the scene bound, 1e18 */
        if (!(fabsf(s->positions[i].x) <= 1e18f && fabsf(s->positions[i].y) <= 1e18f &&
              fabsf(s->positions[i].z) <= 1e18f))
            abort();
    struct camera cam; /* the parser checks the camera with camera_frame: it always builds */
    if (!camera_init(&cam, &s->camera, s->width, s->height, NULL))
        abort();
    for (uint32_t i = 0; i < s->n_warnings && i < SCENE_MAX_WARNINGS; i++)
        if (!strstr(s->warnings[i], ": warning: ") || strpbrk(s->warnings[i], "\r\n"))
            abort();
    for (uint32_t i = 0; i < s->n_tris; i++) {
        const struct scene_tri *t = &s->tris[i];
        if (t->mat_idx >= s->n_materials)
            abort();
        for (int k = 0; k < 3; k++)
            if (t->v[k] >= s->n_positions || t->vn[k] >= (int32_t)s->n_normals ||
                t->vt[k] >= (int32_t)s->n_uvs || t->vn[k] < -1 || t->vt[k] < -1)
                abort();
    }
    for (uint32_t i = 0; i < s->n_spheres; i++)
        if (s->spheres[i].mat_idx >= s->n_materials || !(s->spheres[i].radius > 0.0f))
            abort();
    for (uint32_t i = 0; i < s->n_quads; i++)
        if (s->quads[i].mat_idx >= s->n_materials)
            abort();
    for (uint32_t i = 0; i < s->n_planes; i++)
        if (s->planes[i].mat_idx >= s->n_materials)
            abort();
    if (s->contact_start) { /* scene.c, contacts: planes, quads, then triangles or none */
        uint32_t n_pq = s->n_planes + s->n_quads;
        if (s->n_contact_surfaces != n_pq && s->n_contact_surfaces != n_pq + s->n_tris)
            abort();
        if (s->contact_start[0] != 0)
            abort();
        for (uint32_t k = 0; k < s->n_contact_surfaces; k++)
            if (s->contact_start[k + 1] < s->contact_start[k] ||
                s->contact_start[k + 1] - s->contact_start[k] > 64)
                abort();
        for (uint32_t i = 0; i < s->contact_start[s->n_contact_surfaces]; i++) {
            const struct contact *c = &s->contacts[i];
            double m2 = c->m.x * c->m.x + c->m.y * c->m.y + c->m.z * c->m.z;
            if (!(fabs(m2 - 1.0) < 1e-9 && c->g >= 1.0 && isfinite(c->a.x + c->a.y + c->a.z) &&
                  isfinite(c->b.x + c->b.y + c->b.z)))
                abort();
        }
    } else if (s->contacts || s->n_contact_surfaces) {
        abort();
    }
    for (uint32_t i = 0; i < s->n_lights; i++) {
        const struct light *l = &s->lights[i];
        uint32_t n = l->kind == LIGHT_TRIANGLE ? s->n_tris
                     : l->kind == LIGHT_QUAD   ? s->n_quads
                     : l->kind == LIGHT_SPHERE ? s->n_spheres
                                               : UINT32_MAX;
        if (l->prim_idx >= n)
            abort();
    }
}

/* A few camera samples through the whole integrator (no threads: trace_render's scheduler
 * would cost a 20 ms poll per input).  Depth is capped so an input cannot make one run long. */
static void render_a_little(const struct scene *scene)
{
    struct mcpt_error err = {0};
    struct trace_scene *ts = trace_prepare(scene, 1, &err);
    if (!ts) {
        if (!err.msg[0])
            abort();
        return;
    }
    struct trace_options opt = {.spp = 1,
                                .seed = 1,
                                .sampler = SAMPLER_INDEPENDENT,
                                .n_threads = 1};
    opt.max_depth = scene->render.max_depth < 16 ? scene->render.max_depth : 16;
    uint64_t n_rays = 0;
    for (uint32_t i = 0; i < 4; i++) {
        struct sampler s;
        sample_start(&s, SAMPLER_INDEPENDENT, opt.seed, i, 0);
        vec2 u_pixel = sample_2d(&s);
        vec2 u_lens = sample_2d(&s);
        float px = u_pixel.x * (float)scene->width, py = u_pixel.y * (float)scene->height;
        struct ray ray = trace_camera_ray(ts, px, py, u_lens);
        (void)trace_radiance(ts, &opt, ray, &s, &n_rays); /* NaN is counted, not a crash */
    }
    trace_free(ts);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    fuzz_write_file(scene_path, data, size);
    struct scene scene;
    struct mcpt_error err = {0};
    if (scene_load(scene_path, &scene, &err)) {
        check_scene(&scene);
        render_a_little(&scene);
        scene_free(&scene);
    } else {
        fuzz_check_rejection(&err);
    }
    return 0;
}
