#!/bin/sh
# fuzz/run.sh SECONDS [BUILD] - runs each libFuzzer harness (fuzz_scene, fuzz_obj) for SECONDS
# seconds from the repo root, seeded with scenes/, tests/data/, tests/extremes/ and the bad
# corpus tests/bad/.
# New inputs accumulate in BUILD/corpus-*/ between runs.  Prints each harness's final line
# (executions "#N", coverage "cov:", features "ft:", corpus size) and fails when a harness
# found a crash, leak or hang: the input is BUILD/crash-*; turn it into a tests/bad/ case.
set -eu
secs=${1:-60}
B=${2:-build-fuzz}
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

mkdir -p "$B/seeds-scene" "$B/seeds-obj" "$B/corpus-scene" "$B/corpus-obj"
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

for h in scene obj; do
    log="$B/fuzz_$h.log"
    echo "fuzz_$h: $secs s"
    rc=0
    "$B/fuzz_$h" -max_total_time="$secs" -timeout=10 -rss_limit_mb=2048 \
        -dict="fuzz/$h.dict" -artifact_prefix="$B/crash-$h-" -print_final_stats=1 \
        "$B/corpus-$h" "$B/seeds-$h" >"$log" 2>&1 || rc=$?
    grep -E '^#[0-9]+[[:space:]]+(INITED|DONE)' "$log" | tail -n 2
    grep -E '^stat::number_of_executed_units' "$log" || true
    if [ "$rc" -ne 0 ]; then
        echo "fuzz_$h: FAILED (exit $rc); see $log:"
        grep -E 'ERROR|SUMMARY|Test unit written' "$log" || tail -n 20 "$log"
        status=1
    fi
done
exit $status
