# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The held-out evaluation of the classifiers (docs/evaluation.md): new capture sessions of the
real curves, matchers scored on a tuning split and reported on a test split."""
