"""numpy to Arrow and back without pandas.

``pa.array``, ``pa.scalar`` and ``Array.to_numpy`` ask pandas whether their argument is
one of its types, and so import it (0.8 s), which a one-row ``apply`` need not pay
(benchmarks/run.py, row 3e).  These build the same arrays from their buffers.
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa


def numbers(values: np.ndarray, mask: np.ndarray | None = None) -> pa.Array:
    """``pa.array(values, mask=mask)`` of a 1-D numpy array of fixed-width numbers."""
    values = np.ascontiguousarray(values)
    validity, nulls = None, 0
    if mask is not None and mask.any():
        validity = pa.py_buffer(np.packbits(~mask, bitorder="little"))
        nulls = int(mask.sum())
    return pa.Array.from_buffers(pa.from_numpy_dtype(values.dtype), len(values),
                                 [validity, pa.py_buffer(values)], null_count=nulls)


def strings(texts) -> pa.Array:
    """``pa.array(texts, pa.string())`` of a few Python strings."""
    data = [t.encode() for t in texts]
    offsets = np.cumsum([0, *map(len, data)], dtype=np.int32)
    return pa.Array.from_buffers(pa.string(), len(data), [None, pa.py_buffer(offsets),
                                                          pa.py_buffer(b"".join(data))])


def binary(text: bytes) -> pa.Scalar:
    """``pa.scalar(text, pa.binary())``."""
    offsets = np.array([0, len(text)], dtype=np.int32)
    return pa.Array.from_buffers(pa.binary(), 1, [None, pa.py_buffer(offsets), pa.py_buffer(text)])[0]


def column_floats(col: pa.ChunkedArray | pa.Array) -> np.ndarray:
    """``col.to_numpy()`` as float64, nulls as NaN (read-only when it has none).

    Integers beyond 2**53 are rounded to the nearest double, as a CSV's digits are read
    (Arrow's safe cast refused them with a traceback): the row's forces say what they are."""
    col = col.cast(pa.float64(), safe=not pa.types.is_integer(col.type))
    if isinstance(col, pa.ChunkedArray):
        col = col.combine_chunks()
    n, start = len(col), col.offset
    if n == 0:
        return np.empty(0)
    validity, data = col.buffers()
    x = np.frombuffer(data, dtype=np.float64, count=start + n)[start:]
    if not col.null_count:
        return x
    valid = np.unpackbits(np.frombuffer(validity, dtype=np.uint8), count=start + n,
                          bitorder="little")[start:].astype(bool)
    return np.where(valid, x, np.nan)
