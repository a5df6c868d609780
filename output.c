/* output.c - the files a render writes and their names (see output.h): the image and its
 * preview, snapshots, the sample-count map, the convergence curve with its plot and the
 * contact sheet.  The pixels come from film.c, the pictures from plot.c, the numbers from
 * stats.c; this file decides only what goes where. */
#include "output.h"

#include <stdlib.h>
#include <strings.h>
#include <unistd.h>

#include "image.h"

/* Copies src to out (out_bytes); false with *err (bad input) when it does not fit. */
static bool copy_path(char *out, size_t out_bytes, const char *src, struct mcpt_error *err)
{
    int len = snprintf(out, out_bytes, "%s", src);
    if (len < 0 || (size_t)len >= out_bytes) {
        mcpt_error_set(err, src, 0, 0, "expected a file name of at most %zu bytes, got %d",
                       out_bytes - 1, len);
        return false;
    }
    return true;
}

/* "x/out.exr" -> "x/out" + suffix: the extension (a dot after the last slash, not leading the
 * name) replaced by suffix, or suffix appended where there is none. */
static bool with_suffix(const char *path, const char *suffix, char *out, size_t out_bytes,
                        struct mcpt_error *err)
{
    const char *slash = strrchr(path, '/');
    const char *dot = strrchr(path, '.');
    int len = dot && (!slash || dot > slash + 1) ? (int)(dot - path) : (int)strlen(path);
    char name[FILE_PATH_BYTES + 64];
    snprintf(name, sizeof name, "%.*s%s", len, path, suffix);
    return copy_path(out, out_bytes, name, err);
}

bool output_has_extension(const char *path, const char *ext)
{
    const char *slash = strrchr(path, '/');
    const char *base = slash ? slash + 1 : path;
    const char *dot = strrchr(base, '.');
    return dot && dot > base && strcasecmp(dot + 1, ext) == 0;
}

bool output_paths_init(struct output_paths *p, const char *scene_path, const char *output,
                       const char *checkpoint_path, const char *heatmap_path, bool is_adaptive,
                       bool has_preview, struct mcpt_error *err)
{
    memset(p, 0, sizeof *p);
    if (output && output_has_extension(output, "png")) {
        if (!copy_path(p->png, sizeof p->png, output, err))
            return false;
    } else if (output) {
        if (!output_has_extension(output, "exr")) {
            mcpt_error_set(err, "mcpt", 0, 0,
                           "expected an output name ending in .exr (float image and PNG "
                           "preview) or .png (8-bit sRGB only), got '%.200s'",
                           output);
            return false;
        }
        if (!copy_path(p->exr, sizeof p->exr, output, err))
            return false;
    } else { /* "dir/name.txt" -> "name.exr", here */
        const char *base = strrchr(scene_path, '/');
        base = base ? base + 1 : scene_path;
        const char *dot = strrchr(base, '.');
        int len = dot && dot != base ? (int)(dot - base) : (int)strlen(base);
        snprintf(p->exr, sizeof p->exr, "%.*s.exr", len, base);
    }
    if (p->exr[0] && has_preview && !with_suffix(p->exr, ".png", p->png, sizeof p->png, err))
        return false;
    const char *image = output_image_path(p);
    char name[FILE_PATH_BYTES + 8];
    snprintf(name, sizeof name, "%s.ckpt", image);
    if (!copy_path(p->checkpoint, sizeof p->checkpoint, checkpoint_path ? checkpoint_path : name,
                   err))
        return false;
    if (heatmap_path)
        return copy_path(p->heatmap, sizeof p->heatmap, heatmap_path, err);
    return !is_adaptive || with_suffix(image, ".samples.png", p->heatmap, sizeof p->heatmap, err);
}

const char *output_image_path(const struct output_paths *p) { return p->exr[0] ? p->exr : p->png; }

/* The PNG of film into the temporary af: its means as look says; finished, not renamed
 * (image_encode_png_srgb). */
static bool encode_png(struct file_atomic *af, const struct film *film,
                       const struct image_look *look, struct mcpt_error *err)
{
    size_t n_pixels = (size_t)film->width * (size_t)film->height;
    float *rgb = malloc(sizeof(float) * 3 * n_pixels);
    if (!rgb) {
        mcpt_error_runtime(err, af->path, "out of memory writing the preview");
        file_atomic_abort(af);
        return false;
    }
    for (size_t i = 0; i < n_pixels; i++)
        for (int c = 0; c < 3; c++)
            rgb[3 * i + c] = (float)film_mean(&film->pixels[i], c);
    bool ok = image_encode_png_srgb(af, film->width, film->height, rgb, look, err);
    free(rgb);
    return ok;
}

/* Adds the string attribute name = printf(fmt, ...) to img. */
static void add_attr(struct image *img, const char *name, const char *fmt, ...)
{
    if (img->n_attrs >= IMAGE_MAX_ATTRS)
        return;
    va_list ap;
    va_start(ap, fmt);
    snprintf(img->attr_names[img->n_attrs], sizeof img->attr_names[0], "%s", name);
    vsnprintf(img->attr_values[img->n_attrs], sizeof img->attr_values[0], fmt, ap);
    va_end(ap);
    img->n_attrs++;
}

/* The header attributes of output.h's struct output_meta; samples is the count plane. */
static void add_meta(struct image *img, const struct output_meta *meta, const float *samples)
{
    size_t n_pixels = (size_t)img->width * (size_t)img->height;
    double total = 0.0;
    for (size_t i = 0; i < n_pixels; i++)
        total += samples[i];
    add_attr(img, "mcpt.version", "%s", MCPT_VERSION);
    add_attr(img, "mcpt.spp", "%.6g", total / (double)n_pixels);
    if (!meta)
        return;
    if (meta->scene)
        add_attr(img, "mcpt.scene", "%s", meta->scene);
    if (meta->sampler) {
        add_attr(img, "mcpt.sampler", "%s", meta->sampler);
        add_attr(img, "mcpt.seed", "%llu", (unsigned long long)meta->seed);
        if (meta->max_depth == UINT32_MAX)
            add_attr(img, "mcpt.max-depth", "inf");
        else
            add_attr(img, "mcpt.max-depth", "%u", meta->max_depth);
    }
    if (meta->render_s >= 0.0)
        add_attr(img, "mcpt.render-seconds", "%.3f", meta->render_s);
    if (meta->render)
        add_attr(img, PARTIAL_ATTR_RENDER, "%s", meta->render);
    if (meta->ranges)
        add_attr(img, PARTIAL_ATTR_RANGES, "%s", meta->ranges);
}

/* The EXR of every render into the temporary af: R, G, B, variance of the mean per channel,
 * sample count, and the attributes of meta; finished, not renamed. */
static bool encode_exr(struct file_atomic *af, const struct film *film,
                       const struct output_meta *meta, struct mcpt_error *err)
{
    static const char *names[7] = {"R",          "G",          "B",      "variance.R",
                                   "variance.G", "variance.B", "samples"};
    size_t n_pixels = (size_t)film->width * (size_t)film->height;
    struct image img = {.width = film->width, .height = film->height, .n_channels = 7};
    float *planes = malloc(sizeof(float) * n_pixels * 7);
    if (!planes) {
        mcpt_error_runtime(err, af->path, "out of memory writing the image");
        file_atomic_abort(af);
        return false;
    }
    for (int c = 0; c < 7; c++) {
        snprintf(img.names[c], sizeof img.names[c], "%s", names[c]);
        img.data[c] = planes + (size_t)c * n_pixels;
    }
    film_resolve(film, img.data, img.data + 3, img.data[6]);
    add_meta(&img, meta, img.data[6]);
    bool ok = image_encode_exr(af, &img, err);
    free(planes);
    return ok;
}

/* The PNG alone, at png_path. */
static bool write_png(const struct film *film, const char *png_path, const struct image_look *look,
                      struct mcpt_error *err)
{
    struct file_atomic af;
    return file_atomic_open(&af, png_path, err) && encode_png(&af, film, look, err) &&
           file_atomic_rename(&af, err);
}

/* An image and its preview as a pair (either may be "": not written): both temporaries are
 * written and synced before either is renamed, so a failure or a kill -9 while writing leaves
 * the old pair (and temporaries that the next run removes).  When the image is written but its
 * preview cannot be (a disk full by the PNG), the image is kept, being what the render made,
 * and the old preview is removed rather than left beside an image it does not show; the
 * message says so.  Between the two renames (microseconds) a kill -9 can still leave the new
 * image beside the old preview. */
static bool write_pair(const char *exr_path, const char *png_path, const struct film *film,
                       const struct partial_info *part, const struct output_meta *meta,
                       const struct image_look *look, struct mcpt_error *err)
{
    if (!exr_path[0])
        return !png_path[0] || write_png(film, png_path, look, err);
    struct file_atomic exr, png;
    if (!file_atomic_open(&exr, exr_path, err) ||
        !(part ? partial_encode_exr(&exr, film, part, err) : encode_exr(&exr, film, meta, err)))
        return false; /* nothing replaced */
    if (!png_path[0])
        return file_atomic_rename(&exr, err);
    bool is_png_ready = file_atomic_open(&png, png_path, err) && encode_png(&png, film, look, err);
    if (!file_atomic_rename(&exr, err)) {
        if (is_png_ready)
            file_atomic_abort(&png);
        return false; /* nothing replaced */
    }
    if (is_png_ready && file_atomic_rename(&png, err))
        return true;
    unlink(png_path);
    size_t len = strnlen(err->msg, sizeof err->msg);
    snprintf(err->msg + len, sizeof err->msg - len,
             " (the image %s was written; the old preview was removed, as it showed an "
             "older image)",
             exr_path);
    return false;
}

bool output_write_image(const struct output_paths *p, const struct film *film,
                        const struct partial_info *part, const struct output_meta *meta,
                        const struct image_look *look, struct mcpt_error *err)
{
    return write_pair(p->exr, p->png, film, part, meta, look, err);
}

bool output_write_preview(const struct output_paths *p, const struct film *film,
                          const struct image_look *look, struct mcpt_error *err)
{
    return !p->png[0] || write_png(film, p->png, look, err);
}

bool output_write_snapshot(const struct output_paths *p, const struct film *film, uint32_t spp,
                           uint32_t spp_final, const struct output_meta *meta,
                           const struct image_look *look, struct mcpt_error *err)
{
    char suffix[64], exr_path[FILE_PATH_BYTES], png_path[FILE_PATH_BYTES];
    int digits = snprintf(NULL, 0, "%u", spp_final);
    snprintf(suffix, sizeof suffix, "-spp%0*u.exr", digits, spp);
    if (!with_suffix(output_image_path(p), suffix, exr_path, sizeof exr_path, err) ||
        !with_suffix(exr_path, ".png", png_path, sizeof png_path, err))
        return false;
    return write_pair(exr_path, png_path, film, NULL, meta, look, err);
}

bool output_write_heatmap(const struct output_paths *p, const struct film *film,
                          struct mcpt_error *err)
{
    return !p->heatmap[0] || plot_write_count_heatmap(p->heatmap, film, err);
}

bool output_write_convergence(const struct output_paths *p, const char *curve_path,
                              const struct stats_curve *c, const struct stats_summary *s,
                              const struct plot_sheet *sheet, struct mcpt_error *err)
{
    char path[FILE_PATH_BYTES];
    if (curve_path) {
        if (!stats_write_csv(curve_path, c, err) ||
            !with_suffix(curve_path, ".json", path, sizeof path, err) ||
            !stats_write_json(path, c, s, err) ||
            !with_suffix(curve_path, ".svg", path, sizeof path, err) ||
            !plot_write_svg(path, c, s, err))
            return false;
    }
    if (!sheet->n_thumbs)
        return true;
    return with_suffix(output_image_path(p), "-contact.png", path, sizeof path, err) &&
           plot_write_contact_sheet(path, sheet, err);
}

/* ---- before a render: the memory its writes need, the files it may write and the harm they
 * could do ---- */

double output_save_interval(double asked_s, double last_write_s)
{
    double least = last_write_s > 0.0 ? last_write_s / OUTPUT_MAX_WRITE_SHARE : 0.0;
    return asked_s > least ? asked_s : least;
}

size_t output_peak_bytes(int width, int height, bool is_partial)
{
    size_t n_pixels = (size_t)width * (size_t)height;
    size_t exr_per_pixel = sizeof(float) * (is_partial ? 24 : 7); /* partial.c: 6 + 9 hi + 9 lo */
    size_t png_per_pixel = 3 * sizeof(float) + 3;                 /* linear RGB, then sRGB bytes */
    size_t per_pixel = exr_per_pixel > png_per_pixel ? exr_per_pixel : png_per_pixel;
    /* OpenEXR encodes a chunk of 16 rows at a time (ZIP): the rows, packed, compressed and
     * scratch, 4 copies; zlib and libpng keep well under a few MiB besides */
    size_t band = 4 * 16 * (size_t)width * exr_per_pixel;
    return n_pixels * per_pixel + band + ((size_t)8 << 20);
}

/* Adds path with role to files[*n]; false with *err when it does not fit. */
static bool add_file(struct output_file *files, int *n, const char *path, const char *role,
                     struct mcpt_error *err)
{
    if (*n >= OUTPUT_MAX_FILES || !copy_path(files[*n].path, sizeof files[*n].path, path, err))
        return false;
    files[(*n)++].role = role;
    return true;
}

int output_list(const struct output_paths *p, const char *curve_path, bool snapshots,
                uint32_t spp_final, struct output_file *files, struct mcpt_error *err)
{
    int n = 0;
    char path[FILE_PATH_BYTES], suffix[64];
    bool ok = (!p->exr[0] || add_file(files, &n, p->exr, "the image (-o)", err)) &&
              (!p->png[0] || add_file(files, &n, p->png,
                                      p->exr[0] ? "the PNG preview" : "the image (-o)", err)) &&
              add_file(files, &n, p->checkpoint, "the checkpoint", err) &&
              (!p->heatmap[0] || add_file(files, &n, p->heatmap, "the sample-count map", err));
    if (ok && curve_path)
        ok = add_file(files, &n, curve_path, "the curve (--curve)", err) &&
             with_suffix(curve_path, ".json", path, sizeof path, err) &&
             add_file(files, &n, path, "the curve's JSON", err) &&
             with_suffix(curve_path, ".svg", path, sizeof path, err) &&
             add_file(files, &n, path, "the curve's plot", err);
    if (ok && snapshots) {
        int digits = snprintf(NULL, 0, "%u", spp_final);
        for (uint64_t spp = 1; ok; spp = spp * 2 < spp_final ? spp * 2 : spp_final) {
            snprintf(suffix, sizeof suffix, "-spp%0*u.exr", digits, (uint32_t)spp);
            ok = with_suffix(output_image_path(p), suffix, path, sizeof path, err) &&
                 add_file(files, &n, path, "a snapshot", err) &&
                 with_suffix(files[n - 1].path, ".png", path, sizeof path, err) &&
                 add_file(files, &n, path, "a snapshot's preview", err);
            if (spp >= spp_final)
                break;
        }
        ok = ok && with_suffix(output_image_path(p), "-contact.png", path, sizeof path, err) &&
             add_file(files, &n, path, "the contact sheet", err);
    }
    return ok ? n : -1;
}

bool output_check(const struct output_file *outputs, int n_outputs,
                  const struct output_file *inputs, int n_inputs, struct mcpt_error *err)
{
    return output_check_names(outputs, n_outputs, inputs, n_inputs, err) &&
           output_check_creatable(outputs, n_outputs, err);
}

bool output_check_creatable(const struct output_file *outputs, int n_outputs,
                            struct mcpt_error *err)
{
    bool ok = true;
    for (int i = 0; ok && i < n_outputs; i++)
        ok = file_check_creatable(outputs[i].path, err);
    for (int i = 0; ok && i < n_outputs; i++)
        file_remove_stale(outputs[i].path);
    return ok;
}

bool output_check_names(const struct output_file *outputs, int n_outputs,
                        const struct output_file *inputs, int n_inputs, struct mcpt_error *err)
{
    struct file_id *ids = malloc(sizeof *ids * (size_t)(n_outputs + n_inputs));
    if (!ids) {
        mcpt_error_runtime(err, NULL, "out of memory checking the output files");
        return false;
    }
    bool ok = true;
    for (int i = 0; i < n_outputs + n_inputs; i++) {
        const char *path = i < n_outputs ? outputs[i].path : inputs[i - n_outputs].path;
        if (!file_id_of(path, &ids[i])) {
            mcpt_error_set(err, path, 0, 0,
                           "expected a file name that can be resolved, got one "
                           "too long or outside any working directory");
            ok = false;
            goto done;
        }
    }
    for (int i = 0; i < n_outputs; i++) {
        for (int k = 0; k < n_outputs + n_inputs; k++) {
            if (k == i || (k < n_outputs && k > i) || !file_id_same(&ids[i], &ids[k]))
                continue;
            const struct output_file *other = k < n_outputs ? &outputs[k] : &inputs[k - n_outputs];
            mcpt_error_set(err, outputs[i].path, 0, 0,
                           "expected %s to be a file of its own, got the same file as %s '%s'",
                           outputs[i].role, other->role, other->path);
            ok = false;
            goto done;
        }
    }
    for (int i = 0; ok && i < n_outputs; i++)
        ok = file_check_name(outputs[i].path, err);
done:
    free(ids);
    return ok;
}
