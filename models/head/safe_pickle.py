"""A restricted unpickler for FLAME's files: numpy arrays, chumpy arrays and scipy sparse matrices
become plain numpy; every other class or callable is refused before anything is built.

A FLAME .pkl is a file from the internet. Python's pickle runs whatever callable a file names, so
it is never given one: `find_class` answers only from the table below, whose entries build arrays
and nothing else. chumpy and scipy's sparse classes are never imported; their pickled state is
read as data.
"""

from __future__ import annotations

import codecs
import copyreg
import io
import pickle

import numpy as np


class UnsafePickleError(pickle.UnpicklingError):
    """The pickle names a class or function outside the allowed set."""


class _Captured:
    """Stand-in for a class we do not import: keeps its pickled state as data."""

    kind = "object"

    def __init__(self, *args: object) -> None:
        self.args = args
        self.state: object = None

    def __setstate__(self, state: object) -> None:
        self.state = state


class ChumpyArray(_Captured):
    """A chumpy.ch.Ch as pickled: its value lives in state['x']."""

    kind = "chumpy"


class SparseMatrix(_Captured):
    """A scipy.sparse matrix as pickled: format, shape, data, indices, indptr in its state."""

    kind = "sparse"


_STAND_INS = (ChumpyArray, SparseMatrix)


def _reconstructor(cls: type, base: type, state: object) -> object:
    # copyreg._reconstructor builds base.__new__(cls); only our stand-ins on `object` are allowed.
    if cls not in _STAND_INS or base is not object:
        raise UnsafePickleError(f"refused copyreg._reconstructor for {cls!r}")
    return cls()


def _codecs_encode(text: str, encoding: str = "utf-8") -> bytes:
    # Python 3 writes bytes in protocol 2 as _codecs.encode(str, 'latin1').
    if not isinstance(text, str) or encoding not in ("latin1", "latin-1"):
        raise UnsafePickleError("refused _codecs.encode with unexpected arguments")
    return codecs.encode(text, "latin1")


def _bytes(*args: object) -> bytes:
    # Python 3 writes an empty bytes object in protocol 2 as a call of bytes() with no arguments (a FLAME array of
    # size 0 holds one); bytes with arguments could allocate anything, so only the empty call is allowed.
    if args:
        raise UnsafePickleError("refused bytes() with arguments")
    return b""


def _ndarray_reconstruct(subtype: type, shape: object, dtype: object) -> np.ndarray:
    if subtype is not np.ndarray:
        raise UnsafePickleError(f"refused array subtype {subtype!r}")
    return np.ndarray.__new__(np.ndarray, shape, dtype)


def _scalar(dtype: np.dtype, data: bytes = b"") -> np.generic:
    if not isinstance(dtype, np.dtype) or dtype.hasobject:
        raise UnsafePickleError("refused numpy scalar of object dtype")
    return np.frombuffer(data, dtype=dtype, count=1)[0]


def _dtype(spec: object, align: bool = False, copy: bool = False) -> np.dtype:
    dt = np.dtype(spec, align=align, copy=copy)
    if dt.hasobject:
        raise UnsafePickleError("refused numpy dtype that holds Python objects")
    return dt


_MULTIARRAY = ("numpy.core.multiarray", "numpy._core.multiarray")
_ALLOWED: dict[tuple[str, str], object] = {
    **{(m, "_reconstruct"): _ndarray_reconstruct for m in _MULTIARRAY},
    **{(m, "scalar"): _scalar for m in _MULTIARRAY},
    ("numpy", "ndarray"): np.ndarray,
    ("numpy", "dtype"): _dtype,
    ("copy_reg", "_reconstructor"): _reconstructor,
    ("copyreg", "_reconstructor"): _reconstructor,
    **{(m, t.__name__): t for m in ("__builtin__", "builtins") for t in (object, set, frozenset)},
    ("_codecs", "encode"): _codecs_encode,
    **{(m, "bytes"): _bytes for m in ("__builtin__", "builtins")},
    ("chumpy.ch", "Ch"): ChumpyArray,
    **{(module, f"{fmt}_{kind}"): SparseMatrix
       for fmt in ("csc", "csr") for kind in ("matrix", "array")
       for module in ("scipy.sparse", f"scipy.sparse.{fmt}", f"scipy.sparse._{fmt}")},
}


class RestrictedUnpickler(pickle.Unpickler):
    """Unpickler whose only globals are the array builders of _ALLOWED."""

    def find_class(self, module: str, name: str) -> object:
        try:
            return _ALLOWED[(module, name)]
        except KeyError:
            raise UnsafePickleError(f"refused to load '{module}.{name}': not an array type") from None

    def persistent_load(self, pid: object) -> object:
        raise UnsafePickleError("refused persistent id")


def to_numpy(value: object) -> object:
    """Chumpy and sparse stand-ins turned into numpy arrays; everything else as it is."""
    if isinstance(value, ChumpyArray):
        state = value.state if isinstance(value.state, dict) else {}
        if "x" not in state:
            raise UnsafePickleError("a chumpy array without its value 'x'")
        return np.asarray(state["x"])
    if isinstance(value, SparseMatrix):
        return _sparse_to_dense(value.state)
    return value


def _sparse_to_dense(state: object) -> np.ndarray:
    if not isinstance(state, dict):
        raise UnsafePickleError("a sparse matrix without its state")
    shape = state.get("_shape", state.get("shape"))
    fmt = state.get("format", "csc")
    data, indices, indptr = (np.asarray(state[k]) for k in ("data", "indices", "indptr"))
    dense = np.zeros(shape, np.float64)
    major = shape[1] if fmt == "csc" else shape[0]
    if len(indptr) != major + 1:
        raise UnsafePickleError("a sparse matrix whose indptr does not fit its shape")
    for j in range(major):
        lo, hi = indptr[j], indptr[j + 1]
        if fmt == "csc":
            dense[indices[lo:hi], j] = data[lo:hi]
        else:
            dense[j, indices[lo:hi]] = data[lo:hi]
    return dense


def restricted_load(data: bytes) -> object:
    """Unpickle bytes written by Python 2 or 3 with only array types allowed."""
    obj = RestrictedUnpickler(io.BytesIO(data), encoding="latin1").load()
    if isinstance(obj, dict):
        return {k: to_numpy(v) for k, v in obj.items()}
    return to_numpy(obj)


# copyreg is imported only so that its name documents where _reconstructor comes from.
assert copyreg._reconstructor.__name__ == "_reconstructor"
