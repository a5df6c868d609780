/* shape.c - each kind of primitive's geometry: spheres, parallelograms (quads), infinite planes
 * and the surface of triangles; intersection, surface point with its error bound (PBRT 4e, ch. 6,
 * "Managing Rounding Error") and, for the shapes that emit, sampling from a reference point.
 * Sphere: the quadratic in the form of Haines et al. 2019, "Precision Improvements for
 * Ray/Sphere Intersection" (Ray Tracing Gems ch. 7), and PBRT 4e, ch. 6, "Spheres"; the hit point
 * is reprojected onto the surface.  Quad: plane hit, then the planar coordinates (alpha, beta).
 * Sampling: PBRT 4e, ch. 6, "Shape Interface" (Sample(ctx, u), PDF(ctx, wi)); uniform by area
 * and converted to solid angle, or, for a sphere seen from outside, uniform in its cone. */
#include "shape.h"

#include "sample.h"

static vec3 v3_abs(vec3 a) { return (vec3){fabsf(a.x), fabsf(a.y), fabsf(a.z)}; }

/* ---- from area to solid angle ---- */

/* area -> solid angle: pdf_sa = pdf_area * dist^2 / |cos theta_light| for the point at d from
 * the reference point, normal n, seen along unit wi (PBRT 4e, ch. 4, "Radiometric Integrals":
 * dw = |cos theta| dA / r^2); false when seen edge-on. */
static bool area_to_solid_angle(float pdf_area, vec3 d, vec3 n, vec3 wi, float *pdf_sa)
{
    float cos_light = fabsf(v3_dot(n, wi));
    if (!(cos_light > 0.0f))
        return false;
    *pdf_sa = pdf_area * v3_dot(d, d) / cos_light;
    return true;
}

/* A point p (error p_error, normal n) sampled with density pdf_area per unit area, as seen from
 * ref: fills *ss with wi and pdf_sa. */
static bool sample_by_area(vec3 p, vec3 p_error, vec3 n, float pdf_area, const struct surface *ref,
                           struct shape_sample *ss)
{
    vec3 d = v3_sub(p, ref->p);
    float dist2 = v3_dot(d, d);
    if (!(dist2 > 0.0f))
        return false;
    ss->p = p;
    ss->p_error = p_error;
    ss->n = n;
    ss->wi = v3_scale(d, 1.0f / sqrtf(dist2));
    return area_to_solid_angle(pdf_area, d, n, ss->wi, &ss->pdf_sa) && isfinite(ss->pdf_sa);
}

/* The solid-angle density at the point on where wi meets a shape sampled with pdf_area. */
static float pdf_by_area(float pdf_area, const struct surface *ref, const struct surface *on,
                         vec3 wi)
{
    float pdf_sa;
    return area_to_solid_angle(pdf_area, v3_sub(on->p, ref->p), on->ng, wi, &pdf_sa) ? pdf_sa
                                                                                     : 0.0f;
}

/* ---- by solid angle: spherical triangles and rectangles ---- */

/* PBRT 4e's Triangle::Sample samples by solid angle only between these solid angles (sr):
 * below, float loses the spherical map's precision (and the light is small: little to gain);
 * above, the light fills most of the hemisphere, where BSDF sampling does better anyway. */
static const float SPHERICAL_MIN_SR = 3e-4f;
static const float SPHERICAL_MAX_SR = 6.22f;

/* The weights of the bilinear warp that makes light samples follow |cos theta| at the receiver
 * (PBRT 4e, ch. 6, "Triangles" and "Bilinear Patches"): |ns . d| at the directions d of the
 * corners of the u square, at least 0.01 so that no direction gets density 0 (the BSDF may
 * still reflect there: shading normals, transmission). */
static void receiver_weights(const struct surface *ref, vec3 d00, vec3 d10, vec3 d01, vec3 d11,
                             float w[4])
{
    const vec3 d[4] = {d00, d10, d01, d11};
    for (int k = 0; k < 4; k++)
        w[k] = fmaxf(0.01f, fabsf(v3_dot(ref->ns, d[k])));
}

/* Warps *u by the bilinear density of the receiver weights w (receiver_weights) and returns
 * its density at the warped point, pdf_bilinear(u, w): the factor of pdf_sa before the
 * spherical map's 1 / solid angle. */
static float warp_by_cosine(vec2 *u, const float w[4])
{
    *u = sample_bilinear(*u, w);
    return pdf_bilinear(*u, w);
}

/* Completes *ss, whose point p is set, with the unit direction wi from ref->p and the density
 * pdf_sa; false when p coincides with ref->p or is seen edge-on (n, any length, is the
 * shape's normal) or the density is not finite. */
static bool direction_to(struct shape_sample *ss, vec3 n, const struct surface *ref, float pdf_sa)
{
    vec3 d = v3_sub(ss->p, ref->p);
    float dist = v3_length(d);
    if (!(dist > 0.0f) || v3_dot(n, d) == 0.0f)
        return false;
    ss->wi = v3_scale(d, 1.0f / dist);
    ss->pdf_sa = pdf_sa;
    return pdf_sa > 0.0f && isfinite(pdf_sa);
}

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

/* The point at offset pc (length r) from the centre: error gamma(5) |pc| of the reprojection
 * (PBRT 4e, ch. 6, "Spheres"), plus the rounding of adding the centre back. */
static vec3 sphere_point(const struct sphere *s, vec3 pc, vec3 *p_error)
{
    vec3 p = v3_add(s->center, pc);
    *p_error = v3_add(v3_scale(v3_abs(pc), mcpt_gamma(5)), v3_scale(v3_abs(p), mcpt_gamma(1)));
    return p;
}

struct surface shape_sphere_surface(const struct sphere *s, const struct ray *ray, float t_hit)
{
    struct surface sf;
    vec3 p = v3_add(ray->o, v3_scale(ray->d, t_hit));
    /* reproject onto the sphere */
    vec3 pc = v3_sub(p, s->center);
    float len = v3_length(pc);
    if (len > 0.0f)
        pc = v3_scale(pc, s->radius / len);
    else
        pc = v3(0.0f, s->radius, 0.0f);
    sf.p = sphere_point(s, pc, &sf.p_error);
    sf.ng = v3_scale(pc, 1.0f / s->radius);
    sf.ns = sf.ng;
    float phi = atan2f(sf.ng.z, sf.ng.x);
    sf.uv = (vec2){(phi < 0.0f ? phi + 2.0f * MCPT_PI : phi) * (0.5f * MCPT_INV_PI),
                   acosf(fminf(1.0f, fmaxf(-1.0f, sf.ng.y))) * MCPT_INV_PI};
    sf.mat_idx = s->mat_idx;
    return sf;
}

/* Uniform area sampling of the whole sphere: pdf_area = 1 / (4 pi r^2). */
static float sphere_pdf_area(const struct sphere *s)
{
    return 1.0f / (4.0f * MCPT_PI * s->radius * s->radius);
}

/* The cone of directions in which ref sees sphere s, from ref->p offset towards the centre, so
 * that a point on the sphere itself counts as inside (PBRT 4e, ch. 6, "Spheres"): sin^2
 * theta_max = r^2 / dist^2.  False when that point is inside; *wc = centre - the point. */
static bool sphere_cone(const struct sphere *s, const struct surface *ref, vec3 *wc,
                        struct sample_cone *cone)
{
    vec3 origin = offset_ray_origin(ref->p, ref->p_error, ref->ng, v3_sub(s->center, ref->p));
    *wc = v3_sub(s->center, origin);
    float dist2 = v3_dot(*wc, *wc);
    if (dist2 <= s->radius * s->radius)
        return false;
    *cone = sample_cone_from_sin2(s->radius * s->radius / dist2);
    return true;
}

bool shape_sphere_sample(const struct sphere *s, const struct surface *ref, vec2 u,
                         struct shape_sample *ss)
{
    vec3 wc, p_error;
    struct sample_cone cone;
    if (!sphere_cone(s, ref, &wc, &cone)) {
        /* inside: uniform by area */
        vec3 n = sample_uniform_sphere(u);
        vec3 p = sphere_point(s, v3_scale(n, s->radius), &p_error);
        return sample_by_area(p, p_error, n, sphere_pdf_area(s), ref, ss);
    }
    /* outside: a direction uniform in the cone (sample.c), pdf_sa = 1 / (2 pi (1 - cos
     * theta_max)), then the angle alpha, seen from the centre, between the reference point and
     * the point where that direction first meets the sphere (PBRT 4e, ch. 6, "Spheres") */
    float cos_theta, sin2_theta;
    sample_uniform_cone_theta(u.x, &cone, &cos_theta, &sin2_theta);
    float sin2_theta_max = cone.sin2_theta_max;
    float sin_theta_max = sqrtf(sin2_theta_max);
    float cos_alpha = sin2_theta / sin_theta_max +
                      cos_theta * sqrtf(fmaxf(0.0f, 1.0f - sin2_theta / sin2_theta_max));
    float sin_alpha = sqrtf(fmaxf(0.0f, 1.0f - cos_alpha * cos_alpha));
    float phi = 2.0f * MCPT_PI * u.y;
    vec3 wz = v3_scale(wc, -1.0f / sqrtf(v3_dot(wc, wc))); /* centre -> reference point */
    vec3 wx, wy;
    v3_basis(wz, &wx, &wy);
    vec3 n = v3_from_local(v3(sin_alpha * cosf(phi), sin_alpha * sinf(phi), cos_alpha), wx, wy, wz);
    ss->n = n;
    ss->p = sphere_point(s, v3_scale(n, s->radius), &ss->p_error);
    vec3 d = v3_sub(ss->p, ref->p);
    float dist = v3_length(d);
    if (!(dist > 0.0f))
        return false;
    ss->wi = v3_scale(d, 1.0f / dist);
    ss->pdf_sa = pdf_uniform_cone(&cone);
    return ss->pdf_sa > 0.0f;
}

float shape_sphere_pdf(const struct sphere *s, const struct surface *ref, const struct surface *on,
                       vec3 wi)
{
    vec3 wc;
    struct sample_cone cone;
    if (sphere_cone(s, ref, &wc, &cone))
        return pdf_uniform_cone(&cone);
    return pdf_by_area(sphere_pdf_area(s), ref, on, wi);
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

/* p = corner + alpha e1 + beta e2, rebuilt from the parameterisation: error of a 3-term sum,
 * gamma(3) per term; the products alpha e1, beta e2 add one rounding each. */
static vec3 quad_point(const struct quad *q, float alpha, float beta, vec3 *p_error)
{
    vec3 a_e1 = v3_scale(q->e1, alpha), b_e2 = v3_scale(q->e2, beta);
    *p_error = v3_scale(v3_add(v3_add(v3_abs(q->corner), v3_abs(a_e1)), v3_abs(b_e2)),
                        mcpt_gamma(4));
    return v3_add(v3_add(q->corner, a_e1), b_e2);
}

struct surface shape_quad_surface(const struct quad *q, const struct ray *ray, float t_hit)
{
    struct surface sf;
    vec3 n = v3_cross(q->e1, q->e2);
    vec3 pd = v3_sub(v3_add(ray->o, v3_scale(ray->d, t_hit)), q->corner);
    float inv_nn = 1.0f / v3_dot(n, n);
    float alpha = fminf(1.0f, fmaxf(0.0f, v3_dot(v3_cross(pd, q->e2), n) * inv_nn));
    float beta = fminf(1.0f, fmaxf(0.0f, v3_dot(v3_cross(q->e1, pd), n) * inv_nn));
    sf.p = quad_point(q, alpha, beta, &sf.p_error);
    sf.ng = v3_normalize(n);
    sf.ns = sf.ng;
    sf.uv = (vec2){alpha, beta};
    sf.mat_idx = q->mat_idx;
    return sf;
}

bool shape_quad_sample(const struct quad *q, const struct surface *ref, vec2 u,
                       struct shape_sample *ss)
{
    /* uniform by area: p = corner + u0 e1 + u1 e2, pdf_area = 1 / |e1 x e2| */
    vec3 p_error;
    vec3 p = quad_point(q, u.x, u.y, &p_error);
    vec3 c = v3_cross(q->e1, q->e2);
    return sample_by_area(p, p_error, v3_normalize(c), 1.0f / v3_length(c), ref, ss);
}

float shape_quad_pdf(const struct quad *q, const struct surface *ref, const struct surface *on,
                     vec3 wi)
{
    return pdf_by_area(1.0f / v3_length(v3_cross(q->e1, q->e2)), ref, on, wi);
}

/* Whether the quad q is sampled by solid angle from ref: a rectangle whose solid angle is at
 * least SPHERICAL_MIN_SR (PBRT 4e's BilinearPatch::Sample has no upper bound).  Fills *sr, and
 * w[4] with the cosine weights at ref's shading normal of the corners corner, + e1, + e2,
 * + e1 + e2, where u = (0,0), (1,0), (0,1), (1,1) map. */
static bool quad_by_solid_angle(const struct quad *q, const struct surface *ref,
                                struct sample_sph_rect *sr, float w[4])
{
    if (!sample_sph_rect_init(ref->p, q->corner, q->e1, q->e2, sr) ||
        !(sr->area >= SPHERICAL_MIN_SR))
        return false;
    vec3 c[4] = {q->corner, v3_add(q->corner, q->e1), v3_add(q->corner, q->e2),
                 v3_add(v3_add(q->corner, q->e1), q->e2)};
    for (int k = 0; k < 4; k++)
        c[k] = v3_normalize(v3_sub(c[k], ref->p));
    receiver_weights(ref, c[0], c[1], c[2], c[3], w);
    return true;
}

bool shape_quad_sample_solid_angle(const struct quad *q, const struct surface *ref, vec2 u,
                                   struct shape_sample *ss)
{
    struct sample_sph_rect sr;
    float w[4];
    if (!quad_by_solid_angle(q, ref, &sr, w))
        return shape_quad_sample(q, ref, u, ss);
    /* Urena et al. 2013, u first warped by the cosine at the receiver:
     * pdf_sa = pdf_bilinear(u) / S */
    float pdf_u = warp_by_cosine(&u, w);
    vec3 pr = v3_sub(sample_spherical_rectangle(&sr, u), q->corner);
    float alpha = fminf(1.0f, fmaxf(0.0f, v3_dot(pr, q->e1) / v3_dot(q->e1, q->e1)));
    float beta = fminf(1.0f, fmaxf(0.0f, v3_dot(pr, q->e2) / v3_dot(q->e2, q->e2)));
    ss->p = quad_point(q, alpha, beta, &ss->p_error);
    vec3 c = v3_cross(q->e1, q->e2);
    ss->n = v3_normalize(c);
    return direction_to(ss, c, ref, pdf_u * pdf_spherical_rectangle(&sr));
}

float shape_quad_pdf_solid_angle(const struct quad *q, const struct surface *ref,
                                 const struct surface *on, vec3 wi)
{
    struct sample_sph_rect sr;
    float w[4];
    if (!quad_by_solid_angle(q, ref, &sr, w))
        return shape_quad_pdf(q, ref, on, wi);
    /* pdf_sa = pdf_bilinear(u) / S at the u that maps to the point on->p */
    return pdf_bilinear(sample_invert_spherical_rectangle(&sr, on->p), w) *
           pdf_spherical_rectangle(&sr);
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

/* ---- triangle (the BVH finds the hit) ---- */

/* p = b0 p0 + b1 p1 + b2 p2 and sum |b_i p_i|, which bounds its rounding error (PBRT 4e,
 * ch. 6, "Managing Rounding Error": gamma(7) times it after an intersection, gamma(6) for exact
 * sampled barycentrics). */
static vec3 barycentric_point(const vec3 p[3], float b0, float b1, float b2, vec3 *abs_sum)
{
    vec3 bp0 = v3_scale(p[0], b0), bp1 = v3_scale(p[1], b1), bp2 = v3_scale(p[2], b2);
    *abs_sum = v3_add(v3_add(v3_abs(bp0), v3_abs(bp1)), v3_abs(bp2));
    return v3_add(v3_add(bp0, bp1), bp2);
}

struct surface shape_triangle_surface(const vec3 p[3], const vec3 *ns, const vec2 *uv, float b1,
                                      float b2, uint32_t mat_idx)
{
    float b0 = 1.0f - b1 - b2;
    struct surface sf;
    vec3 abs_sum;
    sf.p = barycentric_point(p, b0, b1, b2, &abs_sum);
    sf.p_error = v3_scale(abs_sum, mcpt_gamma(7));
    sf.ng = v3_normalize(v3_cross(v3_sub(p[1], p[0]), v3_sub(p[2], p[0])));
    sf.ns = sf.ng;
    if (ns) {
        vec3 n = v3_add(v3_add(v3_scale(ns[0], b0), v3_scale(ns[1], b1)), v3_scale(ns[2], b2));
        float len = v3_length(n);
        if (len > 0.0f && isfinite(len)) {
            n = v3_scale(n, 1.0f / len);
            sf.ns = v3_dot(n, sf.ng) < 0.0f ? v3_neg(n) : n;
        }
    }
    sf.uv = (vec2){b1, b2};
    if (uv)
        sf.uv = (vec2){b0 * uv[0].x + b1 * uv[1].x + b2 * uv[2].x,
                       b0 * uv[0].y + b1 * uv[1].y + b2 * uv[2].y};
    sf.mat_idx = mat_idx;
    return sf;
}

float shape_triangle_area(const vec3 p[3], vec3 *ng)
{
    vec3 c = v3_cross(v3_sub(p[1], p[0]), v3_sub(p[2], p[0]));
    float len = v3_length(c);
    if (ng)
        *ng = len > 0.0f ? v3_scale(c, 1.0f / len) : v3_splat(0.0f);
    return 0.5f * len;
}

bool shape_triangle_sample(const vec3 p[3], const struct surface *ref, vec2 u,
                           struct shape_sample *ss)
{
    /* uniform by area: barycentrics by the square-root warp (sample.c), pdf_area = 1 / A */
    vec2 b = sample_uniform_triangle(u);
    vec3 abs_sum, n;
    vec3 pt = barycentric_point(p, b.x, b.y, 1.0f - b.x - b.y, &abs_sum);
    float area = shape_triangle_area(p, &n);
    return sample_by_area(pt, v3_scale(abs_sum, mcpt_gamma(6)), n, 1.0f / area, ref, ss);
}

float shape_triangle_pdf(const vec3 p[3], const struct surface *ref, const struct surface *on,
                         vec3 wi)
{
    return pdf_by_area(1.0f / shape_triangle_area(p, NULL), ref, on, wi);
}

/* Whether the triangle p[3] is sampled by solid angle from ref: its solid angle lies between
 * the bounds (PBRT 4e's Triangle::Sample).  Fills *st, and w[4] with the cosine weights of the
 * corners of Arvo's u square at ref's shading normal (u = (0,0) and (1,0) map to p[1], (0,1) to
 * p[0], (1,1) to p[2]). */
static bool triangle_by_solid_angle(const vec3 p[3], const struct surface *ref,
                                    struct sample_sph_triangle *st, float w[4])
{
    vec3 d[3];
    for (int k = 0; k < 3; k++) {
        d[k] = v3_sub(p[k], ref->p);
        float len = v3_length(d[k]);
        if (!(len > 0.0f))
            return false;
        d[k] = v3_scale(d[k], 1.0f / len);
    }
    if (!sample_sph_triangle_init(d[0], d[1], d[2], st) ||
        !(st->area >= SPHERICAL_MIN_SR && st->area <= SPHERICAL_MAX_SR))
        return false;
    receiver_weights(ref, d[1], d[1], d[0], d[2], w);
    return true;
}

bool shape_triangle_sample_solid_angle(const vec3 p[3], const struct surface *ref, vec2 u,
                                       struct shape_sample *ss)
{
    struct sample_sph_triangle st;
    float w[4];
    if (!triangle_by_solid_angle(p, ref, &st, w))
        return shape_triangle_sample(p, ref, u, ss);
    /* Arvo 1995, u first warped by the cosine at the receiver: pdf_sa = pdf_bilinear(u) / Omega */
    float pdf_u = warp_by_cosine(&u, w);
    vec3 wi = sample_spherical_triangle(&st, u);
    /* the barycentrics where the ray ref->p + t wi meets the triangle's plane (Moller & Trumbore
     * 1997), clamped onto the triangle against rounding */
    vec3 e1 = v3_sub(p[1], p[0]), e2 = v3_sub(p[2], p[0]), s = v3_sub(ref->p, p[0]);
    vec3 s1 = v3_cross(wi, e2);
    float divisor = v3_dot(s1, e1);
    if (divisor == 0.0f)
        return false;
    float b1 = fminf(1.0f, fmaxf(0.0f, v3_dot(s, s1) / divisor));
    float b2 = fminf(1.0f, fmaxf(0.0f, v3_dot(wi, v3_cross(s, e1)) / divisor));
    if (b1 + b2 > 1.0f) {
        float sum = b1 + b2;
        b1 /= sum;
        b2 /= sum;
    }
    vec3 abs_sum;
    ss->p = barycentric_point(p, 1.0f - b1 - b2, b1, b2, &abs_sum);
    ss->p_error = v3_scale(abs_sum, mcpt_gamma(6));
    shape_triangle_area(p, &ss->n);
    return direction_to(ss, ss->n, ref, pdf_u * pdf_spherical_triangle(&st));
}

float shape_triangle_pdf_solid_angle(const vec3 p[3], const struct surface *ref,
                                     const struct surface *on, vec3 wi)
{
    struct sample_sph_triangle st;
    float w[4];
    if (!triangle_by_solid_angle(p, ref, &st, w))
        return shape_triangle_pdf(p, ref, on, wi);
    /* pdf_sa = pdf_bilinear(u) / Omega at the u that maps to wi */
    return pdf_bilinear(sample_invert_spherical_triangle(&st, wi), w) * pdf_spherical_triangle(&st);
}
