"""The early stop of a losing theta (driftlab.core.pruning): the paired test on known numbers, and its settings in
the job document."""

import warnings

import numpy as np
import pytest
from scipy import stats

from driftlab.core.errors import ConfigError
from driftlab.core.pruning import DEFAULT_CONFIDENCE, DEFAULT_MIN_SEEDS, PruneRule, clearly_worse, paired_t_pvalue
from driftlab.core.tuning import TuningSpec

# The best so far on the job's four seeds, and its stored J (the mean over its 4 + 4 seeds).
INCUMBENT = {0: -1.50, 1: -1.42, 2: -1.55, 3: -1.47}
BEST_J = -1.49


def test_a_clearly_worse_candidate_stops_once_it_has_the_minimum_seeds():
    worse = {0: -0.90, 1: -0.85, 2: -0.93, 3: -0.88}  # ~0.6 worse on every seed, the same cars
    assert not clearly_worse({0: worse[0]}, INCUMBENT, best_J=BEST_J, min_seeds=2)
    assert clearly_worse({s: worse[s] for s in (0, 1)}, INCUMBENT, best_J=BEST_J, min_seeds=2)
    assert not clearly_worse({s: worse[s] for s in (0, 1)}, INCUMBENT, best_J=BEST_J, min_seeds=3)
    assert clearly_worse({s: worse[s] for s in (0, 1, 2)}, INCUMBENT, best_J=BEST_J, min_seeds=3)


def test_the_paired_t_test_is_scipys_to_the_bit():
    """The p-value the rule reads is scipy.stats.ttest_rel's (alternative "greater") to the last bit: random pairs of
    J-like values at 2 to 9 seeds, pairs a shift apart (equal differences: t infinite, or nan with no difference),
    and values far apart in size."""
    rng = np.random.default_rng(3)
    cases = []
    for n in range(2, 10):
        for _ in range(300):
            theirs = rng.normal(-1.5, 0.1, n)
            cases.append((theirs + rng.normal(rng.normal(0, 0.05), rng.uniform(1e-4, 0.2), n), theirs))
        base = rng.normal(-1.5, 0.1, n)
        cases += [(base + 0.25, base), (base, base), (base * 1e6 + rng.normal(0, 1, n), base)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        for ours, theirs in cases:
            expected = float(stats.ttest_rel(list(ours), list(theirs), alternative="greater").pvalue)
            got = paired_t_pvalue(list(ours), list(theirs))
            assert got == expected or (np.isnan(got) and np.isnan(expected)), (ours, theirs, got, expected)


def test_pairs_by_seed_not_by_position():
    # The candidate's seeds 1 and 3 are in (say seed 0's episode is still running): compared with seeds 1 and 3.
    assert clearly_worse({3: -0.88, 1: -0.85}, INCUMBENT, best_J=BEST_J)
    # A seed the incumbent never ran is no evidence.
    assert not clearly_worse({1: -0.85, 40: -0.9}, INCUMBENT, best_J=BEST_J)


def test_a_close_candidate_or_one_whose_differences_disagree_does_not_stop():
    close = {0: -1.47, 1: -1.43, 2: -1.50, 3: -1.46}  # a little worse on average, within the seeds' spread
    assert not any(clearly_worse({s: close[s] for s in list(close)[:n]}, INCUMBENT, best_J=BEST_J)
                   for n in range(1, 5))
    mixed = {0: -0.9, 1: -1.45}  # far worse on one seed, as good on the other: two seeds cannot tell
    assert not clearly_worse(mixed, INCUMBENT, best_J=BEST_J)


def test_a_better_candidate_never_stops():
    for shift in (0.0, -0.01, -0.3):
        better = {s: j + shift for s, j in INCUMBENT.items()}
        assert not any(clearly_worse({s: better[s] for s in list(better)[:n]}, INCUMBENT, best_J=BEST_J,
                                     confidence=0.5) for n in range(2, 5))


def test_the_confidence_level_decides_how_far_worse_is_enough():
    # Differences 0.30 and 0.40: t = 7 on one degree of freedom, one-sided p ~ 0.045.
    candidate = {0: -1.20, 1: -1.02}
    assert clearly_worse(candidate, INCUMBENT, best_J=BEST_J, confidence=0.95)
    assert not clearly_worse(candidate, INCUMBENT, best_J=BEST_J, confidence=0.99)


def test_never_a_mean_below_the_best_nor_a_failed_seed():
    # Worse than the incumbent on these two seeds, but easy seeds: its mean over them is below the stored best J,
    # and a pruned evaluation stored with it would become the job's best.
    assert not clearly_worse({0: -1.45, 1: -1.37}, INCUMBENT, best_J=-1.35)
    assert clearly_worse({0: -1.45, 1: -1.37}, INCUMBENT, best_J=-1.49, confidence=0.5)
    assert not clearly_worse({0: float("inf"), 1: -0.5}, INCUMBENT, best_J=BEST_J)


def test_the_rule_in_the_job_document():
    assert TuningSpec().prune == PruneRule(True, DEFAULT_CONFIDENCE, DEFAULT_MIN_SEEDS)
    assert TuningSpec.from_dict({}).prune.enabled  # a document without it (stored before it) takes the default
    spec = TuningSpec.from_dict({"prune": {"confidence": 0.99, "min_seeds": 3}})
    assert spec.prune == PruneRule(True, 0.99, 3)
    assert TuningSpec.from_dict(spec.to_dict()).prune == spec.prune
    off = TuningSpec.from_dict({"prune": {"enabled": False}})
    assert not off.prune.stops({0: 5.0, 1: 5.1}, INCUMBENT, BEST_J)
    assert not PruneRule().stops({0: 5.0, 1: 5.1}, None, None)  # no incumbent yet


@pytest.mark.parametrize("block, field", [
    ({"confidence": 1.0}, "prune.confidence"), ({"confidence": 0.2}, "prune.confidence"),
    ({"confidence": True}, "prune.confidence"), ({"min_seeds": 1}, "prune.min_seeds"),
    ({"min_seeds": 2.0}, "prune.min_seeds"), ({"enabled": "no"}, "prune.enabled"), ({"p": 0.05}, "prune.p"),
    ([], "prune"),
])
def test_a_bad_prune_block_is_refused_naming_the_field_and_range(block, field):
    with pytest.raises(ConfigError) as error:
        TuningSpec.from_dict({"prune": block})
    assert error.value.field == field
    if field in ("prune.confidence", "prune.min_seeds"):
        assert "[" in str(error.value)  # the range it must be in


def test_the_rule_at_the_api_and_the_cli_names_its_field(tmp_path):
    from driftlab.cli.options import prune_rule
    from tests.server.conftest import in_process_client

    with in_process_client(tmp_path / "api.db") as api:
        bad = api.post("/api/jobs", json={"iterations": 3, "prune": {"confidence": 1.5}})
        assert bad.status_code == 422 and "confidence" in bad.text
        assert api.post("/api/jobs", json={"iterations": 3, "prune": {"p": 0.05}}).status_code == 422
        job = api.post("/api/jobs", json={"iterations": 3, "prune": {"enabled": False}}).json()
        assert job["spec"]["prune"] == {"enabled": False, "confidence": DEFAULT_CONFIDENCE,
                                        "min_seeds": DEFAULT_MIN_SEEDS}
        assert api.post("/api/jobs", json={"iterations": 3}).json()["spec"]["prune"]["enabled"]
    from driftlab.cli import build_parser
    from driftlab.cli.tune import tuning_spec

    for given, rule in ((["--prune", "off"], PruneRule(enabled=False)), ([], PruneRule()),
                        (["--prune", "0.9,3"], PruneRule(True, 0.9, 3))):
        assert tuning_spec(build_parser().parse_args(["tune", *given])).prune == rule
    assert prune_rule("off") == PruneRule(enabled=False) and prune_rule(None) == PruneRule()
    assert prune_rule("0.99,3") == PruneRule(True, 0.99, 3)
    with pytest.raises(ConfigError, match="--prune must be"):
        prune_rule("0.99")
    with pytest.raises(ConfigError, match="prune.min_seeds"):
        prune_rule("0.99,1")
