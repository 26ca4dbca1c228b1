# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
# The held-out evaluation of the classifiers (docs/evaluation.md): `make evaluate` draws a tuning
# and a test split of new capture sessions (the real curves, and simulator sweeps), tunes the
# session-robust matcher on the first and prints the test table; build/evaluation.md keeps it.
# The Makefile includes this file. (A few minutes: outside `make test`.)
# The learned models it reports beside the exemplar matchers are trained first (`tofmat train`,
# docs/learned-models.md): one for the real curves' table (about 80 s), one for the simulated
# camera's table on its sweeps too (about 4 min); `make bench-learn` times the first as tofmatd
# runs it.
EVALUATION  := build/evaluation.md
LEARNED     := build/learned.onnx
LEARNED_SIM := build/learned_sim.onnx

.PHONY: evaluate bench-learn
# (Order-only on the table, which is imported again on every run: a model for other curves is
# refused by its contract, and `rm build/learned.onnx` trains it again.)
$(LEARNED): | $(TABLE) build-python
	$(TOFMAT) train --table $(TABLE) -o $(LEARNED) --force

$(LEARNED_SIM): | $(SIM_TABLE) build-python
	$(TOFMAT) train --table $(SIM_TABLE) --sim-sessions 10 -o $(LEARNED_SIM) --force

evaluate: build-python $(TABLE) $(LEARNED) $(LEARNED_SIM)
	$(TOFMAT) evaluate --table $(TABLE) --sim-table $(SIM_TABLE) --model $(LEARNED) --model $(LEARNED_SIM) \
	  -o $(EVALUATION)

bench-learn: build-cpp $(LEARNED)
	$(BUILD)/tests/bench/tofmat_bench_learn $(LEARNED) build/deps/onnxruntime/lib/x86_64/libonnxruntime.so.1 5 $(TABLE)
