#!/usr/bin/env bash
# Where one CLI compile's instructions go (valgrind --tool=callgrind, inclusive counts), split the
# way the threads split the work (issue 13): the SFC's producer thread (`read::tape` Producer::fill:
# reading the file, quick-xml, the records), the reader building the model from the records
# (`read::sfc` Stream::run, on the calling thread), and what comes after the reading (plan, bind,
# emit: the compile less the reader). The reading takes as long as its longer half, so the
# producer and reader columns are the ones to balance. Counts do not depend on machine load
# (wall times on the shared VM moved by 1.7x within an hour). Prints a markdown table row.
#
#   bench/split.sh                  # 10,000 flat steps
#   STEPS=2000 bench/split.sh
#   BIN=/path/to/skillpost bench/split.sh   # another build, for a before/after pair
#   BUILD=0 bench/split.sh          # use the release binaries as they are
set -euo pipefail
cd "$(dirname "$0")/.."
[ "${BUILD:-1}" = 0 ] || cargo build --release --quiet --bin skillpost --example generate
BIN=${BIN:-$PWD/target/release/skillpost}
STEPS=${STEPS:-10000}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
./target/release/examples/generate --steps "$STEPS" --out "$work/p" >/dev/null
(cd "$work/p" && valgrind --tool=callgrind --callgrind-out-file="$work/cg" \
  "$BIN" Blackboard.aml out >/dev/null 2>&1)
# Inclusive count of the first function whose name matches $1, in millions (awk reads to the
# end: an early exit would fail the pipe).
incl() {
  callgrind_annotate --inclusive=yes "$work/cg" 2>/dev/null |
    awk -v f="$1" '!done && index($0, f) && $1 ~ /^[0-9,]+$/ { gsub(",", "", $1); printf "%.1f", $1 / 1e6; done = 1 }'
}
total=$(callgrind_annotate "$work/cg" 2>/dev/null |
  awk '!done && /PROGRAM TOTALS/ { gsub(",", "", $1); printf "%.1f", $1 / 1e6; done = 1 }')
producer=$(incl "read::tape::Producer<R>::fill [")
reader=$(incl "read::sfc::Stream::run [")
compile=$(incl "compile::compile [")
after=$(awk -v c="$compile" -v r="$reader" 'BEGIN { printf "%.1f", c - r }')
echo "date $(date -u +%FT%TZ), commit $(git rev-parse --short HEAD)$(git diff --quiet || echo '+dirty'), $STEPS flat steps"
echo
echo "| total (M) | producer thread (M) | reader (M) | compile on the calling thread, less the reader (M) |"
echo "|---:|---:|---:|---:|"
echo "| $total | $producer | $reader | $after |"
