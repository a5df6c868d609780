#!/bin/sh
# gallery.sh - renders every scene of the gallery at its default spp and writes docs/gallery.md
# with the PNGs (docs/gallery/*.png) and each render's spp, size, wall time, CPU time and the
# machine's load.  Run by `make gallery`; POSIX sh plus coreutils.
#   GALLERY_THREADS  render threads (default 2: the scenes are sized for about a minute on 2
#                    cores)
#   GALLERY_SCENES   a space-separated subset of the names below (default: all)
#   MCPT             the binary (default ./mcpt)
# EXRs go to build/gallery/ (not committed); PNGs to docs/gallery/ (committed, at most 512 px).
set -eu
cd "$(dirname "$0")/.."

MCPT=${MCPT:-./mcpt}
THREADS=${GALLERY_THREADS:-2}
ALL="cornell-box cornell-spheres glass-balls sphere-refract glass-dragon bunny bunny-direct
bunny-indirect depth-of-field materials random-spheres"
SCENES=${GALLERY_SCENES:-$ALL}
OUT=build/gallery
mkdir -p "$OUT" docs/gallery

# name -> "scene file|extra options" (materials.txt's 640x360 film is scaled to 512 wide, so
# that every committed PNG is at most 512 pixels)
job() {
    case "$1" in
    bunny-direct) echo "scenes/bunny.txt|--split direct" ;;
    bunny-indirect) echo "scenes/bunny.txt|--split indirect" ;;
    materials) echo "scenes/materials.txt|--width 512 --height 288" ;;
    *) echo "scenes/$1.txt|" ;;
    esac
}

# A scene's opening comment up to "Render:", as one line, without "name.txt - ".
describe() {
    awk '!/^#/ { exit } { sub(/^# ?/, ""); text = text (text == "" ? "" : " ") $0 }
         END { sub(/ *Render:.*/, "", text); sub(/^[^ ]*\.txt - /, "", text);
               print toupper(substr(text, 1, 1)) substr(text, 2) }' "$1"
}

ROWS=$OUT/rows.md
IMAGES=$OUT/images.md
: >"$ROWS"
: >"$IMAGES"
for name in $SCENES; do
    spec=$(job "$name")
    scene=${spec%%|*}
    extra=${spec#*|}
    [ -f "$scene" ] || { echo "gallery: error: expected $scene, got no such file" >&2; exit 1; }
    load_before=$(cut -d' ' -f1 /proc/loadavg)
    t0=$(date +%s.%N)
    # a subshell, so that `times` reports this render's CPU time alone (its children's line)
    if ! (
        status=0
        # shellcheck disable=SC2086 # $extra is a list of options
        "$MCPT" "$scene" $extra --threads "$THREADS" -o "$OUT/$name.exr" >"$OUT/$name.log" \
            2>"$OUT/$name.err" || status=$?
        times >"$OUT/$name.times"
        exit "$status"
    ); then
        cat "$OUT/$name.err" >&2
        echo "gallery: error: mcpt $scene $extra failed" >&2
        exit 1
    fi
    cpu=$(awk 'NR == 2 { split($1, u, /[ms]/); split($2, s, /[ms]/);
                         printf "%.1f", u[1] * 60 + u[2] + s[1] * 60 + s[2] }' "$OUT/$name.times")
    t1=$(date +%s.%N)
    load_after=$(cut -d' ' -f1 /proc/loadavg)
    wall=$(echo "$t0 $t1" | awk '{ printf "%.1f", $2 - $1 }')
    # "mcpt: 512x512, 256 spp, 2 threads: render 14.87 s, ..."
    size=$(sed -n 's/^mcpt: \([0-9]*x[0-9]*\), .*/\1/p' "$OUT/$name.log")
    spp=$(sed -n 's/^mcpt: [0-9x]*, \([0-9]*\) spp.*/\1/p' "$OUT/$name.log")
    cp "$OUT/$name.png" "docs/gallery/$name.png"
    what=$(describe "$scene")
    cmd="mcpt $scene${extra:+ $extra}"
    echo "gallery: $name: $size, $spp spp, ${wall} s wall, ${cpu} s CPU," \
        "load $load_before -> $load_after"
    printf '| [%s](#%s) | %s | %s | %s | %s | %s -> %s |\n' "$name" "$name" "$size" "$spp" \
        "$wall" "$cpu" "$load_before" "$load_after" >>"$ROWS"
    {
        printf '### %s\n\n' "$name"
        printf '![%s](gallery/%s.png)\n\n' "$name" "$name"
        # shellcheck disable=SC2016 # the backquotes are Markdown
        printf '`%s`: %s, %s spp, %s s (%s s CPU).\n\n' "$cmd" "$size" "$spp" "$wall" "$cpu"
        [ -z "$what" ] || printf '%s\n\n' "$what"
    } >>"$IMAGES"
done

cpu_model=$(sed -n 's/^model name[[:space:]]*: //p' /proc/cpuinfo | head -n 1)
commit=$(git rev-parse --short HEAD 2>/dev/null || echo unknown)
{
    echo "# Gallery"
    echo
    echo "The gallery scenes of \`scenes/\`, rendered by \`make gallery\`"
    echo "(\`scripts/gallery.sh\`) at their default spp with $THREADS threads, on"
    echo "$(date -u +%Y-%m-%d) (commit $commit; $cpu_model, $(nproc) cores online)."
    echo "Regenerate with \`make gallery\`. \`GALLERY_THREADS=N\` sets the"
    echo "threads, and \`GALLERY_SCENES=\"bunny materials\"\` renders a subset. The other scenes"
    echo "(\`cornell-glass.txt\`, \`direct-plane.txt\`) are the measurement scenes of"
    echo "[sampling.md](sampling.md)."
    echo
    echo "*Wall* is the whole run: loading, the BVH build, rendering and writing the EXR and PNG."
    echo "*CPU* is user plus system time. On a machine shared with other work, wall time grows"
    echo "and CPU time stays about the same. With $THREADS threads on $THREADS otherwise idle"
    echo "cores, wall time is close to CPU / $THREADS. *Load* is the 1-minute load average"
    echo "before and after the render."
    echo
    echo "| Scene | Size | spp | Wall (s) | CPU (s) | Load |"
    echo "|---|---|---|---|---|---|"
    cat "$ROWS"
    echo
    echo "The bunny appears three times: the full image, then \`--split direct\` (emission and"
    echo "light that has bounced once) and \`--split indirect\` (two or more bounces). Added"
    echo "together, the last two give the first, sample by sample."
    echo
    cat "$IMAGES"
} >docs/gallery.md.tmp
mv docs/gallery.md.tmp docs/gallery.md
echo "gallery: wrote docs/gallery.md and docs/gallery/*.png"
