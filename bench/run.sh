#!/usr/bin/env bash
# The performance check of docs/PERFORMANCE.md:
#   1. builds the release binary and the generator example;
#   2. generates a project (default 100 000 flat steps) into a temporary folder;
#   3. runs `/usr/bin/time -v ./target/release/skillpost <blackboard> out` RUNS times (the
#      outputs, a long program's parts too, are deleted before each run, so every run writes
#      them; then `sync` and REST seconds: ext4 passes over inodes freed in the last 5-10 s when
#      it makes a file, so the 145 files of a run right after another one's deletion take up to
#      twice as long to create) and reports each run's wall time and maximum resident set
#      size, their median wall time and the largest RSS;
#   4. runs `cargo bench --bench compile` (the in-process tables).
#
# Environment: STEPS (default 100000), RUNS (default 5), REST (default 12), GEN_ARGS (extra generator arguments,
# e.g. "--branch-every 50 --branch-width 3"), BENCH=0 to skip step 4, BENCH_ARGS (case filter
# for the bench, e.g. "100k").
set -euo pipefail
cd "$(dirname "$0")/.."

STEPS=${STEPS:-100000}
RUNS=${RUNS:-5}
REST=${REST:-12}
GEN_ARGS=${GEN_ARGS:-}
BENCH=${BENCH:-1}
BENCH_ARGS=${BENCH_ARGS:-}

if [ ! -x /usr/bin/time ]; then
    echo "run.sh: /usr/bin/time is missing (Debian: apt-get install time)" >&2
    exit 2
fi

work=$(mktemp -d "${TMPDIR:-/tmp}/skillpost-run.XXXXXX")
trap 'rm -rf "$work"' EXIT

echo "== machine: $(nproc) cores, $(lscpu 2>/dev/null | sed -n 's/^Model name: *//p' | head -1), $(date -u +%Y-%m-%d)"
cargo build --release --quiet --bin skillpost --example generate

# shellcheck disable=SC2086 # GEN_ARGS is split on purpose
./target/release/examples/generate --steps "$STEPS" $GEN_ARGS --out "$work/p"
sfc_bytes=$(stat -c %s "$work/p/sfc.xml")

walls=()
max_rss=0
for i in $(seq 1 "$RUNS"); do
    find "$work/p" -maxdepth 1 -type f -name 'out*' -delete
    sync
    sleep "$REST"
    /usr/bin/time -v -o "$work/time.txt" \
        ./target/release/skillpost "$work/p/Blackboard.aml" out >/dev/null 2>"$work/stderr.txt" || {
        echo "run.sh: skillpost failed:" >&2
        cat "$work/stderr.txt" "$work/time.txt" >&2
        exit 1
    }
    # "Elapsed (wall clock) time (h:mm:ss or m:ss): 0:03.22" -> seconds
    wall=$(sed -n 's/.*Elapsed (wall clock) time.*): //p' "$work/time.txt" |
        awk -F: '{ s = 0; for (k = 1; k <= NF; k++) s = s * 60 + $k; printf "%.2f", s }')
    rss=$(sed -n 's/.*Maximum resident set size (kbytes): //p' "$work/time.txt")
    printf 'run %d: %s s, max RSS %d MiB\n' "$i" "$wall" $((rss / 1024))
    walls+=("$wall")
    if [ "$rss" -gt "$max_rss" ]; then max_rss=$rss; fi
done
median=$(printf '%s\n' "${walls[@]}" | sort -n |
    awk '{ v[NR] = $1 } END { if (NR % 2) print v[(NR + 1) / 2]; else printf "%.2f\n", (v[NR / 2] + v[NR / 2 + 1]) / 2 }')
printf '\n| steps | SFC MB | runs | median wall s | max RSS MiB |\n|---:|---:|---:|---:|---:|\n'
printf '| %d | %.1f | %d | %s | %d |\n\n' "$STEPS" "$(echo "$sfc_bytes" | awk '{ print $1 / 1e6 }')" \
    "$RUNS" "$median" $((max_rss / 1024))

if [ "$BENCH" != 0 ]; then
    # shellcheck disable=SC2086
    cargo bench --bench compile -- $BENCH_ARGS
fi
