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
    float fov_deg;        /* vertical field of view, (0, 180) */
    float aperture;       /* lens radius, scene units; 0 = pinhole */
    float focus_dist;     /* distance to the plane in focus; 0 = |look_at - eye| */
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

/* Builds the camera; false (and *err filled, without file/line) when eye == look_at or up is
 * parallel to the view direction. */
bool camera_init(struct camera *cam, const struct camera_params *p, int width, int height,
                 struct mcpt_error *err);

/* Primary ray through film position (px, py) in pixels, (0, 0) = top-left corner of the
 * top-left pixel, x right, y down; u_lens in [0,1)^2 picks the lens point.  d is unit length. */
struct ray camera_ray(const struct camera *cam, float px, float py, vec2 u_lens);

#endif
