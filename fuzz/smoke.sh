#!/usr/bin/env bash
# CI smoke run of the fuzz targets (docs/RELIABILITY.md, "Fuzzing"): builds them once, then runs
# each for FUZZ_SMOKE_SECONDS (15) from a temporary copy of the committed seeds (fuzz/corpus/*/
# seed-*; whatever else a long run left in the corpus folders is not used, and nothing is added
# there). Exits non-zero on any finding (the crashing input is in fuzz/artifacts/<target>/).
#
# The stable toolchain runs cargo-fuzz with RUSTC_BOOTSTRAP=1 (it needs -Z flags). The smoke
# build uses 16 codegen units to build in about half the time of cargo-fuzz's default of 1; the
# long runs use the default.
set -euo pipefail
cd "$(dirname "$0")/.."

secs=${FUZZ_SMOKE_SECONDS:-15}
targets=(blackboard sfc irl template value splice compile cond simulate)
export RUSTC_BOOTSTRAP=1
build=(--codegen-units 16)

if ! cargo fuzz --version >/dev/null 2>&1; then
  cargo install cargo-fuzz --locked
fi

cargo fuzz build "${build[@]}"

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
failed=()
for t in "${targets[@]}"; do
  mkdir -p "$work/$t"
  cp fuzz/corpus/"$t"/seed-* "$work/$t/"
  echo "fuzz smoke: $t (${secs}s)"
  if ! cargo fuzz run "${build[@]}" "$t" "$work/$t" -- \
    -max_total_time="$secs" -timeout=10 -print_final_stats=1 >"$work/$t.log" 2>&1; then
    failed+=("$t")
    tail -n 60 "$work/$t.log" >&2
  fi
  grep -E '^stat::(number_of_executed_units|average_exec_per_sec)' "$work/$t.log" | sed "s/^/  /" || true
done

if [ ${#failed[@]} -gt 0 ]; then
  # The finding itself last, where a truncated CI log still shows it: the panic message (or
  # libFuzzer's error) and the input, base64, when it is small.
  for t in "${failed[@]}"; do
    echo "fuzz smoke: $t:" >&2
    grep -m1 -A3 -E "panicked at|ERROR: libFuzzer" "$work/$t.log" >&2 || true
    for a in fuzz/artifacts/"$t"/*; do
      [ -f "$a" ] && [ "$(stat -c %s "$a")" -le 4096 ] && { echo "  $a (base64):" >&2; base64 -w0 "$a" >&2; echo >&2; }
    done
  done
  echo "fuzz smoke: findings in: ${failed[*]} (inputs in fuzz/artifacts/)" >&2
  exit 1
fi
echo "fuzz smoke: ${#targets[@]} targets, no findings"
