#!/usr/bin/env bash
# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
# Guest instructions per frame of each tofmatd scene profile (aarch64), from
# the reassembled depth packet to the encoded event: tofmat_bench_profiles
# under qemu-aarch64 with the instruction-counting plugin (qemu_insn_count.c).
# For each profile and kernel, count(R) - count(0) divided by R and by the
# frames a pass holds (the packets' rendering and a warm-up pass happen in
# both runs and cancel). Prints markdown tables.
#   usage: profile_counts.sh PLUGIN.so BENCH_EXECUTABLE DB [R]
#   e.g.   tests/bench/profile_counts.sh build/benchprof/tests/bench/qemu_insn_count.so \
#            build/benchprof-aarch64/tests/bench/tofmat_bench_profiles ../shared/data/tanaka2017_kinect2_db 2
# DB: the table the profiles match against (a database folder or a .tmx).
# PROFILE_COUNTS_PART=profiles or steps: only the first table or only the
# segmentation breakdown (both by default; run them side by side on two cores).
# (BENCH_EXECUTABLE: the aarch64 build, with the daemon; it finds the
# simulator's data at the path compiled into it; QEMU_AARCH64 overrides the
# qemu binary; the executables are dynamically linked and run without -L.)
set -euo pipefail
plugin=$1 bench=$2 db=$3 reps=${4:-2}
qemu=${QEMU_AARCH64:-qemu-aarch64}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

# count PROFILE KERNEL R [EXTRA...] -> "instructions units"
count() {
  local profile=$1 kernel=$2 r=$3
  shift 3
  "$qemu" -plugin "$plugin" -d plugin "$bench" --profile "$profile" --kernel "$kernel" --reps "$r" --table "$db" "$@" \
    >"$tmp/out" 2>"$tmp/err" || { cat "$tmp/err" >&2; exit 1; }
  local n u
  n=$(sed -n 's/^insns: //p' "$tmp/err")
  u=$(sed -n 's/.* units \([0-9]*\)$/\1/p' "$tmp/out")
  [ -n "$n" ] && [ -n "$u" ] || { echo "no count for $profile $kernel $r $*" >&2; cat "$tmp/out" "$tmp/err" >&2; exit 1; }
  echo "$n $u"
}

# per_frame PROFILE KERNEL [EXTRA...] -> instructions per frame (integer)
per_frame() {
  local profile=$1 kernel=$2 c0 cr units
  shift 2
  read -r c0 _ < <(count "$profile" "$kernel" 0 "$@")
  read -r cr units < <(count "$profile" "$kernel" "$reps" "$@")
  echo $(((cr - c0) / (reps * units)))
}

echo "qemu: $("$qemu" --version | head -n 1); R = $reps; instructions per frame = (count(R) - count(0)) / (R x frames)"
"$qemu" "$bench" --profile unpack-full --reps 0 | sed 's/^/bench: /'
echo
part=${PROFILE_COUNTS_PART:-all}
if [ "$part" != steps ]; then
echo "| profile | scalar unpack | best unpack (NEON) | scalar / best |"
echo "|---|---:|---:|---:|"
for p in handheld sorting sorting-idle segmentation; do
  s=$(per_frame "$p" scalar)
  n=$(per_frame "$p" best)
  awk -v p="$p" -v s="$s" -v n="$n" 'BEGIN { printf "| %s | %d | %d | %.2f |\n", p, s, n, (n > 0 ? s / n : 0) }'
done
fi


# The camera's path (no truth: a camera never has one) with each exemplar
# classifier, best kernels; the rows above are tofmatd's default, with the
# simulated frames' truth.
echo
echo "| profile, camera path (no truth), best kernels | --classifier session (default: learning, a session starting) | learning, a session learned (--warm-session) | --no-session-learning | --classifier eq12 |"
echo "|---|---:|---:|---:|---:|"
for p in handheld sorting; do
  echo "| $p | $(per_frame "$p" best --no-truth --classifier session) | $(per_frame "$p" best --no-truth --warm-session)" \
    "| $(per_frame "$p" best --no-truth --no-session-learning) | $(per_frame "$p" best --no-truth --classifier eq12) |"
done

[ "$part" != profiles ] || exit 0

# Where segmentation's instructions go: its steps, each row the whole of what
# it names (best kernels); the smoothing rows are the smoothing alone.
echo
echo "| segmentation step (best kernels) | instructions per frame |"
echo "|---|---:|"
echo "| unpack of the whole packet | $(per_frame unpack-full best) |"
echo "| unpack + decode_frame_fixed | $(per_frame decode-full best) |"
echo "| unpack + process (smooth 1: no box mean, no majority) + encode, no truth | $(per_frame segmentation best --smooth 1 --no-truth) |"
echo "| unpack + process (smooth 9) + encode, no truth | $(per_frame segmentation best --no-truth) |"
echo "| unpack + process (smooth 9) + encode, with truth (accuracy()) | $(per_frame segmentation best) |"
echo "| smoothing alone: box mean 9x9 of the two features (integers) | $(per_frame smooth-box best) |"
echo "| smoothing alone: majority 9x9 of the label map | $(per_frame smooth-majority best) |"
