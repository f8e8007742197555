"""intuitf.evaluator."""

from typing import TYPE_CHECKING

from intuitf._lazy import lazy_exports

if TYPE_CHECKING:  # the names below, for type checkers and editors
    from intuitf.evaluator.agreement import agreement_score as agreement_score
    from intuitf.evaluator.budget import Budget as Budget
    from intuitf.evaluator.cache import VerdictCache as VerdictCache
    from intuitf.evaluator.factory import make_judge as make_judge
    from intuitf.evaluator.metric import MetricJudge as MetricJudge
    from intuitf.evaluator.mllm import MLLMJudge as MLLMJudge
    from intuitf.evaluator.pricing import PriceTable as PriceTable
    from intuitf.evaluator.providers import PROVIDERS as PROVIDERS
    from intuitf.evaluator.tournament import MatchRecord as MatchRecord
    from intuitf.evaluator.tournament import SwissTournament as SwissTournament
    from intuitf.evaluator.tournament import TournamentResult as TournamentResult
    from intuitf.intent.aspects import AspectCatalogue as AspectCatalogue
    from intuitf.intent.aspects import aspects_for as aspects_for
    from intuitf.intent.aspects import aspects_for_intent as aspects_for_intent
    from intuitf.intent.aspects import load_aspects as load_aspects

_EXPORTS = {
    "agreement_score": "intuitf.evaluator.agreement",
    "AspectCatalogue": "intuitf.intent.aspects",
    "aspects_for": "intuitf.intent.aspects",
    "aspects_for_intent": "intuitf.intent.aspects",
    "load_aspects": "intuitf.intent.aspects",
    "Budget": "intuitf.evaluator.budget",
    "VerdictCache": "intuitf.evaluator.cache",
    "make_judge": "intuitf.evaluator.factory",
    "MetricJudge": "intuitf.evaluator.metric",
    "MLLMJudge": "intuitf.evaluator.mllm",
    "PriceTable": "intuitf.evaluator.pricing",
    "PROVIDERS": "intuitf.evaluator.providers",
    "MatchRecord": "intuitf.evaluator.tournament",
    "SwissTournament": "intuitf.evaluator.tournament",
    "TournamentResult": "intuitf.evaluator.tournament",
}

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

__all__ = [
    "AspectCatalogue",
    "Budget",
    "MLLMJudge",
    "MatchRecord",
    "MetricJudge",
    "PROVIDERS",
    "PriceTable",
    "SwissTournament",
    "TournamentResult",
    "VerdictCache",
    "agreement_score",
    "aspects_for",
    "aspects_for_intent",
    "load_aspects",
    "make_judge",
]
