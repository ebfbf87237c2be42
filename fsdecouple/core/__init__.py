"""The model: the stage every other stage builds on.

Linear non-coupling slopes omega (eq. 2) and corrected coupling functions chi
(eq. 4) held as kernel sums (eq. 10) and cubic tables; decoupling by eq. (11),
written once as a plan (``plan.py``) and evaluated exactly, through the tables (numpy,
the compiled kernel, one vector); second-order refinement
(eqs. 5-6); chi beyond the calibrated range; the interference error gamma
(eq. 12); the model file.

May import: the base modules at the top of the package (``errors``, ``config``,
``axes``, ``units``, ``files``, ...). Nothing from the other stages.
"""
