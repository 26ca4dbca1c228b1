# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
# The error-against-run-time report (docs/report.md): `make report` runs the benchmarks on this host
# and writes build/report/report.md with its figures. The Makefile includes this file.
REPORT_DIR    := build/report
REPORT_COUNTS := build/bench

.PHONY: report report-counts
report: build-cpp build-python $(TABLE)
	$(TOFMAT) report --table $(TABLE) -o $(REPORT_DIR)

# aarch64 instruction counts for the report: `make bench-cross` and `make bench-profiles-cross`
# print theirs and keep no file; this keeps their output where `tofmat report` reads it
# (the cross build and qemu: tens of minutes).
report-counts:
	@mkdir -p $(REPORT_COUNTS)
	set -o pipefail; $(MAKE) --no-print-directory bench-cross | tee $(REPORT_COUNTS)/insn_counts.md.part
	mv $(REPORT_COUNTS)/insn_counts.md.part $(REPORT_COUNTS)/insn_counts.md
	set -o pipefail; $(MAKE) --no-print-directory bench-profiles-cross | tee $(REPORT_COUNTS)/profile_counts.md.part
	mv $(REPORT_COUNTS)/profile_counts.md.part $(REPORT_COUNTS)/profile_counts.md
