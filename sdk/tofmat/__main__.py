# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""`python -m tofmat` is the `tofmat` command line."""

from .cli import main

main()
