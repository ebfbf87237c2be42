"""Fitting the coupling error model and its baselines.

``fit`` trains one libsvm epsilon-SVR per chi with the Table 2 parameters (or the
solver tolerance the calibration's noise asks for); the least-squares calibration
matrix and the RBF networks of Tables 1 and 3 are the baselines; gross errors
are flagged from the residuals.

May import: the base modules, ``core`` and ``data``.
"""
