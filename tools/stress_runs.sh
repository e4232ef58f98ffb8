#!/usr/bin/env bash
# The flake check of issue 27: `make test` (through .ci/run, as CI runs it) on a fresh clone of
# this repository's HEAD, RUNS times in a row, each under background load (`stress-ng --cpu 1`
# for the whole run: one of the two cores kept busy). Prints one line per run and a summary;
# each run's output is kept in build/stress-runs/run-<i>.log. Exit status 0 only if every run
# passed.
#
#     bash tools/stress_runs.sh [RUNS]     (default 5; CLONE=/tmp/stress_clone)
set -uo pipefail
cd "$(dirname "$0")/.."
runs="${1:-5}"
clone="${CLONE:-/tmp/stress_clone}"
logs="$PWD/build/stress-runs"
mkdir -p "$logs"
if ! command -v stress-ng >/dev/null; then
  apt-get install -y -q stress-ng >/dev/null || { echo "stress_runs: cannot install stress-ng" >&2; exit 2; }
fi
# Every run tests the commit that was HEAD at the start, even if work goes on meanwhile.
head=$(git rev-parse --short HEAD)
# The clone lives elsewhere: the samples beside this checkout are named for it.
samples="${GLTF_SAMPLES_DIR:-$(realpath -m ../shared/gltf-samples)}"
failed=0
for i in $(seq 1 "$runs"); do
  rm -rf "$clone"
  git clone -q "$PWD" "$clone" && git -C "$clone" checkout -q "$head"
  stress-ng --cpu 1 --quiet --timeout 0 &
  load=$!
  start=$(date +%s)
  (cd "$clone" && CI=true GLTF_SAMPLES_DIR="$samples" bash .ci/run) > "$logs/run-$i.log" 2>&1 </dev/null
  code=$?
  kill "$load" 2>/dev/null
  wait "$load" 2>/dev/null
  summary=$(grep -E "^(test result|=+ .*(passed|failed)|[0-9]+ (passed|failed))" "$logs/run-$i.log" | tail -1)
  echo "stress run $i of $runs at $head: exit $code in $(( ($(date +%s) - start) / 60 )) min; $summary"
  [ "$code" -eq 0 ] || failed=$((failed + 1))
done
echo "stress runs: $((runs - failed)) of $runs green at $head"
[ "$failed" -eq 0 ]
