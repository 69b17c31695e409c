"""Input validation shared by the parameter classes.

Every check raises ``ValueError`` whose message names the offending field, so a
user who mistypes one entry of a config learns which one. An integer is a Python or
NumPy integer, never a ``bool``; :func:`is_integer` and :func:`is_real_number` are the
predicates for callers that word their own errors (manifests, wire messages).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike


def refuse_truth_value(value: object, name: str) -> None:
    """A ValueError naming ``name`` for a truth value where a number is wanted (module docstring: ``float(True)`` is
    1.0, and ``dt=True`` a one-second period)."""
    if isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be a number, got {value!r}")


def as_square_matrix(value: ArrayLike, name: str, n: int | None = None) -> np.ndarray:
    """Return ``value`` as a finite float64 (n, n) matrix.

    A scalar or a 1-D vector is read as a diagonal, which is how gains are usually
    written (``M = diag(10, 10)``). Truth values are refused (no number).
    """
    if np.asarray(value).dtype.kind == "b":  # a truth value or an array of them (float(True) is 1)
        raise ValueError(f"{name} must be a matrix of numbers, got {value!r}")
    arr = np.array(value, dtype=float)
    if arr.ndim == 0:
        arr = np.diag(np.full(n if n is not None else 1, float(arr)))
    elif arr.ndim == 1:
        arr = np.diag(arr)
    if arr.ndim != 2 or arr.shape[0] != arr.shape[1]:
        raise ValueError(f"{name} must be a square matrix, got shape {np.shape(value)}")
    if n is not None and arr.shape[0] != n:
        raise ValueError(f"{name} must be {n}x{n} to match the other matrices, got {arr.shape[0]}x{arr.shape[1]}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} has non-finite entries")
    arr.setflags(write=False)
    return arr


def check_symmetric(arr: np.ndarray, name: str) -> None:
    scale = max(1.0, float(np.max(np.abs(arr))))
    if not np.allclose(arr, arr.T, rtol=0.0, atol=1e-12 * scale):
        raise ValueError(f"{name} must be symmetric")


def check_positive_definite(arr: np.ndarray, name: str) -> None:
    check_symmetric(arr, name)
    try:
        np.linalg.cholesky(arr)
    except np.linalg.LinAlgError:
        raise ValueError(
            f"{name} must be positive definite (smallest eigenvalue {np.linalg.eigvalsh(arr).min():.3g})"
        ) from None


def check_positive_semidefinite(arr: np.ndarray, name: str) -> None:
    check_symmetric(arr, name)
    eig_min = float(np.linalg.eigvalsh(arr).min())
    scale = max(1.0, float(np.max(np.abs(arr))))
    if eig_min < -1e-12 * scale:
        raise ValueError(f"{name} must be positive semidefinite (smallest eigenvalue {eig_min:.3g})")


def check_positive_scalar(value: float, name: str) -> float:
    refuse_truth_value(value, name)
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not np.isfinite(out) or out <= 0.0:
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    return out


def check_real(value: object, name: str, lo: float, hi: float = math.inf, *, open_lo: bool = False) -> float:
    """``value`` as a finite float in [lo, hi] ((lo, hi] with ``open_lo``); a ValueError naming ``name`` otherwise."""
    refuse_truth_value(value, name)
    try:
        v = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(v) or v < lo or v > hi or (open_lo and v == lo):
        raise ValueError(
            f"{name} must be finite and {'>' if open_lo else '>='} {lo}"
            + (f" and <= {hi}" if hi < math.inf else "")
            + f", got {value!r}"
        )
    return v


def is_integer(value: object) -> bool:
    """True for a Python or NumPy integer; ``bool`` (an ``int`` subclass) is not one."""
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool)


def is_ascii_integer(text: str) -> bool:
    """Whether ``text`` is an integer typed in ASCII digits (a leading minus allowed): ``int()`` also takes
    full-width digits ("１" is 1), a number nobody typed."""
    return text.isascii() and text.removeprefix("-").isdigit()


def is_real_number(value: object) -> bool:
    """True for a Python or NumPy integer or float (not ``bool``); finiteness is not checked."""
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)


def check_int(value: int, name: str, minimum: int | None = None, maximum: int | None = None) -> int:
    """Return ``value`` as a Python ``int`` if it is an integer in [minimum, maximum].

    NumPy integers are accepted, ``bool`` is not (``True`` is no count). Either bound
    may be left out.
    """
    if not is_integer(value):
        raise ValueError(f"{name} must be an integer, got {value!r}")
    if minimum is not None and value < minimum:
        raise ValueError(f"{name} must be >= {minimum}, got {value}")
    if maximum is not None and value > maximum:
        raise ValueError(f"{name} must be <= {maximum}, got {value}")
    return int(value)


def check_int_at_least(value: int, name: str, minimum: int) -> int:
    """Return ``value`` as a Python ``int`` if it is an integer >= ``minimum``."""
    return check_int(value, name, minimum)


def check_optional_int(value: int | None, name: str, minimum: int | None = None) -> int | None:
    """``None``, or ``value`` as a Python ``int`` if it is an integer >= ``minimum``."""
    if value is None:
        return None
    if not is_integer(value):
        raise ValueError(f"{name} must be an integer or None, got {value!r}")
    return check_int(value, name, minimum)


def as_real_array(value: object) -> np.ndarray | None:
    """``value`` as a float64 array if it is plainly numeric (real ints or floats), else None.

    Booleans, strings, object arrays and complex numbers are refused rather than
    converted: ``np.asarray(["1.5"], float)`` or ``[True, False]`` would otherwise
    pass as numbers. Anything that fails to convert (``__float__`` raising, an int too
    large for a float, a torch tensor requiring grad) is refused too.
    """
    if type(value) is np.ndarray and value.dtype == np.float64:
        return value  # the loop's own arrays (the common, per-tick case): returned as they are, not copied
    try:
        if isinstance(value, np.ndarray):
            arr = value
        else:
            arr = np.asarray(value)
            if arr.dtype.kind in "fiu" and arr.size and not isinstance(value, (int, float, np.generic)):
                # A nested sequence mixing bools with numbers converts to float: look inside.
                items = np.asarray(value, dtype=object).ravel()
                if any(isinstance(v, (bool, np.bool_)) for v in items):
                    return None
        if arr.dtype.kind not in "fiu":
            return None
        with np.errstate(over="ignore"):  # float128 beyond float64 becomes inf: flagged as non-finite
            return arr.astype(float, copy=False)
    except Exception:  # noqa: BLE001 -- any failure to convert is bad input, not a crash of the loop
        return None
