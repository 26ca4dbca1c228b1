#!/usr/bin/env bash
# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
# Where one scene profile's aarch64 instructions go, per function: the
# profile's frames under qemu-aarch64 with the per-block plugin
# (qemu_tb_profile.c), at R passes and at 0, each function's difference
# divided by R and the frames a pass holds (as profile_counts.sh does for the
# total), demangled, most first. Functions in shared libraries are charged to
# their file ([libc.so.6], [libm.so.6], ...).
#   usage: profile_frame.sh PLUGIN.so BENCH_EXECUTABLE DB PROFILE [R] [-- BENCH_OPTIONS...]
#   e.g.   tests/bench/profile_frame.sh build/bench/tests/bench/qemu_tb_profile.so \
#            build/aarch64/tests/bench/tofmat_bench_profiles ../shared/data/tanaka2017_kinect2_db handheld 2 \
#            -- --kernel best --no-truth
# `make profile-frame PROFILE=handheld PROFILE_OPTIONS="--no-truth"` runs it on the box's build.
# PROFILE_TOP: how many functions to print (30).
set -euo pipefail
plugin=$1 bench=$2 db=$3 profile=$4
shift 4
reps=2
if [ $# -gt 0 ] && [ "$1" != -- ]; then
  reps=$1
  shift
fi
[ $# -eq 0 ] || { [ "$1" = -- ] && shift; }
case $reps in '' | *[!0-9]* | 0) echo "profile_frame.sh: R must be a whole number >= 1, not '$reps'" >&2; exit 2 ;; esac
qemu=${QEMU_AARCH64:-qemu-aarch64}
top=${PROFILE_TOP:-30}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

extra=("$@")
# run R NAME: the plugin's lines to NAME.profile, the bench's output to NAME.out
run() {
  local r=$1 out=$2
  "$qemu" -plugin "$plugin" -d plugin "$bench" --profile "$profile" --reps "$r" --table "$db" "${extra[@]}" \
    >"$tmp/$out.out" 2>"$tmp/$out.err" || { cat "$tmp/$out.err" >&2; exit 1; }
  sed -n 's/^profile: //p' "$tmp/$out.err" >"$tmp/$out.profile"
  [ -s "$tmp/$out.profile" ] || { echo "profile_frame.sh: no profile from the plugin" >&2; cat "$tmp/$out.err" >&2; exit 1; }
}
run 0 zero
run "$reps" many
units=$(sed -n 's/.* units \([0-9]*\)$/\1/p' "$tmp/many.out")
[ -n "$units" ] || { echo "profile_frame.sh: the bench printed no units" >&2; cat "$tmp/many.out" >&2; exit 1; }
echo "qemu: $("$qemu" --version | head -n 1); $profile ${extra[*]}; R = $reps, $units frames a pass;" \
  "instructions per frame = (count(R) - count(0)) / (R x frames), per function"
demangle() { if command -v c++filt >/dev/null; then c++filt; else cat; fi; }
python3 - "$tmp/zero.profile" "$tmp/many.profile" $((reps * units)) "$top" <<'PY' | demangle
import bisect, collections, re, shutil, subprocess, sys

zero_path, many_path, frames, top = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
LIBRARY = re.compile(r"^\[(.*)\]\+0x([0-9a-f]+)$")
nm = shutil.which("aarch64-linux-gnu-nm") or shutil.which("nm")
symbols: dict[str, tuple[list[int], list[str]]] = {}


def library_symbol(path: str, offset: int) -> str:
    """The dynamic symbol at or below OFFSET in PATH (the library's file name where none is known)."""
    short = "[" + path.rsplit("/", 1)[-1] + "]"
    if path not in symbols:
        table: list[tuple[int, str]] = []
        if nm:
            run = subprocess.run([nm, "-D", "--defined-only", path], capture_output=True, text=True, check=False)
            for line in run.stdout.splitlines():
                parts = line.split()
                if len(parts) == 3 and parts[1] in "TtWi":
                    table.append((int(parts[0], 16), parts[2].split("@")[0]))
        table.sort()
        symbols[path] = ([a for a, _ in table], [n for _, n in table])
    addresses, names = symbols[path]
    at = bisect.bisect_right(addresses, offset) - 1
    # (text and file offsets agree in a library's first segment; a block far past the last symbol is unnamed)
    return f"{names[at]} {short}" if at >= 0 else short


def read(path: str) -> collections.Counter:
    out: collections.Counter = collections.Counter()
    with open(path) as f:
        for line in f:
            count, name = line.rstrip("\n").split(" ", 1)
            m = LIBRARY.match(name)
            out[library_symbol(m.group(1), int(m.group(2), 16)) if m else name] += int(count)
    return out


zero, many = read(zero_path), read(many_path)
per = {name: (many[name] - zero.get(name, 0)) / frames for name in many}
total = per.pop("total")
print(f"{total:12.0f}  total")
for name, n in sorted(per.items(), key=lambda kv: (-kv[1], kv[0]))[:top]:
    if n >= 0.5:
        print(f"{n:12.0f}  {100 * n / total:5.1f} %  {name}")
PY
