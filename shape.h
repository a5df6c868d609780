/* shape.h - analytic shapes kept outside the BVH: spheres, parallelograms ("quads") and
 * infinite planes.  Each has a ray intersection that returns the hit parameter and a
 * surface query that returns the point with its floating-point error bound (PBRT 4e, ch. 6,
 * "Managing Rounding Error"), so secondary rays can be offset without scene-tuned epsilons. */
#ifndef MCPT_SHAPE_H
#define MCPT_SHAPE_H

#include "vec.h"

struct sphere {
    vec3 center;
    float radius; /* > 0, scene units */
    uint32_t mat_idx;
};

/* Parallelogram p = corner + s e1 + t e2, s, t in [0, 1]; front normal = normalize(e1 x e2). */
struct quad {
    vec3 corner;
    vec3 e1;
    vec3 e2;
    uint32_t mat_idx;
};

/* Infinite plane through point with unit normal n (front side). */
struct plane {
    vec3 point;
    vec3 n;
    uint32_t mat_idx;
};

/* A point on a surface, as the integrator needs it. */
struct surface {
    vec3 p;        /* position */
    vec3 p_error;  /* absolute error bound of p, per component */
    vec3 ng;       /* unit geometric normal (front side of the primitive) */
    vec3 ns;       /* unit shading normal, on the same side as ng */
    vec2 uv;       /* surface parameterisation */
    uint32_t mat_idx;
};

/* Ray-shape tests: return true and set *t_hit when the ray meets the shape at
 * t in (ray->t_min, ray->t_max). */
bool shape_sphere_intersect(const struct sphere *s, const struct ray *ray, float *t_hit);
bool shape_quad_intersect(const struct quad *q, const struct ray *ray, float *t_hit);
bool shape_plane_intersect(const struct plane *pl, const struct ray *ray, float *t_hit);

/* Surface at the hit t_hit of ray (which must have hit the shape). */
struct surface shape_sphere_surface(const struct sphere *s, const struct ray *ray, float t_hit);
struct surface shape_quad_surface(const struct quad *q, const struct ray *ray, float t_hit);
struct surface shape_plane_surface(const struct plane *pl, const struct ray *ray, float t_hit);

#endif
