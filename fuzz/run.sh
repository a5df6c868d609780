#!/bin/sh
# fuzz/run.sh SECONDS [BUILD [HARNESS...]] - runs each libFuzzer harness (fuzz_scene, fuzz_obj,
# fuzz_checkpoint, fuzz_partial; or those named) for SECONDS seconds from the repo root, seeded
# with scenes/, tests/data/, tests/extremes/ and the bad corpus tests/bad/.
# FUZZ_RUNS=N runs each for N executions instead (-runs=N; SECONDS then bounds the time).
# FUZZ_TIMEOUT=S: an input running longer than S seconds of wall time is a hang (default 10;
# raise it on a loaded machine, where the seed scenes with the big models take longer).
# FUZZ_FLAGS: more libFuzzer flags for every harness run (the 10-million runs of
# docs/reliability.md: FUZZ_FLAGS=-fork=2 for scene, FUZZ_FLAGS=-max_len=65536 for obj).
# New inputs accumulate in BUILD/corpus-*/ between runs.  Prints each harness's final line
# (executions "#N", coverage "cov:", features "ft:", corpus size) and fails when a harness
# found a crash, leak or hang: the input is BUILD/crash-*; turn it into a tests/bad/ case.
set -eu
secs=${1:-60}
B=${2:-build-fuzz}
[ $# -ge 2 ] && shift 2 || shift $#
harnesses=${*:-scene obj checkpoint partial}
runs=${FUZZ_RUNS:--1}
timeout=${FUZZ_TIMEOUT:-10}
flags=${FUZZ_FLAGS:-}
status=0

# seed_copy DEST FILE...: copies each file under a name made from its path (names repeat)
seed_copy() {
    dest=$1
    shift
    for f in "$@"; do
        [ -f "$f" ] && cp "$f" "$dest/$(echo "$f" | tr '/' '_')"
    done
    return 0
}

for h in scene obj checkpoint partial; do
    mkdir -p "$B/seeds-$h" "$B/corpus-$h"
done
seed_copy "$B/seeds-scene" scenes/*.txt tests/data/scene/*.txt tests/data/cli/*.txt \
    tests/bad/scene/*.txt tests/bad/obj/*.txt tests/bad/mtl/*.txt tests/extremes/*.txt
seed_copy "$B/seeds-obj" scenes/models/*.obj tests/data/obj/*.obj tests/data/scene/*.obj \
    tests/bad/obj/*.obj tests/extremes/*.obj
# an OBJ with its MTL as one input: "mtllib NAME" becomes "mtllib a.mtl", the MTL follows #MTL
for obj in tests/bad/mtl/*.obj tests/data/obj/*.obj scenes/models/*.obj; do
    mtl=$(sed -n 's/^mtllib[ \t]*\([^ \t\r]*\).*/\1/p' "$obj" | head -n 1)
    [ -n "$mtl" ] && [ -f "$(dirname "$obj")/$mtl" ] || continue
    {
        sed 's/^mtllib.*/mtllib a.mtl/' "$obj"
        printf '\n#MTL\n'
        cat "$(dirname "$obj")/$mtl"
    } >"$B/seeds-obj/$(echo "$obj" | tr '/' '_').mtl"
done

# a checkpoint input is a control byte (odd: the harness reseals the checksum) and the file
for f in tests/bad/ckpt/*.ckpt; do
    for c in 0 1; do
        { printf "\\$c"; cat "$f"; } >"$B/seeds-checkpoint/$c-$(basename "$f")"
    done
done
seed_copy "$B/seeds-partial" tests/data/partial/*.exr tests/data/image/*.exr

for h in $harnesses; do
    log="$B/fuzz_$h.log"
    echo "fuzz_$h: $secs s"
    rc=0
    dict=""
    [ -f "fuzz/$h.dict" ] && dict="-dict=fuzz/$h.dict"
    "$B/fuzz_$h" -max_total_time="$secs" -runs="$runs" -timeout="$timeout" -rss_limit_mb=2048 $dict $flags \
        -artifact_prefix="$B/crash-$h-" -print_final_stats=1 \
        "$B/corpus-$h" "$B/seeds-$h" >"$log" 2>&1 || rc=$?
    grep -E '^#[0-9]+([[:space:]]+(INITED|DONE)|: cov:)|^INFO: fuzzed for' "$log" | tail -n 2
    grep -E '^stat::number_of_executed_units' "$log" || true
    if [ "$rc" -ne 0 ]; then
        echo "fuzz_$h: FAILED (exit $rc); see $log:"
        grep -E 'ERROR|SUMMARY|Test unit written' "$log" || tail -n 20 "$log"
        status=1
    fi
done
exit $status
