"""The shared Levenberg-Marquardt kernel against scipy's least_squares and closed forms."""

from __future__ import annotations

import numpy as np
import pytest

from robocal_casadi.common.least_squares import (
    STATUS,
    Damping,
    Tolerances,
    damped_step,
    levenberg_marquardt,
)

scipy_optimize = pytest.importorskip("scipy.optimize")

T = np.linspace(0.0, 4.0, 40)
TRUTH = np.array([2.5, -1.3, 0.4])


def model(x: np.ndarray) -> np.ndarray:
    return x[0] * np.exp(x[1] * T) + x[2]


def jacobian(x: np.ndarray) -> np.ndarray:
    e = np.exp(x[1] * T)
    return np.column_stack([e, x[0] * T * e, np.ones_like(T)])


NOISE = np.random.default_rng(3).normal(0.0, 1e-3, len(T))
DATA = model(TRUTH) + NOISE


def evaluate(x, _jacobian):
    return model(x) - DATA, jacobian(x)


@pytest.mark.parametrize("damping", [Damping(), Damping(scaling="identity", initial=1e-6),
                                     None], ids=["marquardt", "levenberg", "gauss_newton"])
def test_minimum_matches_scipy(damping):
    x0 = np.array([1.0, -0.5, 0.0])
    fit = levenberg_marquardt(evaluate, x0, max_iterations=200, damping=damping,
                              tolerances=Tolerances(ftol=1e-15, xtol=1e-12))
    reference = scipy_optimize.least_squares(lambda x: model(x) - DATA, x0, jac=lambda x:
                                             jacobian(x), xtol=1e-15, ftol=1e-15, gtol=1e-15)
    assert fit.converged and fit.word == "converged", fit
    np.testing.assert_allclose(fit.x, reference.x, rtol=1e-9, atol=1e-12)
    assert fit.cost == pytest.approx(reference.cost, rel=1e-12)


def test_exact_data_stop_at_the_residual_floor():
    data = model(TRUTH)
    fit = levenberg_marquardt(lambda x, _: (model(x) - data, jacobian(x)),
                              np.array([1.0, -0.5, 0.0]), max_iterations=100,
                              tolerances=Tolerances(residual_floor=1e-12))
    assert fit.status == 4 and STATUS[4][0] == "converged"
    np.testing.assert_allclose(fit.x, TRUTH, rtol=1e-10)


def test_iteration_limit_and_gradient_test():
    x0 = np.array([1.0, -0.5, 0.0])
    limited = levenberg_marquardt(evaluate, x0, max_iterations=1)
    assert (limited.status, limited.word, limited.iterations) == (0, "max_iterations", 1)
    loose = levenberg_marquardt(evaluate, x0, max_iterations=200,
                                tolerances=Tolerances(gtol=1e-6))
    assert loose.status == 1
    r, J = evaluate(loose.x, True)
    cosine = np.abs(J.T @ r) / np.linalg.norm(J, axis=0) / np.linalg.norm(r)
    assert cosine.max() <= 1e-6


def test_bounds_agree_with_scipy_trust_region_reflective():
    x0 = np.array([1.0, -0.5, 0.0])
    lower, upper = np.array([0.0, -1.0, 0.5]), np.array([10.0, 0.0, 1.0])
    fit = levenberg_marquardt(evaluate, x0, max_iterations=500, bounds=(lower, upper),
                              tolerances=Tolerances(ftol=1e-15, xtol=1e-14))
    reference = scipy_optimize.least_squares(lambda x: model(x) - DATA, np.clip(x0, lower, upper),
                                             jac=lambda x: jacobian(x), bounds=(lower, upper),
                                             xtol=1e-15, ftol=1e-15, gtol=1e-15)
    assert fit.x[2] == 0.5  # the offset is held at its lower bound
    np.testing.assert_allclose(fit.x, reference.x, rtol=1e-7, atol=1e-9)


def test_every_unknown_held_at_a_bound():
    # the cost falls outwards for both unknowns, which sit at their upper bounds
    fit = levenberg_marquardt(lambda x, _: (x - 5.0, np.eye(2)), np.array([1.0, 1.0]),
                              max_iterations=10, bounds=(np.zeros(2), np.ones(2)))
    assert (fit.status, fit.word) == (-2, "held")
    np.testing.assert_array_equal(fit.x, [1.0, 1.0])


def test_manifold_state_on_the_unit_circle():
    """Closest point on the unit circle to p, state an angle stored as a unit vector."""
    p = np.array([3.0, 4.0])

    def evaluate_circle(u, _):
        return u - p, np.array([[-u[1]], [u[0]]])

    def retract(u, step):
        c, s = np.cos(step[0]), np.sin(step[0])
        return np.array([c * u[0] - s * u[1], s * u[0] + c * u[1]])

    fit = levenberg_marquardt(evaluate_circle, np.array([1.0, 0.0]), max_iterations=100,
                              retract=retract, coordinates=lambda u: np.zeros(1),
                              tolerances=Tolerances(gtol=1e-12))
    assert fit.converged
    np.testing.assert_allclose(fit.x, p / 5.0, atol=1e-10)


def test_damped_step_is_the_regularised_least_squares_solution():
    rng = np.random.default_rng(0)
    Js, r, mu = rng.normal(size=(12, 4)), rng.normal(size=12), 0.3
    stacked = np.linalg.lstsq(np.vstack([Js, np.sqrt(mu) * np.eye(4)]),
                              np.concatenate([-r, np.zeros(4)]), rcond=None)[0]
    np.testing.assert_allclose(damped_step(Js, r, mu), stacked, rtol=1e-12)
    # rank deficient and undamped: still a least-squares step (not necessarily least-norm)
    deficient = np.column_stack([Js[:, 0], Js[:, 0]])
    step = damped_step(deficient, r, 0.0)
    best = deficient @ (np.linalg.pinv(deficient) @ -r) + r
    assert np.linalg.norm(deficient @ step + r) == pytest.approx(np.linalg.norm(best), rel=1e-9)


def test_a_refused_step_below_xtol_ends_the_fit_without_more_damping():
    # Started at the least-squares minimum of a linear problem, the only steps left are
    # rounding: the first is refused or accepted, and no ladder of ever more damped
    # trials follows (each trial is one residual evaluation).
    rng = np.random.default_rng(11)
    A = rng.normal(size=(200, 4))
    b = A @ np.array([1.0, -2.0, 0.5, 3.0]) + rng.normal(0.0, 1e-3, 200)
    x_min = np.linalg.lstsq(A, b, rcond=None)[0]
    calls = []

    def linear(x, _jacobian):
        calls.append(1)
        return A @ x - b, A

    fit = levenberg_marquardt(linear, x_min.copy(), max_iterations=50,
                              tolerances=Tolerances(xtol=1e-10))
    assert fit.status == 3
    assert len(calls) <= 3  # the start, one trial and at most one more
    np.testing.assert_allclose(fit.x, x_min, rtol=1e-12, atol=1e-14)


def test_a_fit_reaches_the_same_minimum_as_scipy_run_to_convergence():
    # The exponential model from a poor start: our default xtol against scipy with every
    # tolerance at 1e-15, to 1e-9 relative (far above rounding, far below the noise).
    fit = levenberg_marquardt(evaluate, np.array([1.0, -0.5, 0.0]), max_iterations=200,
                              tolerances=Tolerances(xtol=1e-10, ftol=1e-15))
    ref = scipy_optimize.least_squares(lambda x: model(x) - DATA, [1.0, -0.5, 0.0],
                                       jac=jacobian, ftol=1e-15, xtol=1e-15, gtol=1e-15)
    np.testing.assert_allclose(fit.x, ref.x, rtol=1e-9)
