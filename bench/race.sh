#!/usr/bin/env bash
# The write-back race at size (docs/RELIABILITY.md): SAVES saves (default 3000) in each of the
# four save styles of tests/race.rs against the release daemon; prints one line per style
# ("race <Mode>: N saves, L lost, C not compiled, ...") and fails if any save was lost or not
# compiled. Takes about 15 minutes for 3,000 per style on 2 cores.
set -euo pipefail
cd "$(dirname "$0")/.."
SKILLPOST_RACE_SAVES="${SAVES:-${1:-3000}}" cargo test --release --test race -- --nocapture --test-threads=1 2>&1 |
  grep -oE 'race [A-Za-z]+: .*|test result.*'
