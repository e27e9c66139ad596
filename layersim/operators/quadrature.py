"""Quadrature rules on mu = cos(theta) in [-1, 1] that avoid mu = 0.

Each rule returns ``(nodes, weights)`` for ``n`` nodes in increasing order, symmetric about 0,
with ``n`` even so that no node lies on the horizon (mu = 0, where the discrete-ordinates
operators are singular). The solver keeps the positive half (``n // 2`` nodes) for each
hemisphere; see :func:`hemisphere`.

===================  ==============================  ==========================================
rule                 exact for polynomials of degree  notes
===================  ==============================  ==========================================
``gauss-legendre``   2n - 1                           no node at mu = +-1
``gauss-lobatto``    2n - 3                           nodes at mu = +-1 (normal incidence)
``simpson38``        3 (error O(h^4))                 n = 3k + 1 equispaced nodes, k odd
===================  ==============================  ==========================================

``snell:<eta>`` (hemisphere only, :func:`snell_matched`) is the grid of a stack with a smooth
dielectric boundary of relative index ``eta > 1``: its nodes inside the escape cone are the Snell
images of a Gauss-Radau rule on the outside hemisphere, and the total-internal-reflection range
has its own Gauss-Legendre rule (as adding-doubling codes for slabs with mismatched boundaries do:
Prahl 1995, "The adding-doubling method", sec. 4, and iadpython).

References: Abramowitz & Stegun (1964) 25.4.29-25.4.32; Chandrasekhar (1960), ch. II.
"""

from __future__ import annotations

import numpy as np
import scipy.special

__all__ = ["gauss_legendre", "gauss_lobatto", "simpson38", "rule", "hemisphere"]


def _check_even(n: int, minimum: int = 2) -> None:
    if not isinstance(n, (int, np.integer)) or n < minimum or n % 2:
        raise ValueError(f"need an even number of nodes >= {minimum} (no node at mu = 0), "
                         f"got {n!r}")


def gauss_legendre(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre rule with ``n`` nodes on [-1, 1] (exact to degree 2n - 1)."""
    _check_even(n)
    x, w = scipy.special.roots_legendre(n)
    return np.asarray(x, float), np.asarray(w, float)


def gauss_lobatto(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Lobatto rule with ``n`` nodes on [-1, 1] including both endpoints (exact to degree
    2n - 3).

    Interior nodes are the roots of P'_{n-1}, found by Newton's method from the Chebyshev-Gauss-
    Lobatto points (quadratic convergence; stable for n in the thousands, unlike companion-matrix
    root finding). Weights: 2 / (n (n - 1) P_{n-1}(x)^2) (A&S 25.4.32).
    """
    _check_even(n, 4)
    N = n - 1
    x = -np.cos(np.pi * np.arange(n) / N)
    for _ in range(100):
        # Legendre recurrence: p1 = P_N(x), p0 = P_{N-1}(x)
        p0, p1 = np.ones_like(x), x.copy()
        for k in range(2, N + 1):
            p0, p1 = p1, ((2 * k - 1) * x * p1 - (k - 1) * p0) / k
        # Newton step on (1 - x^2) P_N'(x) = N (P_{N-1} - x P_N), written with the standard
        # Lobatto update (von Winckel's form), valid at the endpoints too.
        dx = (x * p1 - p0) / (n * p1)
        x = x - dx
        if np.max(np.abs(dx)) < 1e-15:
            break
    x[0], x[-1] = -1.0, 1.0
    x = 0.5 * (x - x[::-1])  # enforce exact symmetry
    p0, p1 = np.ones_like(x), x.copy()
    for k in range(2, N + 1):
        p0, p1 = p1, ((2 * k - 1) * x * p1 - (k - 1) * p0) / k
    w = 2.0 / (N * n * p1 * p1)
    return x, w


def simpson38(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Composite Simpson 3/8 rule with ``n = 3k + 1`` equispaced nodes on [-1, 1], ``k`` odd so
    that ``n`` is even (exact to degree 3 per panel of three intervals)."""
    _check_even(n, 4)
    if (n - 1) % 3:
        raise ValueError(f"composite Simpson 3/8 needs n = 3k + 1 nodes (k odd), got {n}")
    k = (n - 1) // 3
    x = np.linspace(-1.0, 1.0, n)
    h = 2.0 / (n - 1)
    w = np.zeros(n)
    for p in range(k):
        w[3 * p:3 * p + 4] += np.array([1.0, 3.0, 3.0, 1.0]) * (3.0 * h / 8.0)
    return x, w


_RULES = {"gauss-legendre": gauss_legendre, "gauss-lobatto": gauss_lobatto,
          "simpson38": simpson38}


def rule(name: str, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The named rule (one of ``gauss-legendre``, ``gauss-lobatto``, ``simpson38``)."""
    try:
        return _RULES[name](n)
    except KeyError:
        raise ValueError(f"unknown quadrature rule {name!r}; expected one of "
                         + ", ".join(_RULES)) from None


def gauss_radau(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Radau rule with ``n`` nodes on [-1, 1] including ``+1`` (exact to degree
    2n - 2): the roots of ``(P_{n-1}(-x) + P_n(-x)) / (1 - x)`` and 1, weights
    ``(1 + x) / (n^2 P_{n-1}(x)^2)`` and ``2 / n^2`` (A&S 25.4.31, reflected)."""
    c = np.zeros(n + 1)
    c[n - 1] = c[n] = 1.0
    t = np.sort(np.polynomial.legendre.legroots(c).real)[1:]     # drop t = -1
    p = np.polynomial.legendre.legval(t, np.eye(n)[n - 1])
    w = (1.0 - t) / (n * n * p * p)
    x = np.concatenate([np.sort(-t), [1.0]])
    return x, np.concatenate([w[::-1], [2.0 / n**2]])


SNELL = "snell:"


def snell_rule(eta: float) -> str:
    """The name of the Snell-matched rule for relative index ``eta`` (see :func:`snell_matched`)."""
    return f"{SNELL}{float(eta)!r}"


def snell_split(h: int, eta: float) -> int:
    """Nodes of the Snell-matched hemisphere (``h`` in all) that lie in the escape cone: in
    proportion to the cone's polar angle, at least 4 on either side."""
    theta_c = np.arcsin(1.0 / eta)
    return int(min(h - 4, max(4, round(h * theta_c / (np.pi / 2)))))


def snell_matched(eta: float, h: int) -> tuple[np.ndarray, np.ndarray]:
    """Hemisphere nodes and weights matched across a smooth boundary of relative index ``eta``.

    ``h_e = snell_split(h, eta)`` outside nodes ``x_j`` and weights ``v_j`` of Gauss-Radau on
    (0, 1] (normal incidence is a node, as in the default Gauss-Lobatto grids) map to the inside
    cosines ``mu_j = sqrt(1 - (1 - x_j^2) / eta^2)`` in (mu_c, 1) with weights
    ``v_j x_j / (eta^2 mu_j)`` (``mu dmu = x dx / eta^2``), so that the flux weights ``w mu`` of an
    outside node and its image differ by exactly ``eta^2`` and a sum over the escape cone is the
    outside rule's sum. The total-internal-reflection range (0, mu_c),
    ``mu_c = sqrt(1 - 1 / eta^2)``, gets Gauss-Legendre with the other ``h - h_e`` nodes.
    Returns increasing nodes (h,) and weights (h,).
    """
    eta = float(eta)
    if not eta > 1.0:
        raise ValueError(f"a Snell-matched grid needs a relative index above 1, got {eta!r}")
    if h < 8:
        raise ValueError(f"a Snell-matched grid needs at least 8 nodes per hemisphere, got {h}")
    h_e = snell_split(h, eta)
    mu_c = np.sqrt(1.0 - 1.0 / eta**2)
    x, v = gauss_radau(h_e)
    x, v = 0.5 * (x + 1.0), 0.5 * v
    mu_e = np.sqrt(1.0 - (1.0 - x * x) / eta**2)
    w_e = v * x / (eta**2 * mu_e)
    t, u = scipy.special.roots_legendre(h - h_e)
    mu_t, w_t = 0.5 * mu_c * (t + 1.0), 0.5 * mu_c * u
    return np.concatenate([mu_t, mu_e]), np.concatenate([w_t, w_e])


def hemisphere(name: str, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Positive half of the named rule: ``n // 2`` nodes in (0, 1], increasing, with weights.

    The solver uses these for both hemispheres (the rules are symmetric). ``snell:<eta>``
    names the hemisphere rule :func:`snell_matched`.
    """
    if name.startswith(SNELL):
        _check_even(n, 16)
        try:
            eta = float(name[len(SNELL):])
        except ValueError:
            raise ValueError(f"bad Snell-matched rule name {name!r}") from None
        return snell_matched(eta, n // 2)
    x, w = rule(name, n)
    h = n // 2
    return x[h:].copy(), w[h:].copy()
