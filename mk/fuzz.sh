#!/usr/bin/env bash
# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
# Runs every libFuzzer target of a sanitizer build for SECONDS each, JOBS at once, from its seed
# corpus (tests/fuzz/corpus/NAME) and the build's own (DIR/corpus/NAME). Each target's whole
# output goes to DIR/logs/NAME.log. A failing target is reported once all have run, at the end of
# the output (where a CI log's tail shows it): its exit code, its sanitizer report and the input
# that failed, in base64 when it is small, so the failure can be replayed from the log alone.
# SEED is libFuzzer's -seed (`make fuzz` passes one derived from the commit, so each commit
# explores afresh; 0 lets libFuzzer pick): with the corpus growing and the time limit a wall
# clock's, a run is not repeated exactly by its seed; the printed input is what replays a failure.
# Usage: mk/fuzz.sh DIR SECONDS JOBS [SEED]
set -euo pipefail
dir=$1 seconds=$2 jobs=$3 seed=${4:-0}
mkdir -p "$dir/logs" "$dir/artifacts"

mapfile -t targets < <(find "$dir/tests/fuzz" -maxdepth 1 -name 'fuzz_*' -type f -executable | sort)
if ((${#targets[@]} == 0)); then
  echo "fuzz: no fuzz targets in $dir/tests/fuzz (a build with -DTOFMAT_FUZZ=ON has them)" >&2
  exit 1
fi
for target in "${targets[@]}"; do rm -f "$dir/logs/$(basename "$target").rc"; done

run_one() {
  local target=$1 dir=$2 seconds=$3 seed=$4 name rc=0 used
  name=$(basename "$target")
  mkdir -p "$dir/corpus/$name"
  rm -f "$dir/artifacts/$name"-*
  "$target" -seed="$seed" -max_total_time="$seconds" -print_final_stats=1 -dict="tests/fuzz/${name#fuzz_}.dict" \
    -artifact_prefix="$dir/artifacts/$name-" "$dir/corpus/$name" "tests/fuzz/corpus/$name" \
    >"$dir/logs/$name.log" 2>&1 || rc=$?
  echo "$rc" >"$dir/logs/$name.rc"
  used=$(grep -m1 -oE 'Seed: [0-9]+' "$dir/logs/$name.log" | cut -d' ' -f2) || used='?'
  echo "fuzz: $name for $seconds s, seed $used: $(grep -m1 -oE 'number_of_executed_units: [0-9]+' "$dir/logs/$name.log" || echo 'no stats') (exit $rc)"
}
export -f run_one

# (each target's result is its .rc file: xargs's own status only says that some child failed)
printf '%s\0' "${targets[@]}" | xargs -0 -P"$jobs" -I{} bash -c 'run_one "$@"' _ {} "$dir" "$seconds" "$seed" || true

failed=0
for target in "${targets[@]}"; do
  name=$(basename "$target")
  log="$dir/logs/$name.log"
  rc=$(cat "$dir/logs/$name.rc" 2>/dev/null) || rc='none (its runner did not finish)'
  [[ $rc == 0 ]] && continue
  failed=1
  used=$(grep -m1 -oE 'Seed: [0-9]+' "$log" 2>/dev/null | cut -d' ' -f2) || used='?'
  echo "fuzz: FAILED $name (exit $rc, seed $used); its report ($log):"
  # The report: from the first sanitizer or libFuzzer error line, bounded; else the log's end.
  report='==[0-9]+==(ERROR|WARNING)|runtime error|ALARM|deadly signal|out-of-memory|SUMMARY|Test unit written'
  if grep -qE "$report" "$log" 2>/dev/null; then
    awk -v pattern="$report" '$0 ~ pattern {on = 1} on && n < 60 {print "  " $0; n++}' "$log"
  else
    tail -n 20 "$log" 2>/dev/null | sed 's/^/  /'
  fi
  for artifact in "$dir/artifacts/$name"-*; do
    [[ -f $artifact ]] || continue
    size=$(stat -c %s "$artifact")
    echo "fuzz: $name input $(basename "$artifact"), $size bytes, sha256 $(sha256sum "$artifact" | cut -c1-16)"
    if ((size <= 8192)); then
      echo "fuzz: its base64, the lines up to 'fuzz: end' (replay: base64 -d > crash && $target crash):"
      base64 -w 100 "$artifact"
      echo "fuzz: end"
    fi
  done
done
exit "$failed"
