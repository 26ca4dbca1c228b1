# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
# The held-out evaluation of the classifiers (docs/evaluation.md): `make evaluate` draws a tuning
# and a test split of new capture sessions (the real curves, and simulator sweeps), tunes the
# session-robust matcher on the first and prints the test table; build/evaluation.md keeps it.
# The Makefile includes this file. (A few minutes: outside `make test`.)
EVALUATION := build/evaluation.md

.PHONY: evaluate
evaluate: build-python $(TABLE)
	$(TOFMAT) evaluate --table $(TABLE) -o $(EVALUATION)
