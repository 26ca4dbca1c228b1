# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
# The held-out evaluation of the classifiers (docs/evaluation.md): `make evaluate` draws a tuning
# and a test split of new capture sessions (the real curves, and simulator sweeps), tunes the
# session-robust matcher on the first and prints the test table; build/evaluation.md keeps it.
# The Makefile includes this file. (A few minutes: outside `make test`.)
# The learned model it reports beside the exemplar matchers is trained first (`tofmat train`, about
# 80 s; docs/learned-models.md); `make bench-learn` times it as tofmatd runs it.
EVALUATION := build/evaluation.md
LEARNED    := build/learned.onnx

.PHONY: evaluate bench-learn
# (Order-only on the table, which is imported again on every run: a model for other curves is
# refused by its contract, and `rm build/learned.onnx` trains it again.)
$(LEARNED): | $(TABLE) build-python
	$(TOFMAT) train --table $(TABLE) -o $(LEARNED) --force

evaluate: build-python $(TABLE) $(LEARNED)
	$(TOFMAT) evaluate --table $(TABLE) --model $(LEARNED) -o $(EVALUATION)

bench-learn: build-cpp $(LEARNED)
	$(BUILD)/tests/bench/tofmat_bench_learn $(LEARNED) build/deps/onnxruntime/lib/x86_64/libonnxruntime.so.1 5 $(TABLE)
