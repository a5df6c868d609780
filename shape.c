/* shape.c - each kind of primitive's geometry: spheres, parallelograms (quads), infinite planes
 * and the surface of triangles; intersection, surface point with its error bound (PBRT 4e, ch. 6,
 * "Managing Rounding Error") and, for the shapes that emit, sampling from a reference point.
 * Robustness (docs/theory.md, "Self-intersection"): intersections, hit points and normals are
 * computed in double from the float inputs, so a point's error is its rounding to float (half an
 * ulp) whatever the size of its primitive, and the side of a spawned ray's origin is decided
 * exactly; the sphere's roots carry an interval (PBRT 4e, ch. 6, "Bounding Intersection Point
 * Error"), in double.  Sphere: the quadratic of Haines et al. 2019, "Precision Improvements for
 * Ray/Sphere Intersection" (Ray Tracing Gems ch. 7).  Sampling: PBRT 4e, ch. 6, "Shape
 * Interface"; uniform by area and converted to solid angle, or, for a sphere seen from outside,
 * uniform in its cone. */
#include "shape.h"

#include <float.h>
#include <string.h>

#include "sample.h"

/* ---- double precision ----
 * Products of two floats are exact in double and no sum of a few of them overflows or
 * underflows, so these computations are 2^29 times more precise than the float ones and need no
 * absolute error term.  A quad's corner and edges are doubles (shape.h): their products round
 * once more, which each bound below allows for (one rounding per product).  gamma_d(n) =
 * n u / (1 - n u), u = 2^-53 (PBRT 4e, ch. 6, "Managing Rounding Error"). */
/* (d3_add, d3_sub, d3_dot, d3_cross and the others: vec.h) */
static double d3_sum(struct dvec3 a) { return a.x + a.y + a.z; }
/* |a_y b_z| + |a_z b_y|, ...: bounds each component of a x b and scales its rounding error */
static struct dvec3 d3_cross_abs(struct dvec3 a, struct dvec3 b)
{
    return (struct dvec3){fabs(a.y * b.z) + fabs(a.z * b.y), fabs(a.z * b.x) + fabs(a.x * b.z),
                          fabs(a.x * b.y) + fabs(a.y * b.x)};
}
/* the greater of two finite values (a comparison: fmax is a library call) */
static double max_d(double a, double b) { return a > b ? a : b; }
static double d3_max(struct dvec3 a) { return max_d(a.x, max_d(a.y, a.z)); }

static double gamma_d(int n)
{
    const double u = 0x1p-53;
    return ((double)n * u) / (1.0 - (double)n * u);
}

/* A float that is >= x (x >= 0): the rounded value, moved up when rounding went down.  For
 * x >= 0 that step is next_float_up's bits + 1, here without its branches (from the largest
 * float it gives infinity, as next_float_up does). */
static float float_up(double x)
{
    float f = (float)x;
    uint32_t bits;
    memcpy(&bits, &f, sizeof bits);
    bits += (uint32_t)((double)f < x);
    memcpy(&f, &bits, sizeof f);
    return f;
}

/* The bound, per component and in double, of the error of the float point nearest p_d, where
 * p_d is within err_d of the exact point: err_d plus the rounding to float, at most 2^-24 |p_d|
 * (half an ulp) or 2^-150 below FLT_MIN.  eta bounds each component of the error of the unit
 * normal the caller returns beside the point: offset_ray_origin pushes along that normal by
 * n . p_error, and 4 eta (sum of the errors) added to every component keeps the push, projected
 * on the exact normal, beyond the exact distance (docs/theory.md, "Self-intersection"). */
static ALWAYS_INLINE struct dvec3 point_error_d(struct dvec3 p_d, struct dvec3 err_d, double eta)
{
    struct dvec3 e = d3_add(err_d, d3_add(d3_scale(d3_abs(p_d), 0x1p-24),
                                          (struct dvec3){0x1p-149, 0x1p-149, 0x1p-149}));
    double spread = 4.0 * eta * d3_sum(e);
    return d3_add(e, (struct dvec3){spread, spread, spread});
}

/* The float point nearest p_d, with that bound rounded up to float. */
static ALWAYS_INLINE vec3 round_point(struct dvec3 p_d, struct dvec3 err_d, double eta,
                                      vec3 *p_error)
{
    struct dvec3 e = point_error_d(p_d, err_d, eta);
    *p_error = (vec3){float_up(e.x), float_up(e.y), float_up(e.z)};
    return d3_to_float(p_d);
}

/* The point o + a e1 + b e2 of the plane through o spanned by e1, e2 (exact doubles: a
 * triangle's float vertex and differences of floats, a quad's stored corner and edges), in
 * double: each term carries at most 2 roundings (e, and the product) and the two sums 2 more, so
 * |p_d - exact| <= gamma_d(4) (|o| + |a e1| + |b e2|) = *err; the exact point lies on the plane
 * for any a, b. */
static ALWAYS_INLINE struct dvec3 plane_point_d(struct dvec3 o, struct dvec3 e1, struct dvec3 e2,
                                                double a, double b, struct dvec3 *err)
{
    struct dvec3 a_e1 = d3_scale(e1, a);
    struct dvec3 b_e2 = d3_scale(e2, b);
    *err = d3_scale(d3_add(d3_add(d3_abs(o), d3_abs(a_e1)), d3_abs(b_e2)), gamma_d(4));
    return d3_add(d3_add(o, a_e1), b_e2);
}

/* An upper bound on the sum of the three error bounds round_point will give p_d. */
static double rounded_error_sum(struct dvec3 p_d, struct dvec3 err_d, double eta)
{
    double e = d3_sum(err_d) + 0x1p-24 * d3_sum(d3_abs(p_d)) + 3.0 * 0x1p-149;
    return e * (1.0 + 12.0 * eta) * (1.0 + 0x1p-20);
}

/* point_error_d's bound, raised past the rounding of round_point's float_up, so that a margin
 * may project it on a direction: the sum of its components is at most rounded_error_sum's. */
static struct dvec3 rounded_error_vec(struct dvec3 p_d, struct dvec3 err_d, double eta)
{
    return d3_scale(point_error_d(p_d, err_d, eta), 1.0 + 0x1p-20);
}

/* The ray's point o + t_hit d projected onto the plane through o_pl with normal c (c_abs: the
 * magnitudes of the terms each component of c was formed from, c within gamma_d(2) of them), in
 * double, with *err bounding each component's share of its distance from the exact plane: the
 * projection's s = c . (x - o_pl) is within gamma_d(6) c_abs . |x - o_pl| (as plane_t), c's
 * direction within 2 gamma_d(2) |c_abs| / |c| (moving the point by that times its distance
 * |s| / |c|), and the subtraction rounds.  The error does not grow with |o_pl|, only with the
 * terms of c that are not zero: for a huge axis-aligned floor seen from nearby it is the
 * rounding of the point itself, where rebuilding the point from o_pl and the barycentrics costs
 * |o_pl| u (bvh.c: a floor of 1e15 at y = 0 seen from 1 unit above). */
static struct dvec3 ray_point_on_plane(const struct ray *ray, float t_hit, struct dvec3 o_pl,
                                       struct dvec3 c, struct dvec3 c_abs, struct dvec3 *err)
{
    struct dvec3 x = d3_add(d3(ray->o), d3_scale(d3(ray->d), t_hit));
    struct dvec3 xo = d3_sub(x, o_pl);
    double nn = d3_dot(c, c);
    double len = sqrt(nn);
    double s = d3_dot(c, xo);
    double k = s / nn;
    struct dvec3 p = d3_sub(x, d3_scale(c, k));
    double dist = gamma_d(6) * d3_dot(c_abs, d3_abs(xo)) / len +
                  2.0 * gamma_d(2) * d3_length(c_abs) / len * (fabs(s) / len);
    struct dvec3 kc = d3_abs(d3_scale(c, k));
    struct dvec3 ax = d3_abs(x);
    *err = (struct dvec3){dist + gamma_d(3) * (ax.x + kc.x), dist + gamma_d(3) * (ax.y + kc.y),
                          dist + gamma_d(3) * (ax.z + kc.z)};
    return p;
}

/* The unit normal of the plane spanned by e1, e2 (differences of floats) in double, rounded to
 * float, the length of e1 x e2 (*len, twice a triangle's area), and the bound eta on the error of
 * each of the normal's components: the cross product's components are off by
 * gamma_d(3) |e1| |e2| at most, which moves the direction by gamma_d(3) sqrt(3) / sin(angle)
 * and twice that after normalising, with 1 / sin(angle) = |e1| |e2| / |e1 x e2| <=
 * (|e1|^2 + |e2|^2) / (2 |e1 x e2|); the rounding to float adds 2^-24 per component.  A
 * degenerate pair (angle 0) gives ng = 0, *len = 0 and eta = 1.  c is e1 x e2 (d3_cross), which
 * plane_normal computes. */
static ALWAYS_INLINE vec3 plane_normal_c(struct dvec3 e1, struct dvec3 e2, struct dvec3 c,
                                         double *len, double *eta)
{
    *len = d3_length(c);
    if (!(*len > 0.0)) {
        *eta = 1.0;
        return v3_splat(0.0f);
    }
    double inv_len = 1.0 / *len;
    *eta = 0x1p-23 + 2.0 * gamma_d(3) * (d3_dot(e1, e1) + d3_dot(e2, e2)) * inv_len;
    return d3_to_float(d3_scale(c, inv_len));
}
static ALWAYS_INLINE vec3 plane_normal(struct dvec3 e1, struct dvec3 e2, double *len, double *eta)
{
    return plane_normal_c(e1, e2, d3_cross(e1, e2), len, eta);
}

/* The ray parameter t (a double, whose sign is certain) as a float, when it is > 0 and in
 * (t_min, t_max) as float compares it (a positive t that underflows becomes the least positive
 * float). */
static bool t_to_float(double t, const struct ray *ray, float *t_hit)
{
    if (!(t > 0.0))
        return false;
    float tf = (float)t > 0.0f ? (float)t : FLT_TRUE_MIN;
    *t_hit = tf;
    return tf > ray->t_min && tf < ray->t_max;
}

/* ---- from area to solid angle ---- */

/* Sampling by area, and the density of a direction found otherwise, are both measured from the
 * vertex's point ref->p, as PBRT 4e measures them (ch. 6, "Shape Interface": the sample
 * context's p(), not its spawned origin), to the exact point on the shape's plane (in double):
 * the sampled point before rounding, or where the line from ref->p along wi meets the plane.
 * Then the two strategies that MIS combines price every point alike, far from the origin too,
 * where a rounded point can be a few percent of the distance off (a closed emitting cube 32
 * float steps across lost 0.15% of its direct light with MIS, docs/theory.md,
 * "Self-intersection").  Not from the spawned origin (offset_ray_origin), where the shadow ray
 * and BSDF rays start: it lies a float step or two off the surface, and an estimate measured
 * from it is the light of a point moved into the room (the Cornell box 10^5 from the origin
 * gained 0.9% so, where from ref->p it gains 0.25%).  pdf_sa = pdf_area dist^2 /
 * |cos theta_light| (PBRT 4e, ch. 4, "Radiometric Integrals": dw = |cos theta| dA / r^2); in
 * double, since dist^2 and pdf_area scale as the square and inverse square of the scene's unit. */

/* The point x (exact, on the shape; p its rounded copy with error p_error, n the unit normal)
 * sampled with density pdf_area per unit area, as seen from ref: fills *ss with wi and pdf_sa. */
static bool sample_by_area(vec3 p, vec3 p_error, vec3 n, struct dvec3 x, double pdf_area,
                           const struct surface *ref, struct shape_sample *ss)
{
    struct dvec3 d = d3_sub(x, d3(ref->p));
    double dist = d3_length(d);
    if (!(dist > 0.0))
        return false;
    struct dvec3 w = d3_scale(d, 1.0 / dist);
    double cos_light = fabs(d3_dot(d3(n), w));
    if (!(cos_light > 0.0))
        return false;
    ss->p = p;
    ss->p_error = p_error;
    ss->n = n;
    ss->wi = d3_to_float(w);
    ss->pdf_sa = (float)(pdf_area * dist * dist / cos_light);
    return isfinite(ss->pdf_sa);
}

/* The solid-angle density of the direction wi for a shape in the plane through p0 with normal
 * c (in double, any length, c_len = |c|: the callers' area) sampled with pdf_area: the line from
 * ref->p along wi meets the plane at distance dist, seen at |cos theta_light| =
 * |c . wi| / (|c| |wi|). */
static float pdf_by_area(double pdf_area, struct dvec3 p0, struct dvec3 c, double c_len,
                         const struct surface *ref, vec3 wi)
{
    struct dvec3 w = d3(wi);
    double den = d3_dot(c, w);
    double t = d3_dot(c, d3_sub(p0, d3(ref->p))) / den;
    double w_len = d3_length(w);
    double cos_light = fabs(den) / (c_len * w_len);
    if (!(t > 0.0) || !(cos_light > 0.0))
        return 0.0f;
    double dist = t * w_len;
    float pdf_sa = (float)(pdf_area * dist * dist / cos_light);
    return isfinite(pdf_sa) ? pdf_sa : 0.0f;
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
        w[k] = max_f(0.01f, fabsf(v3_dot(ref->ns, d[k])));
}

/* Warps *u by the bilinear density of the receiver weights w (receiver_weights) and returns
 * its density at the warped point, pdf_bilinear(u, w): the factor of pdf_sa before the
 * spherical map's 1 / solid angle. */
static float warp_by_cosine(vec2 *u, const float w[4])
{
    *u = sample_bilinear(*u, w);
    return pdf_bilinear(*u, w);
}

/* The apex of a shape's spherical projection (sampling by solid angle): the vertex's point
 * ref->p, from which sample_by_area measures too. */
static vec3 solid_angle_apex(const struct surface *ref) { return ref->p; }

/* Completes *ss, whose point p is set, with the unit direction wi from apex (solid_angle_apex)
 * to x, the point sampled before rounding (far from the origin the rounded p can be a few
 * percent of the distance off, and the density is that of the sampled direction), and the
 * density pdf_sa; false when x coincides with the apex or is seen edge-on (n, any length, is
 * the shape's normal) or the density is not finite. */
static bool direction_to(struct shape_sample *ss, vec3 x, vec3 n, vec3 apex, float pdf_sa)
{
    vec3 d = v3_sub(x, apex);
    float dist = v3_length(d);
    if (!(dist > 0.0f) || v3_dot(n, d) == 0.0f)
        return false;
    ss->wi = v3_scale(d, 1.0f / dist);
    ss->pdf_sa = pdf_sa;
    return pdf_sa > 0.0f && isfinite(pdf_sa);
}

/* ---- sphere ---- */

/* An interval [lo, hi] of doubles holding an exact value; each operation rounds its bounds
 * outward, so the result holds the exact result of the exact operands (PBRT 4e,
 * ch. 6, "Interval Arithmetic"). */
struct interval {
    double lo;
    double hi;
}; /* 16 bytes */

static struct interval iv_exact(double x) { return (struct interval){x, x}; }
/* [lo, hi] widened by two ulps at each end: x - |x| 2^-51 is at least 2 ulps below x and exact,
 * and the least subnormal covers x == 0 (nextafter, a library call, made sphere tests 20 times
 * slower) */
static struct interval iv_out(double lo, double hi)
{
    return (struct interval){lo - (fabs(lo) * 0x1p-51 + DBL_TRUE_MIN),
                             hi + (fabs(hi) * 0x1p-51 + DBL_TRUE_MIN)};
}
static struct interval iv_add(struct interval a, struct interval b)
{
    return iv_out(a.lo + b.lo, a.hi + b.hi);
}
static struct interval iv_sub(struct interval a, struct interval b)
{
    return iv_out(a.lo - b.hi, a.hi - b.lo);
}
/* the least and greatest of four finite values (comparisons, not fmin/fmax: library calls) */
static double min4(const double v[4])
{
    double a = v[0] < v[1] ? v[0] : v[1];
    double b = v[2] < v[3] ? v[2] : v[3];
    return a < b ? a : b;
}
static double max4(const double v[4])
{
    double a = v[0] > v[1] ? v[0] : v[1];
    double b = v[2] > v[3] ? v[2] : v[3];
    return a > b ? a : b;
}
static struct interval iv_mul(struct interval a, struct interval b)
{
    double p[4] = {a.lo * b.lo, a.lo * b.hi, a.hi * b.lo, a.hi * b.hi};
    return iv_out(min4(p), max4(p));
}
/* a / b for b not containing 0 (the caller checks) */
static struct interval iv_div(struct interval a, struct interval b)
{
    double q[4] = {a.lo / b.lo, a.lo / b.hi, a.hi / b.lo, a.hi / b.hi};
    return iv_out(min4(q), max4(q));
}
/* sqrt of the non-negative part */
static struct interval iv_sqrt(struct interval a)
{
    return iv_out(sqrt(a.lo > 0.0 ? a.lo : 0.0), sqrt(a.hi > 0.0 ? a.hi : 0.0));
}
static struct interval iv_neg(struct interval a) { return (struct interval){-a.hi, -a.lo}; }
static bool iv_has_zero(struct interval a) { return a.lo <= 0.0 && a.hi >= 0.0; }
static double iv_mid(struct interval a) { return 0.5 * (a.lo + a.hi); }
static struct interval iv_dot(const struct interval a[3], const struct interval b[3])
{
    return iv_add(iv_add(iv_mul(a[0], b[0]), iv_mul(a[1], b[1])), iv_mul(a[2], b[2]));
}

/* |o + t d - c|^2 = r^2:  a t^2 + 2 b' t + c' = 0 with f = o - c, a = d.d, b' = f.d,
 * c' = f.f - r^2.  Discriminant / 4 = a (r^2 - |f - (b'/a) d|^2)  (RTG ch. 7, eq. 10), which
 * keeps its precision for rays far from the sphere; q = -(b' + sign(b') sqrt(disc)), roots
 * q / a and c' / q (Numerical Recipes form).  Here every value is an interval in double, so
 * each root is known with its error (PBRT 4e, ch. 6, "Bounding Intersection Point Error"): a
 * root is taken only when its whole interval lies inside (t_min, t_max), and one whose interval
 * reaches t_min is not taken (the origin may lie on the surface: a spawned ray, offset by its
 * own error bound, never has such a root). */
static bool sphere_hit_interval(const struct sphere *s, const struct ray *ray, float *t_hit)
{
    const float o[3] = {ray->o.x, ray->o.y, ray->o.z};
    const float d_f[3] = {ray->d.x, ray->d.y, ray->d.z};
    const float c_f[3] = {s->center.x, s->center.y, s->center.z};
    struct interval f[3];
    struct interval d[3];
    for (int k = 0; k < 3; k++) {
        f[k] = iv_sub(iv_exact(o[k]), iv_exact(c_f[k]));
        d[k] = iv_exact(d_f[k]);
    }
    struct interval r = iv_exact(s->radius);
    struct interval a = iv_dot(d, d);
    if (iv_has_zero(a))
        return false;
    struct interval b = iv_dot(f, d);
    struct interval c = iv_sub(iv_dot(f, f), iv_mul(r, r));
    struct interval b_over_a = iv_div(b, a);
    struct interval l[3];
    for (int k = 0; k < 3; k++)
        l[k] = iv_sub(f[k], iv_mul(b_over_a, d[k]));
    struct interval len_l = iv_sqrt(iv_dot(l, l));
    struct interval disc = iv_mul(a, iv_mul(iv_sub(r, len_l), iv_add(r, len_l)));
    if (disc.hi < 0.0)
        return false;
    struct interval root = iv_sqrt(disc);
    struct interval q = iv_mid(b) < 0.0 ? iv_sub(root, b) : iv_neg(iv_add(b, root));
    struct interval t0 = iv_div(q, a);
    if (iv_has_zero(q))
        return false; /* a grazing ray through the origin's own point: nothing certain */
    struct interval t1 = iv_div(c, q);
    if (t0.lo > t1.lo) {
        struct interval tmp = t0;
        t0 = t1;
        t1 = tmp;
    }
    double t_lo = ray->t_min > 0.0f ? ray->t_min : 0.0;
    struct interval t = t0;
    if (!(t.lo > t_lo))
        t = t1;
    if (!(t.lo > t_lo && t.hi < (double)ray->t_max))
        return false;
    return t_to_float(iv_mid(t), ray, t_hit);
}

/* The same quadratic in plain double first (intervals cost several times as much, and scenes
 * with spheres test every sphere on every ray), with running error bounds: with u = 2^-53 and
 * S2 = 2 (f.f + r^2) >= (|f| + r)^2, the errors of b', c' and disc are at most 4 u sum |f_i d_i|,
 * 8 u S2 and 128 u a S2 (docs/theory.md, "Self-intersection"), so
 *   dq = db + ddisc / sqrt(disc) + 2 u |q|,  dt0 = dq / a + 4 u |t0|,
 *   dt1 = (dc + |t1| dq) / |q| + 4 u |t1|
 * (the square root's error bound needs disc well above ddisc).  A root farther than twice its
 * bound from t_min is on its side of it; a near-tangent ray, disc <= 2^-40 a S2, or a root
 * closer to t_min is decided by the intervals. */
bool shape_sphere_intersect(const struct sphere *s, const struct ray *ray, float *t_hit)
{
    const double u = 0x1p-53;
    struct dvec3 f = d3_sub(d3(ray->o), d3(s->center));
    struct dvec3 d = d3(ray->d);
    double r = s->radius;
    double a = d3_dot(d, d);
    if (!(a > 0.0))
        return false;
    double b = d3_dot(f, d);
    double ff = d3_dot(f, f);
    double scale2 = 2.0 * (ff + r * r);
    /* most rays pass most spheres: a ray whose closest approach to the centre is certainly
     * outside, -disc = a (f.f - r^2) - b^2 > 2^-40 a S2 (its rounding here is below 10 u a S2),
     * is one the test below rejects too (disc < -disc_err), found without its division and
     * square root */
    if (a * ff - b * b - a * (r * r) > 0x1p-40 * a * scale2)
        return false;
    double inv_a = 1.0 / a;
    double c = ff - r * r;
    struct dvec3 l = d3_sub(f, d3_scale(d, b * inv_a));
    double len_l = d3_length(l);
    double disc = a * (r - len_l) * (r + len_l);
    double disc_err = 128.0 * u * a * scale2;
    if (disc < -disc_err)
        return false; /* certainly past the sphere */
    if (!(disc > 0x1p-40 * a * scale2))
        return sphere_hit_interval(s, ray, t_hit); /* near tangent */
    double root = sqrt(disc);
    double q = -(b + copysign(root, b));
    double inv_q = 1.0 / q;
    double q_err = 4.0 * u * d3_dot(d3_abs(f), d3_abs(d)) + disc_err / root + 2.0 * u * fabs(q);
    double t0 = q * inv_a;
    double t1 = c * inv_q;
    double t0_err = q_err * inv_a + 4.0 * u * fabs(t0);
    double t1_err = (8.0 * u * scale2 + fabs(t1) * q_err) * fabs(inv_q) + 4.0 * u * fabs(t1);
    if (t0 > t1) {
        double tmp = t0;
        t0 = t1;
        t1 = tmp;
        tmp = t0_err;
        t0_err = t1_err;
        t1_err = tmp;
    }
    double t_lo = ray->t_min > 0.0f ? ray->t_min : 0.0;
    if (fabs(t0 - t_lo) <= 2.0 * t0_err || fabs(t1 - t_lo) <= 2.0 * t1_err)
        return sphere_hit_interval(s, ray, t_hit);
    double t = t0 > t_lo ? t0 : t1;
    if (!(t > t_lo && t < (double)ray->t_max))
        return false;
    return t_to_float(t, ray, t_hit);
}

/* The point at direction n (not exactly unit) from the centre, on the sphere: c + r n / |n| in
 * double, within gamma_d(8) (|c|_1 + r) of the exact point; the unit normal n / |n| rounded to
 * float, each component within 2^-23 of it. */
static vec3 sphere_point(const struct sphere *s, struct dvec3 n, vec3 *ng, vec3 *p_error)
{
    double len = d3_length(n);
    struct dvec3 u = len > 0.0 ? d3_scale(n, 1.0 / len) : (struct dvec3){0.0, 1.0, 0.0};
    struct dvec3 c = d3(s->center);
    struct dvec3 p = d3_add(c, d3_scale(u, s->radius));
    double e = gamma_d(8) * (d3_sum(d3_abs(c)) + s->radius);
    *ng = d3_to_float(u);
    /* the sagitta: the offset origin (offset_ray_origin) is off the exact point by the point's
     * error and by the rounding of its push, at most 1.5 ulps = 3 of each component's half-ulp
     * share of ep, so up to |f| <= 4 |ep| sideways; there it lies outside the curved surface by
     * up to |f|^2 / (2 r) beyond the push along the normal, and a ray spawned into the sphere
     * could leave between the tangent plane and the surface (a sphere of radius 1e5 at 1e10).
     * 8 |ep|^2 / r added to every component raises the push n . p_error by at least that.
     * It is below r / 10 for a sphere at least 2^-20 of its centre's coordinates in radius
     * (16 float steps across); a smaller one (scene.c warns) is capped at r, so that a tiny
     * lamp's sampled points are not pushed away by more than its size. */
    struct dvec3 ep = point_error_d(p, (struct dvec3){e, e, e}, 0x1p-23);
    double sag = fmin(d3_dot(ep, ep) * (8.0 * (1.0 + 0x1p-20) / s->radius), (double)s->radius);
    *p_error = (vec3){float_up(ep.x + sag), float_up(ep.y + sag), float_up(ep.z + sag)};
    return d3_to_float(p);
}

struct surface shape_sphere_surface(const struct sphere *s, const struct ray *ray, float t_hit)
{
    struct surface sf;
    /* o + t d in double, reprojected onto the sphere (PBRT 4e, ch. 6, "Spheres") */
    struct dvec3 p = d3_add(d3(ray->o), d3_scale(d3(ray->d), t_hit));
    sf.p = sphere_point(s, d3_sub(p, d3(s->center)), &sf.ng, &sf.p_error);
    sf.ns = sf.ng;
    float phi = atan2f(sf.ng.z, sf.ng.x);
    sf.uv = (vec2){(phi < 0.0f ? phi + 2.0f * MCPT_PI : phi) * (0.5f * MCPT_INV_PI),
                   acosf(min_f(1.0f, max_f(-1.0f, sf.ng.y))) * MCPT_INV_PI};
    sf.mat_idx = s->mat_idx;
    return sf;
}

/* The cone of directions in which ref sees sphere s, from ref->p offset towards the centre, so
 * that a point on the sphere itself counts as inside (PBRT 4e, ch. 6, "Spheres"): sin^2
 * theta_max = r^2 / dist^2.  False when that point is inside; *wc = centre - the point. */
static bool sphere_cone(const struct sphere *s, const struct surface *ref, vec3 *wc,
                        struct sample_cone *cone)
{
    vec3 origin = offset_ray_origin(ref->p, ref->p_error, ref->ng, v3_sub(s->center, ref->p));
    *wc = v3_sub(s->center, origin);
    struct dvec3 w = d3(*wc);
    double dist2 = d3_dot(w, w);
    double r2 = (double)s->radius * s->radius;
    if (dist2 <= r2)
        return false;
    *cone = sample_cone_from_sin2((float)(r2 / dist2));
    return true;
}

/* From inside, every direction meets the sphere, so it is sampled as the sky is: wi
 * cosine-weighted about n_cos (the side of ref being lit), pdf_sa = cos theta / pi (PBRT 4e,
 * ch. A.5, "Cosine-Weighted Hemisphere Sampling"), its point where the ray spawned along wi
 * meets the sphere, found as a BSDF ray along wi finds it.  No distance or cosine at the
 * sampled point enters the estimate.  PBRT 4e samples by area here (ch. 6, "Spheres"), dividing
 * by the cosine at the sampled point; for a ref on the sphere, that cosine is about dist / 2r,
 * and ref's own rounding (|p_error|) moves it by |p_error| / dist, so it is noise within
 * sqrt(2 r |p_error|) of ref: a two-sided lamp of radius 1 at x = 1e5, seen from inside, gave
 * pixels of 1e3 in an image of 2. */
static bool sphere_sample_inside(const struct sphere *s, const struct surface *ref, vec3 n_cos,
                                 vec2 u, struct shape_sample *ss)
{
    vec3 t, b;
    v3_basis(n_cos, &t, &b);
    vec3 wi = v3_normalize(v3_from_local(sample_cosine_hemisphere(u), t, b, n_cos));
    struct ray ray = {.o = offset_ray_origin(ref->p, ref->p_error, ref->ng, wi),
                      .t_min = 0.0f,
                      .d = wi,
                      .t_max = INFINITY};
    float t_hit;
    if (!shape_sphere_intersect(s, &ray, &t_hit))
        return false;
    struct dvec3 p = d3_add(d3(ray.o), d3_scale(d3(wi), t_hit));
    ss->p = sphere_point(s, d3_sub(p, d3(s->center)), &ss->n, &ss->p_error);
    ss->wi = wi;
    ss->pdf_sa = max_f(0.0f, v3_dot(wi, n_cos)) * MCPT_INV_PI;
    return ss->pdf_sa > 0.0f;
}

bool shape_sphere_sample(const struct sphere *s, const struct surface *ref, vec3 n_cos, vec2 u,
                         struct shape_sample *ss)
{
    vec3 wc;
    struct sample_cone cone;
    if (!sphere_cone(s, ref, &wc, &cone))
        return sphere_sample_inside(s, ref, n_cos, u, ss);
    /* outside: a direction uniform in the cone (sample.c), pdf_sa = 1 / (2 pi (1 - cos
     * theta_max)), then the angle alpha, seen from the centre, between the reference point and
     * the point where that direction first meets the sphere (PBRT 4e, ch. 6, "Spheres") */
    float cos_theta, sin2_theta;
    sample_uniform_cone_theta(u.x, &cone, &cos_theta, &sin2_theta);
    float sin2_theta_max = cone.sin2_theta_max;
    float sin_theta_max = sqrtf(sin2_theta_max);
    float cos_alpha = sin2_theta / sin_theta_max +
                      cos_theta * sqrtf(max_f(0.0f, 1.0f - sin2_theta / sin2_theta_max));
    float sin_alpha = sqrtf(max_f(0.0f, 1.0f - cos_alpha * cos_alpha));
    float phi = 2.0f * MCPT_PI * u.y;
    struct dvec3 w = d3(wc);
    vec3 wz = d3_to_float(d3_scale(w, -1.0 / d3_length(w))); /* centre -> reference point */
    vec3 wx, wy;
    v3_basis(wz, &wx, &wy);
    vec3 dir = v3_from_local(v3(sin_alpha * cosf(phi), sin_alpha * sinf(phi), cos_alpha), wx, wy,
                             wz);
    ss->p = sphere_point(s, d3(dir), &ss->n, &ss->p_error);
    /* wi from the cone's apex to the point before rounding (far from the origin the rounded
     * point, and ref->p, can be a few percent of the distance off) */
    struct dvec3 apex = d3_sub(d3(s->center), w);
    struct dvec3 x = d3_add(d3(s->center), d3_scale(d3(dir), (double)s->radius));
    struct dvec3 d = d3_sub(x, apex);
    double dist = d3_length(d);
    if (!(dist > 0.0))
        return false;
    ss->wi = d3_to_float(d3_scale(d, 1.0 / dist));
    ss->pdf_sa = pdf_uniform_cone(&cone);
    return ss->pdf_sa > 0.0f;
}

float shape_sphere_pdf(const struct sphere *s, const struct surface *ref, vec3 n_cos, vec3 wi)
{
    vec3 wc;
    struct sample_cone cone;
    if (sphere_cone(s, ref, &wc, &cone))
        return pdf_uniform_cone(&cone);
    return max_f(0.0f, v3_dot(wi, n_cos)) * MCPT_INV_PI; /* inside: sphere_sample_inside */
}

/* ---- planes: a quad's and an infinite plane's intersection ---- */

/* The ray's intersection with the plane through point q with normal n (both exact in double:
 * n_abs bounds the terms each component of n was formed from, and n carries at most gamma_d(2)
 * of it), in double: t = n . (q - o) / n . d.  The numerator is n times the distance of the
 * origin from the plane; when its error bound covers it (the origin on the plane to double
 * precision) or the denominator's covers it (the ray in the plane), there is no hit: a spawned
 * origin lies 2^-24 |p| off its plane, 2^29 times farther. */
static bool plane_t(struct dvec3 q, struct dvec3 n, struct dvec3 n_abs, const struct ray *ray,
                    double *t)
{
    struct dvec3 qo = d3_sub(q, d3(ray->o));
    struct dvec3 d = d3(ray->d);
    double num = d3_dot(n, qo);
    double den = d3_dot(n, d);
    /* n_i: gamma_d(2) n_abs_i; q - o: gamma_d(1); each product and the sum: gamma_d(3) more */
    double num_err = gamma_d(6) * d3_dot(n_abs, d3_abs(qo));
    double den_err = gamma_d(6) * d3_dot(n_abs, d3_abs(d));
    if (!(fabs(num) > num_err && fabs(den) > den_err))
        return false;
    *t = num / den;
    return true;
}

/* How far inside its edges triangle_point and quad_point place a point, per edge: a distance
 *   M = EDGE_MARGIN_E (m . e) + EDGE_MARGIN_N (n . e),
 * with e the point's per-component error bounds (rounded_error_vec), m the unit normal of the
 * edge within the plane, n the plane's unit normal, and a . e meaning sum |a_k| e_k.  The
 * spawned origin moves from the exact point by, per component: the rounding to float (e_k), the
 * step of offset_ray_origin's addition to the next float (1.5 ulp <= 3 e_k), and along n the
 * push n . p_error (about n . e).  At a right-angled concave edge (a box's) the neighbouring
 * face's normal is m, so the origin moves towards it by at most 4 (m . e): the first term,
 * 6 (m . e), keeps it in front of that face, never on its plane or past it.  A face at angle
 * theta has normal m sin(theta) - n cos(theta), towards which the origin moves by at most
 * 4 (m . e) sin + (4 (n . e) + push) |cos|; the margin covers that while
 * (2 (m . e) + (n . e)) sin > 5 (n . e) |cos|: from 59 to 121 degrees where m . e ~ n . e, from
 * 79 to 101 where the error lies along n.  Projecting on m, not summing every component's
 * error, leaves out what cannot cross a right-angled neighbour: a wall at x = 10^6 has an error
 * of 0.06 in x (its coordinate) but ~10^-7 in y and z, so its points are pulled 0.06 from its
 * edges (the second term), where 6 E pulled them 0.36 and, shrunk towards the centre, a wall of
 * size 2 rendered nearly as its triangles' centres (tests/extremes, the Cornell box moved). */
#define EDGE_MARGIN_E 6.0
#define EDGE_MARGIN_N 1.0

/* The margin M / h of the edge of direction v of a plane with normal c = e1 x e2 (cc = c . c),
 * h = |c| / |v| the height over that edge: the distance M in units of the coordinate that is 0
 * on the edge and 1 at the height h, (M |v| / |c|).  |c x v| = |c| |v| since v lies in the
 * plane, so m = (c x v) / (|c| |v|).  g >= EDGE_MARGIN_N is the normal term's factor: an edge
 * where the shape meets another at a groove of angle phi < 90 degrees (scene.c, grooves) needs
 * M sin(phi) to exceed the origin's move towards the neighbour, 4 (m . e) sin(phi) +
 * 5 (n . e) cos(phi), since the push along n, parallel to a right-angled neighbour, heads into
 * this one: g = 6 cot(phi) (5 cot(phi) and a fifth more) keeps the origin in front of it. */
static double edge_margin_groove(struct dvec3 c, double cc, struct dvec3 v, struct dvec3 e,
                                 double g)
{
    double in_plane = d3_dot(d3_abs(d3_cross(c, v)), e) / cc;
    double normal = d3_dot(d3_abs(c), e) * sqrt(d3_dot(v, v)) / cc;
    return (EDGE_MARGIN_E * in_plane + g * normal) * (1.0 + 0x1p-20);
}

/* ---- quad ---- */

/* The quad's planar coordinates of the point o + t d on its plane, in double: pd = o + t d -
 * corner = alpha e1 + beta e2, alpha = (pd x e2) . n / n . n, beta = (e1 x pd) . n / n . n,
 * with n = e1 x e2 in double (d3_cross). */
static void quad_coords(const struct quad *q, struct dvec3 n, const struct ray *ray, double t,
                        double *alpha, double *beta)
{
    struct dvec3 e1 = q->e1;
    struct dvec3 e2 = q->e2;
    struct dvec3 pd = d3_sub(d3_add(d3(ray->o), d3_scale(d3(ray->d), t)), q->corner);
    double inv_nn = 1.0 / d3_dot(n, n);
    *alpha = d3_dot(d3_cross(pd, e2), n) * inv_nn;
    *beta = d3_dot(d3_cross(e1, pd), n) * inv_nn;
}

bool shape_quad_intersect(const struct quad *q, const struct ray *ray, float *t_hit)
{
    /* the plane first, then the interval, then the edges: most rays that meet the plane meet
     * it behind the origin or beyond t_max, and need no planar coordinates */
    struct dvec3 e1 = q->e1;
    struct dvec3 e2 = q->e2;
    struct dvec3 n = d3_cross(e1, e2);
    double t, alpha, beta;
    if (!plane_t(q->corner, n, d3_cross_abs(e1, e2), ray, &t) || !t_to_float(t, ray, t_hit))
        return false;
    quad_coords(q, n, ray, t, &alpha, &beta);
    return alpha >= 0.0 && alpha <= 1.0 && beta >= 0.0 && beta <= 1.0;
}

/* quad_point's margins for a point with per-component error bounds e (edge_margin_groove): in
 * alpha, across the edges alpha = 0, 1 (direction e2), and in beta (direction e1), with the
 * quad's groove factor on every edge. */
static double quad_groove(const struct quad *q)
{
    return q->groove > EDGE_MARGIN_N ? q->groove : EDGE_MARGIN_N;
}

static void quad_margins(const struct quad *q, struct dvec3 e, double *eps_alpha, double *eps_beta)
{
    struct dvec3 c = d3_cross(q->e1, q->e2);
    double cc = d3_dot(c, c);
    *eps_alpha = edge_margin_groove(c, cc, q->e2, e, quad_groove(q));
    *eps_beta = edge_margin_groove(c, cc, q->e1, e, quad_groove(q));
}

/* The quad's point corner + alpha e1 + beta e2 with its error bound and unit normal, pulled
 * inside the quad as triangle_point pulls a triangle's: alpha, beta clamped to
 * [eps, 1 - eps] with the margins of quad_margins (EDGE_MARGIN_E), so quads that close a box
 * keep spawned origins off each other's planes. */
static vec3 quad_point(const struct quad *q, double alpha, double beta, vec3 *ng, vec3 *p_error)
{
    struct dvec3 e1 = q->e1;
    struct dvec3 e2 = q->e2;
    double area, eta;
    *ng = plane_normal(e1, e2, &area, &eta);
    struct dvec3 err;
    struct dvec3 p = plane_point_d(q->corner, e1, e2, alpha, beta, &err);
    double eps_alpha = 0.5, eps_beta = 0.5;
    if (area > 0.0) {
        /* bounds first (edge_margin_groove's terms are at most E = sum e_k each): most points
         * are far from every edge */
        double k = (EDGE_MARGIN_E + quad_groove(q)) * rounded_error_sum(p, err, eta) / area *
                   (1.0 + 0x1p-18);
        eps_alpha = k * d3_length(e2);
        eps_beta = k * d3_length(e1);
        if (!(alpha >= eps_alpha && alpha <= 1.0 - eps_alpha && beta >= eps_beta &&
              beta <= 1.0 - eps_beta))
            quad_margins(q, rounded_error_vec(p, err, eta), &eps_alpha, &eps_beta);
    }
    if (!(alpha >= eps_alpha && alpha <= 1.0 - eps_alpha && beta >= eps_beta &&
          beta <= 1.0 - eps_beta)) {
        alpha = eps_alpha < 0.5 ? fmin(1.0 - eps_alpha, fmax(eps_alpha, alpha)) : 0.5;
        beta = eps_beta < 0.5 ? fmin(1.0 - eps_beta, fmax(eps_beta, beta)) : 0.5;
        p = plane_point_d(q->corner, e1, e2, alpha, beta, &err);
    }
    return round_point(p, err, eta, p_error);
}

struct surface shape_quad_surface(const struct quad *q, const struct ray *ray, float t_hit)
{
    struct surface sf;
    /* the planar coordinates of o + t_hit d; the point is rebuilt on the plane from them, or,
     * for a quad 2^8 times larger than t |d| + |o| (a huge floor seen from nearby), taken from
     * the ray where that is the more precise, as shape_triangle_surface does */
    struct dvec3 c = d3_cross(q->e1, q->e2);
    double alpha, beta;
    quad_coords(q, c, ray, t_hit, &alpha, &beta);
    alpha = fmin(1.0, fmax(0.0, alpha));
    beta = fmin(1.0, fmax(0.0, beta));
    struct dvec3 d = d3(ray->d);
    double near = 0x1p8 * ((double)t_hit * sqrt(d3_dot(d, d)) + d3_max(d3_abs(d3(ray->o))));
    double l1 = d3_dot(q->e1, q->e1), l2 = d3_dot(q->e2, q->e2);
    if (max_d(l1, l2) > near * near) {
        double area, eta;
        vec3 ng = plane_normal(q->e1, q->e2, &area, &eta);
        struct dvec3 err_r, err_b;
        struct dvec3 pr = ray_point_on_plane(ray, t_hit, q->corner, c, d3_cross_abs(q->e1, q->e2),
                                             &err_r);
        struct dvec3 pb = plane_point_d(q->corner, q->e1, q->e2, alpha, beta, &err_b);
        double E = rounded_error_sum(pr, err_r, eta);
        double eps_a, eps_b;
        quad_margins(q, rounded_error_vec(pr, err_r, eta), &eps_a, &eps_b);
        bool inside = alpha >= eps_a && alpha <= 1.0 - eps_a && beta >= eps_b &&
                      beta <= 1.0 - eps_b;
        double db = gamma_d(8) * d3_length(d3_sub(pr, q->corner)) * sqrt(max_d(l1, l2)) / area;
        bool resolved = db <= fmin(eps_a, eps_b);
        if (area > 0.0 && E < rounded_error_sum(pb, err_b, eta) && (inside || !resolved)) {
            sf.p = round_point(pr, err_r, eta, &sf.p_error);
            sf.ng = ng;
        } else {
            sf.p = quad_point(q, alpha, beta, &sf.ng, &sf.p_error);
        }
    } else {
        sf.p = quad_point(q, alpha, beta, &sf.ng, &sf.p_error);
    }
    sf.ns = sf.ng;
    sf.uv = (vec2){(float)alpha, (float)beta};
    sf.mat_idx = q->mat_idx;
    return sf;
}

float shape_quad_area(const struct quad *q) { return (float)d3_length(d3_cross(q->e1, q->e2)); }

bool shape_quad_sample(const struct quad *q, const struct surface *ref, vec2 u,
                       struct shape_sample *ss)
{
    /* uniform by area: p = corner + u0 e1 + u1 e2, pdf_area = 1 / |e1 x e2| */
    vec3 n, p_error;
    vec3 p = quad_point(q, u.x, u.y, &n, &p_error);
    struct dvec3 x_err; /* the point as quad_point forms it, before its margins */
    struct dvec3 x = plane_point_d(q->corner, q->e1, q->e2, u.x, u.y, &x_err);
    return sample_by_area(p, p_error, n, x, 1.0 / d3_length(d3_cross(q->e1, q->e2)), ref, ss);
}

float shape_quad_pdf(const struct quad *q, const struct surface *ref, const struct surface *on,
                     vec3 wi)
{
    (void)on; /* the plane's own point along wi (pdf_by_area) */
    struct dvec3 c = d3_cross(q->e1, q->e2);
    double c_len = d3_length(c);
    return pdf_by_area(1.0 / c_len, q->corner, c, c_len, ref, wi);
}

/* Whether the quad q is sampled by solid angle from ref: a rectangle whose solid angle is at
 * least SPHERICAL_MIN_SR (PBRT 4e's BilinearPatch::Sample has no upper bound).  Fills *sr, and
 * w[4] with the cosine weights at ref's shading normal of the corners corner, + e1, + e2,
 * + e1 + e2, where u = (0,0), (1,0), (0,1), (1,1) map. */
static bool quad_by_solid_angle(const struct quad *q, const struct surface *ref,
                                struct sample_sph_rect *sr, float w[4], vec3 *apex)
{
    vec3 corner = d3_to_float(q->corner), e1 = d3_to_float(q->e1), e2 = d3_to_float(q->e2);
    *apex = solid_angle_apex(ref);
    if (!sample_sph_rect_init(*apex, corner, e1, e2, sr) || !(sr->area >= SPHERICAL_MIN_SR))
        return false;
    vec3 c[4] = {corner, v3_add(corner, e1), v3_add(corner, e2), v3_add(v3_add(corner, e1), e2)};
    for (int k = 0; k < 4; k++)
        c[k] = v3_normalize(v3_sub(c[k], *apex));
    receiver_weights(ref, c[0], c[1], c[2], c[3], w);
    return true;
}

bool shape_quad_sample_solid_angle(const struct quad *q, const struct surface *ref, vec2 u,
                                   struct shape_sample *ss)
{
    struct sample_sph_rect sr;
    float w[4];
    vec3 apex;
    if (!quad_by_solid_angle(q, ref, &sr, w, &apex))
        return shape_quad_sample(q, ref, u, ss);
    /* Urena et al. 2013, u first warped by the cosine at the receiver:
     * pdf_sa = pdf_bilinear(u) / S */
    float pdf_u = warp_by_cosine(&u, w);
    vec3 x = sample_spherical_rectangle(&sr, u);
    struct dvec3 pr = d3_sub(d3(x), q->corner);
    double alpha = fmin(1.0, fmax(0.0, d3_dot(pr, q->e1) / d3_dot(q->e1, q->e1)));
    double beta = fmin(1.0, fmax(0.0, d3_dot(pr, q->e2) / d3_dot(q->e2, q->e2)));
    ss->p = quad_point(q, alpha, beta, &ss->n, &ss->p_error);
    /* wi to the sampled point, not to its rounded copy: the density is that direction's */
    return direction_to(ss, x, ss->n, apex, pdf_u * pdf_spherical_rectangle(&sr));
}

float shape_quad_pdf_solid_angle(const struct quad *q, const struct surface *ref,
                                 const struct surface *on, vec3 wi)
{
    struct sample_sph_rect sr;
    float w[4];
    vec3 apex;
    if (!quad_by_solid_angle(q, ref, &sr, w, &apex))
        return shape_quad_pdf(q, ref, on, wi);
    /* pdf_sa = pdf_bilinear(u) / S at the u that maps to the point where apex + t wi meets the
     * quad's plane (in double: on->p, rounded, can be a few percent of the distance off) */
    struct dvec3 c = d3_cross(q->e1, q->e2), o = d3(apex), w_d = d3(wi);
    double t = d3_dot(c, d3_sub(q->corner, o)) / d3_dot(c, w_d);
    vec3 x = t > 0.0 && isfinite(t) ? d3_to_float(d3_add(o, d3_scale(w_d, t))) : on->p;
    return pdf_bilinear(sample_invert_spherical_rectangle(&sr, x), w) *
           pdf_spherical_rectangle(&sr);
}

/* ---- infinite plane ---- */

bool shape_plane_intersect(const struct plane *pl, const struct ray *ray, float *t_hit)
{
    /* the plane is {x : n . (x - point) = 0} with the float n and point exactly */
    struct dvec3 n = d3(pl->n);
    double t;
    if (!plane_t(d3(pl->point), n, d3_abs(n), ray, &t))
        return false;
    return t_to_float(t, ray, t_hit);
}

struct surface shape_plane_surface(const struct plane *pl, const struct ray *ray, float t_hit)
{
    struct surface sf;
    /* o + t d in double, projected back onto the plane: p -= (n . (p - point) / n . n) n; the
     * projection leaves it within gamma_d(8) (|p| + |point|) of the plane, and the plane's
     * normal is the float n itself (no normal error) */
    struct dvec3 n = d3(pl->n);
    struct dvec3 q = d3(pl->point);
    struct dvec3 p = d3_add(d3(ray->o), d3_scale(d3(ray->d), t_hit));
    struct dvec3 pp = d3_sub(p, q);
    p = d3_sub(p, d3_scale(n, d3_dot(pp, n) / d3_dot(n, n)));
    double e = gamma_d(8) * (d3_length(p) + d3_length(q));
    sf.p = round_point(p, (struct dvec3){e, e, e}, 0.0, &sf.p_error);
    sf.ng = pl->n;
    sf.ns = pl->n;
    vec3 t, b;
    v3_basis(pl->n, &t, &b);
    vec3 ppf = d3_to_float(pp);
    sf.uv = (vec2){v3_dot(ppf, t), v3_dot(ppf, b)};
    sf.mat_idx = pl->mat_idx;
    return sf;
}

void shape_pull_from_contacts(struct surface *sf, const struct contact *cs, uint32_t n, vec3 from)
{
    for (uint32_t i = 0; i < n; i++) {
        const struct contact *c = &cs[i];
        struct dvec3 p = d3(sf->p), e = d3(sf->p_error);
        /* the margin of triangle_margins: M = 6 (m . e) + g (n . e) */
        double M = 6.0 * d3_dot(d3_abs(c->m), e) + c->g * d3_dot(d3_abs(d3(sf->ng)), e);
        struct dvec3 ab = d3_sub(c->b, c->a), ap = d3_sub(p, c->a);
        double len2 = d3_dot(ab, ab), along = d3_dot(ap, ab), s = d3_dot(ap, c->m);
        double reach = M * sqrt(len2);
        if (!(fabs(s) < M && along >= -reach && along <= len2 + reach))
            continue;
        double side = d3_dot(d3_sub(d3(from), c->a), c->m);
        double sgn = side > 0.0 || (side == 0.0 && s >= 0.0) ? 1.0 : -1.0;
        struct dvec3 q = d3_add(p, d3_scale(c->m, sgn * M - s));
        sf->p = d3_to_float(q);
        sf->p_error = (vec3){float_up(e.x + fabs(q.x) * 0x1p-24),
                             float_up(e.y + fabs(q.y) * 0x1p-24),
                             float_up(e.z + fabs(q.z) * 0x1p-24)};
    }
}

/* ---- triangle (the BVH finds the hit) ---- */

/* What every point of triangle p[3] shares (shape.h): a hit computes it for its triangle, the
 * light table once per emitting triangle, by these same operations, so a light's sampled points
 * are the bits a fresh computation would give. */
static ALWAYS_INLINE void triangle_plane(const vec3 p[3], const float *groove,
                                         struct triangle_plane *tp)
{
    tp->p0 = p[0];
    tp->e1 = d3_sub(d3(p[1]), d3(p[0]));
    tp->e2 = d3_sub(d3(p[2]), d3(p[0]));
    tp->c = d3_cross(tp->e1, tp->e2);
    tp->ng = plane_normal_c(tp->e1, tp->e2, tp->c, &tp->area2, &tp->eta);
    for (int i = 0; i < 3; i++)
        tp->groove[i] = groove && groove[i] > EDGE_MARGIN_N ? groove[i] : (float)EDGE_MARGIN_N;
    /* surely_inside's bound per unit of E: (6 + g_i) sqrt(3) max |v_i,k| / |c|, raised by 2^-18
     * past its own roundings and the product with E (a few units of 2^-53) */
    double k = 1.7320508075688774 * (1.0 + 0x1p-18) / tp->area2;
    tp->inside_k[0] = (EDGE_MARGIN_E + tp->groove[0]) * k * d3_max(d3_abs(d3_sub(tp->e2, tp->e1)));
    tp->inside_k[1] = (EDGE_MARGIN_E + tp->groove[1]) * k * d3_max(d3_abs(tp->e2));
    tp->inside_k[2] = (EDGE_MARGIN_E + tp->groove[2]) * k * d3_max(d3_abs(tp->e1));
}

void shape_triangle_plane(const vec3 p[3], const float *groove, struct triangle_plane *tp)
{
    triangle_plane(p, groove, tp);
}

/* triangle_point's margins for a point with per-component error bounds e (edge_margin_groove):
 * eps_i for barycentric b_i (b0 = 1 - b1 - b2), 0 on the edge opposite corner i: p2 - p1, e2,
 * e1, each with its groove factor. */
static void triangle_margins(const struct triangle_plane *tp, struct dvec3 e, double eps[3])
{
    double cc = d3_dot(tp->c, tp->c);
    eps[0] = edge_margin_groove(tp->c, cc, d3_sub(tp->e2, tp->e1), e, tp->groove[0]);
    eps[1] = edge_margin_groove(tp->c, cc, tp->e2, e, tp->groove[1]);
    eps[2] = edge_margin_groove(tp->c, cc, tp->e1, e, tp->groove[2]);
}

/* b_i >= eps_i for every i, decided from bounds alone (most points are far from every edge):
 * m . e and n . e are at most E = sum e_k (rounded_error_sum), and |v| <= sqrt(3) max |v_i,k|,
 * so eps_i <= (6 + g_i) sqrt(3) E max |v_i,k| / |c| = E inside_k[i] (g_i the edge's groove
 * factor; triangle_plane keeps the factors, so that no division waits here).  False says only
 * that triangle_margins must decide. */
static bool surely_inside(const struct triangle_plane *tp, double E, const double b[3])
{
    return b[0] >= E * tp->inside_k[0] && b[1] >= E * tp->inside_k[1] &&
           b[2] >= E * tp->inside_k[2];
}

/* Barycentrics b moved the least way into b_i >= eps_i (sum eps < 1): each b_i below its margin
 * raised to it, the others lowered in proportion to what they hold above theirs, which keeps
 * them above it (what they give, sum of the shortfalls, is less than what they hold, since the
 * two differ by 1 - sum eps). */
static void pull_inside(double b[3], const double eps[3])
{
    double shortfall = 0.0, slack = 0.0;
    for (int i = 0; i < 3; i++) {
        if (b[i] < eps[i])
            shortfall += eps[i] - b[i];
        else
            slack += b[i] - eps[i];
    }
    for (int i = 0; i < 3; i++)
        b[i] = b[i] < eps[i] ? eps[i] : b[i] - (b[i] - eps[i]) * (shortfall / slack);
}

/* The point p0 + b1 e1 + b2 e2 of triangle tp (triangle_plane) with its error bound
 * (plane_point_d, round_point), pulled inside the triangle: where some b_i is below its margin
 * eps_i (triangle_margins, EDGE_MARGIN_E), the barycentrics move the least way into the inset
 * triangle b_i >= eps_i (pull_inside).  So the rounded point lies inside every edge by more than
 * the spawned origin can move: at a concave edge a spawned ray then meets the neighbour in front
 * of its origin, not at t = 0.  Only points within the margin move, by at most the margin (an
 * affine shrink towards the centre, before, moved every point near an edge by up to sum eps of
 * the triangle).  A triangle narrower than its margins (sum eps >= 1) has no inset: its point
 * is the centre.  A point more than eps outside (only from the ray's point of a huge triangle,
 * whose float inside test is off by u times its size) is left where it is. */
static ALWAYS_INLINE vec3 triangle_point(const struct triangle_plane *tp, double b1, double b2,
                                         vec3 *p_error)
{
    struct dvec3 e1 = tp->e1, e2 = tp->e2;
    double area2 = tp->area2, eta = tp->eta;
    struct dvec3 err;
    struct dvec3 pd = plane_point_d(d3(tp->p0), e1, e2, b1, b2, &err);
    double b[3] = {1.0 - b1 - b2, b1, b2};
    if (area2 > 0.0 && !surely_inside(tp, rounded_error_sum(pd, err, eta), b)) {
        double eps[3];
        triangle_margins(tp, rounded_error_vec(pd, err, eta), eps);
        bool inside = b[0] >= eps[0] && b[1] >= eps[1] && b[2] >= eps[2];
        bool near = b[0] >= -eps[0] && b[1] >= -eps[1] && b[2] >= -eps[2];
        if (!inside && near) {
            double eps_sum = eps[0] + eps[1] + eps[2];
            if (!(eps_sum < 1.0)) {
                b1 = b2 = 1.0 / 3.0; /* smaller than its error: the centre */
            } else {
                pull_inside(b, eps);
                b1 = b[1];
                b2 = b[2];
            }
            pd = plane_point_d(d3(tp->p0), e1, e2, b1, b2, &err);
        }
    }
    return round_point(pd, err, eta, p_error);
}

/* shape_triangle_surface's body, inlined into both entry points (a call and a copy of the plane
 * cost a mesh's renders 8%). */
static ALWAYS_INLINE struct surface triangle_surface(const struct triangle_plane *tpp,
                                                     const vec3 *ns, const vec2 *uv,
                                                     const struct ray *ray, float t_hit, float b1,
                                                     float b2, uint32_t mat_idx)
{
    const struct triangle_plane tp = *tpp;
    struct dvec3 e1 = tp.e1, e2 = tp.e2;
    double b1_d = b1;
    double b2_d = b2;
    /* float barycentrics place the point to about 2^-24 of the triangle's size, the ray's t to
     * 2^-24 of the hit distance when the BVH decided it in double, which it does where the
     * triangle is large beside both the distance and the point's magnitude (bvh.c, "the hit's
     * own precision"): for a triangle 2^8 times larger than t |d| + |o| (a huge floor seen from
     * nearby) the barycentrics of o + t d, in double, are the more precise */
    struct dvec3 d = ray ? d3(ray->d) : (struct dvec3){0.0, 0.0, 0.0};
    double o_max = ray ? d3_max(d3_abs(d3(ray->o))) : 0.0;
    double near = 0x1p8 * ((double)t_hit * sqrt(d3_dot(d, d)) + o_max);
    bool projected = false;
    struct surface sf;
    if (ray && max_d(d3_dot(e1, e1), d3_dot(e2, e2)) > near * near) {
        struct dvec3 q = d3_sub(d3_add(d3(ray->o), d3_scale(d, t_hit)), d3(tp.p0));
        struct dvec3 n = tp.c;
        double nn = d3_dot(n, n);
        if (nn > 0.0) {
            b1_d = d3_dot(d3_cross(q, e2), n) / nn;
            b2_d = d3_dot(d3_cross(e1, q), n) / nn;
            b1 = (float)b1_d;
            b2 = (float)b2_d;
            /* the point itself from the ray, where that is the more precise and triangle_point
             * would not move it: inside every edge by its margin, or outside one by more (the
             * float inside test of a huge triangle errs by u times its size: the hit is the
             * coplanar neighbour's point), or where the barycentrics' own error (db, from
             * |q| u) is larger than that margin, so that no computation in double can tell
             * (a floor of 1e15 seen from 1 unit: its diagonal is a band 0.1 wide, where the
             * rebuilt point would be pulled inside by 6 errors of 1.8, 10 units) */
            struct dvec3 err_r, err_b;
            struct dvec3 pr = ray_point_on_plane(ray, t_hit, d3(tp.p0), n, d3_cross_abs(e1, e2),
                                                 &err_r);
            struct dvec3 pb = plane_point_d(d3(tp.p0), e1, e2, b1_d, b2_d, &err_b);
            double E = rounded_error_sum(pr, err_r, tp.eta);
            double b[3] = {1.0 - b1_d - b2_d, b1_d, b2_d};
            double eps[3];
            triangle_margins(&tp, rounded_error_vec(pr, err_r, tp.eta), eps);
            bool inside = b[0] >= eps[0] && b[1] >= eps[1] && b[2] >= eps[2];
            bool near_edge = !inside && b[0] >= -eps[0] && b[1] >= -eps[1] && b[2] >= -eps[2];
            double db = gamma_d(8) * d3_length(q) * sqrt(max_d(d3_dot(e1, e1), d3_dot(e2, e2))) /
                        sqrt(nn);
            bool resolved = db <= fmin(eps[0], fmin(eps[1], eps[2]));
            if (E < rounded_error_sum(pb, err_b, tp.eta) && !(near_edge && resolved)) {
                sf.p = round_point(pr, err_r, tp.eta, &sf.p_error);
                projected = true;
            }
        }
    }
    float b0 = 1.0f - b1 - b2;
    if (!projected)
        sf.p = triangle_point(&tp, b1_d, b2_d, &sf.p_error);
    sf.ng = tp.ng;
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

struct surface shape_triangle_surface(const vec3 p[3], const float *groove, const vec3 *ns,
                                      const vec2 *uv, const struct ray *ray, float t_hit, float b1,
                                      float b2, uint32_t mat_idx)
{
    struct triangle_plane tp;
    triangle_plane(p, groove, &tp);
    return triangle_surface(&tp, ns, uv, ray, t_hit, b1, b2, mat_idx);
}

struct surface shape_triangle_plane_surface(const struct triangle_plane *tp, const vec3 *ns,
                                            const vec2 *uv, const struct ray *ray, float t_hit,
                                            float b1, float b2, uint32_t mat_idx)
{
    return triangle_surface(tp, ns, uv, ray, t_hit, b1, b2, mat_idx);
}

/* Twice the area, |(p1 - p0) x (p2 - p0)|, in double. */
static double triangle_area2(const vec3 p[3])
{
    return d3_length(d3_cross(d3_sub(d3(p[1]), d3(p[0])), d3_sub(d3(p[2]), d3(p[0]))));
}

float shape_triangle_area(const vec3 p[3], vec3 *ng)
{
    if (ng) {
        double len, eta;
        *ng = plane_normal(d3_sub(d3(p[1]), d3(p[0])), d3_sub(d3(p[2]), d3(p[0])), &len, &eta);
    }
    return (float)(0.5 * triangle_area2(p));
}

bool shape_triangle_plane_sample(const struct triangle_plane *tp, const struct surface *ref, vec2 u,
                                 struct shape_sample *ss)
{
    /* uniform by area: barycentrics (b0, b1, b2) = (b.x, b.y, 1 - b.x - b.y) by the square-root
     * warp (sample.c), pdf_area = 1 / A */
    double area = 0.5 * tp->area2; /* area2 = |e1 x e2|, as triangle_area2 computes it */
    if (!(area > 0.0))
        return false;
    vec2 b = sample_uniform_triangle(u);
    double b1 = b.y, b2 = 1.0 - (double)b.x - (double)b.y;
    vec3 p_error;
    vec3 pt = triangle_point(tp, b1, b2, &p_error);
    struct dvec3 x_err; /* the point as triangle_point forms it, before its margins */
    struct dvec3 x = plane_point_d(d3(tp->p0), tp->e1, tp->e2, b1, b2, &x_err);
    return sample_by_area(pt, p_error, tp->ng, x, 1.0 / area, ref, ss);
}

float shape_triangle_plane_pdf(const struct triangle_plane *tp, const struct surface *ref,
                               const struct surface *on, vec3 wi)
{
    (void)on; /* the plane's own point along wi (pdf_by_area) */
    double area = 0.5 * tp->area2;
    return area > 0.0 ? pdf_by_area(1.0 / area, d3(tp->p0), tp->c, tp->area2, ref, wi) : 0.0f;
}

bool shape_triangle_sample(const vec3 p[3], const struct surface *ref, vec2 u,
                           struct shape_sample *ss)
{
    struct triangle_plane tp;
    triangle_plane(p, NULL, &tp);
    return shape_triangle_plane_sample(&tp, ref, u, ss);
}

float shape_triangle_pdf(const vec3 p[3], const struct surface *ref, const struct surface *on,
                         vec3 wi)
{
    struct triangle_plane tp;
    triangle_plane(p, NULL, &tp);
    return shape_triangle_plane_pdf(&tp, ref, on, wi);
}

/* Whether the triangle p[3] is sampled by solid angle from ref: its solid angle lies between
 * the bounds (PBRT 4e's Triangle::Sample).  Fills *st, and w[4] with the cosine weights of the
 * corners of Arvo's u square at ref's shading normal (u = (0,0) and (1,0) map to p[1], (0,1) to
 * p[0], (1,1) to p[2]). */
static bool triangle_by_solid_angle(const vec3 p[3], const struct surface *ref,
                                    struct sample_sph_triangle *st, float w[4], vec3 *apex)
{
    *apex = solid_angle_apex(ref);
    vec3 d[3];
    for (int k = 0; k < 3; k++) {
        d[k] = v3_sub(p[k], *apex);
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
    vec3 apex;
    if (!triangle_by_solid_angle(p, ref, &st, w, &apex))
        return shape_triangle_sample(p, ref, u, ss);
    /* Arvo 1995, u first warped by the cosine at the receiver: pdf_sa = pdf_bilinear(u) / Omega */
    float pdf_u = warp_by_cosine(&u, w);
    vec3 wi = sample_spherical_triangle(&st, u);
    /* the barycentrics where the ray apex + t wi meets the triangle's plane (Moller & Trumbore
     * 1997), clamped onto the triangle against rounding */
    vec3 e1 = v3_sub(p[1], p[0]), e2 = v3_sub(p[2], p[0]), s = v3_sub(apex, p[0]);
    vec3 s1 = v3_cross(wi, e2);
    float divisor = v3_dot(s1, e1);
    if (divisor == 0.0f)
        return false;
    float b1 = min_f(1.0f, max_f(0.0f, v3_dot(s, s1) / divisor));
    float b2 = min_f(1.0f, max_f(0.0f, v3_dot(wi, v3_cross(s, e1)) / divisor));
    if (b1 + b2 > 1.0f) {
        float sum = b1 + b2;
        b1 /= sum;
        b2 /= sum;
    }
    struct triangle_plane tp;
    triangle_plane(p, NULL, &tp);
    ss->p = triangle_point(&tp, b1, b2, &ss->p_error);
    ss->n = tp.ng;
    struct dvec3 x_err;
    struct dvec3 x = plane_point_d(d3(tp.p0), tp.e1, tp.e2, b1, b2, &x_err);
    if (!direction_to(ss, d3_to_float(x), ss->n, apex, pdf_u * pdf_spherical_triangle(&st)))
        return false;
    ss->wi = wi; /* the sampled direction, whose density this is */
    return true;
}

float shape_triangle_pdf_solid_angle(const vec3 p[3], const struct surface *ref,
                                     const struct surface *on, vec3 wi)
{
    struct sample_sph_triangle st;
    float w[4];
    vec3 apex;
    if (!triangle_by_solid_angle(p, ref, &st, w, &apex))
        return shape_triangle_pdf(p, ref, on, wi);
    /* pdf_sa = pdf_bilinear(u) / Omega at the u that maps to wi */
    return pdf_bilinear(sample_invert_spherical_triangle(&st, wi), w) * pdf_spherical_triangle(&st);
}
