"""intuitf.evaluator."""

# Model judge, aspects and its plumbing (explicit re-exports).
from intuitf.evaluator.agreement import agreement_score as agreement_score
from intuitf.evaluator.aspects import AspectCatalogue as AspectCatalogue
from intuitf.evaluator.aspects import aspects_for as aspects_for
from intuitf.evaluator.aspects import aspects_for_intent as aspects_for_intent
from intuitf.evaluator.aspects import load_aspects as load_aspects
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
