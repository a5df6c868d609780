/* cmd.h - the subcommands beside rendering: `mcpt compare` (error metrics of an image against a
 * reference), `mcpt integrate` (the sampler laboratory) and `mcpt merge` (partial renders into
 * one), and the command-line helpers main.c shares with them: strict number parsing, usage
 * errors, and the one place where an error becomes a printed line and an exit status.  Each
 * subcommand returns its exit status; none calls exit(). */
#ifndef MCPT_CMD_H
#define MCPT_CMD_H

#include "vec.h"

#define CMD_EXIT_OK 0      /* success */
#define CMD_EXIT_RUNTIME 1 /* runtime or I/O failure (MCPT_ERROR_RUNTIME) */
#define CMD_EXIT_INPUT 2   /* bad usage or bad input (MCPT_ERROR_INPUT) */

/* Whether name is a subcommand: "compare", "integrate" or "merge". */
bool cmd_is_subcommand(const char *name);

/* Runs the subcommand argv[0] with its arguments argv[1 .. argc-1] and returns its exit status
 * (0, or that of its error: cmd_fail).  argv[0] must be a subcommand (cmd_is_subcommand). */
int cmd_run(int argc, char **argv);

/* Prints err as one line on stderr, "file:line:col: error: msg" (mcpt_error_format), and
 * returns the exit status its kind names: 2 for bad input, 1 for a runtime failure. */
int cmd_fail(const struct mcpt_error *err);

/* Fills *err with a usage error, printed "mcpt: error: <msg> (see mcpt --help)" (bad input),
 * and returns false, so that a parser can `return cmd_usage_error(err, ...)`. */
bool cmd_usage_error(struct mcpt_error *err, const char *fmt, ...);

/* Strict parse of the whole string s as a decimal integer in [lo, hi] (no sign, no spaces);
 * false on anything else. */
bool cmd_parse_u64(const char *s, uint64_t lo, uint64_t hi, uint64_t *out);

/* Strict parse of the whole string s as a finite number in [lo, hi]; false on anything else. */
bool cmd_parse_float(const char *s, float lo, float hi, float *out);

#endif
