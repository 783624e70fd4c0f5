"""GP + EI against known optima, failure handling, determinism and resume."""

import numpy as np
import pytest

from driftlab.core.errors import ConfigError
from driftlab.core.optimizer import BayesianOptimizer
from tests.core.functions import BRANIN_BOUNDS, BRANIN_MIN, HARTMANN6_BOUNDS, HARTMANN6_MIN, branin, hartmann6


def _bo_regret(f, bounds, f_min, budget, seed, seed_points):
    opt = BayesianOptimizer(bounds, seed_points=seed_points, seed=seed)
    for _ in range(budget):
        theta = opt.ask()
        opt.tell(theta, f(theta))
    return opt.best[1] - f_min


def _random_regret(f, bounds, f_min, budget, seed):
    rng = np.random.default_rng(seed)
    return min(f({k: rng.uniform(*b) for k, b in bounds.items()}) for _ in range(budget)) - f_min


def test_branin_reaches_low_regret_and_beats_random_search():
    # Published GP+EI reaches ~1e-3 regret on Branin within ~40 evaluations.
    bo = [_bo_regret(branin, BRANIN_BOUNDS, BRANIN_MIN, 40, s, 10) for s in range(3)]
    rnd = [_random_regret(branin, BRANIN_BOUNDS, BRANIN_MIN, 40, s) for s in range(3)]
    assert np.median(bo) < 1e-3
    assert max(bo) < 1e-2
    assert np.median(bo) < 0.01 * np.median(rnd)


def test_hartmann6_reaches_low_regret_and_beats_random_search():
    bo = [_bo_regret(hartmann6, HARTMANN6_BOUNDS, HARTMANN6_MIN, 80, s, 20) for s in range(3)]
    rnd = [_random_regret(hartmann6, HARTMANN6_BOUNDS, HARTMANN6_MIN, 80, s) for s in range(3)]
    assert np.median(bo) < 0.01
    assert np.median(rnd) > 0.3
    assert all(b < r for b, r in zip(bo, rnd, strict=True))


def test_failing_region_is_learnt_and_avoided():
    """Points with x1 > 2.5 fail; the constrained Branin minimum (x1 = pi, 9.42 excluded) is 0.3979 at
    (-pi, 12.275). The optimizer must find it while proposing few points in the failing region."""
    opt = BayesianOptimizer(BRANIN_BOUNDS, seed_points=10, seed=0)
    failing_after_seeds = 0
    for i in range(50):
        theta = opt.ask()
        fails = theta["x1"] > 2.5
        failing_after_seeds += fails and i >= 10
        opt.tell(theta, None if fails else branin(theta))
    # Half the box fails; a model-free sampler would propose there half of the time.
    assert failing_after_seeds <= 6
    assert opt.best[1] - BRANIN_MIN < 1e-2
    assert opt.best[0]["x1"] < 0.0


def test_a_known_constraint_is_never_asked_and_the_search_learns_from_it():
    """Points with x1 > 2.5 are known beforehand not to run (a theta whose model has no drift): none is asked,
    the constrained minimum is found as when they are evaluated and fail, and with no constraint it changes
    nothing (the same proposals, bit for bit)."""
    opt = BayesianOptimizer(BRANIN_BOUNDS, seed_points=10, seed=0, feasible=lambda t: t["x1"] <= 2.5)
    asked = []
    for _ in range(50):
        theta = opt.ask()
        asked.append(theta)
        opt.tell(theta, branin(theta))
    assert all(t["x1"] <= 2.5 for t in asked) and len(opt.refused) > 0
    assert opt.best[1] - BRANIN_MIN < 1e-2 and opt.best[0]["x1"] < 0.0
    assert len(opt.refused) < 60  # refusals teach the classifier: far fewer than half the proposals after the design
    free, constrained = (BayesianOptimizer(BRANIN_BOUNDS, seed_points=6, seed=1, feasible=f)
                         for f in (None, lambda t: True))
    for _ in range(12):
        a, b = free.ask(), constrained.ask()
        assert a == b
        free.tell(a, branin(a))
        constrained.tell(b, branin(b))


def test_resume_from_history_gives_the_same_next_proposal():
    uninterrupted = BayesianOptimizer(BRANIN_BOUNDS, seed_points=8, seed=3)
    history = []
    for _ in range(27):
        theta = uninterrupted.ask()
        value = branin(theta) if theta["x2"] < 13 else None
        uninterrupted.tell(theta, value)
        history.append((theta, value))
    resumed = BayesianOptimizer(BRANIN_BOUNDS, seed_points=8, seed=3)
    for theta, value in history:
        resumed.tell(theta, value)
    for _ in range(3):
        a, b = uninterrupted.ask(), resumed.ask()
        assert a == b
        uninterrupted.tell(a, branin(a))
        resumed.tell(b, branin(b))


def test_a_design_point_lost_in_a_crash_is_run_once_and_none_twice():
    """Two design points in flight, the later one stored, then a crash: the resumed optimizer runs the lost one
    and never the stored one again (it used to ask design[n_issued], i.e. the stored point a second time)."""
    before = BayesianOptimizer(BRANIN_BOUNDS, seed_points=5, seed=0)
    design = [before.ask() for _ in range(5)]
    stored = design[:3] + design[4:]  # design[3] was in flight when the runner died
    resumed = BayesianOptimizer(BRANIN_BOUNDS, seed_points=5, seed=0)
    for theta in stored:
        resumed.tell(theta, branin(theta))
    assert resumed.ask() == design[3]
    later = [resumed.ask() for _ in range(3)]
    told = {tuple(sorted(t.items())) for t in stored + [design[3]] + later}
    assert len(told) == len(stored) + 1 + len(later)


def test_initial_points_are_asked_first_then_the_design_and_a_resume_keeps_the_order():
    start = {"x1": 0.0, "x2": 5.0}
    opt = BayesianOptimizer(BRANIN_BOUNDS, seed_points=5, seed=0, initial_points=[start])
    asked = [opt.ask() for _ in range(5)]
    assert asked[0] == pytest.approx(start)
    plain = BayesianOptimizer(BRANIN_BOUNDS, seed_points=4, seed=0)
    assert asked[1:] == [plain.ask() for _ in range(4)]  # the hypercube fills the rest of the budget
    resumed = BayesianOptimizer(BRANIN_BOUNDS, seed_points=5, seed=0, initial_points=[start])
    for theta in asked[1:3]:  # the first was lost in flight
        resumed.tell(theta, branin(theta))
    assert resumed.ask() == pytest.approx(start)
    with pytest.raises(ConfigError, match="initial_points"):
        BayesianOptimizer(BRANIN_BOUNDS, seed_points=5, initial_points=[{"x1": 20.0, "x2": 5.0}])


def test_pending_points_give_distinct_proposals():
    opt = BayesianOptimizer(BRANIN_BOUNDS, seed_points=5, seed=0)
    for _ in range(8):
        theta = opt.ask()
        opt.tell(theta, branin(theta))
    first, second = opt.ask(), opt.ask()
    assert first != second
    assert len(opt.pending) == 2


@pytest.mark.parametrize(("bounds", "field"), [({"k": (0.1, 0.1)}, "bounds.k"), ({"k": (1.0, 0.0)}, "bounds.k")])
def test_bad_bounds_name_the_field(bounds, field):
    with pytest.raises(ConfigError, match=field):
        BayesianOptimizer(bounds)


def test_the_surrogate_equals_sklearns_gp_and_its_likelihood_gradient_is_exact():
    """driftlab.core.surrogate against scikit-learn's GaussianProcessRegressor with the same fixed kernel, and the
    analytic log-likelihood gradient against central differences."""
    from sklearn.gaussian_process import GaussianProcessRegressor
    from sklearn.gaussian_process.kernels import ConstantKernel, Matern, WhiteKernel

    from driftlab.core.surrogate import GaussianProcess, Hyperparameters, log_marginal_likelihood

    rng = np.random.default_rng(3)
    x = rng.random((80, 4))
    y = np.sin(5 * x[:, 0]) + x[:, 1] ** 2 + 0.01 * rng.standard_normal(80)
    hp = Hyperparameters(np.array([0.3, 0.5, 0.8, 0.2]), 1.2, 1e-3)
    kernel = ConstantKernel(1.2, "fixed") * Matern([0.3, 0.5, 0.8, 0.2], "fixed", nu=2.5) + WhiteKernel(1e-3, "fixed")
    z = (y - y.mean()) / y.std()
    reference = GaussianProcessRegressor(kernel).fit(x, z)
    ours = GaussianProcess(x, z, hp)
    query = rng.random((200, 4))
    mean, std = ours.predict(query)
    ref_mean, ref_std = reference.predict(query, return_std=True)
    np.testing.assert_allclose(mean, ref_mean, atol=1e-9)
    np.testing.assert_allclose(std, np.sqrt(np.maximum(ref_std**2 - 1e-3, 0.0)), atol=1e-7)  # latent, no noise
    value, grad = log_marginal_likelihood(hp.as_log_vector(), x, z)
    assert value == pytest.approx(reference.log_marginal_likelihood_value_, rel=1e-9)
    h = 1e-6
    numeric = [(log_marginal_likelihood(hp.as_log_vector() + h * e, x, z)[0]
                - log_marginal_likelihood(hp.as_log_vector() - h * e, x, z)[0]) / (2 * h) for e in np.eye(6)]
    np.testing.assert_allclose(grad, numeric, rtol=1e-5, atol=1e-5)


def test_success_probability_is_sklearns_classifier_conditioned_and_predicting():
    """The Laplace conditioning written out gives sklearn's factors to the bit (so every proposal is what it was
    through sklearn's estimator), and P(success) its predict_proba."""
    from sklearn.gaussian_process import GaussianProcessClassifier
    from sklearn.gaussian_process.kernels import RBF, ConstantKernel

    from driftlab.core.failure_model import LabelKernel, SuccessProbability

    rng = np.random.default_rng(3)
    x = rng.random((300, 4))
    ok = (x[:, 0] + x[:, 3] < 1.2).astype(int)
    for constant, length_scales in ((4.0, np.full(4, 0.3)), (2.7182818, np.array([0.31, 0.07, 1.9, 0.45]))):
        kernel = ConstantKernel(constant) * RBF(length_scales)
        clf = GaussianProcessClassifier(kernel, optimizer=None, warm_start=True).fit(x, ok)
        ours = SuccessProbability.conditioned(LabelKernel(constant, length_scales), x, ok)
        fitted = clf.base_estimator_
        assert np.array_equal(ours.coef, fitted.y_train_ - fitted.pi_)
        assert np.array_equal(ours.w_sr, fitted.W_sr_)
        assert np.array_equal(ours.chol_lower, fitted.L_)
        query = rng.random((500, 4))
        np.testing.assert_allclose(ours(query), clf.predict_proba(query)[:, 1], atol=1e-10)


def test_the_erf_approximation_is_sklearns_and_its_fit():
    from scipy.special import erf, expit
    from sklearn.gaussian_process import _gpc

    from driftlab.core import failure_model

    assert np.array_equal(failure_model.LAMBDAS, _gpc.LAMBDAS) and np.array_equal(failure_model.COEFS, _gpc.COEFS)
    x = np.array([0.0, 0.6, 2.0, 3.5, 4.5, np.inf])  # the fit the weights come from, as sklearn's source states it
    weights = np.linalg.lstsq((erf(np.outer(x, failure_model.LAMBDAS[:, 0])) + 1) / 2, expit(x), rcond=None)[0]
    np.testing.assert_allclose(failure_model.COEFS[:, 0], weights, rtol=1e-9)


@pytest.mark.parametrize("dim", [1, 4])
def test_the_label_kernel_fit_is_sklearns_to_the_bit(dim):
    """The classifier's kernel learnt without sklearn's estimator: the same L-BFGS-B iterates on the same
    likelihood and gradient, so the same kernel (and every proposal as before)."""
    import warnings

    from sklearn.exceptions import ConvergenceWarning
    from sklearn.gaussian_process import GaussianProcessClassifier
    from sklearn.gaussian_process.kernels import RBF, ConstantKernel

    from driftlab.core.failure_model import LabelKernel, bounded_lbfgs

    rng = np.random.default_rng(dim)
    x = rng.random((80, dim))
    ok = (x[:, 0] + 0.3 * rng.standard_normal(80) < 0.6).astype(int)
    kernel = ConstantKernel(4.0, (1e-1, 1e3)) * RBF(np.full(dim, 0.3), (0.05, 5.0))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        reference = GaussianProcessClassifier(kernel, optimizer=bounded_lbfgs).fit(x, ok).kernel_
    ours = LabelKernel.start(dim).fitted(x, ok)
    assert ours.constant == reference.k1.constant_value
    assert np.array_equal(ours.length_scales, np.squeeze(reference.k2.length_scale))
    assert ours.constant != LabelKernel.start(dim).constant  # it moved


def test_pending_points_enter_by_a_block_update_equal_to_a_full_refactorization():
    """Kriging believer's pending points extend the Cholesky factor in O(n^2 q); the factor is the joint
    kernel matrix's."""
    from driftlab.core.surrogate import GaussianProcess, Hyperparameters, matern52

    rng = np.random.default_rng(4)
    x, y = rng.random((60, 4)), rng.standard_normal(60)
    base = GaussianProcess(x[:50], y[:50], Hyperparameters.default(4))
    updated = base.with_observations(x[50:], y[50:])
    joint = matern52(x, x, base.hp) + (base.hp.noise_variance + 1e-10) * np.eye(60)
    joint[50:, 50:] += 1e-12 * np.eye(10)
    np.testing.assert_allclose(updated.chol @ updated.chol.T, joint, atol=1e-10)
    mean, std = updated.predict(x[50:])
    np.testing.assert_allclose(mean, y[50:], atol=0.1)  # observed with noise 1e-3: the mean passes near them


def test_with_no_success_yet_it_searches_near_the_failure_that_got_furthest():
    # A small feasible island at (0.8, 0.2); failures score their distance to it (as a failed episode's penalty
    # falls with the fraction of the course driven). Space filling alone rarely lands in it.
    bounds = {"a": (0.0, 1.0), "b": (0.0, 1.0)}
    island = np.array([0.8, 0.2])

    def run(use_scores: bool) -> int:
        opt = BayesianOptimizer(bounds, seed_points=4, seed=3, initial_points=[{"a": 0.75, "b": 0.3}])
        for i in range(30):
            theta = opt.ask()
            d = float(np.hypot(theta["a"] - island[0], theta["b"] - island[1]))
            if d < 0.04:
                return i
            opt.tell(theta, None, 3.5 + d if use_scores else None)
        return 30

    assert run(use_scores=True) < 30  # finds the island from its closest failure
    assert run(use_scores=True) < run(use_scores=False)


def test_a_local_phase_spreads_its_points_around_the_first_initial_point_then_the_box():
    bounds = {"a": (0.0, 10.0), "b": (-1.0, 1.0), "c": (0.0, 1.0)}
    start = {"a": 9.0, "b": 0.0, "c": 0.5}
    opt = BayesianOptimizer(bounds, seed_points=10, seed=3, initial_points=[start], local_points=4,
                            local_radius=0.1)
    asked = [opt.ask() for _ in range(10)]
    assert asked[0] == start
    for theta in asked[1:5]:  # within 0.1 of each width around the start (clipped at the box)
        assert 8.0 <= theta["a"] <= 10.0 and -0.2 <= theta["b"] <= 0.2 and 0.4 <= theta["c"] <= 0.6
    spread = np.array([[t["a"], t["b"], t["c"]] for t in asked[5:]])
    assert np.ptp(spread[:, 0]) > 4.0  # the rest covers the box
    again = BayesianOptimizer(bounds, seed_points=10, seed=3, initial_points=[start], local_points=4,
                              local_radius=0.1)
    assert [again.ask() for _ in range(10)] == asked
    with pytest.raises(ConfigError, match=r"local_points must be an integer in \[0, 10\]"):
        BayesianOptimizer(bounds, seed_points=10, local_points=11)


def test_a_growing_trust_region_holds_the_named_dimensions_near_the_start_then_opens():
    bounds = {"a": (0.0, 1.0), "b": (0.0, 1.0)}
    start = {"a": 0.5, "b": 0.5}
    opt = BayesianOptimizer(bounds, seed_points=6, seed=1, initial_points=[start], local_points=5,
                            local_radius={"b": 0.05}, local_growth=10)
    asked = [opt.ask() for _ in range(6)]
    assert all(0.45 <= t["b"] <= 0.55 for t in asked)  # b near the start, a over its whole range
    assert np.ptp([t["a"] for t in asked]) > 0.6
    for t in asked:  # J rises with a's distance from 0.9 and b's from 0.95: outside the region's first box
        opt.tell(t, (t["a"] - 0.9) ** 2 + (t["b"] - 0.95) ** 2)
    for n in range(6, 16):
        theta = opt.ask()
        half_width = 0.05 + 0.95 * (n - 6) / 10
        assert abs(theta["b"] - 0.5) <= half_width + 1e-9
        opt.tell(theta, (theta["a"] - 0.9) ** 2 + (theta["b"] - 0.95) ** 2)
    assert opt.ask()["b"] > 0.6  # the region has opened: the GP goes where J is low
