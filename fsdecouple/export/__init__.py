"""The C header: a model as one dependency-free C99 file for controllers.

``plan`` holds what the header holds (the model's decoupling plan with the header's
tables), ``header`` decides and checks every number of it (``export_header``),
``resample`` builds coarser chi tables to an error bound, ``c_source`` writes the C
text and ``c_function`` the decoupling function, the plan's steps in order.

May import: the base modules, ``core``, ``data``, ``fitting`` and ``evaluation``;
no other top stage (``reporting``, ``logs``, ``fleet``, ``sim``).
"""
