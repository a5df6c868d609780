/* camera.c - look-at perspective camera with vertical field of view and a thin lens.
 * The image plane sits at distance 1 along the view direction and spans
 * [-aspect tan(fov/2), aspect tan(fov/2)] x [-tan(fov/2), tan(fov/2)].  Thin lens: PBRT 4e,
 * ch. 5, "Projective Camera Models": a lens point at radius `aperture` (concentric disk) and the
 * pinhole ray's point on the plane of focus define the ray.  Directions are normalised after an
 * exact power-of-two scaling, so tiny and huge vectors keep their direction. */
#include "camera.h"

#include "sample.h"

/* v times 2^k, k chosen so the largest |component| lies in [1, 2): exact for every component
 * that stays a normal float, and it leaves v / |v| as plain float arithmetic computes it
 * whenever that does not overflow or underflow (every rounding scales by the same 2^k).
 * *k receives k; a zero or non-finite v comes back unscaled with k = 0. */
static vec3 scale_to_unit_range(vec3 v, int *k)
{
    float m = max_f(fabsf(v.x), max_f(fabsf(v.y), fabsf(v.z)));
    *k = 0;
    if (!(m > 0.0f) || !isfinite(m))
        return v;
    int e;
    frexpf(m, &e); /* m = f 2^e, f in [0.5, 1) */
    *k = 1 - e;
    return v3(ldexpf(v.x, *k), ldexpf(v.y, *k), ldexpf(v.z, *k));
}

/* v / |v| for any finite nonzero v, without overflow or underflow in |v|^2. */
static vec3 normalize_scaled(vec3 v)
{
    int k;
    return v3_normalize(scale_to_unit_range(v, &k));
}

enum camera_fault camera_frame(const struct camera_params *p, vec3 *forward, vec3 *right, vec3 *up,
                               float *view_len)
{
    vec3 view = v3_sub(p->look_at, p->eye);
    if (!v3_is_finite(p->eye) || !v3_is_finite(p->look_at) || !v3_is_finite(p->up) ||
        !v3_is_finite(view))
        return CAMERA_NOT_FINITE;
    if (v3_is_zero(view))
        return CAMERA_SAME_POINT;
    if (v3_is_zero(p->up))
        return CAMERA_UP_ZERO;
    int k_view, k_up;
    vec3 view_s = scale_to_unit_range(view, &k_view);
    float len_s = v3_length(view_s);
    float len = ldexpf(len_s, -k_view); /* exact, unless |view| passes FLT_MAX (sqrt(3) x) */
    if (!isfinite(len))
        return CAMERA_NOT_FINITE;
    vec3 f = v3_scale(view_s, 1.0f / len_s);
    vec3 up_s = scale_to_unit_range(p->up, &k_up);
    vec3 r = v3_cross(f, up_s);
    float r_len = v3_length(r);
    if (!(r_len > 1e-6f * v3_length(up_s))) /* 1e-6: |sin| below which up counts as parallel */
        return CAMERA_UP_PARALLEL;
    *forward = f;
    *right = v3_scale(r, 1.0f / r_len);
    *up = v3_cross(*right, f);
    *view_len = len;
    return CAMERA_OK;
}

bool camera_init(struct camera *cam, const struct camera_params *p, int width, int height,
                 struct mcpt_error *err)
{
    float view_len = 0.0f;
    enum camera_fault fault = camera_frame(p, &cam->forward, &cam->right, &cam->up, &view_len);
    if (fault != CAMERA_OK) {
        static const char *const why[] = {
            [CAMERA_NOT_FINITE] = "expected finite camera vectors, got a non-finite one",
            [CAMERA_SAME_POINT] = "expected eye and look-at to differ, got the same point",
            [CAMERA_UP_ZERO] = "expected a nonzero up vector, got 0,0,0",
            [CAMERA_UP_PARALLEL] = "expected an up vector not parallel to the view direction",
        };
        mcpt_error_set(err, "", 0, 0, "%s", why[fault]);
        return false;
    }
    cam->eye = p->eye;
    cam->tan_half_fov_y = tanf(0.5f * p->fov_deg * (MCPT_PI / 180.0f));
    cam->aspect = (float)width / (float)height;
    cam->aperture = p->aperture;
    cam->focus_dist = p->focus_dist > 0.0f ? p->focus_dist : view_len;
    cam->width = width;
    cam->height = height;
    return true;
}

struct ray camera_ray(const struct camera *cam, float px, float py, vec2 u_lens)
{
    /* film position -> image plane at distance 1: x right, y up */
    float sx = (2.0f * px / (float)cam->width - 1.0f) * cam->aspect * cam->tan_half_fov_y;
    float sy = (1.0f - 2.0f * py / (float)cam->height) * cam->tan_half_fov_y;
    vec3 d = v3_add(cam->forward, v3_add(v3_scale(cam->right, sx), v3_scale(cam->up, sy)));
    struct ray ray = {.o = cam->eye, .t_min = 0.0f, .t_max = INFINITY};
    if (cam->aperture > 0.0f) {
        /* thin lens: the pinhole ray meets the plane of focus at p_focus = eye + focus_dist d
         * (d has unit length along forward); the lens ray starts at a disk point of radius
         * aperture and passes through p_focus */
        vec2 lens = sample_concentric_disk(u_lens);
        vec3 o = v3_add(cam->eye, v3_add(v3_scale(cam->right, cam->aperture * lens.x),
                                         v3_scale(cam->up, cam->aperture * lens.y)));
        vec3 p_focus = v3_add(cam->eye, v3_scale(d, cam->focus_dist));
        ray.o = o;
        ray.d = normalize_scaled(v3_sub(p_focus, o)); /* |p_focus - o| may pass 1e19 */
        return ray;
    }
    ray.d = v3_normalize(d); /* 1 <= |d| <= ~4e11 (fov < 180, aspect <= 65535) */
    return ray;
}
