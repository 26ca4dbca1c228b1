# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
# `make lint-cpp`: the C++ side's formatting, lint and SPDX checks (docs/coding-style.md); included by the Makefile.
#
#   lint-cpp-spdx    every git-tracked C/C++, CMake, shell and Python file opens with the SPDX line
#                    (tests/lint/check_spdx.sh)
#   lint-cpp-format  clang-format --dry-run --Werror over the git-tracked C/C++ files of firmware/, bindings/
#                    and tests/ (style: .clang-format)
#   lint-cpp-tidy    clang-tidy (checks: .clang-tidy) over the .cpp files of firmware/ and tests/cpp, with the
#                    compile commands of a clang build configured in build/tidy (configured only, not built)
#
# lint-cpp runs all three and fails if any failed; each can also run alone. About 6 minutes on 2 idle cores,
# nearly all of it clang-tidy (lint-cpp-tidy alone: 346 s on machine B).

TIDY_BUILD   := build/tidy
CLANG_FORMAT ?= clang-format
CLANG_TIDY   ?= clang-tidy
# The C/C++ sources and headers clang-format checks, as git pathspecs.
LINT_CPP_FORMAT_FILES := 'firmware/*.cpp' 'firmware/*.hpp' 'firmware/*.h' 'firmware/*.c' \
                         'bindings/*.cpp' 'bindings/*.hpp' 'bindings/*.h' 'bindings/*.c' \
                         'tests/*.cpp' 'tests/*.hpp' 'tests/*.h' 'tests/*.c'
# The translation units clang-tidy checks (our headers through .clang-tidy's HeaderFilterRegex).
LINT_CPP_TIDY_FILES := 'firmware/*.cpp' 'tests/cpp/*.cpp'

.PHONY: lint-cpp lint-cpp-spdx lint-cpp-format lint-cpp-tidy

lint-cpp: setup
	@status=0; \
	for t in lint-cpp-spdx lint-cpp-format lint-cpp-tidy; do \
	  $(MAKE) --no-print-directory $$t || { echo "lint-cpp: $$t failed" >&2; status=1; }; \
	done; \
	exit $$status

lint-cpp-spdx:
	tests/lint/check_spdx.sh

lint-cpp-format:
	git ls-files -z -- $(LINT_CPP_FORMAT_FILES) | xargs -0 $(CLANG_FORMAT) --dry-run --Werror
	@echo "lint-cpp-format: clean"

# One clang-tidy per file, JOBS at once; each prints its findings in one piece when it ends. (clang's own
# "N warnings generated." lines count warnings in system headers that clang-tidy never shows: dropped.)
lint-cpp-tidy:
	cmake -S . -B $(TIDY_BUILD) -G Ninja -DCMAKE_CXX_COMPILER=clang++ -DCMAKE_CXX_COMPILER_LAUNCHER= -DCMAKE_BUILD_TYPE=Debug \
	  -DCMAKE_EXPORT_COMPILE_COMMANDS=ON -DTOFMAT_DB_DIR=$(DB) >/dev/null
	@git ls-files -z -- $(LINT_CPP_TIDY_FILES) | xargs -0 -n1 -P$(JOBS) bash -c \
	  'out=$$($(CLANG_TIDY) -p $(TIDY_BUILD) --quiet "$$1" 2>&1); rc=$$?; \
	   [ -z "$$out" ] || grep -Ev "^[0-9]+ warnings? (and [0-9]+ errors? )?generated\.$$" <<<"$$out"; \
	   exit $$rc' lint-cpp-tidy
	@echo "lint-cpp-tidy: clean"
