# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Learned classifiers (docs/learned-models.md): an MLP trained on new capture sessions of a table's
curves (the evaluation's session model, tuning side only), exported to ONNX with the tofmat model
contract, and run through onnxruntime here and in tofmatd (``--classifier onnx:FILE``).

Needs ``tofmat[learn]`` (scikit-learn, onnx, onnxruntime); running a model needs onnxruntime only.
"""

from .model import CONTRACT, LearnedClassifier, ModelContract

__all__ = ["CONTRACT", "LearnedClassifier", "ModelContract"]
