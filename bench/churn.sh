#!/usr/bin/env bash
# Memory and CPU of the daemon while root projects come and go (docs/RELIABILITY.md, "Churn
# figures"): batches of 500 copies of the reference sample are created in a root, waited for
# (`watching`), deleted, then 3.5 s pass (the daemon forgets them after `forget_after_s`); after
# each batch it prints the cycles so far, VmRSS (kB) and the daemon's CPU ticks (utime + stime).
# At the end: the mean compile time of the first and last 10 % of compiles.
#
# Environment: CYCLES (6000), BIN (default: the debug build of this tree; set it to compare
# another build), EXTRA (configuration lines, default `forget_after_s = 1`; empty for builds
# without that key).
set -euo pipefail
cd "$(dirname "$0")/.."
sample=$PWD/fixtures/ok/reference-sample
CYCLES=${CYCLES:-6000}
if [ -z "${BIN:-}" ]; then
  cargo build --quiet --bin skillpost
  BIN=$PWD/target/debug/skillpost
fi
EXTRA=${EXTRA-forget_after_s = 1}

work=$(mktemp -d "${TMPDIR:-/tmp}/skillpost-churn.XXXXXX")
pid=
trap '[ -n "$pid" ] && kill "$pid" 2>/dev/null; rm -rf "$work"' EXIT
cd "$work"
mkdir -p ws/root
printf 'settle_ms = 20\nevents = "ev.jsonl"\n%s\n[[root]]\npath = "ws/root"\n' "$EXTRA" > cfg.toml
"$BIN" watch --config cfg.toml 2> err.log &
pid=$!
sleep 1
rss() { awk '/VmRSS/{print $2}' "/proc/$pid/status"; }
echo "0 $(rss)"
made=0
start=$(date +%s.%N)
while [ "$made" -lt "$CYCLES" ]; do
  for i in $(seq "$made" $((made + 499))); do
    mkdir "ws/root/p$i"
    cp "$sample/Blackboard.aml" "$sample/sfc.xml" "$sample/kr15-2.irl" "ws/root/p$i/"
  done
  made=$((made + 500))
  for _ in $(seq 1 600); do
    [ "$(grep -c '"event":"watching"' ev.jsonl)" -ge "$made" ] && break
    sleep 0.1
  done
  rm -rf ws/root/p* 2>/dev/null || true
  sleep 0.2
  rm -rf ws/root/p* 2>/dev/null || true
  sleep 3.5
  echo "$made $(rss) cpu_ticks=$(awk '{print $14 + $15}' "/proc/$pid/stat")"
done
echo "elapsed $(echo "$(date +%s.%N) - $start" | bc) s"
python3 - <<'PY'
import json
d = [json.loads(l) for l in open('ev.jsonl')]
c = [e['duration_ms'] for e in d if e['event'] == 'compile-succeeded']
n = len(c); q = max(n // 10, 1)
print('compiles %d, first 10%% mean %.1f ms, last 10%% mean %.1f ms' % (n, sum(c[:q]) / q, sum(c[-q:]) / q))
PY
