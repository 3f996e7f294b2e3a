"""numpy arrays to and from pyarrow arrays without pandas.

pyarrow's own conversions (``pa.array`` of a numpy array or a list, ``Array.to_numpy``)
import pandas, when it is installed, to check the types of what they convert: 30 MB of
``radarviz track``'s peak memory that the command never uses. These go through the arrays'
buffers instead (pyarrow's columnar layout: a validity bitmap, then the values; strings as
int32 offsets and UTF-8 bytes), which is also a copy fewer.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray


def to_numpy(column: Any) -> NDArray[Any]:
    """A pyarrow array or chunked array of fixed-width numbers as a (writable) numpy array
    of its type; nulls become NaN (a float type) or 0 (an integer type)."""
    import pyarrow as pa

    if isinstance(column, pa.ChunkedArray):
        column = column.combine_chunks()
    dtype = np.dtype(column.type.to_pandas_dtype())
    n = len(column)
    validity, values = column.buffers()[:2]
    if values is None:  # every value null: no values buffer
        out = np.zeros(n, dtype=dtype)
    else:
        out = np.frombuffer(values, dtype=dtype, count=n, offset=column.offset * dtype.itemsize)
        out = out.copy()
    if column.null_count:
        bits = np.unpackbits(np.frombuffer(validity, dtype=np.uint8), bitorder="little")
        valid = bits[column.offset : column.offset + n].astype(bool)
        out[~valid] = np.nan if dtype.kind == "f" else 0
    return out


def from_numpy(values: NDArray[Any]) -> Any:
    """A 1-D numpy array of fixed-width numbers as a pyarrow array of its type (no nulls)."""
    import pyarrow as pa

    values = np.ascontiguousarray(values)
    return pa.Array.from_buffers(
        pa.from_numpy_dtype(values.dtype), values.size, [None, pa.py_buffer(values)]
    )


def strings(texts: Sequence[str]) -> Any:
    """Python strings as a pyarrow string array."""
    import pyarrow as pa

    data = [t.encode("utf-8") for t in texts]
    offsets = np.zeros(len(data) + 1, dtype=np.int32)
    offsets[1:] = np.cumsum([len(d) for d in data])
    return pa.Array.from_buffers(
        pa.string(), len(data), [None, pa.py_buffer(offsets), pa.py_buffer(b"".join(data))]
    )
