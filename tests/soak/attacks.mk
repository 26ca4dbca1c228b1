# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
# Attacks on tofmatd (issue 16), run by hand: neither is part of `make test` or CI.
# Included from the Makefile (PYTHON and build-python are its own). tests/soak/README.md says what
# each attack does and what is measured.
#
#   make bench-attacks [ATTACK_SECONDS=10] [ATTACKS=flood,token_guess]   figures only, never fails on timing
#   make soak [SOAK_SECONDS=1800]                                        exit 1 if its criteria fail
#
# DAEMON_ARGS passes flags to the tofmatd under test, e.g. DAEMON_ARGS='--idle-timeout 30 --max-tcp-clients 8'.
# The figures also go to $(ATTACKS_JSON) and $(SOAK_JSON).
ATTACK_SECONDS ?= 10
SOAK_SECONDS   ?= 1800
ATTACKS        ?=
DAEMON_ARGS    ?=
# tofmatd's niceness, as the box's systemd unit runs it (Nice=-5); 0 for none.
DAEMON_NICE    ?= -5
ATTACKS_JSON   ?= build/bench-attacks.json
SOAK_JSON      ?= build/soak.json

ATTACK_FLAGS = $(if $(ATTACKS),--attacks '$(ATTACKS)') $(if $(DAEMON_ARGS),--daemon-arg='$(DAEMON_ARGS)') \
               --daemon-nice=$(DAEMON_NICE)

.PHONY: bench-attacks soak
bench-attacks: build-python
	@mkdir -p $(dir $(ATTACKS_JSON))
	$(PYTHON) tests/soak/daemon_attacks.py bench --seconds $(ATTACK_SECONDS) $(ATTACK_FLAGS) --json $(ATTACKS_JSON)

soak: build-python
	@mkdir -p $(dir $(SOAK_JSON))
	$(PYTHON) tests/soak/daemon_attacks.py soak --seconds $(SOAK_SECONDS) $(ATTACK_FLAGS) --json $(SOAK_JSON)
