/* shape.h - the geometry of each kind of primitive: spheres, parallelograms ("quads") and
 * infinite planes kept outside the BVH, and the surface of triangles (the BVH intersects them).
 * Each has a ray intersection that returns the hit parameter (triangles: bvh.h) and a surface
 * query that returns the point with its floating-point error bound (PBRT 4e, ch. 6, "Managing
 * Rounding Error"), so secondary rays can be offset without scene-tuned epsilons; the shapes that
 * can emit (triangles, quads, spheres) also sample a point as seen from a reference point. */
#ifndef MCPT_SHAPE_H
#define MCPT_SHAPE_H

#include "vec.h"

struct sphere {
    vec3 center;
    float radius; /* > 0, scene units */
    uint32_t mat_idx;
};

/* Parallelogram p = corner + s e1 + t e2, s, t in [0, 1]; front normal = normalize(e1 x e2).
 * In double, as the scene file wrote it: quads meet only where their corners and edges agree,
 * and float would put gaps of half an ulp of the corner between the faces of a box that is
 * rotated or away from the origin (triangles close by sharing vertices; docs/theory.md,
 * "Self-intersection"). */
struct quad {
    struct dvec3 corner;
    struct dvec3 e1;
    struct dvec3 e2;
    uint32_t mat_idx;
    float groove; /* the factor of its edges' margins where another quad meets one of them at an
                     acute groove (scene.c, grooves); 0 or 1: none */
};

/* Infinite plane through point with unit normal n (front side). */
struct plane {
    vec3 point;
    vec3 n;
    uint32_t mat_idx;
};

/* A line where a mesh stands on a plane, a quad or a triangle (scene.c, contacts): a mesh edge
 * from a to b lying on the surface, whose triangle rises off it; m is the unit normal of the
 * line within the surface's plane, g the factor of the margin's normal term (docs/theory.md,
 * "Self-intersection": 6 cot of the acute angle between the triangle and the surface, at least
 * 1). */
struct contact {
    struct dvec3 a, b, m;
    double g;
};

/* A point on a surface, as the integrator needs it. */
struct surface {
    vec3 p;       /* position */
    vec3 p_error; /* absolute error bound of p, per component */
    vec3 ng;      /* unit geometric normal (front side of the primitive) */
    vec3 ns;      /* unit shading normal, on the same side as ng */
    vec2 uv;      /* surface parameterisation */
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
/* A point sf of a plane, quad or triangle within the margin of one of its n contacts cs (a wall
 * that stands on the surface there) moved, within the surface, to that margin on the side of
 * the line the point `from` lies on (the incoming ray's origin), as triangle_point pulls points
 * away from a triangle's edges: a ray spawned there then starts in front of the wall, not past
 * it. */
void shape_pull_from_contacts(struct surface *sf, const struct contact *cs, uint32_t n, vec3 from);

/* Surface of the triangle with corners p[3] at barycentrics (1 - b1 - b2, b1, b2) of a hit of
 * ray at t_hit; ns[3] and uv[3] are the corners' shading normals and uvs, each NULL when the
 * mesh has none.  For a triangle larger than the hit distance the point is that of the ray at
 * t_hit (float barycentrics are the less precise there); ray NULL: from b1, b2 alone.  groove[3]
 * (NULL: 1, 1, 1) are the factors of the edges' margins at acute grooves (struct
 * triangle_plane). */
struct surface shape_triangle_surface(const vec3 p[3], const float *groove, const vec3 *ns,
                                      const vec2 *uv, const struct ray *ray, float t_hit, float b1,
                                      float b2, uint32_t mat_idx);
/* Area of the triangle with corners p[3] (computed in double, so it neither overflows nor
 * underflows on the way); *ng (may be NULL) receives its unit normal (p1 - p0) x (p2 - p0), or
 * 0 when the triangle is degenerate. */
float shape_triangle_area(const vec3 p[3], vec3 *ng);
/* Area |e1 x e2| of a quad, likewise. */
float shape_quad_area(const struct quad *q);

/* ---- sampling a shape from a reference point (area lights) ----
 * PBRT 4e, ch. 6, "Shape Interface": Shape::Sample(ctx, u) and Shape::PDF(ctx, wi).  Triangles,
 * quads and spheres seen from inside are sampled uniformly by area and the density converted to
 * solid angle; spheres seen from outside uniformly in the cone of directions they subtend. */

/* A point sampled on a shape as seen from a reference point. */
struct shape_sample {
    vec3 p;       /* the point on the shape */
    vec3 p_error; /* absolute error bound of p, per component */
    vec3 n;       /* unit geometric normal at p (front side) */
    vec3 wi;      /* unit direction from the reference point to p */
    float pdf_sa; /* density of wi, per unit solid angle */
};

/* What every point of a triangle shares, computed in double once (shape_triangle_plane) for a
 * triangle that emits (the light table keeps one per emitting triangle, 160 bytes): sampling
 * then skips a cross product, a square root and a division per sample, and gives the same bits
 * as shape_triangle_sample and shape_triangle_pdf.  trace.c keeps one per triangle of a small
 * scene for its hits (shape_triangle_plane_surface). */
struct triangle_plane {
    vec3 p0;         /* the first corner */
    struct dvec3 e1; /* p1 - p0 */
    struct dvec3 e2; /* p2 - p0 */
    struct dvec3 c;  /* e1 x e2: its direction is the front side */
    vec3 ng;         /* unit normal, c / |c| rounded to float; 0 when degenerate */
    double area2;    /* |c|, twice the area */
    double eta;      /* bound on the error of each component of ng */
    double inside_k[3]; /* surely_inside's factors (shape.c), per edge opposite corner i */
    float groove[3];    /* per edge opposite corner i, the factor of its margin's normal term where
                        it meets another triangle at an acute groove (scene.h, tri_groove); 1
                        elsewhere */
};
/* groove: the three factors, or NULL for 1, 1, 1. */
void shape_triangle_plane(const vec3 p[3], const float *groove, struct triangle_plane *tp);
/* shape_triangle_surface of the triangle whose plane is *tp: the same bits. */
struct surface shape_triangle_plane_surface(const struct triangle_plane *tp, const vec3 *ns,
                                            const vec2 *uv, const struct ray *ray, float t_hit,
                                            float b1, float b2, uint32_t mat_idx);

/* Sample a point on the shape from ref->p with uniforms u.  False when the sample is unusable:
 * the point coincides with ref->p, is seen edge-on, or its density is not finite. */
bool shape_triangle_sample(const vec3 p[3], const struct surface *ref, vec2 u,
                           struct shape_sample *ss);
bool shape_triangle_plane_sample(const struct triangle_plane *tp, const struct surface *ref, vec2 u,
                                 struct shape_sample *ss);
bool shape_quad_sample(const struct quad *q, const struct surface *ref, vec2 u,
                       struct shape_sample *ss);
/* A sphere from outside by its cone of directions (PBRT 4e, ch. 6, "Spheres"); from inside (ref
 * on the sphere counts as inside) cosine-weighted about n_cos, the unit normal on the side of
 * ref being lit (light.c passes the vertex's sky normal), the point where that direction meets
 * the sphere. */
bool shape_sphere_sample(const struct sphere *s, const struct surface *ref, vec3 n_cos, vec2 u,
                         struct shape_sample *ss);

/* The solid-angle density with which shape_*_sample picks the unit direction wi from ref, given
 * the point on->p (geometric normal on->ng) where the ray along wi first meets the shape; 0 when
 * wi meets the shape edge-on. */
float shape_triangle_pdf(const vec3 p[3], const struct surface *ref, const struct surface *on,
                         vec3 wi);
float shape_triangle_plane_pdf(const struct triangle_plane *tp, const struct surface *ref,
                               const struct surface *on, vec3 wi);
float shape_quad_pdf(const struct quad *q, const struct surface *ref, const struct surface *on,
                     vec3 wi);
/* The sphere's density depends on ref and wi alone (n_cos: as for shape_sphere_sample). */
float shape_sphere_pdf(const struct sphere *s, const struct surface *ref, vec3 n_cos, vec3 wi);

/* The same by solid angle (--light-sampling solid-angle): a triangle by Arvo's spherical-triangle
 * map (Arvo 1995), a rectangular quad by the spherical-rectangle map (Urena et al. 2013), each
 * with its uniforms first warped by the bilinear approximation of |cos theta| at ref's shading
 * normal (PBRT 4e, ch. 6, "Triangles" and "Bilinear Patches"), so pdf_sa = pdf_bilinear(u) /
 * solid angle.  Where the solid angle lies outside PBRT 4e's bounds (3e-4 sr and, for a
 * triangle, 6.22 sr) or the quad is not a rectangle, they are the area samplers above. */
bool shape_triangle_sample_solid_angle(const vec3 p[3], const struct surface *ref, vec2 u,
                                       struct shape_sample *ss);
float shape_triangle_pdf_solid_angle(const vec3 p[3], const struct surface *ref,
                                     const struct surface *on, vec3 wi);
bool shape_quad_sample_solid_angle(const struct quad *q, const struct surface *ref, vec2 u,
                                   struct shape_sample *ss);
float shape_quad_pdf_solid_angle(const struct quad *q, const struct surface *ref,
                                 const struct surface *on, vec3 wi);

#endif
