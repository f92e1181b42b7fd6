#!/usr/bin/env bash
# The guard of the compile's cost that CI runs (.ci/run): the instructions of one CLI compile of
# the 10,000-step flat project (`examples/generate`), whole process, against those of a bare
# quick-xml pass over the same SFC in memory (`examples/floor`), both counted by
# `valgrind --tool=callgrind` in the same job. Instruction counts do not depend on the machine's
# load (wall times on a shared 2-core machine move by 1.7x within minutes) and repeat to 0.2 %,
# so a change that makes the compile dearer fails here when it lands, not a week later in a
# benchmark. Exits 1 when compile / floor is above LIMIT.
#
#   bench/guard.sh                  # builds the release binaries, then counts (~30 s after the build)
#   BUILD=0 bench/guard.sh          # the release binaries as they are
#   LIMIT=1.9 bench/guard.sh        # another limit
#
# LIMIT is the ratio measured when it was last set plus about 3 % (docs/PERFORMANCE.md,
# "The guard"); lower it when a change brings the ratio down, so that the room it gives is not
# spent unnoticed. Raising it needs the reason in the commit message.
set -euo pipefail
cd "$(dirname "$0")/.."
LIMIT=${LIMIT:-1.75}
STEPS=${STEPS:-10000}
if ! command -v valgrind >/dev/null 2>&1; then
  if [ "${SKILLPOST_STRICT_TESTS:-0}" = 1 ]; then
    echo "guard: valgrind is not installed (apt-get install valgrind): the compile's cost is not checked" >&2
    exit 1
  fi
  echo "guard: skipped: valgrind is not installed (apt-get install valgrind)" >&2
  exit 0
fi
[ "${BUILD:-1}" = 0 ] ||
  cargo build --release --locked --quiet --bin skillpost --example generate --example floor
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
./target/release/examples/generate --steps "$STEPS" --out "$work/p" >/dev/null
# The instructions of one command (millions); fails with its output when the command fails.
count() {
  if ! (cd "$work/p" && valgrind --tool=callgrind --callgrind-out-file=/dev/null "$@" \
    >"$work/out" 2>"$work/err"); then
    echo "guard: $* failed:" >&2
    cat "$work/out" "$work/err" >&2
    exit 1
  fi
  awk '/I +refs:/ { gsub(",", "", $NF); printf "%.1f", $NF / 1e6 }' "$work/err"
}
compile=$(count "$PWD/target/release/skillpost" Blackboard.aml out)
floor=$(count "$PWD/target/release/examples/floor" sfc.xml)
ratio=$(awk -v c="$compile" -v f="$floor" 'BEGIN { printf "%.3f", c / f }')
echo "guard: $STEPS flat steps: compile $compile M instructions, quick-xml floor $floor M: $ratio (limit $LIMIT)"
if awk -v r="$ratio" -v l="$LIMIT" 'BEGIN { exit !(r > l) }'; then
  echo "guard: the compile costs $ratio times the quick-xml pass, more than the limit of $LIMIT: find what made it dearer (bench/split.sh, docs/PERFORMANCE.md)" >&2
  exit 1
fi
