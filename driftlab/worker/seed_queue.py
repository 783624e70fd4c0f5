"""A job's asked evaluations and the order their episodes start in: one episode per seed, a failed seed drops the
evaluation's unstarted seeds, and the prune rule (driftlab.core.pruning) stops a theta whose first seeds are clearly
worse than the incumbent's on the same seeds."""

from __future__ import annotations

from dataclasses import dataclass, field

from driftlab.core.pruning import PruneRule
from driftlab.core.robust import RobustScore, SampleResult, aggregate
from driftlab.worker.executors import EpisodeOutcome


@dataclass
class PendingEvaluation:
    """One asked theta whose episodes (one per seed) are running."""

    theta: dict[str, float]
    seeds: list[int]
    outcomes: dict[int, EpisodeOutcome] = field(default_factory=dict)
    confirming: bool = False
    enqueued_id: int | None = None  # an enqueued theta's row (driftlab.db.enqueued), not the optimizer's proposal
    pruned: bool = False  # stopped early, worse than the best (SeedQueue.prune_if_worse); scored on the seeds it read
    tested: int = 0  # the longest prefix of its seeds the prune rule has looked at

    @property
    def done(self) -> bool:
        # every seed it is scored on is in (a pruned one may have another episode still running, not waited for)
        return all(seed in self.outcomes for seed in self.seeds)

    def score(self) -> tuple[RobustScore, list[SampleResult], EpisodeOutcome]:
        ordered = [self.outcomes[s] for s in self.seeds]
        samples = [o.sample for o in ordered]
        score = aggregate(samples)
        return score, samples, ordered[score.representative]


class SeedQueue:
    """The (evaluation, seed) episodes asked and not started yet, in the order asked, and the incumbent the prune
    rule compares with: the best J so far and that evaluation's J on each of its seeds."""

    def __init__(self, rule: PruneRule, best_J: float | None, incumbent_J: dict[int, float] | None,
                 deterministic: bool) -> None:
        self.rule, self.best_J, self.incumbent_J, self.deterministic = rule, best_J, incumbent_J, deterministic
        self._waiting: list[tuple[PendingEvaluation, int]] = []

    def __bool__(self) -> bool:
        return bool(self._waiting)

    def add(self, evaluation: PendingEvaluation, seeds: list[int]) -> None:
        self._waiting.extend((evaluation, seed) for seed in seeds)

    def clear(self) -> None:
        self._waiting.clear()

    def new_best(self, best_J: float, incumbent_J: dict[int, float]) -> None:
        self.best_J, self.incumbent_J = best_J, incumbent_J

    def any_startable(self) -> bool:
        """Whether an episode waits that may start now (one held back for the prune rule may not)."""
        return any(not self._held_back(e, seed) for e, seed in self._waiting)

    def pop_startable(self) -> tuple[PendingEvaluation, int]:
        """The first waiting episode that may start now, taken off the queue (:meth:`any_startable` first)."""
        ready = next(i for i, (e, seed) in enumerate(self._waiting) if not self._held_back(e, seed))
        return self._waiting.pop(ready)

    def _drop(self, evaluation: PendingEvaluation) -> set[int]:
        dropped = {seed for queued, seed in self._waiting if queued is evaluation}
        self._waiting = [(queued, seed) for queued, seed in self._waiting if queued is not evaluation]
        return dropped

    def skip_unstarted(self, evaluation: PendingEvaluation) -> None:
        """One of the evaluation's seeds failed, so the evaluation fails whatever the others do (it completes only
        if every seed does): its seeds not started yet are dropped, and it is scored and stored with the seeds that
        ran (J: their mean). In the job default's 500-run 310 of 500 evaluations failed, 295 of them within their
        first two seeds, and failed evaluations took 57 % of the workers' time. Not in a deterministic job: which
        seeds had started when the failure came back depends on the workers' timing."""
        skipped = self._drop(evaluation)
        if skipped:
            evaluation.seeds = [seed for seed in evaluation.seeds if seed not in skipped]

    def prune_if_worse(self, evaluation: PendingEvaluation) -> None:
        """Stop an evaluation whose first seeds are worse than the incumbent's on the same seeds with confidence
        (driftlab.core.pruning): its seeds not started yet are dropped and it is scored on the seeds the decision
        read (told to the optimizer as their mean, a completed value). A would-be best is confirming and never stops
        here.

        The rule reads the prefix of the evaluation's seeds, in the job's order, that have come back completed, and
        each prefix length once, shortest first: it stops at the shortest prefix that is clearly worse, whichever
        order the episodes came back in, so in a deterministic job (one evaluation at a time, the incumbent fixed
        while it runs) what is stored and told depends on the episodes' results only, never on the workers' timing.
        An episode that had started beyond that prefix is not waited for, and its result is not used: which had
        started is timing, and a pruned evaluation's mean must be the mean the rule judged (above the best J: it
        must never become the best). Outside a deterministic job an evaluation with a failed seed is a failure
        (:meth:`skip_unstarted`), told as one, and is not pruned; in a deterministic one a failure after the prefix
        the rule stopped at is not used, as any other seed after it (whether it was in first is timing)."""
        if evaluation.confirming or evaluation.pruned or not self.rule.enabled or self.incumbent_J is None:
            return
        if not self.deterministic and any(not o.completed for o in evaluation.outcomes.values()):
            return
        prefix: dict[int, float] = {}
        for seed in evaluation.seeds:
            outcome = evaluation.outcomes.get(seed)
            if outcome is None or not outcome.completed:
                break
            prefix[seed] = outcome.J
        seeds = list(prefix)[:len(evaluation.seeds) - 1]  # with every seed in there is nothing left to save
        while evaluation.tested < len(seeds):
            evaluation.tested += 1
            decided = seeds[:evaluation.tested]
            if self.rule.stops({s: prefix[s] for s in decided}, self.incumbent_J, self.best_J):
                evaluation.pruned = True
                evaluation.seeds = decided
                self._drop(evaluation)
                return

    def _held_back(self, evaluation: PendingEvaluation, seed: int) -> bool:
        """Whether a seed of the evaluation waits to start: until its first seed is back (not in a deterministic job,
        which drops no seed on a failure): a seed started beside a first that failed ran for nothing (in the job
        default's 500-run, 10-15 % of the episodes' simulated time); and until its first ``min_seeds`` are back while
        the prune rule can stop the theta (it is on, there is a best), or a seed started before the rule decided
        runs for nothing if the theta stops. The workers take the next theta's seeds meanwhile. A would-be best's
        confirmation seeds start at once: every seed before them is back."""
        first = evaluation.seeds[0]
        if not self.deterministic and seed != first and first not in evaluation.outcomes:
            return True
        if evaluation.confirming or evaluation.pruned or not self.rule.enabled or self.incumbent_J is None:
            return False
        leading = evaluation.seeds[:self.rule.min_seeds]
        return seed not in leading and not all(s in evaluation.outcomes for s in leading)
