"""The two distribution functions the gap estimator needs, from ``scipy.special`` instead of ``scipy.stats``.

``scipy.stats``' generic distribution methods check and broadcast their arguments on every call:
``stats.f.sf`` costs ~210 us and ``stats.t.ppf`` ~260 us a call here, for two numbers that ``scipy.stats`` itself
takes from ``scipy.special`` (``t._ppf`` is ``stdtrit``, ``f._sf`` is ``fdtrc``), which cost 3-6 us.  They
return the same float, bit for bit, for the arguments used here (test_distributions.py compares them with
``scipy.stats`` to 1e-12).  (This saves per-call time, not import time: ``scipy.signal``, which gap.py needs for
``savgol_filter``, imports ``scipy.stats`` itself.)
"""
from __future__ import annotations

from scipy.special import fdtrc, stdtrit


def t_quantile(q: float, dof: float) -> float:
    """Student t quantile: the x with P(T <= x) = q for T ~ t(dof); as ``scipy.stats.t.ppf(q, dof)``
    for 0 < q < 1 and dof > 0."""
    return float(stdtrit(dof, q))


def f_survival(x: float, dfn: float, dfd: float) -> float:
    """Survival function P(F > x) of the F(dfn, dfd) distribution; as ``scipy.stats.f.sf(x, dfn, dfd)``
    for x >= 0 and dfn, dfd > 0."""
    return float(fdtrc(dfn, dfd, x))
