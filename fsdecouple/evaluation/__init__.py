"""Judging a model on points it was not trained on.

Held-out protocols (repetitions, load levels), cross-validation against the
baselines (Section 4, Tables 3-5), the verdict against the calibration matrix,
tuning the SVR settings by held-out error, ``validate`` on an independent set
and the assumption checks; the certificate's ISO 376 figures and class
(``iso376``, ``creep``) and its EURAMET cg-4 budget (``budget``, ``certificate``); and
the one fit (``calibrate.py``, ``fsdecouple.fit``) that adds the verdict, the outliers,
the least-squares matrix and the held-out data to the model of ``fitting``, for the API
and the ``fit`` command alike.

May import: the base modules, ``core``, ``data`` and ``fitting``.
"""
