# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
# The documentation site (docs/: Sphinx with MyST Markdown, autodoc and sphinx-click) in
# build/docs, warnings as errors. The Makefile includes this file; `make docs`.
# conf.py imports the SDK's Python sources from sdk/ with the installed extension
# (make build-python), and formats the man pages with groff (Debian: groff-base).
DOCS_OUT := build/docs

.PHONY: docs
docs:
	@command -v groff >/dev/null || { echo "docs: installing groff-base"; \
	  $(SUDO) apt-get update -qq && DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y -qq groff-base >/dev/null; }
	$(PYTHON) -m pip install -q --disable-pip-version-check -r docs/requirements.txt
	$(PYTHON) -m sphinx -W --keep-going -b html docs $(DOCS_OUT)
