"""A population prior: what the calibrations of robots of one model say about the next one.

Robots of one model share most of their deviation from the drawing (castings, fixtures,
gearboxes). Each robot ``i``'s true deviation ``theta_i`` [SI, p parameters] is taken as a
draw from the model's population,

    theta_i ~ N(mu, Sigma),

and its calibration as a noisy look at it. What a calibration says about ``theta_i`` is
its likelihood, in information form (``Evidence``): ``H_i`` [1/SI^2] the information its
data carry (zero along what they do not see) and ``h_i = H_i y_i`` with ``y_i`` what the
data alone would estimate. A calibration under a Gaussian prior ``N(c0, C0)`` with
posterior mean ``m`` and covariance ``S`` gives them back exactly (for a linear model):
``H = S^-1 - C0^-1`` and ``h = S^-1 m - C0^-1 c0``.

``estimate`` fits ``mu`` and ``Sigma`` by maximising the marginal likelihood of the
robots' evidence with the EM algorithm for the normal random-effects model (Dempster,
Laird and Rubin 1977; Laird and Ware 1982). E step, each robot's posterior under the
current population (``w_i`` its weight, below):

    P_i = w_i Sigma^-1 + H_i,   C_i = P_i^-1,   m_i = C_i (w_i Sigma^-1 mu + h_i);

M step:

    mu    = sum_i w_i m_i / sum_i w_i,
    S     = sum_i w_i [(m_i - mu)(m_i - mu)^T + C_i] / N,

and ``Sigma`` is ``S`` shrunk (below).

Each robot's estimation covariance is taken out of the spread (``C_i``, not the scatter
of raw estimates, enters ``Sigma``) and each robot counts along a parameter as much as its
data saw it: along a direction a robot's data do not see, ``m_i`` is the population's own
prediction and ``C_i`` the population's spread, so that robot neither pulls ``mu`` nor
widens ``Sigma``.

Shrinkage. With few robots against many parameters ``S`` is singular and overconfident.
Variances and correlations are shrunk apart, with the target of Schaefer and Strimmer
(2005, "A shrinkage approach to large-scale covariance matrix estimation", target "D":
correlations toward zero) but fixed intensities instead of their estimated ones:

    sigma_j^2 = (nu0 t_j^2 + N S_jj) / (nu0 + N),         (the tolerance as nu0 robots)
    R         = (1 - lambda) corr(S) + lambda I,  lambda = p_seen / (p_seen + N),
    Sigma     = diag(sigma) R diag(sigma),

``t_j`` the tolerance, ``p_seen`` the parameters at least one robot saw. The variance's
update is the conjugate one of a scaled inverse-chi-square prior worth ``nu0`` robots at
the tolerance (Gelman et al., Bayesian Data Analysis, 3rd ed., section 2.6): with
``nu0 = 0.25`` four robots keep a seventeenth of the tolerance's variance, forty about
0.6 per cent. A parameter no robot saw keeps its tolerance (``S_jj = Sigma_jj`` there, whose
fixed point is ``t_j^2``) and no correlation. The correlations, of which there are
``p^2 / 2`` against ``N`` robots, weigh by how few robots there are per parameter.

An odd robot (one built or repaired off the model) must not drag the mean. Its evidence
is judged against the population by the prior-predictive statistic of its posterior
mean (Box 1980): under the model ``m_i - mu`` has covariance ``Sigma - C_i`` (both at
``w_i = 1``), so

    d_i^2 = (m_i - mu)^T (Sigma - C_i)^+ (m_i - mu)  ~  chi^2(k_i),

``k_i`` the directions its data see (eigenvalues of ``Sigma^-1/2 (Sigma - C_i)
Sigma^-1/2``, each the data's share of one direction, above ``SEEN_SHARE``). Its weight
is that of the multivariate t model's EM (Lange, Little and Taylor 1989),
``w_i = (nu + k_i) / (nu + d_i^2)`` with ``nu = T_DOF``, capped at one (a robot that
belongs counts once, as in the Gaussian model; only one far off, ``w_i ~ k_i / d_i^2``,
counts less). A robot whose ``d_i^2`` exceeds the
``ODD_LEVEL`` quantile of ``chi^2(k_i)`` is named odd.

Units: SI (m, rad) throughout; the caller converts at the file's edge.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.special import chdtri

PSEUDO_ROBOTS = 0.25  # nu0: the tolerance counts as this many robots in each variance
T_DOF = 4.0  # nu: degrees of freedom of the t weights that down-weight an odd robot
ODD_LEVEL = 0.999  # quantile of chi^2(k) beyond which a robot does not belong
SEEN_SHARE = 0.05  # data share of a direction below which it is not counted as seen
SAW_SHARE = 0.5  # data share of a parameter (under the tolerance) for "this robot saw it"
MAX_ROUNDS = 2000
SETTLED = 1e-7  # change of mu, Sigma (in tolerance units) and weights that ends EM


@dataclass(frozen=True)
class Evidence:
    """One robot's calibration as a likelihood of its deviation from nominal [SI]:
    ``information`` ``H`` (p x p, positive semi-definite, zero where unseen) and
    ``natural`` ``h = H y`` (``y`` the data-alone estimate), over the population's
    parameter order."""

    robot: str
    information: np.ndarray
    natural: np.ndarray

    @classmethod
    def from_posterior(cls, robot: str, estimate: np.ndarray, covariance: np.ndarray,
                       prior_centre: np.ndarray, prior_covariance: np.ndarray) -> Evidence:
        """The evidence of a calibration that had posterior mean ``estimate`` and
        ``covariance`` under the prior ``N(prior_centre, prior_covariance)`` (all
        deviations from nominal [SI]); rounding that makes ``H`` slightly indefinite is
        clipped away."""
        posterior_precision = _inverse(covariance)
        prior_precision = _inverse(prior_covariance)
        information = posterior_precision - prior_precision
        values, vectors = np.linalg.eigh(0.5 * (information + information.T))
        # directions the data add less information to than rounding of the prior's: none
        floor = 1e-9 * np.max(np.abs(np.linalg.eigvalsh(prior_precision)))
        values = np.where(values > floor, values, 0.0)
        information = (vectors * values) @ vectors.T
        natural = posterior_precision @ estimate - prior_precision @ prior_centre
        # the part of ``natural`` along unseen directions is rounding too
        seen = vectors[:, values > 0]
        natural = seen @ (seen.T @ natural)
        return cls(robot, information, natural)

    def embedded(self, position: Sequence[int], size: int) -> Evidence:
        """This evidence over ``size`` parameters, its own at ``position`` (zero elsewhere)."""
        information = np.zeros((size, size))
        natural = np.zeros(size)
        index = np.asarray(position, int)
        information[np.ix_(index, index)] = self.information
        natural[index] = self.natural
        return Evidence(self.robot, information, natural)


@dataclass(frozen=True)
class Membership:
    """How one robot's evidence sits against a population: the statistic ``distance``
    (``d^2``, dimensionless), the directions ``seen`` it rests on, the ``threshold`` it is
    judged against and the EM ``weight`` it was given."""

    robot: str
    distance: float
    seen: int
    threshold: float
    weight: float

    @property
    def belongs(self) -> bool:
        return not self.distance > self.threshold


class PopulationFigures:
    """What a population record derives from its ``covariance`` and ``members``: the
    ``spread`` (square roots of the covariance's diagonal, SI) and the ``odd`` robots."""

    covariance: np.ndarray
    members: tuple[Membership, ...]

    @property
    def spread(self) -> np.ndarray:
        return np.sqrt(np.diag(self.covariance))

    @property
    def odd(self) -> tuple[Membership, ...]:
        return tuple(m for m in self.members if not m.belongs)


@dataclass(frozen=True)
class Population(PopulationFigures):
    """The population of one model: ``mean`` deviation from nominal [SI] and
    ``covariance`` [SI^2] over ``names``; ``spread`` the square roots of its diagonal;
    ``seen_by`` how many robots' data decided at least half of each parameter;
    ``members`` each robot's statistic; ``rounds`` the EM rounds spent."""

    names: tuple[str, ...]
    mean: np.ndarray
    covariance: np.ndarray
    seen_by: tuple[int, ...]
    members: tuple[Membership, ...]
    rounds: int


    def __repr__(self) -> str:
        return (f"Population({len(self.names)} parameters, {len(self.members)} robots, "
                f"{len(self.odd)} odd)")


def membership(robot: str, information: np.ndarray, natural: np.ndarray, mean: np.ndarray,
               covariance: np.ndarray, weight: float = 1.0) -> Membership:
    """The prior-predictive statistic of one robot's evidence (module docstring)."""
    posterior, centre = _posteriors(information[None], natural[None], mean, covariance,
                                    np.ones(1))
    return conflict(robot, centre[0] - mean, covariance, posterior[0], weight)


def conflict(robot: str, offset: np.ndarray, prior_covariance: np.ndarray,
             posterior_covariance: np.ndarray, weight: float = 1.0) -> Membership:
    """``d^2 = offset^T (C0 - S)^+ offset`` with ``offset`` the posterior mean less the
    prior centre [SI], ``C0`` the prior's and ``S`` the posterior's covariance: the
    prior-data conflict of a calibration (chi-square with the seen directions' count)."""
    root = np.linalg.cholesky(prior_covariance)
    whitened_posterior = _solve_both(root, posterior_covariance)
    share = np.eye(len(offset)) - whitened_posterior
    values, vectors = np.linalg.eigh(0.5 * (share + share.T))
    seen = values > SEEN_SHARE
    z = vectors[:, seen].T @ np.linalg.solve(root, offset)
    distance = float(np.sum(z**2 / values[seen]))
    k = int(seen.sum())
    return Membership(robot, distance, k, _threshold(k), float(weight))


def estimate(evidence: Sequence[Evidence], names: Sequence[str], tolerance: np.ndarray,
             pseudo_robots: float = PSEUDO_ROBOTS) -> Population:
    """The population ``N(mu, Sigma)`` over ``names`` from the robots' ``evidence``
    (module docstring); ``tolerance`` [SI] per parameter sets the shrinkage target.

    Computed in units of the tolerances (each parameter divided by its own), where every
    matrix is of order one; the robots of a round are solved together."""
    tolerance = np.asarray(tolerance, float)
    p = len(names)
    if not evidence:
        raise ValueError("expected at least one robot's evidence, got none")
    if pseudo_robots <= 0:
        raise ValueError(f"pseudo_robots must be > 0, got {pseudo_robots}")
    information = np.array([e.information for e in evidence]) * np.outer(tolerance, tolerance)
    natural = np.array([e.natural for e in evidence]) * tolerance
    ones = np.ones(p)
    shares = 1.0 - np.diagonal(np.linalg.inv(np.eye(p) + information), axis1=1, axis2=2)
    seen = int(np.sum(np.any(shares >= SAW_SHARE, axis=0)))
    mean, covariance = np.zeros(p), np.eye(p)
    weights = np.ones(len(evidence))
    rounds = 0
    while rounds < MAX_ROUNDS:
        rounds += 1
        posterior, centre = _posteriors(information, natural, mean, covariance, weights)
        new_mean = weights @ centre / weights.sum()
        offset = centre - new_mean
        scatter = np.einsum("i,ij,ik->jk", weights, offset, offset) + np.einsum(
            "i,ijk->jk", weights, posterior)
        new_covariance = _shrunk(scatter / len(evidence), ones, len(evidence), pseudo_robots,
                                 seen)
        distance, count = _distances(information, natural, new_mean, new_covariance)
        new_weights = np.minimum(1.0, (T_DOF + count) / (T_DOF + distance))
        change = max(np.max(np.abs(new_mean - mean)),
                     np.max(np.abs(new_covariance - covariance)),
                     np.max(np.abs(new_weights - weights)))
        mean, covariance, weights = new_mean, new_covariance, new_weights
        if change < SETTLED:
            break
    distance, count = _distances(information, natural, mean, covariance)
    members = tuple(Membership(e.robot, float(d), int(k), _threshold(int(k)), float(w))
                    for e, d, k, w in zip(evidence, distance, count, weights))
    seen_by = tuple(int(k) for k in np.sum(shares >= SAW_SHARE, axis=0))
    return Population(tuple(names), mean * tolerance,
                      covariance * np.outer(tolerance, tolerance), seen_by, members, rounds)


def _threshold(seen: int) -> float:
    """The ``ODD_LEVEL`` quantile of chi^2(``seen``) (infinite for none seen)."""
    return float(chdtri(seen, 1.0 - ODD_LEVEL)) if seen else math.inf


def _posteriors(information: np.ndarray, natural: np.ndarray, mean: np.ndarray,
                covariance: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every robot's posterior covariance and mean under ``N(mean, covariance / w_i)``."""
    precision = _inverse(covariance)
    posterior = np.linalg.inv(weights[:, None, None] * precision + information)
    posterior = 0.5 * (posterior + np.swapaxes(posterior, 1, 2))
    pulled = weights[:, None] * (precision @ mean) + natural
    return posterior, np.einsum("ijk,ik->ij", posterior, pulled)


def _distances(information: np.ndarray, natural: np.ndarray, mean: np.ndarray,
               covariance: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every robot's prior-predictive statistic ``d^2`` and directions seen (``conflict``)
    at weight one."""
    posterior, centre = _posteriors(information, natural, mean, covariance,
                                    np.ones(len(information)))
    inverse_root = np.linalg.inv(np.linalg.cholesky(covariance))
    whitened = inverse_root @ posterior @ inverse_root.T
    share = np.eye(len(mean)) - 0.5 * (whitened + np.swapaxes(whitened, 1, 2))
    values, vectors = np.linalg.eigh(share)
    z = np.einsum("ijk,ij->ik", vectors, (centre - mean) @ inverse_root.T)
    seen = values > SEEN_SHARE
    distance = np.sum(np.where(seen, z**2 / np.where(seen, values, 1.0), 0.0), axis=1)
    return distance, seen.sum(axis=1)


def _shrunk(scatter: np.ndarray, tolerance: np.ndarray, robots: int, pseudo_robots: float,
            seen: int) -> np.ndarray:
    """The M step's covariance ``S`` shrunk: variances toward the tolerances, correlations
    toward zero (module docstring)."""
    variance = (pseudo_robots * tolerance**2 + robots * np.diag(scatter)) / (pseudo_robots
                                                                              + robots)
    root = np.sqrt(np.diag(scatter))
    correlation = scatter / np.outer(root, root)
    weight = seen / (seen + robots)
    correlation = (1.0 - weight) * correlation + weight * np.eye(len(tolerance))
    sigma = np.sqrt(variance)
    out = correlation * np.outer(sigma, sigma)
    return 0.5 * (out + out.T)


def _inverse(matrix: np.ndarray) -> np.ndarray:
    """The inverse of a symmetric positive definite ``matrix``, symmetric to rounding."""
    root = np.linalg.cholesky(0.5 * (matrix + matrix.T))
    inverse_root = np.linalg.solve(root, np.eye(len(matrix)))
    return inverse_root.T @ inverse_root


def _solve_both(root: np.ndarray, matrix: np.ndarray) -> np.ndarray:
    """``L^-1 M L^-T`` for the lower triangular ``root`` ``L``."""
    left = np.linalg.solve(root, matrix)
    return np.linalg.solve(root, left.T).T
