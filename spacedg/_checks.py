"""Small validation helpers that produce the project's uniform error messages.

Array messages follow one pattern: ``"<source>: field '<name>': <what> (<count> of <total>,
first at index <i>: <value>). <fix>"`` so a user can find the record and knows what to do.
Scalar and pose checks (:func:`finite_float`, :func:`require_homogeneous`) start with the
caller's ``what`` (where the value came from and its name) and raise the caller's error type.
"""

from __future__ import annotations

import math

import numpy as np

from spacedg.errors import InvalidDataError, ParameterError


def _where(source: str, field: str) -> str:
    return f"{source}: field {field!r}"


def first_bad(mask: np.ndarray) -> tuple[int, int]:
    """Return ``(count, first_row)`` of True entries of ``mask`` (rows for 2-D masks)."""
    rows = mask.reshape(mask.shape[0], -1).any(axis=1) if mask.ndim > 1 else mask
    idx = np.flatnonzero(rows)
    return int(idx.size), int(idx[0]) if idx.size else -1


def as_array(value: object, field: str, source: str, dtype: np.dtype | type) -> np.ndarray:
    """Convert ``value`` to a C-contiguous array of ``dtype`` or fail naming the field."""
    try:
        return np.ascontiguousarray(np.asarray(value), dtype=dtype)
    except (TypeError, ValueError) as err:
        raise InvalidDataError(f"{_where(source, field)}: cannot convert to {np.dtype(dtype).name} ({err})") from err


def require_shape(array: np.ndarray, shape: tuple[int | None, ...], field: str, source: str) -> None:
    """Require ``array.shape`` to match ``shape`` (``None`` matches any size)."""
    ok = array.ndim == len(shape) and all(want is None or got == want for got, want in zip(array.shape, shape))
    if not ok:
        pretty = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
        raise InvalidDataError(f"{_where(source, field)}: expected shape {pretty}, got {tuple(array.shape)}")


def require_finite(array: np.ndarray, field: str, source: str) -> None:
    """Reject NaN and +/-Inf entries."""
    bad = ~np.isfinite(array)
    if bad.any():
        count, row = first_bad(bad)
        raise InvalidDataError(
            f"{_where(source, field)}: {count} of {array.shape[0]} entries hold NaN or Inf "
            f"(first at index {row}: {array[row].tolist()}). Remove or repair those entries."
        )


def require_range(
    array: np.ndarray,
    low: float | None,
    high: float | None,
    field: str,
    source: str,
    hint: str = "",
) -> None:
    """Require ``low <= array <= high`` elementwise (either bound may be ``None``)."""
    bad = np.zeros(array.shape, dtype=bool)
    if low is not None:
        bad |= array < low
    if high is not None:
        bad |= array > high
    if bad.any():
        count, row = first_bad(bad)
        lo = "-inf" if low is None else f"{low:g}"
        hi = "inf" if high is None else f"{high:g}"
        raise InvalidDataError(
            f"{_where(source, field)}: {count} of {array.shape[0]} entries outside [{lo}, {hi}] "
            f"(first at index {row}: {array[row].tolist()}).{(' ' + hint) if hint else ''}"
        )


def require_same_length(lengths: dict[str, int], source: str) -> None:
    """Require all named arrays to have the same first dimension."""
    if len(set(lengths.values())) > 1:
        listing = ", ".join(f"{k}={v}" for k, v in lengths.items())
        raise InvalidDataError(f"{source}: mismatched lengths ({listing}); every per-Gaussian field needs one row per Gaussian")


def require_rotation(matrix: np.ndarray, field: str, source: str, tol: float = 1e-5) -> None:
    """Require a proper rotation matrix (orthonormal, determinant +1) within ``tol``."""
    require_shape(matrix, (3, 3), field, source)
    if not np.isfinite(matrix).all():
        raise InvalidDataError(f"{_where(source, field)}: holds NaN or Inf: {matrix.tolist()}")
    err = float(np.abs(matrix.T @ matrix - np.eye(3)).max())
    if err > tol:
        raise InvalidDataError(f"{_where(source, field)}: not orthonormal (max |RᵀR − I| = {err:.3g} > {tol:g})")
    det = float(np.linalg.det(matrix))
    if det < 0:
        raise InvalidDataError(f"{_where(source, field)}: is a reflection (det = {det:.3g}); flip one axis to get a right-handed rotation")


def _short(value: object, limit: int = 80) -> str:
    """``repr(value)`` cut to ``limit`` characters (a hostile value may be megabytes long)."""
    try:
        text = repr(value)
    except ValueError:  # int repr beyond Python's digit limit
        return "<a number too long to print>"
    return text if len(text) <= limit else f"{text[:limit]}… ({len(text):,} characters)"


def finite_float(value: object, what: str, error: type[Exception] = InvalidDataError) -> float:
    """``value`` as a finite ``float``; else ``error("<what> must be a number, got …")`` or ``("<what> must be finite, got …")``."""
    try:
        number = float(value)  # type: ignore[arg-type]
    except OverflowError:  # an integer beyond float range (> 1.8e308)
        digits = int(int(value).bit_length() * 0.30103) + 1  # type: ignore[call-overload]
        raise error(f"{what} must be finite, got an integer of about {digits:,} digits") from None
    except (TypeError, ValueError):
        raise error(f"{what} must be a number, got {_short(value)}") from None
    if not math.isfinite(number):
        raise error(f"{what} must be finite, got {number}")
    return number


def require_homogeneous(matrix: np.ndarray, what: str, error: type[Exception] = InvalidDataError) -> None:
    """Require a 4×4 pose matrix (shape checked by the caller) to be finite with last row ``[0, 0, 0, 1]`` (atol 1e-9).

    Raises ``error("<what> holds NaN or Inf")`` or ``error("<what> last row must be [0, 0, 0, 1], got …")``.
    """
    if not np.isfinite(matrix).all():
        raise error(f"{what} holds NaN or Inf")
    if not np.allclose(matrix[3], [0.0, 0.0, 0.0, 1.0], atol=1e-9):
        raise error(f"{what} last row must be [0, 0, 0, 1], got {matrix[3].tolist()}")


# ------------------------------------------------------------------ arguments of public calls
# Each raises ``error`` (ParameterError by default) with "<argument> must be <what it accepts>,
# got <what it got>"; ``argument`` names the call too, e.g. "SpaceDGDataset: split_fractions".
#: ``repr(value)`` cut to ``limit`` characters, for error messages (the public name of :func:`_short`).
short_repr = _short


def check_choice(value: object, argument: str, choices: tuple[str, ...] | list[str], error: type[Exception] | None = None) -> str:
    """``value`` if it is one of ``choices`` (strings), else ``error``."""
    if not isinstance(value, str) or value not in choices:
        raise (error or ParameterError)(f"{argument} must be one of {list(choices)}, got {_short(value)}")
    return value


def check_int(
    value: object, argument: str, *, minimum: int | None = None, maximum: int | None = None, error: type[Exception] | None = None,
) -> int:
    """``value`` as an ``int`` (a Python or numpy integer, not a bool) within ``[minimum, maximum]``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise (error or ParameterError)(f"{argument} must be an integer{_bounds(minimum, maximum)}, got {_short(value)}")
    number = int(value)
    if (minimum is not None and number < minimum) or (maximum is not None and number > maximum):
        raise (error or ParameterError)(f"{argument} must be an integer{_bounds(minimum, maximum)}, got {_short(value)}")
    return number


def check_number(
    value: object, argument: str, *, low: float | None = None, high: float | None = None, error: type[Exception] | None = None,
) -> float:
    """``value`` as a finite ``float`` (an int, float or numpy number, not a bool) within ``[low, high]``."""
    kind = error or ParameterError
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise kind(f"{argument} must be a number{_bounds(low, high)}, got {_short(value)}")
    number = finite_float(value, argument, kind)
    if (low is not None and number < low) or (high is not None and number > high):
        raise kind(f"{argument} must be a number{_bounds(low, high)}, got {_short(value)}")
    return number


def check_bool(value: object, argument: str, error: type[Exception] | None = None) -> bool:
    """``value`` if it is ``True`` or ``False`` (numpy bools too)."""
    if not isinstance(value, (bool, np.bool_)):
        raise (error or ParameterError)(f"{argument} must be True or False, got {_short(value)}")
    return bool(value)


def check_names(value: object, argument: str, error: type[Exception] | None = None) -> tuple[str, ...]:
    """A non-empty list (or tuple, set) of non-empty strings; a lone string is refused (it would be read letter by letter)."""
    kind = error or ParameterError
    if isinstance(value, (str, bytes)) or not isinstance(value, (list, tuple, set, frozenset)):
        raise kind(f"{argument} must be a list of names, e.g. [{_short(value)}], got {_short(value)}")
    names = tuple(value)
    if not names or any(not isinstance(n, str) or not n.strip() for n in names):
        raise kind(f"{argument} must be a non-empty list of non-empty strings, got {_short(value)}")
    return names


def check_image_size(value: object, argument: str, error: type[Exception] | None = None) -> tuple[int, int] | None:
    """``None`` or ``(width, height)`` as two positive integers (pixels)."""
    if value is None:
        return None
    kind = error or ParameterError
    if isinstance(value, (str, bytes)) or not isinstance(value, (tuple, list)) or len(value) != 2:
        raise kind(f"{argument} must be (width, height) in pixels, two positive integers, or None; got {_short(value)}")
    width, height = (check_int(v, f"{argument} {side}", minimum=1, error=kind) for v, side in zip(value, ("width", "height")))
    return width, height


def check_fractions(value: object, argument: str, error: type[Exception] | None = None) -> tuple[float, float]:
    """``(val, bench)``: two numbers in [0, 1] whose sum is at most 1."""
    kind = error or ParameterError
    if isinstance(value, (str, bytes)) or not isinstance(value, (tuple, list)) or len(value) != 2:
        raise kind(f"{argument} must be (val, bench): two fractions in [0, 1] summing to at most 1, e.g. (0.1, 0.1); got {_short(value)}")
    val, bench = (check_number(v, f"{argument} {side}", low=0.0, high=1.0, error=kind) for v, side in zip(value, ("val", "bench")))
    if val + bench > 1.0 + 1e-9:
        raise kind(f"{argument} (val, bench) must sum to at most 1, got {_short(value)} (sum {val + bench:g})")
    return val, bench


def _bounds(low: float | None, high: float | None) -> str:
    if low is not None and high is not None:
        return f" in [{low:g}, {high:g}]"
    if low is not None:
        return f" >= {low:g}"
    if high is not None:
        return f" <= {high:g}"
    return ""
