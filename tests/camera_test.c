/* tests/camera_test.c - camera.c: primary rays at the film's centre and corners match the
 * pinhole model (vertical fov, aspect), and the thin lens focuses on the plane of focus
 * (PBRT 4e, ch. 5, "Projective Camera Models").  The frame is computed after an exact
 * power-of-two scaling: the same bits as plain float arithmetic for ordinary vectors, the true
 * direction for tiny and huge ones (issue 15). */
#include <criterion/criterion.h>

#include "camera.h"

static struct camera make_cam(int w, int h, float aperture)
{
    struct camera_params p = {.eye = v3(0, 1, 3.9f),
                              .look_at = v3(0, 1, 0),
                              .up = v3(0, 1, 0),
                              .fov_deg = 40.0f,
                              .aperture = aperture};
    struct camera cam;
    struct mcpt_error err;
    cr_assert(camera_init(&cam, &p, w, h, &err));
    return cam;
}

/* The film centre looks straight at look_at. */
Test(camera, centre)
{
    struct camera cam = make_cam(512, 256, 0.0f);
    struct ray r = camera_ray(&cam, 256.0f, 128.0f, (vec2){0.5f, 0.5f});
    cr_assert_float_eq(r.d.x, 0.0f, 1e-6f);
    cr_assert_float_eq(r.d.y, 0.0f, 1e-6f);
    cr_assert_float_eq(r.d.z, -1.0f, 1e-6f);
    cr_assert_float_eq(r.o.z, 3.9f, 1e-6f);
}

/* Corners: the top-left corner is at (-aspect tan(fov/2), +tan(fov/2), -1) before normalising;
 * y grows downwards on the film. */
Test(camera, corners)
{
    struct camera cam = make_cam(512, 256, 0.0f);
    float th = tanf(20.0f * MCPT_PI / 180.0f);
    vec3 tl = v3_normalize(v3(-2.0f * th, th, -1.0f));
    vec3 br = v3_normalize(v3(2.0f * th, -th, -1.0f));
    struct ray r = camera_ray(&cam, 0.0f, 0.0f, (vec2){0.5f, 0.5f});
    cr_assert_float_eq(r.d.x, tl.x, 1e-6f);
    cr_assert_float_eq(r.d.y, tl.y, 1e-6f);
    cr_assert_float_eq(r.d.z, tl.z, 1e-6f);
    r = camera_ray(&cam, 512.0f, 256.0f, (vec2){0.5f, 0.5f});
    cr_assert_float_eq(r.d.x, br.x, 1e-6f);
    cr_assert_float_eq(r.d.y, br.y, 1e-6f);
    cr_assert_float_eq(r.d.z, br.z, 1e-6f);
}

/* Thin lens: every lens sample's ray passes through the same point on the plane of focus. */
Test(camera, thin_lens_focus)
{
    struct camera cam = make_cam(100, 100, 0.2f);
    vec3 target = v3(0, 0, 0);
    for (int i = 0; i < 16; i++) {
        vec2 u = {0.0625f * (float)i + 0.01f, 0.37f * (float)(i % 3) + 0.05f};
        struct ray r = camera_ray(&cam, 30.0f, 70.0f, u);
        /* plane of focus: z = eye.z - focus_dist = 0 */
        float t = -r.o.z / r.d.z;
        vec3 p = v3_add(r.o, v3_scale(r.d, t));
        if (i == 0)
            target = p;
        cr_assert_float_eq(p.x, target.x, 1e-5f);
        cr_assert_float_eq(p.y, target.y, 1e-5f);
    }
}

/* Degenerate cameras are refused, each with its fault. */
Test(camera, degenerate)
{
    struct camera cam;
    struct mcpt_error err;
    struct camera_params p = {.eye = v3(1, 1, 1),
                              .look_at = v3(1, 1, 1),
                              .up = v3(0, 1, 0),
                              .fov_deg = 40.0f};
    vec3 f, r, u;
    float len;
    cr_assert_not(camera_init(&cam, &p, 10, 10, &err));
    cr_assert_eq(camera_frame(&p, &f, &r, &u, &len), CAMERA_SAME_POINT);
    p.look_at = v3(1, 5, 1);
    cr_assert_not(camera_init(&cam, &p, 10, 10, &err), "up parallel to view");
    cr_assert_eq(camera_frame(&p, &f, &r, &u, &len), CAMERA_UP_PARALLEL);
    p.up = v3(0, 0, 0);
    cr_assert_eq(camera_frame(&p, &f, &r, &u, &len), CAMERA_UP_ZERO);
    p.up = v3(0, 1, 0);
    p.eye = v3(-3e38f, 0, 0);
    p.look_at = v3(3e38f, 0, 0); /* look_at - eye overflows */
    cr_assert_eq(camera_frame(&p, &f, &r, &u, &len), CAMERA_NOT_FINITE);
    p.eye = v3(-1e38f, -1e38f, -1e38f);
    p.look_at = v3(1e38f, 1e38f, 1e38f); /* finite, but |look_at - eye| = 3.5e38 is not */
    cr_assert_eq(camera_frame(&p, &f, &r, &u, &len), CAMERA_NOT_FINITE);
}

/* The frame as camera.c computed it before the scaling (plain float arithmetic). */
static void plain_frame(const struct camera_params *p, vec3 *f, vec3 *r, vec3 *u, float *len)
{
    vec3 view = v3_sub(p->look_at, p->eye);
    *len = v3_length(view);
    *f = v3_scale(view, 1.0f / *len);
    vec3 c = v3_cross(*f, p->up);
    *r = v3_scale(c, 1.0f / v3_length(c));
    *u = v3_cross(*r, *f);
}

static bool same_bits(vec3 a, vec3 b) { return memcmp(&a, &b, sizeof a) == 0; }

static bool same_value(vec3 a, vec3 b) { return a.x == b.x && a.y == b.y && a.z == b.z; }

/* Scaling a float by 2^k is exact and every rounding scales with it, so for vectors whose
 * squares stay normal floats the scaled frame has exactly the bits of the plain one (images of
 * existing scenes do not change): 10000 random cameras with coordinates in [-100, 100]. */
Test(camera, frame_bits_equal_plain_float)
{
    uint64_t state = 12345;
    for (int i = 0; i < 10000; i++) {
        float x[9];
        for (int k = 0; k < 9; k++) {
            state = state * 6364136223846793005u + 1442695040888963407u;
            x[k] = (float)((double)(state >> 11) / 9007199254740992.0 * 200.0 - 100.0);
        }
        struct camera_params p = {.eye = v3(x[0], x[1], x[2]),
                                  .look_at = v3(x[3], x[4], x[5]),
                                  .up = v3(x[6], x[7], x[8]),
                                  .fov_deg = 40.0f};
        vec3 f, r, u, f0, r0, u0;
        float len, len0;
        if (camera_frame(&p, &f, &r, &u, &len) != CAMERA_OK)
            continue; /* up nearly parallel: rare */
        plain_frame(&p, &f0, &r0, &u0, &len0);
        cr_assert(same_bits(f, f0) && same_bits(r, r0) && same_bits(u, u0) && len == len0,
                  "camera %d differs", i);
    }
}

/* Tiny and huge vectors give the true frame: look-at 1e-30 from the eye, up of length 1e-30,
 * 3e38 or a denormal; plain float arithmetic gave no frame at all (|v|^2 under- or overflows). */
Test(camera, frame_of_tiny_and_huge_vectors)
{
    struct camera_params p = {.eye = v3(0, 0, 0),
                              .look_at = v3(1e-30f, 0, 0),
                              .up = v3(0, 1, 0),
                              .fov_deg = 40.0f};
    vec3 f, r, u;
    float len;
    cr_assert_eq(camera_frame(&p, &f, &r, &u, &len), CAMERA_OK);
    cr_assert(same_value(f, v3(1, 0, 0)) && same_value(u, v3(0, 1, 0)) &&
              same_value(r, v3(0, 0, 1)));
    cr_assert_eq(len, 1e-30f);
    const vec3 ups[] = {v3(0, 1e-30f, 0), v3(0, 3e38f, 0), v3(0, 0x1p-149f, 0)};
    p.look_at = v3(0, 0, -2);
    for (int i = 0; i < 3; i++) {
        p.up = ups[i];
        cr_assert_eq(camera_frame(&p, &f, &r, &u, &len), CAMERA_OK, "up %d", i);
        cr_assert(same_value(f, v3(0, 0, -1)) && same_value(r, v3(1, 0, 0)) &&
                      same_value(u, v3(0, 1, 0)),
                  "up %d: r (%g %g %g) u (%g %g %g)", i, r.x, r.y, r.z, u.x, u.y, u.z);
        cr_assert_eq(len, 2.0f);
    }
}

/* Extreme but accepted cameras give finite unit rays everywhere on the film: fov just under
 * 180 on a 65535 x 1 film, and a lens of radius 1e18 focused 1e18 away (|p_focus - o| passes
 * 1e19, whose square overflows: the lens ray is normalised after scaling). */
Test(camera, extreme_rays_are_unit)
{
    struct camera_params p = {.eye = v3(1e18f, 0, 0),
                              .look_at = v3(0, 0, 0),
                              .up = v3(0, 1, 0),
                              .fov_deg = 179.9999f};
    struct camera cam;
    struct mcpt_error err;
    cr_assert(camera_init(&cam, &p, 65535, 1, &err));
    for (int i = 0; i <= 4; i++) {
        struct ray ray = camera_ray(&cam, 65535.0f * (float)i / 4.0f, 0.5f, (vec2){0.5f, 0.5f});
        cr_assert(v3_is_finite(ray.d) && fabsf(v3_length(ray.d) - 1.0f) < 1e-6f, "pixel %d", i);
    }
    p.fov_deg = 40.0f;
    p.aperture = 1e18f;
    p.focus_dist = 1e18f;
    cr_assert(camera_init(&cam, &p, 64, 64, &err));
    for (int i = 0; i < 16; i++) {
        vec2 u = {(float)(i % 4) / 4.0f + 0.1f, (float)(i / 4) / 4.0f + 0.1f};
        struct ray ray = camera_ray(&cam, 64.0f * u.y, 64.0f * u.x, u);
        cr_assert(v3_is_finite(ray.o) && v3_is_finite(ray.d) &&
                      fabsf(v3_length(ray.d) - 1.0f) < 1e-6f,
                  "sample %d", i);
    }
}
