#!/usr/bin/env bash
# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
# Runs every libFuzzer target of a sanitizer build for SECONDS each, JOBS at once, from its seed
# corpus (tests/fuzz/corpus/NAME) and the build's own (DIR/corpus/NAME). Each target's whole
# output goes to DIR/logs/NAME.log. A failing target is reported once all have run, at the end of
# the output (where a CI log's tail shows it): its exit code, its sanitizer report and the input
# that failed, in base64 when it is small, so the failure can be replayed from the log alone:
#   base64 -d > crash && DIR/tests/fuzz/NAME crash
# SEED (libFuzzer's -seed) makes a run repeatable: `make fuzz` passes one derived from the commit,
# so each commit's run can be repeated exactly where it failed and the next commit explores
# further; 0 lets libFuzzer pick (each target's log says which it took).
# Usage: mk/fuzz.sh DIR SECONDS JOBS [SEED]
set -euo pipefail
dir=$1 seconds=$2 jobs=$3 seed=${4:-0}
mkdir -p "$dir/logs" "$dir/artifacts"
rm -f "$dir"/logs/*.rc

run_one() {
  local target=$1 dir=$2 seconds=$3 seed=$4 name rc=0
  name=$(basename "$target")
  mkdir -p "$dir/corpus/$name"
  rm -f "$dir/artifacts/$name"-*
  "$target" -seed="$seed" -max_total_time="$seconds" -print_final_stats=1 -dict="tests/fuzz/${name#fuzz_}.dict" \
    -artifact_prefix="$dir/artifacts/$name-" "$dir/corpus/$name" "tests/fuzz/corpus/$name" \
    >"$dir/logs/$name.log" 2>&1 || rc=$?
  echo "$rc" >"$dir/logs/$name.rc"
  seed=$(grep -m1 -oE 'Seed: [0-9]+' "$dir/logs/$name.log" | cut -d' ' -f2 || true)
  echo "fuzz: $name for $seconds s, seed ${seed:-?}: $(grep -m1 -oE 'number_of_executed_units: [0-9]+' "$dir/logs/$name.log" || echo 'no stats') (exit $rc)"
}
export -f run_one

find "$dir/tests/fuzz" -maxdepth 1 -name 'fuzz_*' -type f -executable | sort |
  xargs -P"$jobs" -I{} bash -c 'run_one "$@"' _ {} "$dir" "$seconds" "$seed"

failed=0
for rcfile in "$dir"/logs/*.rc; do
  rc=$(cat "$rcfile")
  [[ $rc == 0 ]] && continue
  failed=1
  name=$(basename "$rcfile" .rc)
  log="$dir/logs/$name.log"
  echo "fuzz: FAILED $name (exit $rc, seed $(grep -m1 -oE 'Seed: [0-9]+' "$log" | cut -d' ' -f2 || true)); its report ($log):"
  # The report: from the first sanitizer or libFuzzer error line, bounded.
  awk '/ERROR|WARNING: |ALARM|SUMMARY|deadly signal|out-of-memory|Test unit written/{on=1} on&&n<60{print "  " $0; n++}' "$log"
  grep -q . <(awk '/ERROR|ALARM|deadly/' "$log") || tail -n 20 "$log" | sed 's/^/  /'
  for artifact in "$dir/artifacts/$name"-*; do
    [[ -f $artifact ]] || continue
    size=$(stat -c %s "$artifact")
    echo "fuzz: $name input $(basename "$artifact"), $size bytes, sha256 $(sha256sum "$artifact" | cut -c1-16)"
    if ((size <= 8192)); then
      echo "fuzz: base64 of it (replay: base64 -d > crash && $dir/tests/fuzz/$name crash):"
      base64 -w 100 "$artifact" | sed 's/^/  /'
    fi
  done
done
exit "$failed"
