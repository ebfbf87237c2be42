"""Judging a model on points it was not trained on.

Held-out protocols (repetitions, load levels), cross-validation against the
baselines (Section 4, Tables 3-5), the verdict against the calibration matrix,
tuning the SVR settings by held-out error, ``validate`` on an independent set
and the assumption checks; the certificate's ISO 376 figures and class
(``iso376``, ``creep``) and its EURAMET cg-4 budget (``budget``, ``certificate``).

May import: the base modules, ``core``, ``data`` and ``fitting``.
"""
