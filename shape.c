/* shape.c - analytic shapes: spheres, parallelograms (quads) and infinite planes.
 * Sphere: the quadratic in the form of Haines et al. 2019, "Precision Improvements for
 * Ray/Sphere Intersection" (Ray Tracing Gems ch. 7), and PBRT 4e, ch. 6, "Spheres"; the hit point
 * is reprojected onto the surface and carries an error bound (PBRT 4e, ch. 6, "Managing Rounding
 * Error").  Quad: plane hit, then the planar coordinates (alpha, beta) of the hit. */
#include "shape.h"

static vec3 v3_abs(vec3 a) { return (vec3){fabsf(a.x), fabsf(a.y), fabsf(a.z)}; }

/* ---- sphere ---- */

bool shape_sphere_intersect(const struct sphere *s, const struct ray *ray, float *t_hit)
{
    /* |o + t d - c|^2 = r^2:  a t^2 + 2 b' t + c' = 0 with f = o - c, a = d.d, b' = f.d,
     * c' = f.f - r^2.  Discriminant / 4 = a (r^2 - |f - (b'/a) d|^2)  (RTG ch. 7, eq. 10),
     * which keeps its precision for rays far from the sphere. */
    vec3 f = v3_sub(ray->o, s->center);
    float a = v3_dot(ray->d, ray->d);
    float b = v3_dot(f, ray->d);
    float c = v3_dot(f, f) - s->radius * s->radius;
    vec3 l = v3_sub(f, v3_scale(ray->d, b / a));
    float disc = a * (s->radius - v3_length(l)) * (s->radius + v3_length(l));
    if (!(disc >= 0.0f))
        return false;
    /* q = -(b' + sign(b') sqrt(disc)); roots q / a and c' / q (Numerical Recipes form) */
    float q = -(b + copysignf(sqrtf(disc), b));
    float t0 = q / a;
    float t1 = q != 0.0f ? c / q : t0;
    if (t0 > t1) {
        float tmp = t0;
        t0 = t1;
        t1 = tmp;
    }
    if (t0 > ray->t_min && t0 < ray->t_max) {
        *t_hit = t0;
        return true;
    }
    if (t1 > ray->t_min && t1 < ray->t_max) {
        *t_hit = t1;
        return true;
    }
    return false;
}

struct surface shape_sphere_surface(const struct sphere *s, const struct ray *ray, float t_hit)
{
    struct surface sf;
    vec3 p = v3_add(ray->o, v3_scale(ray->d, t_hit));
    /* reproject onto the sphere: error gamma(5) |p - c| (PBRT 4e, ch. 6, "Spheres"), plus
     * the rounding of adding the centre back */
    vec3 pc = v3_sub(p, s->center);
    float len = v3_length(pc);
    if (len > 0.0f)
        pc = v3_scale(pc, s->radius / len);
    else
        pc = v3(0.0f, s->radius, 0.0f);
    sf.p = v3_add(s->center, pc);
    sf.p_error = v3_add(v3_scale(v3_abs(pc), mcpt_gamma(5)),
                        v3_scale(v3_abs(sf.p), mcpt_gamma(1)));
    sf.ng = v3_scale(pc, 1.0f / s->radius);
    sf.ns = sf.ng;
    float phi = atan2f(sf.ng.z, sf.ng.x);
    sf.uv = (vec2){(phi < 0.0f ? phi + 2.0f * MCPT_PI : phi) * (0.5f * MCPT_INV_PI),
                   acosf(fminf(1.0f, fmaxf(-1.0f, sf.ng.y))) * MCPT_INV_PI};
    sf.mat_idx = s->mat_idx;
    return sf;
}

/* ---- quad ---- */

bool shape_quad_intersect(const struct quad *q, const struct ray *ray, float *t_hit)
{
    vec3 n = v3_cross(q->e1, q->e2);
    float denom = v3_dot(n, ray->d);
    if (denom == 0.0f)
        return false;
    float t = v3_dot(n, v3_sub(q->corner, ray->o)) / denom;
    if (!(t > ray->t_min && t < ray->t_max))
        return false;
    /* planar coordinates: pd = alpha e1 + beta e2, alpha = (pd x e2).n / n.n,
     * beta = (e1 x pd).n / n.n */
    vec3 pd = v3_sub(v3_add(ray->o, v3_scale(ray->d, t)), q->corner);
    float inv_nn = 1.0f / v3_dot(n, n);
    float alpha = v3_dot(v3_cross(pd, q->e2), n) * inv_nn;
    float beta = v3_dot(v3_cross(q->e1, pd), n) * inv_nn;
    if (!(alpha >= 0.0f && alpha <= 1.0f && beta >= 0.0f && beta <= 1.0f))
        return false;
    *t_hit = t;
    return true;
}

struct surface shape_quad_surface(const struct quad *q, const struct ray *ray, float t_hit)
{
    struct surface sf;
    vec3 n = v3_cross(q->e1, q->e2);
    vec3 pd = v3_sub(v3_add(ray->o, v3_scale(ray->d, t_hit)), q->corner);
    float inv_nn = 1.0f / v3_dot(n, n);
    float alpha = fminf(1.0f, fmaxf(0.0f, v3_dot(v3_cross(pd, q->e2), n) * inv_nn));
    float beta = fminf(1.0f, fmaxf(0.0f, v3_dot(v3_cross(q->e1, pd), n) * inv_nn));
    /* p rebuilt from the parameterisation: error of a 3-term sum, gamma(3) per term; the
     * products alpha e1, beta e2 add one rounding each */
    vec3 a_e1 = v3_scale(q->e1, alpha), b_e2 = v3_scale(q->e2, beta);
    sf.p = v3_add(v3_add(q->corner, a_e1), b_e2);
    sf.p_error = v3_scale(v3_add(v3_add(v3_abs(q->corner), v3_abs(a_e1)), v3_abs(b_e2)),
                          mcpt_gamma(4));
    sf.ng = v3_normalize(n);
    sf.ns = sf.ng;
    sf.uv = (vec2){alpha, beta};
    sf.mat_idx = q->mat_idx;
    return sf;
}

/* ---- infinite plane ---- */

bool shape_plane_intersect(const struct plane *pl, const struct ray *ray, float *t_hit)
{
    float denom = v3_dot(pl->n, ray->d);
    if (denom == 0.0f)
        return false;
    float t = v3_dot(pl->n, v3_sub(pl->point, ray->o)) / denom;
    if (!(t > ray->t_min && t < ray->t_max))
        return false;
    *t_hit = t;
    return true;
}

struct surface shape_plane_surface(const struct plane *pl, const struct ray *ray, float t_hit)
{
    struct surface sf;
    vec3 p = v3_add(ray->o, v3_scale(ray->d, t_hit));
    /* project back onto the plane: p -= ((p - point) . n) n */
    vec3 pp = v3_sub(p, pl->point);
    p = v3_sub(p, v3_scale(pl->n, v3_dot(pp, pl->n)));
    sf.p = p;
    sf.p_error = v3_scale(v3_add(v3_abs(p), v3_abs(pl->point)), mcpt_gamma(7));
    sf.ng = pl->n;
    sf.ns = pl->n;
    vec3 t, b;
    v3_basis(pl->n, &t, &b);
    sf.uv = (vec2){v3_dot(pp, t), v3_dot(pp, b)};
    sf.mat_idx = pl->mat_idx;
    return sf;
}
