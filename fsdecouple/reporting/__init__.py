"""What a person reads: the HTML report, the certificate (HTML or PDF), their figures
and the terminal tables.

May import: the base modules, ``core``, ``data``, ``fitting`` and ``evaluation``;
no other top stage (``logs``, ``fleet``, ``export``, ``sim``).
"""
