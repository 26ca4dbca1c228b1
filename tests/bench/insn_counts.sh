#!/usr/bin/env bash
# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
# Guest instructions per frame / ROI / query of tofmat_bench_fixed (aarch64)
# under qemu-aarch64 with the instruction-counting plugin (qemu_insn_count.c):
# for each op and kernel, count(R) - count(0) over R reps, divided by R and by
# the units a rep holds (1 frame, 1 ROI, 1 depth packet, or the number of
# queries). Prints markdown tables. Used by `make bench-cross`.
#   usage: insn_counts.sh PLUGIN.so BENCH_EXECUTABLE DB_DIR [R]
set -euo pipefail
plugin=$1 bench=$2 db=$3 reps=${4:-3}
qemu=${QEMU_AARCH64:-qemu-aarch64}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

# count OP KERNEL R -> "instructions units" (no -L: qemu takes the arm64 loader and libraries of multiarch from /)
# $window: only queries of that window length (nn, dist; 0 = all five lengths)
window=0
count() {
  "$qemu" -plugin "$plugin" -d plugin "$bench" --op "$1" --kernel "$2" --reps "$3" --db "$db" --window "$window" \
    >"$tmp/out" 2>"$tmp/err" || { cat "$tmp/err" >&2; exit 1; }
  local n u
  n=$(sed -n 's/^insns: //p' "$tmp/err")
  u=$(sed -n 's/.* units \([0-9]*\)$/\1/p' "$tmp/out")
  [ -n "$n" ] && [ -n "$u" ] || { echo "no count for $*" >&2; cat "$tmp/out" "$tmp/err" >&2; exit 1; }
  echo "$n $u"
}

# per_unit OP KERNEL -> instructions per unit (integer)
per_unit() {
  local c0 cr
  read -r c0 _ < <(count "$1" "$2" 0)
  read -r cr units < <(count "$1" "$2" "$reps")
  echo $(((cr - c0) / (reps * units)))
}

echo "qemu: $("$qemu" --version | head -n 1); R = $reps; instructions per unit = (count(R) - count(0)) / (R x units)"
echo
echo "| op | unit | float | fixed scalar | fixed NEON | scalar / NEON | issue's target | met |"
echo "|---|---|---:|---:|---:|---:|---|---|"
declare -A counted  # "OP KERNEL" -> instructions per unit, for the unpack table below
row() {  # OP UNIT TARGET_RATIO (empty: none) WITH_FLOAT
  local op=$1 unit=$2 target=$3 fl="" s n ratio met="" tgt=""
  if [ "$4" = yes ]; then fl=$(per_unit "$op" float); fi
  s=$(per_unit "$op" scalar)
  n=$(per_unit "$op" best)
  counted["$op scalar"]=$s counted["$op best"]=$n
  ratio=$(awk -v s="$s" -v n="$n" 'BEGIN { printf "%.2f", s / n }')
  if [ -n "$target" ]; then
    tgt=">= ${target}x fewer"
    met=$(awk -v r="$ratio" -v t="$target" 'BEGIN { print (r >= t) ? "yes" : "no" }')
  fi
  echo "| $op | $unit | ${fl:--} | $s | $n | $ratio | ${tgt:--} | ${met:--} |"
}
row decode "512x424 frame" 2 yes
row roi "20x20 region" "" yes
# (the 4x target is the distance kernel's: the dist row; a whole query adds the same
# scalar quantisation and ranking to both sides)
row nn "query (quantise + search 29 materials)" "" yes
row dist "query (distance kernel calls only)" 4 no
for window in 1 10 100; do
  row dist "query of ${window} bins (distance kernel calls only)" "" no
done
window=0
row frame "frame: decode + per-pixel classification" "" no
# The 11-bit unpack (firmware/kinect raw_unpack.hpp): nine sub-images of packed
# codes to raw values, whole, the rows of a 48x48 region at the centre, and
# that region alone.
row unpack "depth packet: 11-bit unpack of 9 sub-images" "" no
row unpack_roi "depth packet rows 188..236: 11-bit unpack (9 x 48 rows)" "" no
row unpack_region "depth packet 48x48 region (x 232..280, rows 188..236): 11-bit unpack" "" no

# The unpack's definition (the unpack as first written: code by code from
# 16-bit words, then the device table; whole rows only) against the kernels
# above. Before the region-aware unpack, a region cost the whole packet.
echo
echo "| unpack | definition | scalar | NEON | definition / scalar | definition / NEON |"
echo "|---|---:|---:|---:|---:|---:|"
for op in unpack unpack_roi; do
  d=$(per_unit "$op" reference)
  s=${counted["$op scalar"]} n=${counted["$op best"]}
  awk -v op="$op" -v d="$d" -v s="$s" -v n="$n" \
    'BEGIN { printf "| %s | %d | %d | %d | %.1f | %.1f |\n", op, d, s, n, d / s, d / n }'
done

# A table row's name for the query window: "1 bin", "10 bins", or all five lengths (0).
window_label() { [ "$window" = 0 ] && echo "all five lengths" || echo "$window bin$([ "$window" = 1 ] || echo s)"; }

# The session-robust matcher (docs/evaluation.md), tuned settings, a whole
# query against the 29 materials: its float reference (double) against its
# fixed-point path (scalar and NEON kernels), next to Eq. (12)'s fixed NEON
# search, by sweep length.
echo
echo "| session matcher: query of | Eq. (12) fixed NEON | session float (double) | session fixed (scalar) | session fixed (NEON) | float / NEON |"
echo "|---|---:|---:|---:|---:|---:|"
for window in 1 10 100 0; do
  e=$(per_unit nn best)
  f=$(per_unit session float)
  x=$(per_unit session scalar)
  n=$(per_unit session best)
  label=$(window_label)
  awk -v l="$label" -v e="$e" -v f="$f" -v x="$x" -v n="$n" \
    'BEGIN { printf "| %s | %d | %d | %d | %d | %.2f |\n", l, e, f, x, n, f / n }'
done
window=0

# The session learner (tofmatd's default, session_learner.hpp) as a session
# starts: a query scored under all six scaled priors (four in a sweep of 20
# bins or more, three from 40) on the fixed path with NEON, against the session
# matcher alone.
echo
echo "| session learner: query of | session fixed (NEON) | learner fixed (NEON), every scale | learner / session |"
echo "|---|---:|---:|---:|"
for window in 1 10 100 0; do
  n=$(per_unit session best)
  l=$(per_unit learning best)
  label=$(window_label)
  awk -v lb="$label" -v n="$n" -v l="$l" 'BEGIN { printf "| %s | %d | %d | %.2f |\n", lb, n, l, l / n }'
done
window=0
