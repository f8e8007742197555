"""The names of the search methods, apart from their code (the command line lists them)."""

#: ``make_explorer`` methods: the genetic algorithm, the authors' GA settings, CMA-ES, random.
METHODS = ("ga", "paper-ga", "cmaes", "random")
