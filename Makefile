# mcpt - a plain Makefile.  `make` builds ./mcpt; `make test` builds and runs the test suite;
# `make check-sanitize` runs it under ASan + UBSan.  PORTABLE=1 builds without -march=native;
# WERROR=1 turns warnings into errors (CI).  Objects go to build/ (build-san/ for sanitizers).
# `make sobol-table` and `make ggx-table` regenerate the two checked-in tables.
# Each build folder keeps the compiler and flags it was built with in flags.stamp; every object
# depends on it, so changing CC, OPT_FLAGS, PORTABLE, WERROR or EXTRA_CFLAGS rebuilds all.

CC ?= cc
PKG_CONFIG ?= pkg-config

# OpenEXR's C API: only the OpenEXRCore library is linked, never the C++ ones.
EXR_CFLAGS := $(shell $(PKG_CONFIG) --cflags OpenEXR 2>/dev/null)
EXR_LIBS := $(filter -L% -lOpenEXRCore%,$(shell $(PKG_CONFIG) --libs OpenEXR 2>/dev/null))
PNG_CFLAGS := $(shell $(PKG_CONFIG) --cflags libpng 2>/dev/null)
PNG_LIBS := $(shell $(PKG_CONFIG) --libs libpng 2>/dev/null)

ifeq ($(PORTABLE),1)
ARCH_FLAGS :=
else
ARCH_FLAGS := -march=native
endif

# -flto=auto: link-time optimisation lets gcc inline across files (the shapes' tests into
# trace.c's closest_hit, the sampler's reads into the path loop); same pixels on every scene,
# and bench-render measured x1.02-1.10 (docs/performance.md, "Per-sample cost").
OPT_FLAGS ?= -O3 $(ARCH_FLAGS) -flto=auto
WARN_FLAGS := -Wall -Wextra -Wpedantic
ifeq ($(WERROR),1)
WARN_FLAGS += -Werror
endif
# -fno-math-errno: sqrt and friends set no errno (mcpt never reads it after libm), so gcc keeps
# them inline without a slow path for negative arguments; same pixels, the sphere scenes 2-3%
# faster (docs/performance.md, "Latency levers").
CFLAGS_ALL = -std=c11 -D_DEFAULT_SOURCE -g $(OPT_FLAGS) -fno-math-errno $(WARN_FLAGS) -I. \
             $(EXR_CFLAGS) $(PNG_CFLAGS) -MMD -MP $(EXTRA_CFLAGS)
LDLIBS_ALL = $(EXR_LIBS) $(PNG_LIBS) -lpthread -lm

BUILD ?= build
LIB_SRCS := $(filter-out main.c,$(wildcard *.c))
# tests/report.c: the list of skipped tests, with their reasons, at the end of the run
TEST_SRCS := $(wildcard tests/*_test.c) tests/report.c
LIB_OBJS := $(LIB_SRCS:%.c=$(BUILD)/%.o)
TEST_OBJS := $(TEST_SRCS:%.c=$(BUILD)/%.o)

.PHONY: all test check-sanitize check-valgrind fuzz clean sobol-table ggx-table gallery install \
        uninstall bench bench-embree bench-render bench-cycles bench-scaling
all: mcpt

# The flags stamp: $(BUILD)/flags.stamp holds the command objects were compiled with, and every
# object depends on it.  Where the file is missing or holds another command, the stamp depends
# on FORCE and is rewritten, so every object is out of date; otherwise it is an ordinary
# up-to-date file, and a second `make` (or `make -n`) does nothing.
# $(call stamp_deps,FILE,TEXT): FORCE unless FILE holds TEXT; $(call stamp_write,FILE,TEXT).
str_eq = $(and $(findstring $(1),$(2)),$(findstring $(2),$(1)))
stamp_deps = $(if $(call str_eq,$(file <$(1)),$(2)),,FORCE)
stamp_write = mkdir -p $(dir $(1)) && printf '%s\n' '$(subst ','\'',$(2))' > $(1)
FLAGS_NOW = $(CC) $(CFLAGS_ALL) $(LDLIBS_ALL)
FLAGS_STAMP := $(BUILD)/flags.stamp

$(FLAGS_STAMP): $(call stamp_deps,$(FLAGS_STAMP),$(FLAGS_NOW))
	@$(call stamp_write,$@,$(FLAGS_NOW))

FORCE:

# The link stamp: ./mcpt and bench/'s programs live outside the build folders, so
# build/link.stamp holds the folder and command they were last linked from; a `make` with
# another BUILD or other flags relinks them even where that folder's objects are older.
LINK_STAMP := build/link.stamp
LINK_NOW = $(BUILD) $(FLAGS_NOW)

$(LINK_STAMP): $(call stamp_deps,$(LINK_STAMP),$(LINK_NOW))
	@$(call stamp_write,$@,$(LINK_NOW))

mcpt: $(BUILD)/main.o $(LIB_OBJS) $(LINK_STAMP)
	$(CC) $(CFLAGS_ALL) -o $@ $(filter %.o,$^) $(LDLIBS_ALL)

$(BUILD)/mcpt: $(BUILD)/main.o $(LIB_OBJS)
	$(CC) $(CFLAGS_ALL) -o $@ $^ $(LDLIBS_ALL)

$(BUILD)/%.o: %.c $(FLAGS_STAMP)
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS_ALL) -c $< -o $@

# Link-time optimisation discards the section entries by which Criterion finds report.c's hooks
# (ReportHook: nothing references them), so that file is compiled without it.
$(BUILD)/tests/report.o: tests/report.c $(FLAGS_STAMP)
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS_ALL) -fno-lto -c $< -o $@

$(BUILD)/tests/run_tests: $(TEST_OBJS) $(LIB_OBJS)
	$(CC) $(CFLAGS_ALL) -o $@ $^ -lcriterion $(LDLIBS_ALL)

# The suite runs from the repo root (tests read tests/data/ and scenes/); it also runs ./mcpt.
test: mcpt $(BUILD)/tests/run_tests
	MCPT=./mcpt ./$(BUILD)/tests/run_tests $(TEST_ARGS)

check-sanitize:
	$(MAKE) BUILD=build-san OPT_FLAGS="-O1 -fno-omit-frame-pointer" \
	    EXTRA_CFLAGS="-fsanitize=address,undefined -fno-sanitize-recover=undefined -DTEST_TIMEOUT_SCALE=10" \
	    build-san/tests/run_tests build-san/mcpt
	ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 \
	    LSAN_OPTIONS=suppressions=$(CURDIR)/tests/lsan.supp \
	    MCPT=./build-san/mcpt ./build-san/tests/run_tests $(TEST_ARGS)

# valgrind (memcheck) on three small end-to-end renders (analytic shapes and sky; the OBJ/MTL
# Cornell box; the Cornell box by the adaptive budget rule): any error or leak fails.  Built without
# -march=native into build-vg/, since valgrind does not decode every AVX-512 instruction.
check-valgrind:
	$(MAKE) BUILD=build-vg OPT_FLAGS="-O2" build-vg/mcpt
	for s in tests/data/resume/small.txt scenes/cornell-box.txt; do \
	    valgrind -q --error-exitcode=1 --leak-check=full \
	        --errors-for-leak-kinds=definite,indirect ./build-vg/mcpt $$s --spp 4 --width 32 \
	        --height 24 --threads 2 --quiet -o build-vg/valgrind.exr || exit 1; \
	done
	valgrind -q --error-exitcode=1 --leak-check=full --errors-for-leak-kinds=definite,indirect \
	    ./build-vg/mcpt scenes/cornell-box.txt --spp 16 --adaptive --adaptive-rule budget \
	    --width 32 --height 24 --threads 2 --quiet -o build-vg/valgrind.exr
	@echo "valgrind: no errors, no leaks"

# Fuzzing with libFuzzer (clang): `make fuzz FUZZ_SECONDS=N` runs each harness in fuzz/ for N
# seconds (fuzz/run.sh); every module is built with ASan + UBSan into build-fuzz/.
FUZZ_CC ?= clang
FUZZ_SECONDS ?= 60
FUZZ_BUILD := build-fuzz
FUZZ_CFLAGS = -std=c11 -D_DEFAULT_SOURCE -g -O1 -fno-omit-frame-pointer -I. $(EXR_CFLAGS) \
              $(PNG_CFLAGS) -fsanitize=address,undefined -fno-sanitize-recover=undefined -MMD -MP
FUZZ_LIB_OBJS := $(LIB_SRCS:%.c=$(FUZZ_BUILD)/%.o)
FUZZ_STAMP := $(FUZZ_BUILD)/flags.stamp

FUZZ_FLAGS_NOW = $(FUZZ_CC) $(FUZZ_CFLAGS)

$(FUZZ_STAMP): $(call stamp_deps,$(FUZZ_STAMP),$(FUZZ_FLAGS_NOW))
	@$(call stamp_write,$@,$(FUZZ_FLAGS_NOW))

$(FUZZ_BUILD)/%.o: %.c $(FUZZ_STAMP)
	@mkdir -p $(dir $@)
	$(FUZZ_CC) $(FUZZ_CFLAGS) -fsanitize=fuzzer-no-link -c $< -o $@

$(FUZZ_BUILD)/fuzz_%: fuzz/fuzz_%.c $(FUZZ_LIB_OBJS) $(FUZZ_STAMP)
	$(FUZZ_CC) $(FUZZ_CFLAGS) -fsanitize=fuzzer -o $@ $(filter %.c %.o,$^) $(LDLIBS_ALL)

# the objects are kept between builds (a pattern rule's prerequisites are otherwise removed)
.SECONDARY: $(FUZZ_LIB_OBJS)
FUZZ_HARNESSES := scene obj checkpoint partial
fuzz: $(FUZZ_HARNESSES:%=$(FUZZ_BUILD)/fuzz_%)
	fuzz/run.sh $(FUZZ_SECONDS) $(FUZZ_BUILD) $(FUZZ_HARNESSES)

# Regenerates the checked-in sobol_matrices.h from Joe & Kuo's direction numbers (only when the
# table should change; mcpt never reads the direction file).
SOBOL_DIRECTIONS ?= ../shared/data/new-joe-kuo-6.21201
sobol-table:
	python3 scripts/gen_sobol_table.py $(SOBOL_DIRECTIONS) 16 > sobol_matrices.h.tmp
	mv sobol_matrices.h.tmp sobol_matrices.h

# Regenerates the checked-in material_ggx_table.inc, the GGX coat albedo table of material.c,
# with tests/data/trace/ggx_albedo_gen.c (nested adaptive Simpson over material.c's own VNDF
# warp, G1 and G2; takes minutes).  Only when those functions change.  Fixed flags, not
# OPT_FLAGS: the generated file must not depend on the machine that ran it.
GGX_GEN_CFLAGS = -std=c11 -D_DEFAULT_SOURCE -O2 -I.
ggx-table:
	@mkdir -p $(BUILD)
	$(CC) $(GGX_GEN_CFLAGS) -o $(BUILD)/ggx_albedo_gen tests/data/trace/ggx_albedo_gen.c \
	    material.c sample.c -lm
	./$(BUILD)/ggx_albedo_gen > material_ggx_table.inc.tmp
	mv material_ggx_table.inc.tmp material_ggx_table.inc

# The gallery: renders every scene at its default spp (GALLERY_THREADS threads, default 2) and
# writes docs/gallery.md with docs/gallery/*.png and each render's time (scripts/gallery.sh).
GALLERY_THREADS ?= 2
gallery: mcpt
	MCPT=./mcpt GALLERY_THREADS=$(GALLERY_THREADS) GALLERY_SCENES="$(GALLERY_SCENES)" \
	    scripts/gallery.sh

# `make install PREFIX=/opt/mcpt` (DESTDIR for staged installs): the binary to PREFIX/bin, the
# man page to PREFIX/share/man/man1 (its FILES section rewritten to PREFIX), the README and
# docs (with their pictures) to PREFIX/share/doc/mcpt, and the example scenes with their
# models to PREFIX/share/mcpt/scenes, where they render as they do here:
#   mcpt PREFIX/share/mcpt/scenes/cornell-box.txt
# `make uninstall` (same PREFIX and DESTDIR) removes all of it.  INSTALL_BIN names another
# binary to install (the test of this target passes the one it tests, without building).
PREFIX ?= /usr/local
DOCDIR = $(PREFIX)/share/doc/mcpt
SCENEDIR = $(PREFIX)/share/mcpt/scenes
INSTALL_BIN ?= mcpt
install: $(INSTALL_BIN)
	install -d $(DESTDIR)$(PREFIX)/bin $(DESTDIR)$(PREFIX)/share/man/man1 \
	    $(DESTDIR)$(DOCDIR)/gallery $(DESTDIR)$(DOCDIR)/convergence $(DESTDIR)$(SCENEDIR)/models
	install -m 755 $(INSTALL_BIN) $(DESTDIR)$(PREFIX)/bin/mcpt
	sed 's|/usr/local/|$(PREFIX)/|g' docs/mcpt.1 > $(DESTDIR)$(PREFIX)/share/man/man1/mcpt.1
	chmod 644 $(DESTDIR)$(PREFIX)/share/man/man1/mcpt.1
	install -m 644 README.md docs/*.md $(DESTDIR)$(DOCDIR)
	install -m 644 docs/gallery/* $(DESTDIR)$(DOCDIR)/gallery
	install -m 644 docs/convergence/* $(DESTDIR)$(DOCDIR)/convergence
	install -m 644 scenes/*.txt $(DESTDIR)$(SCENEDIR)
	install -m 644 scenes/models/* $(DESTDIR)$(SCENEDIR)/models

uninstall:
	rm -f $(DESTDIR)$(PREFIX)/bin/mcpt $(DESTDIR)$(PREFIX)/share/man/man1/mcpt.1
	rm -rf $(DESTDIR)$(DOCDIR) $(DESTDIR)$(SCENEDIR)
	-rmdir $(DESTDIR)$(PREFIX)/share/mcpt 2>/dev/null

# Ray-throughput benchmark (issue 3, docs/bvh.md): bench/raybench builds the BVH of each model
# and traces the standard ray sets of ../shared/BENCHMARKS.md, written once into $(BUILD)/bench/
# (delete that folder to regenerate them).  `make bench-embree` traces the same files through
# Embree 3 in the same invocation and prints mcpt/Embree ratios; it is built only where Embree
# is installed (Debian: libembree-dev), and nothing else depends on Embree.
BENCH_MODELS_DIR ?= ../shared/models
BENCH_MODELS ?= stanford-bunny stanford-dragon-100k sponza-dabrovic lucy-100k
BENCH_RUNS ?= 5
BENCH_DIR := $(BUILD)/bench
BENCH_OBJS := $(BUILD)/bvh.o $(BUILD)/bvh_wide.o $(BUILD)/obj.o $(BUILD)/camera.o $(BUILD)/sample.o \
    $(BUILD)/file.o
BENCH_RAYS := $(foreach m,$(BENCH_MODELS),$(BENCH_DIR)/$(m)-primary.bin)
EMBREE_FOUND := $(shell $(PKG_CONFIG) --exists embree3 2>/dev/null && echo yes || \
                  { test -f /usr/include/embree3/rtcore.h && echo yes; })
EMBREE_CFLAGS := $(shell $(PKG_CONFIG) --cflags embree3 2>/dev/null)
EMBREE_LIBS := $(shell $(PKG_CONFIG) --libs embree3 2>/dev/null || echo -lembree3)
BENCH_CFLAGS = $(filter-out -MMD -MP,$(CFLAGS_ALL))

bench/raybench: bench/raybench.c bench/bench.c bench/bench.h $(BENCH_OBJS) $(FLAGS_STAMP) $(LINK_STAMP)
	$(CC) $(BENCH_CFLAGS) -o $@ bench/raybench.c bench/bench.c $(BENCH_OBJS) -lpthread -lm

# bench/raydump: the rays of a render as ray files for raybench (links the renderer)
bench/raydump: bench/raydump.c bench/bench.c bench/bench.h bench/bench_scene.c bench/bench_scene.h $(LIB_OBJS) $(FLAGS_STAMP) $(LINK_STAMP)
	$(CC) $(BENCH_CFLAGS) -o $@ bench/raydump.c bench/bench.c bench/bench_scene.c $(LIB_OBJS) $(LDLIBS_ALL)

# bench/packetbench: a render with camera packets against one with single camera rays
bench/packetbench: bench/packetbench.c bench/bench.c bench/bench.h bench/bench_scene.c bench/bench_scene.h $(LIB_OBJS) $(FLAGS_STAMP) $(LINK_STAMP)
	$(CC) $(BENCH_CFLAGS) -o $@ bench/packetbench.c bench/bench.c bench/bench_scene.c $(LIB_OBJS) $(LDLIBS_ALL)

bench/embree_bench: bench/embree_bench.c bench/bench.c bench/bench.h $(BENCH_OBJS) $(FLAGS_STAMP) $(LINK_STAMP)
	$(CC) $(BENCH_CFLAGS) $(EMBREE_CFLAGS) -o $@ bench/embree_bench.c bench/bench.c $(BENCH_OBJS) \
	    $(EMBREE_LIBS) -lpthread -lm

# one raybench call writes all three sets of a model
$(BENCH_DIR)/%-primary.bin: $(BENCH_MODELS_DIR)/%.obj | bench/raybench
	@mkdir -p $(BENCH_DIR)
	./bench/raybench $< --gen all -o $(BENCH_DIR)/$*

bench: bench/raybench $(BENCH_RAYS)
	@for m in $(BENCH_MODELS); do \
	    ./bench/raybench $(BENCH_MODELS_DIR)/$$m.obj $(BENCH_DIR)/$$m-primary.bin \
	        $(BENCH_DIR)/$$m-diffuse.bin $(BENCH_DIR)/$$m-shadow.bin --runs $(BENCH_RUNS) \
	        --packets || exit 1; \
	done

ifeq ($(EMBREE_FOUND),yes)
bench-embree: bench/embree_bench $(BENCH_RAYS)
	@for m in $(BENCH_MODELS); do \
	    ./bench/embree_bench $(BENCH_MODELS_DIR)/$$m.obj $(BENCH_DIR)/$$m-primary.bin \
	        $(BENCH_DIR)/$$m-diffuse.bin $(BENCH_DIR)/$$m-shadow.bin --runs $(BENCH_RUNS) || exit 1; \
	done
else
bench-embree:
	@echo "bench-embree: Embree 3 not found (Debian: apt-get install libembree-dev); skipped"
endif

# `make bench-render` (scripts/bench_render.py): per scene (cornell-box, bunny, glass-balls at
# reduced size) Msamples/s, Mrays/s, MSE against bench/ref/SCENE.exr, efficiency, and the
# render's rays/s as a fraction of raybench's on the scene's own rays (bench/raydump), for this
# tree's mcpt and for a baseline built from commit BENCH_BASE (default: where issue 13 began;
# empty: no baseline), interleaved over BENCH_RENDER_RUNS rounds.
BENCH_BASE ?= 1ca94b3
BENCH_RENDER_RUNS ?= 5
BENCH_THREADS ?= 1
BENCH_BASE_DIR := $(BUILD)/bench-base/$(BENCH_BASE)
bench-render: mcpt bench/raybench bench/raydump bench/packetbench $(if $(BENCH_BASE),$(BENCH_BASE_DIR)/mcpt)
	python3 scripts/bench_render.py --mcpt ./mcpt --runs $(BENCH_RENDER_RUNS) \
	    --threads $(BENCH_THREADS) $(if $(BENCH_BASE),--base $(BENCH_BASE_DIR)/mcpt)

# `make bench-scaling` (scripts/bench_scaling.py): the render (cornell-box, bunny at 256 pixels
# wide; whole process and render alone, beside a control of as many independent one-thread
# renders) and the BVH build (raybench --build-only: Lucy, Sponza, torus:1M) at 1, 2, 4, ...
# threads up to the CPUs; medians over BENCH_SCALING_RUNS interleaved rounds.  Meant for a
# many-core machine (docs/performance.md, "Thread scaling").
BENCH_SCALING_RUNS ?= 3
bench-scaling: mcpt bench/raybench
	python3 scripts/bench_scaling.py --mcpt ./mcpt --raybench bench/raybench \
	    --runs $(BENCH_SCALING_RUNS)

# the baseline: `git archive` of BENCH_BASE, built in its own folder with its own Makefile
$(BUILD)/bench-base/%/mcpt:
	rm -rf $(BUILD)/bench-base/$*
	mkdir -p $(BUILD)/bench-base/$*
	git archive $* | tar -x -C $(BUILD)/bench-base/$*
	$(MAKE) -C $(BUILD)/bench-base/$* mcpt

# `make bench-cycles` (scripts/bench_cycles.py): the equal-error time ratio mcpt/Cycles on the
# Cornell box at 256x256, both renderers in the same run, mcpt uniform and with the adaptive
# budget rule.  Only where Blender is installed; nothing depends on it.  CYCLES_REF: the
# 16384-spp Cycles reference, made on first use.
BLENDER ?= blender
CYCLES_REF ?= bench/ref/cornell256-cycles16384.exr
BENCH_CYCLES_RUNS ?= 3
BLENDER_FOUND := $(shell command -v $(BLENDER) 2>/dev/null)
ifneq ($(BLENDER_FOUND),)
bench-cycles: mcpt
	python3 scripts/bench_cycles.py --mcpt ./mcpt --blender $(BLENDER) --ref $(CYCLES_REF) \
	    --runs $(BENCH_CYCLES_RUNS)
else
bench-cycles:
	@echo "bench-cycles: Blender not found (Debian: apt-get install blender); skipped"
endif

clean:
	rm -rf build build-san build-fuzz build-vg mcpt bench/raybench bench/embree_bench bench/raydump \
	    bench/packetbench

-include $(wildcard $(BUILD)/*.d $(BUILD)/tests/*.d $(FUZZ_BUILD)/*.d)
