/* camera.h - look-at camera with vertical field of view and a thin lens.
 * Thin lens: PBRT 4e, ch. 5, "Projective Camera Models" (thin lens model and depth of field). */
#ifndef MCPT_CAMERA_H
#define MCPT_CAMERA_H

#include "vec.h"

/* What the scene file says about the camera. */
struct camera_params {
    vec3 eye;
    vec3 look_at;
    vec3 up;
    float fov_deg;    /* vertical field of view, (0, 180) */
    float aperture;   /* lens radius, scene units; 0 = pinhole */
    float focus_dist; /* distance to the plane in focus; 0 = |look_at - eye| */
};

/* Precomputed camera frame for a film of width x height pixels. */
struct camera {
    vec3 eye;
    vec3 forward; /* unit, towards look_at */
    vec3 right;   /* unit */
    vec3 up;      /* unit */
    float tan_half_fov_y;
    float aspect; /* width / height */
    float aperture;
    float focus_dist;
    int width;
    int height;
};

/* Why camera_frame cannot build a frame. */
enum camera_fault {
    CAMERA_OK,
    CAMERA_NOT_FINITE,  /* eye, look_at or up not finite, or look_at - eye or its length
                           beyond float range */
    CAMERA_SAME_POINT,  /* look_at == eye: no view direction */
    CAMERA_UP_ZERO,     /* up is the zero vector */
    CAMERA_UP_PARALLEL, /* |sin| of the angle between up and the view direction <= 1e-6 */
};

/* The camera's orthonormal frame from p: forward (unit, towards look_at), right and up (unit),
 * and |look_at - eye| in *view_len.  Vectors are scaled by a power of two before they are
 * normalised, which is exact, so a tiny (1e-30) or huge (3e38) but finite vector gives its
 * true direction, and any other gives the bits plain float arithmetic gives.  Returns
 * CAMERA_OK, or the fault with the outputs untouched.  scene.c checks a scene's camera with
 * it, so camera_init never fails on a loaded scene. */
enum camera_fault camera_frame(const struct camera_params *p, vec3 *forward, vec3 *right, vec3 *up,
                               float *view_len);

/* Builds the camera; false (and *err filled, without file/line) when camera_frame refuses p. */
bool camera_init(struct camera *cam, const struct camera_params *p, int width, int height,
                 struct mcpt_error *err);

/* Primary ray through film position (px, py) in pixels, (0, 0) = top-left corner of the
 * top-left pixel, x right, y down; u_lens in [0,1)^2 picks the lens point.  d is unit length. */
struct ray camera_ray(const struct camera *cam, float px, float py, vec2 u_lens);

#endif
