/* output.h - the files a render writes, and their names.  The image's path (-o, or the scene's
 * name with .exr) says its format: OUT.exr is the float image, with its PNG preview OUT.png
 * beside it (unless --no-preview); OUT.png is an 8-bit sRGB image and nothing else, as in
 * pbrt-v4 and Mitsuba 3.  From OUT follow the snapshots OUT-sppN.exr/.png, the contact sheet
 * OUT-contact.png, the sample-count map OUT.samples.png and the checkpoint OUT.exr.ckpt (or
 * OUT.png.ckpt); from --curve CSV its .json and .svg.  Every file is written atomically
 * (file.h).  All the names are fixed here before a render starts, so that they can be checked
 * before it. */
#ifndef MCPT_OUTPUT_H
#define MCPT_OUTPUT_H

#include "file.h"
#include "film.h"
#include "image.h"
#include "partial.h"
#include "plot.h"
#include "stats.h"

/* The names of a render's files; "" where there is none. */
struct output_paths {
    char exr[FILE_PATH_BYTES];        /* the image: R, G, B, variance.R/G/B, samples; "" when
                                         -o names a PNG */
    char png[FILE_PATH_BYTES];        /* its sRGB preview, or the image itself when exr is "";
                                         "" with --no-preview */
    char checkpoint[FILE_PATH_BYTES]; /* where an interrupted render saves its state */
    char heatmap[FILE_PATH_BYTES];    /* the sample-count map, or "" */
};

/* What an image's EXR header records besides its pixels: the standard chromaticities
 * (image.h) and these as string attributes mcpt.NAME, each left out where NULL or negative. */
struct output_meta {
    const char *scene;   /* mcpt.scene: the scene file as named, "<stdin>" for standard input */
    const char *sampler; /* mcpt.sampler; with it mcpt.seed and mcpt.max-depth */
    uint64_t seed;
    uint32_t max_depth; /* bounces; UINT32_MAX (TRACE_DEPTH_INFINITE) is written "inf" */
    double render_s;    /* mcpt.render-seconds: the render's wall-clock time; < 0: left out */
    const char *render; /* a merge: its parts' settings line (mcpt.render, partial.h) */
    const char *ranges; /* a merge: their sample ranges (mcpt.sample-ranges) */
};
/* Always written too: mcpt.version, and mcpt.spp, the mean over pixels of the samples channel
 * (the spp of a plain render; the mean of an adaptive or interrupted one). */

/* Names the files: the image is output, else the scene's base name with .exr in the current
 * folder ("dir/name.txt" -> "name.exr").  An image named *.exr (any case) sets exr, and png =
 * exr with its extension replaced by .png unless has_preview is false; one named *.png sets
 * png only.  checkpoint = checkpoint_path, else the image + ".ckpt"; heatmap = heatmap_path,
 * else OUT.samples.png for an adaptive render, else none.  False with *err (bad input) when
 * the image's name ends in neither .exr nor .png (file "mcpt"), or when a name would not fit
 * in FILE_PATH_BYTES (file = the path). */
bool output_paths_init(struct output_paths *p, const char *scene_path, const char *output,
                       const char *checkpoint_path, const char *heatmap_path, bool is_adaptive,
                       bool has_preview, struct mcpt_error *err);

/* The name the image was given: p->exr, or p->png when the image is a PNG. */
const char *output_image_path(const struct output_paths *p);

/* Writes the film as p->exr and p->png (each where named): with part NULL the EXR of every
 * render (R, G, B, variance of the mean per channel, sample count, and meta's attributes),
 * else the partial render's EXR with its sums and ranges (partial_encode_exr; p->exr must be
 * named); the PNG at look (exposure, tone curve).  The two are a pair: both temporaries are
 * written and synced before either is renamed, so a failure or kill -9 leaves the old pair.
 * When only the preview cannot be written (a disk full by it), the new image is kept and the
 * old preview removed, and *err says so.  False with *err (runtime) on failure. */
bool output_write_image(const struct output_paths *p, const struct film *film,
                        const struct partial_info *part, const struct output_meta *meta,
                        const struct image_look *look, struct mcpt_error *err);

/* Rewrites only the PNG p->png from the film as it stands (true when there is none). */
bool output_write_preview(const struct output_paths *p, const struct film *film,
                          const struct image_look *look, struct mcpt_error *err);

/* Writes the snapshot of a render at spp of spp_final samples per pixel: OUT-sppN.exr (with
 * meta) and OUT-sppN.png, N zero-padded to the digits of spp_final. */
bool output_write_snapshot(const struct output_paths *p, const struct film *film, uint32_t spp,
                           uint32_t spp_final, const struct output_meta *meta,
                           const struct image_look *look, struct mcpt_error *err);

/* Writes the sample-count map p->heatmap (plot_write_count_heatmap); true when there is none. */
bool output_write_heatmap(const struct output_paths *p, const struct film *film,
                          struct mcpt_error *err);

/* The convergence files: with curve_path, the CSV there and its .json and .svg beside it; with
 * a non-empty sheet, the contact sheet OUT-contact.png. */
bool output_write_convergence(const struct output_paths *p, const char *curve_path,
                              const struct stats_curve *c, const struct stats_summary *s,
                              const struct plot_sheet *sheet, struct mcpt_error *err);

/* The most bytes the writes of a film of width x height allocate at any one time, besides the
 * film: the EXR's planes (7 floats a pixel, or 24 for a partial render's sums), the preview's
 * (3 floats and 3 bytes a pixel), and the encoders' buffers of a band of rows.  Counted before
 * a render, so that a memory limit fails it then rather than after hours. */
size_t output_peak_bytes(int width, int height, bool is_partial);

/* The interval between a render's periodic writes (--preview-every, --checkpoint-every): the
 * asked_s seconds asked for, but at least 1 / OUTPUT_MAX_WRITE_SHARE times last_write_s, what
 * the last such write took (0: none yet), so that those writes take at most that share of the
 * time.  A tiny interval on a large film would otherwise spend much of it writing (a 1024 x
 * 1024 Cornell box at 16 spp: +44% wall time at --checkpoint-every 0.001). */
#define OUTPUT_MAX_WRITE_SHARE 0.1
double output_save_interval(double asked_s, double last_write_s);

/* One file a command reads or writes, and what it is, for messages ("the image (-o)"). */
struct output_file {
    char path[FILE_PATH_BYTES];
    const char *role; /* a static string */
};

/* The most files output_list names: image, preview, checkpoint, sample map, 2 per snapshot
 * (33 at most), contact sheet, curve CSV, JSON and SVG. */
#define OUTPUT_MAX_FILES 80

/* Lists into files (room for OUTPUT_MAX_FILES) every file a render named by p may write:
 * with curve_path the curve's three files, with snapshots those at 1, 2, 4, ... spp_final spp
 * and the contact sheet.  Returns the count; -1 with *err (bad input) when a name does not
 * fit. */
int output_list(const struct output_paths *p, const char *curve_path, bool snapshots,
                uint32_t spp_final, struct output_file *files, struct mcpt_error *err);

/* Checks, before any work, that the outputs can be written without harm: no output is the same
 * file as an input or as another output (file_id_same: device and inode where the file exists,
 * the normalised path otherwise), and each can be created (file_check_creatable).  Then removes
 * the temporaries dead writers left beside each output (file_remove_stale).  False with *err
 * (file = the output; bad input, or a runtime error for a full disk) on the first problem, e.g.
 * "expected the image (-o) to be a file of its own, got the scene file 'box.txt'". */
bool output_check(const struct output_file *outputs, int n_outputs,
                  const struct output_file *inputs, int n_inputs, struct mcpt_error *err);

/* Whether path's extension (after the last dot of its last component, not a leading one) is
 * ext, in any case: "png" for -o OUT.png, --heatmap and convert's OUT. */
bool output_has_extension(const char *path, const char *ext);

/* output_check in its two steps: the checks that touch nothing (the same-file rule, each
 * output a regular file or a new name in an existing folder: file_check_name), then the
 * creatability probes and the stale temporaries.  A caller with a check of its own to make
 * between them (a checkpoint in the way) calls both. */
bool output_check_names(const struct output_file *outputs, int n_outputs,
                        const struct output_file *inputs, int n_inputs, struct mcpt_error *err);
bool output_check_creatable(const struct output_file *outputs, int n_outputs,
                            struct mcpt_error *err);

#endif
