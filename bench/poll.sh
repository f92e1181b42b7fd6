#!/usr/bin/env bash
# What an idle polled project costs (docs/PERFORMANCE.md, "Polling"): generates a project
# (default 100 000 steps, a 78 MB SFC), runs `skillpost watch` on it with polling forced
# (SKILLPOST_FORCE_POLL=1, as on NFS/SMB), waits for the startup compile, lets it settle for
# 5 s, then measures over SECONDS_IDLE (30) seconds the daemon's CPU time (utime + stime from
# /proc/PID/stat) and the bytes it read (rchar from /proc/PID/io). Then one edit, and the time
# from the save to compile-succeeded.
#
# Environment: STEPS (100000), SECONDS_IDLE (30), BIN (default: the release build of this tree;
# set it to compare another build).
set -euo pipefail
cd "$(dirname "$0")/.."

STEPS=${STEPS:-100000}
SECONDS_IDLE=${SECONDS_IDLE:-30}

cargo build --release --quiet --bin skillpost --example generate
BIN=${BIN:-$PWD/target/release/skillpost}

work=$(mktemp -d "${TMPDIR:-/tmp}/skillpost-poll.XXXXXX")
pid=
cleanup() {
    [ -n "$pid" ] && kill "$pid" 2>/dev/null && wait "$pid" 2>/dev/null
    rm -rf "$work"
}
trap cleanup EXIT
[ -n "${KEEP:-}" ] && trap 'kill "$pid"; echo "kept $work"' EXIT

./target/release/examples/generate --steps "$STEPS" --out "$work/p" >/dev/null
sfc_bytes=$(stat -c %s "$work/p/sfc.xml")

count() {
    local n
    n=$(grep -c "\"event\":\"$1\"" "$work/ev.jsonl" 2>/dev/null)
    echo "${n:-0}"
}
wait_for() { # event, count before, timeout in s
    local deadline=$((SECONDS + $3))
    while [ "$(count "$1")" -le "$2" ]; do
        [ $SECONDS -ge $deadline ] && { echo "poll.sh: no $1 within $3 s" >&2; exit 1; }
        sleep 0.05
    done
}

SKILLPOST_FORCE_POLL=1 "$BIN" watch --events "$work/ev.jsonl" "$work/p" 2>"$work/log" &
pid=$!
wait_for compile-succeeded 0 120
sleep 5

ticks() { awk '{print $14 + $15}' "/proc/$pid/stat"; }
rchar() { awk '/^rchar/ {print $2}' "/proc/$pid/io"; }
hz=$(getconf CLK_TCK)
t0=$(ticks); r0=$(rchar); s0=$(date +%s.%N)
sleep "$SECONDS_IDLE"
t1=$(ticks); r1=$(rchar); s1=$(date +%s.%N)

# One edit (a space put into the first frame's value): save to compile-succeeded.
n=$(count compile-succeeded)
e0=$(date +%s.%N)
sed -i '0,/Frame" Value="(/s//Frame" Value="( /' "$work/p/sfc.xml"
wait_for compile-succeeded "$n" 120
e1=$(date +%s.%N)

awk -v steps="$STEPS" -v mb="$(echo "$sfc_bytes / 1000000" | bc -l)" -v t="$((t1 - t0))" \
    -v hz="$hz" -v r="$((r1 - r0))" -v s0="$s0" -v s1="$s1" -v e0="$e0" -v e1="$e1" 'BEGIN {
    wall = s1 - s0
    printf "| steps | SFC | idle CPU | read while idle | save → compile-succeeded |\n"
    printf "|---|---|---|---|---|\n"
    printf "| %d | %.1f MB | %.2f %% | %.1f MB/s | %.2f s |\n", steps, mb,
        100 * t / hz / wall, r / wall / 1e6, e1 - e0
}'
