#!/usr/bin/env bash
# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
# Checks that every git-tracked source file (C/C++, CMake, shell, Python) opens with the project's SPDX line.
#
# The line must be the file's first, or its second after a shebang, in the
# file's comment syntax:
#   // SPDX-License-Identifier: LicenseRef-tofmat-proprietary   (C, C++)
#   # SPDX-License-Identifier: LicenseRef-tofmat-proprietary    (CMake, shell, Python)
# Shell scripts without a .sh suffix are found by their shebang. Prints each
# file that lacks it and exits 1 if there is any; run from anywhere in the
# checkout (`make lint-cpp` runs it).
set -euo pipefail
cd "$(git rev-parse --show-toplevel)"

readonly ID='SPDX-License-Identifier: LicenseRef-tofmat-proprietary'
missing=0
checked=0
while IFS= read -r -d '' f; do
  [[ -f "$f" ]] || continue  # tracked, but deleted in the work tree
  case "$f" in
    *.cpp | *.hpp | *.h | *.c) prefix='//' ;;
    CMakeLists.txt | */CMakeLists.txt | *.cmake | *.sh | *.py | *.pyi) prefix='#' ;;
    *)
      # Other files count only when they are shell scripts.
      IFS= read -r first <"$f" || true
      [[ "$first" =~ ^#!.*(/|[[:space:]])(ba|da)?sh([[:space:]]|$) ]] || continue
      prefix='#'
      ;;
  esac
  checked=$((checked + 1))
  line1='' line2=''
  { IFS= read -r line1 || true; IFS= read -r line2 || true; } <"$f"
  [[ "$line1" == '#!'* ]] && line1="$line2"
  if [[ "$line1" != "$prefix $ID" ]]; then
    echo "$f: no '$prefix $ID' line at its top"
    missing=$((missing + 1))
  fi
done < <(git ls-files -z)

if ((missing > 0)); then
  echo "check_spdx: $missing of $checked source files lack the SPDX line" >&2
  exit 1
fi
echo "check_spdx: all $checked source files carry the SPDX line"
