"""Plain numbers in one-line messages: numpy scalars' reprs (``np.float64(2.3985)``, ``np.True_``) as the plain
number a reader expects (``2.3985``, ``True``).  Applied where a message leaves the program (the nodes'
statuses and logs, ``jident diagnose``'s lines), so that a ``{value!r}`` deep inside never shows numpy's repr."""
from __future__ import annotations

import re

__all__ = ["plain_numbers"]

_NP_SCALAR = re.compile(r"\bnp\.(?:float|int|uint|complex|longdouble|double|single|half)\d*\(([^()]*)\)")
_NP_BOOL = re.compile(r"\bnp\.(True|False)_")


def plain_numbers(text: str) -> str:
    """``text`` with numpy scalar reprs replaced by their plain values."""
    if "np." not in text:
        return text
    return _NP_BOOL.sub(r"\1", _NP_SCALAR.sub(r"\1", text))
