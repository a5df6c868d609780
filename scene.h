/* scene.h - struct scene and the scene-file parser.  A scene is camera, film size, material
 * table, world-space triangles (meshes after their transforms), analytic shapes, lights, sky and
 * render defaults.  The grammar is in docs/scene-format.md. */
#ifndef MCPT_SCENE_H
#define MCPT_SCENE_H

#include "camera.h"
#include "material.h"
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

/* Render defaults from the scene's "render" statement; the CLI overrides them. */
struct render_settings {
    uint32_t spp;       /* samples per pixel */
    uint32_t max_depth; /* longest path in segments from the camera; 0 = emission only */
};

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

    struct sphere *spheres;
    uint32_t n_spheres;
    struct quad *quads;
    uint32_t n_quads;
    struct plane *planes;
    uint32_t n_planes;

    struct light *lights; /* every emissive triangle, quad and sphere, then point lights */
    uint32_t n_lights;
    struct sky sky;
};

/* Parses the scene file at path (and the OBJ/MTL files it names, relative to its folder).
 * On success fills *scene (free with scene_free) and returns true.  On bad input returns false
 * with *scene zeroed and *err naming file:line:col and what was expected. */
bool scene_load(const char *path, struct scene *scene, struct mcpt_error *err);

/* Frees everything scene_load allocated and zeroes *scene.  Safe on a zeroed scene. */
void scene_free(struct scene *scene);

#endif
