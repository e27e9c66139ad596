"""The outcome of a fit: fitted scene and values, their standard errors and correlations, and
what the data leave undetermined.

Standard errors are those of nonlinear least squares at the optimum (Press et al., Numerical
Recipes, 3rd ed. 2007, sec. 15.5, eqs. 15.5.15 and 15.4.18): covariance ``sigma^2 (J^T J)^-1``
with ``J`` the Jacobian of the residuals and ``sigma^2 = |r|^2 / (M - P)`` the residual
variance of M residuals and P parameters.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..scene import Scene

__all__ = ["FitResult", "covariance", "diagnose", "misfit"]

#: Condition number of the column-normalised Jacobian beyond which the parameters are called
#: unidentifiable from the data (their combination is pinned, not each one).
MAX_CONDITION = 1e6
#: Correlation beyond which a pair of parameters is named as the cause.
HIGH_CORRELATION = 0.99
#: RMS of the residuals in standard deviations above which the stated sigmas and the model do
#: not describe the data (an RMS chi of 1 is a fit within the noise; 2 is four times the
#: variance the sigmas allow).
MAX_CHI = 2.0


@dataclass
class FitResult:
    """A fitted template.

    Attributes
    ----------
    scene : Scene
        The template with the fitted values (``scene.to_dict()`` writes it).
    params : dict
        Parameter name -> fitted value (its field's unit).
    uncertainty : dict
        Parameter name -> standard error (same unit); ``inf`` where undetermined.
    correlation : ndarray, shape (P, P)
        Correlations of the parameters (order of ``params``).
    residual : float
        RMS of the residuals, final plan: ``(f_model - f_target) cos(theta_o)`` (1/sr), or
        ``(f_model - f) / sigma`` for measurements with standard deviations.
    unit : str
        What the residuals are measured in.
    residuals : ndarray, shape (M,)
        The residuals themselves.
    history : list of dict
        Every solve: ``stage``, ``n``, ``md``, ``x`` (the values), ``rms``.
    warnings : list of str
        Degenerate or unidentifiable parameters, parameters at a bound, a stopped optimiser.
    plans : list of dict
        Per stage, the ``n`` and ``md`` it solved with and its evaluation count.
    """

    scene: Scene
    params: dict
    uncertainty: dict
    correlation: np.ndarray
    residual: float
    residuals: np.ndarray
    unit: str = "1/sr (f cos theta_o)"
    history: list = field(default_factory=list)
    warnings: list = field(default_factory=list)
    plans: list = field(default_factory=list)

    def summary(self) -> str:
        """One line per parameter, ``name = value +- error``, then the RMS residual and the
        warnings."""
        lines = [f"{k} = {v:.6g} +- {self.uncertainty[k]:.2g}" for k, v in self.params.items()]
        lines.append(f"rms residual = {self.residual:.3g} {self.unit}")
        lines += [f"warning: {w}" for w in self.warnings]
        return "\n".join(lines)


def covariance(jac: np.ndarray, residuals: np.ndarray) -> tuple:
    """Covariance of the parameters, ``sigma^2 (J^T J)^+``, and the condition number of the
    column-normalised ``J``.

    Parameters
    ----------
    jac : ndarray, shape (M, P)
    residuals : ndarray, shape (M,)

    Returns
    -------
    cov : ndarray, shape (P, P)
        ``inf`` on the diagonal of a parameter the residuals do not depend on.
    cond : float
    """
    m, p = jac.shape
    sigma2 = float(residuals @ residuals) / max(m - p, 1)
    norms = np.linalg.norm(jac, axis=0)
    scale = np.where(norms > 0, norms, 1.0)
    js = jac / scale
    s = np.linalg.svd(js, compute_uv=False)
    cond = float(s[0] / s[-1]) if s[-1] > 0 else float("inf")
    cov = sigma2 * np.linalg.pinv(js.T @ js) / np.outer(scale, scale)
    cov[norms == 0, norms == 0] = np.inf
    return cov, cond


def correlation(cov: np.ndarray) -> np.ndarray:
    """Correlation matrix of a covariance (0 off the diagonal of an undetermined parameter)."""
    d = np.sqrt(np.diag(cov))
    with np.errstate(invalid="ignore", divide="ignore"):
        c = cov / np.outer(d, d)
    c[~np.isfinite(c)] = 0.0
    np.fill_diagonal(c, 1.0)
    return c


def diagnose(names, x, lo, hi, jac, cond, corr, active) -> list:
    """Warnings for parameters the data leave undetermined or that end at a bound."""
    out = []
    for k, name in enumerate(names):
        if not np.any(jac[:, k]):
            out.append(f"{name} does not change the residuals: it is undetermined by the data")
        if active[k] != 0 or np.isclose(x[k], lo[k], rtol=0, atol=1e-9 * (hi[k] - lo[k])) \
                or np.isclose(x[k], hi[k], rtol=0, atol=1e-9 * (hi[k] - lo[k])):
            end = "lower" if abs(x[k] - lo[k]) <= abs(x[k] - hi[k]) else "upper"
            out.append(f"{name} = {x[k]:.6g} is at its {end} bound: the optimum may lie "
                       "beyond it, and its standard error assumes it does not")
    if cond > MAX_CONDITION:
        pairs = [f"{names[a]} and {names[b]} (correlation {corr[a, b]:+.3f})"
                 for a in range(len(names)) for b in range(a + 1, len(names))
                 if abs(corr[a, b]) > HIGH_CORRELATION]
        out.append(f"J^T J is ill-conditioned (condition number of the normalised Jacobian "
                   f"{cond:.3g}): the data pin combinations of the parameters, not each one"
                   + ("; " + ", ".join(pairs) if pairs else ""))
    return out


def misfit(residuals: np.ndarray, unit: str) -> list:
    """A warning where measurements with stated standard deviations are fitted far outside them
    (RMS chi above :data:`MAX_CHI`): the model cannot reach the data, or the sigmas are too small
    (e.g. readings of 0 given a sigma relative to f; give them a floor)."""
    if unit != "sigma (chi)" or residuals.size == 0:
        return []
    chi = float(np.sqrt(np.mean(np.square(residuals))))
    if chi <= MAX_CHI:
        return []
    worst = float(np.max(np.abs(residuals)))
    return [f"the residuals are {chi:.3g} standard deviations RMS (largest {worst:.3g}): the model "
            "does not fit the data within the stated sigmas, or the sigmas are too small (readings "
            "of 0 with a relative sigma need a floor); the uncertainties assume a fit within them"]
