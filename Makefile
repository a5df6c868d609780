# mcpt - a plain Makefile.  `make` builds ./mcpt; `make test` builds and runs the test suite;
# `make check-sanitize` runs it under ASan + UBSan.  PORTABLE=1 builds without -march=native;
# WERROR=1 turns warnings into errors (CI).  Objects go to build/ (build-san/ for sanitizers).

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

OPT_FLAGS ?= -O3 $(ARCH_FLAGS)
WARN_FLAGS := -Wall -Wextra -Wpedantic
ifeq ($(WERROR),1)
WARN_FLAGS += -Werror
endif
CFLAGS_ALL = -std=c11 -D_DEFAULT_SOURCE -g $(OPT_FLAGS) $(WARN_FLAGS) -I. $(EXR_CFLAGS) \
             $(PNG_CFLAGS) -MMD -MP $(EXTRA_CFLAGS)
LDLIBS_ALL = $(EXR_LIBS) $(PNG_LIBS) -lpthread -lm

BUILD ?= build
LIB_SRCS := $(filter-out main.c,$(wildcard *.c))
TEST_SRCS := $(wildcard tests/*_test.c)
LIB_OBJS := $(LIB_SRCS:%.c=$(BUILD)/%.o)
TEST_OBJS := $(TEST_SRCS:%.c=$(BUILD)/%.o)

.PHONY: all test check-sanitize clean
all: mcpt

mcpt: $(BUILD)/main.o $(LIB_OBJS)
	$(CC) $(CFLAGS_ALL) -o $@ $^ $(LDLIBS_ALL)

$(BUILD)/mcpt: $(BUILD)/main.o $(LIB_OBJS)
	$(CC) $(CFLAGS_ALL) -o $@ $^ $(LDLIBS_ALL)

$(BUILD)/%.o: %.c
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS_ALL) -c $< -o $@

$(BUILD)/tests/run_tests: $(TEST_OBJS) $(LIB_OBJS)
	$(CC) $(CFLAGS_ALL) -o $@ $^ -lcriterion $(LDLIBS_ALL)

# The suite runs from the repo root (tests read tests/data/ and scenes/); it also runs ./mcpt.
test: mcpt $(BUILD)/tests/run_tests
	MCPT=./mcpt ./$(BUILD)/tests/run_tests $(TEST_ARGS)

check-sanitize:
	$(MAKE) BUILD=build-san OPT_FLAGS="-O1 -fno-omit-frame-pointer" \
	    EXTRA_CFLAGS="-fsanitize=address,undefined -fno-sanitize-recover=undefined" \
	    build-san/tests/run_tests build-san/mcpt
	ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 \
	    MCPT=./build-san/mcpt ./build-san/tests/run_tests $(TEST_ARGS)

clean:
	rm -rf build build-san mcpt

-include $(wildcard $(BUILD)/*.d $(BUILD)/tests/*.d)
