#!/usr/bin/env bash
# Instruction counts (valgrind --tool=callgrind) of one CLI compile per input dimension at 1x, 4x
# and 16x of a base size (issue 13). Counts do not depend on machine load. Prints a markdown table;
# the ratio columns are the 4x and 16x counts over the 1x count: about 4 and 16 mean linear (less
# when the fixed start-up, ~4 M instructions, weighs in). "slope" compares the cost per unit from
# 4x to 16x with that from 1x to 4x, which cancels the fixed part: 1.0 = linear, 4 = quadratic.
#
#   bench/scaling.sh                      # every dimension, base sizes below
#   DIMS="vars skills" bench/scaling.sh   # some
#   SCALE=4 bench/scaling.sh              # every base size times 4
#   BIN=/path/to/skillpost bench/scaling.sh
#   BUILD=0 bench/scaling.sh              # use the release binaries as they are
set -euo pipefail
cd "$(dirname "$0")/.."
[ "${BUILD:-1}" = 0 ] || cargo build --release --quiet --bin skillpost --example generate
BIN=${BIN:-$PWD/target/release/skillpost}
GEN=$PWD/target/release/examples/generate
SCALE=${SCALE:-1}
# Base size (1x) per dimension: big enough that the start-up does not hide the growth.
declare -A BASE=(
  [steps]=1000 [vars]=2000 [skills]=250 [resources]=1000 [functions]=250 [irl]=250 [files]=250 [chain]=250 [unused]=250
  [signals]=1000 [cond]=20 [width]=250 [depth]=8 [loops]=250 [nest]=2000
  [loopnest]=8 [markup]=2000 [jumps]=150 [overlap]=150
)
DIMS=${DIMS:-"steps vars skills resources functions irl files chain unused signals cond width depth loops nest loopnest markup jumps overlap"}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
count() { # dim n -> instructions
  local dir="$work/$1-$2"
  "$GEN" --shape "$1" --steps "$2" --out "$dir" >/dev/null
  (cd "$dir" && valgrind --tool=callgrind --callgrind-out-file=/dev/null \
    "$BIN" Blackboard.aml out 2>&1 >/dev/null | sed -n 's/.*Collected : *\([0-9]*\).*/\1/p')
  rm -rf "$dir"
}
echo "date $(date -u +%FT%TZ), commit $(git rev-parse --short HEAD)$(git diff --quiet || echo '+dirty')"
echo
echo "| dimension | 1x n | 1x instr (M) | 4x instr (M) | 16x instr (M) | 4x / 1x | 16x / 1x | slope |"
echo "|---|---:|---:|---:|---:|---:|---:|---:|"
for d in $DIMS; do
  n=$(( ${BASE[$d]} * SCALE ))
  n16=$(( n * 16 ))
  case $d in depth | loopnest) [ "$n16" -gt 127 ] && n16=127 ;; esac
  a=$(count "$d" "$n"); b=$(count "$d" $(( n * 4 ))); c=$(count "$d" "$n16")
  awk -v d="$d" -v n="$n" -v a="$a" -v b="$b" -v c="$c" -v n16="$n16" 'BEGIN {
    note = (n16 != n * 16) ? sprintf(" (16x: n = %d)", n16) : "";
    slope = ((c - b) / (n16 - 4 * n)) / ((b - a) / (3 * n));
    printf "| %s%s | %d | %.1f | %.1f | %.1f | %.2f | %.2f | %.2f |\n", d, note, n, a/1e6, b/1e6, c/1e6, b/a, c/a, slope }'
done
